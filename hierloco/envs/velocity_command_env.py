"""The velocity-command environment: B robots learning to track a commanded CoM velocity at 100 Hz (SAC-SAC's low
level, Li et al., RA-L 2021, baselines).

One step is one 100 Hz control step (5 physics steps) for all B robots of a :class:`BatchedSimulator`, in one
``sim.run(targets[:, None])`` call. The action (``B x J`` in ``[-1, 1]``) sets joint targets as offsets around the
standing pose, ``standing + action_scale * action`` clipped to the joint range, tracked by the robot's position
servos. The observation (``B x D``, :class:`VelocityCommandInterface`) holds the joint positions (relative to the
standing pose) and velocities, roll and pitch, the base angular rate, the CoM velocity in the local frame, the command
``(vx, vy, yaw_rate)`` (local frame, m/s and rad/s), a phase clock (sine and cosine of ``2 pi t / gait_period``) and
the previous action. The reward is a sum of named terms, each returned under ``("reward_terms", <term>)``:

- ``tracking_linear``: ``exp(-||v_cmd - v||^2 / linear_sigma)``, v the local-frame CoM velocity (m/s);
- ``tracking_yaw``: ``exp(-(yaw_rate_cmd - yaw_rate)^2 / yaw_sigma)``;
- ``alive``: 1 while the robot has not fallen;
- ``torque``: ``-mean_j (tau_j / tau_max_j)^2``, the servo torques relative to their limits;
- ``action_rate``: ``-mean_j (a_j - a_prev_j)^2``;
- ``orientation``: ``-(roll^2 + pitch^2)`` (rad^2);

each scaled by its weight (``DEFAULT_REWARD_WEIGHTS``). A fall (roll or pitch beyond the robot's limits, the base
below its minimum height, or a physics blow-up) terminates the robot's episode; the time limit truncates it.
Commands are drawn uniformly from the robot's command box (``robot.command_low/high``) at reset and every
``command_interval`` seconds.

Example:
    >>> import torch
    >>> from torchrl.envs.utils import check_env_specs
    >>> env = VelocityCommandEnv("a1", num_robots=4, seed=0)
    >>> check_env_specs(env)
    >>> td = env.rollout(10)
    >>> td["next", "reward_terms", "tracking_linear"].shape
    torch.Size([4, 10, 1])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.frames import quat_to_roll_pitch_yaw, world_to_local, yaw_rate_from_base
from hierloco.envs.robots import (
    CONTROL_TIMESTEP,
    RobotSpec,
    compile_model,
    get_robot,
    joint_qpos_indices,
    joint_qvel_indices,
)

REWARD_TERMS = ("tracking_linear", "tracking_yaw", "alive", "torque", "action_rate", "orientation")
DEFAULT_REWARD_WEIGHTS = {"tracking_linear": 1.0, "tracking_yaw": 0.5, "alive": 0.2, "torque": 0.05,
                          "action_rate": 0.05, "orientation": 1.0}

# observation scales: each block of the observation is of order 1 for a walking robot
JOINT_VELOCITY_SCALE = 0.05  # per rad/s
ANGULAR_VELOCITY_SCALE = 0.25  # per rad/s
LINEAR_VELOCITY_SCALE = 2.0  # per m/s (commands and velocities, the command box is about +-0.3 m/s)


@dataclass(frozen=True)
class VelocityCommandInterface:
    """What a velocity-command policy sees and how its action becomes joint targets (shared by
    :class:`VelocityCommandEnv` and :class:`hierloco.components.sac_low_level.SACLowLevel`).

    Build it with :meth:`for_robot`. All methods take and return NumPy arrays with ``B`` leading.

    Attributes:
        robot: the robot.
        action_scale: rad of joint-target offset per unit of action.
        gait_period: period of the phase clock in s.
        joint_low, joint_high: ``J`` joint (servo) ranges in rad.
        torque_limit: ``J`` servo torque limits in N m.
    """

    robot: RobotSpec
    action_scale: float
    gait_period: float
    joint_low: np.ndarray
    joint_high: np.ndarray
    torque_limit: np.ndarray
    kp: np.ndarray
    kv: np.ndarray
    joint_qpos: np.ndarray
    joint_qvel: np.ndarray

    @classmethod
    def for_robot(cls, robot: str | RobotSpec, *, action_scale: float = 0.3,
                  gait_period: float | None = None) -> "VelocityCommandInterface":
        """The interface of ``robot``: joint ranges, servo gains and torque limits are read from its model.

        Args:
            robot: a registered robot name or a :class:`RobotSpec`.
            action_scale: rad of joint-target offset per unit of action (actions are in ``[-1, 1]``).
            gait_period: phase-clock period in s (default: the robot's ``gait_period``).
        """
        robot = get_robot(robot)
        gait_period = robot.gait_period if gait_period is None else float(gait_period)
        if not (action_scale > 0 and gait_period > 0):
            raise ValueError(f"action_scale and gait_period must be positive, got {action_scale}, {gait_period}")
        model = compile_model(robot)
        limited = model.actuator_ctrllimited.astype(bool)
        low = np.where(limited, model.actuator_ctrlrange[:, 0], -np.pi)
        high = np.where(limited, model.actuator_ctrlrange[:, 1], np.pi)
        force_limited = model.actuator_forcelimited.astype(bool)
        torque_limit = np.where(force_limited, model.actuator_forcerange[:, 1], model.actuator_gainprm[:, 0])
        return cls(robot, float(action_scale), gait_period, low.copy(), high.copy(), torque_limit.copy(),
                   model.actuator_gainprm[:, 0].copy(), -model.actuator_biasprm[:, 2].copy(),
                   joint_qpos_indices(model, robot), joint_qvel_indices(model, robot))

    @property
    def num_joints(self) -> int:
        return self.robot.num_joints

    @property
    def observation_size(self) -> int:
        """``D`` = 3 J + 12: joint positions, velocities and the previous action (J each), roll and pitch (2),
        angular rate (3), local CoM velocity (2), command (3), phase clock (2)."""
        return 3 * self.num_joints + 12

    def describe(self) -> dict:
        return {"robot": self.robot.name, "action_scale": self.action_scale, "gait_period": self.gait_period}

    def joint_targets(self, action: np.ndarray) -> np.ndarray:
        """``B x J`` actions in ``[-1, 1]`` -> ``B x J`` joint targets in rad, inside the joint ranges."""
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        standing = np.asarray(self.robot.standing_pose)
        return np.clip(standing + self.action_scale * action, self.joint_low, self.joint_high)

    def torques(self, targets: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """``B x J`` servo torques in N m for joint ``targets`` at the state ``(qpos, qvel)`` (``B x nq``,
        ``B x nv``): ``kp (target - q) - kv qdot`` clipped to the torque limits."""
        q, qdot = qpos[:, self.joint_qpos], qvel[:, self.joint_qvel]
        return np.clip(self.kp * (targets - q) - self.kv * qdot, -self.torque_limit, self.torque_limit)

    def base_motion(self, qpos: np.ndarray, qvel: np.ndarray) -> dict:
        """The base's ``roll_pitch`` (``B x 2``, rad), ``angular_velocity_local`` (``B x 3``, body frame, rad/s),
        ``com_velocity_local`` (``B x 2``, forward and left, m/s) and ``yaw_rate`` (``B``, rad/s)."""
        quat = qpos[:, 3:7]
        rpy = quat_to_roll_pitch_yaw(quat)
        return {"roll_pitch": rpy[:, :2], "angular_velocity_local": qvel[:, 3:6],
                "com_velocity_local": world_to_local(qvel[:, 0:2], rpy[:, 2]),
                "yaw_rate": yaw_rate_from_base(quat, qvel[:, 3:6])}

    def phase_features(self, time: np.ndarray) -> np.ndarray:
        """``B`` times in s -> ``B x 2`` ``(sin, cos)`` of the gait phase ``2 pi t / gait_period``."""
        angle = 2 * np.pi * np.asarray(time, dtype=np.float64) / self.gait_period
        return np.stack([np.sin(angle), np.cos(angle)], -1)

    def observe(self, qpos: np.ndarray, qvel: np.ndarray, command: np.ndarray, time: np.ndarray,
                last_action: np.ndarray) -> np.ndarray:
        """The ``B x D`` float32 observation at the state ``(qpos, qvel)`` (``B x nq``, ``B x nv``) for ``B x 3``
        commands, ``B`` clock times (s) and ``B x J`` previous actions."""
        motion = self.base_motion(qpos, qvel)
        standing = np.asarray(self.robot.standing_pose)
        command = np.asarray(command, dtype=np.float64)
        parts = [qpos[:, self.joint_qpos] - standing, JOINT_VELOCITY_SCALE * qvel[:, self.joint_qvel],
                 motion["roll_pitch"], ANGULAR_VELOCITY_SCALE * motion["angular_velocity_local"],
                 LINEAR_VELOCITY_SCALE * motion["com_velocity_local"], LINEAR_VELOCITY_SCALE * command[:, :2],
                 command[:, 2:3], self.phase_features(time), np.asarray(last_action, dtype=np.float64)]
        return np.concatenate(parts, -1).astype(np.float32)


def reward_terms(motion: Mapping[str, np.ndarray], command: np.ndarray, torques: np.ndarray,
                 torque_limit: np.ndarray, action: np.ndarray, last_action: np.ndarray, failed: np.ndarray, *,
                 linear_sigma: float, yaw_sigma: float) -> dict[str, np.ndarray]:
    """The unweighted reward terms (``B`` each) of one control step (see the module docstring).

    Args:
        motion: :meth:`VelocityCommandInterface.base_motion` after the step.
        command: ``B x 3`` ``(vx, vy, yaw_rate)`` in the local frame, m/s and rad/s.
        torques: ``B x J`` servo torques in N m; torque_limit: ``J`` limits in N m.
        action, last_action: ``B x J`` actions of this step and the previous one.
        failed: ``B`` bool, the robot fell (or its physics blew up) during the step.
        linear_sigma: m^2/s^2; yaw_sigma: rad^2/s^2, widths of the tracking kernels.
    """
    linear_error = np.sum((command[:, :2] - motion["com_velocity_local"]) ** 2, -1)
    yaw_error = (command[:, 2] - motion["yaw_rate"]) ** 2
    return {
        "tracking_linear": np.exp(-linear_error / linear_sigma),
        "tracking_yaw": np.exp(-yaw_error / yaw_sigma),
        "alive": (~np.asarray(failed, dtype=bool)).astype(np.float64),
        "torque": -np.mean((torques / torque_limit) ** 2, -1),
        "action_rate": -np.mean((np.asarray(action) - np.asarray(last_action)) ** 2, -1),
        "orientation": -np.sum(motion["roll_pitch"] ** 2, -1),
    }


class VelocityCommandEnv(EnvBase):
    """B robots tracking velocity commands, one 100 Hz control step per env step (see the module docstring).

    Args:
        robot: a registered robot name or a :class:`RobotSpec`.
        num_robots: B, the env's batch size.
        action_scale: rad of joint-target offset per unit of action.
        command_low, command_high: the command box ``(vx, vy, yaw_rate)`` (default the robot's).
        command_interval: s between command resamplings.
        episode_length: s before an episode is truncated.
        gait_period: phase-clock period in s (default the robot's).
        reward_weights: weight per term of ``REWARD_TERMS`` (missing terms keep ``DEFAULT_REWARD_WEIGHTS``).
        linear_sigma: width of the linear tracking kernel, m^2/s^2; yaw_sigma: of the yaw-rate kernel, rad^2/s^2.
        disabled_legs: legs locked at their standing angles.
        init_joint_noise: rad of uniform noise on the standing joint angles at reset.
        seed: seeds the reset noise and the commands (and the pushes and randomised dynamics).
        nthread: simulation threads.
        terrain, pushes, randomization: the ground, pushes on the trunk and randomised dynamics (a name or mapping
            of options each, or the built object), passed to the batched simulator
            (:class:`hierloco.envs.batched_sim.BatchedSimulator`, ``docs/terrain.md``): the robots learn on that
            ground, are pushed as they learn and meet new dynamics at every reset. Default: flat, none, nominal.

    Besides ``observation`` the env returns ``command`` (``B x 3``, the command now in force) and, for the step
    just taken, ``tracking_error`` (``B x 1``, ``||v_cmd - v||`` in m/s for the command the step was rewarded for)
    and ``("reward_terms", term)`` (``B x 1`` each, weighted; they sum to ``reward``).
    """

    def __init__(self, robot: str | RobotSpec, num_robots: int = 1, *, action_scale: float = 0.3,
                 command_low: Sequence[float] | None = None, command_high: Sequence[float] | None = None,
                 command_interval: float = 3.0, episode_length: float = 10.0, gait_period: float | None = None,
                 reward_weights: Mapping[str, float] | None = None, linear_sigma: float = 0.04,
                 yaw_sigma: float = 0.1, disabled_legs: Sequence[str] = (), init_joint_noise: float = 0.02,
                 seed: int | None = None, nthread: int | None = None, device: str = "cpu", terrain=None,
                 pushes=None, randomization=None):
        robot = get_robot(robot)
        b = int(num_robots)
        if b < 1:
            raise ValueError(f"num_robots must be at least 1, got {num_robots}")
        weights = dict(DEFAULT_REWARD_WEIGHTS)
        unknown = set(reward_weights or {}) - set(REWARD_TERMS)
        if unknown:
            raise ValueError(f"unknown reward terms {sorted(unknown)}; the terms are {list(REWARD_TERMS)}")
        weights.update({k: float(v) for k, v in (reward_weights or {}).items()})
        low = np.asarray(robot.command_low if command_low is None else command_low, dtype=np.float64)
        high = np.asarray(robot.command_high if command_high is None else command_high, dtype=np.float64)
        if low.shape != (3,) or high.shape != (3,) or np.any(low > high):
            raise ValueError(f"the command box must be two 3-vectors with low <= high, got {low}, {high}")
        if not (command_interval > 0 and episode_length > 0 and linear_sigma > 0 and yaw_sigma > 0):
            raise ValueError("command_interval, episode_length, linear_sigma and yaw_sigma must be positive, got "
                             f"{command_interval}, {episode_length}, {linear_sigma}, {yaw_sigma}")
        super().__init__(batch_size=torch.Size([b]), device=device)
        self.robot = robot
        self.interface = VelocityCommandInterface.for_robot(robot, action_scale=action_scale, gait_period=gait_period)
        self.sim = BatchedSimulator(robot, b, disabled_legs=disabled_legs, init_joint_noise=init_joint_noise,
                                    seed=seed, nthread=nthread, terrain=terrain, pushes=pushes,
                                    randomization=randomization)
        self.command_low, self.command_high = low, high
        self.command_steps = max(1, int(round(command_interval / CONTROL_TIMESTEP)))
        self.episode_steps = max(1, int(round(episode_length / CONTROL_TIMESTEP)))
        self.reward_weights = weights
        self.linear_sigma, self.yaw_sigma = float(linear_sigma), float(yaw_sigma)
        self._rng = np.random.default_rng(seed)
        j = robot.num_joints
        self._step_count = np.zeros(b, dtype=np.int64)
        self._command = np.zeros((b, 3))
        self._last_action = np.zeros((b, j))
        self.failures = 0  # robots that fell or blew up, over the env's life

        dim = self.interface.observation_size
        observation = {"observation": Unbounded((b, dim), device=self.device),
                       "command": Unbounded((b, 3), device=self.device),
                       "tracking_error": Unbounded((b, 1), device=self.device),
                       "reward_terms": Composite({term: Unbounded((b, 1), device=self.device) for term in REWARD_TERMS},
                                                 shape=(b,), device=self.device)}
        self.observation_spec = Composite(observation, shape=(b,), device=self.device)
        self.action_spec = Bounded(-torch.ones(b, j, device=self.device), torch.ones(b, j, device=self.device), (b, j),
                                  device=self.device)
        self.reward_spec = Unbounded((b, 1), device=self.device)
        flag = Categorical(2, (b, 1), dtype=torch.bool, device=self.device)
        self.done_spec = Composite(done=flag, terminated=flag.clone(), truncated=flag.clone(), shape=(b,),
                                   device=self.device)

    # ------------------------------------------------------------------ helpers
    def sample_commands(self, count: int) -> np.ndarray:
        """``count x 3`` commands drawn uniformly from the command box."""
        return self._rng.uniform(self.command_low, self.command_high, (count, 3))

    def _tensor(self, array, dtype=torch.float32) -> torch.Tensor:
        return torch.as_tensor(np.asarray(array), dtype=dtype, device=self.device)

    def _observation(self) -> np.ndarray:
        return self.interface.observe(self.sim.qpos, self.sim.qvel, self._command,
                                      self._step_count * CONTROL_TIMESTEP, self._last_action)

    # ------------------------------------------------------------------ EnvBase
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        b = self.batch_size[0]
        mask = np.ones(b, dtype=bool)
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(-1).cpu().numpy().astype(bool)
        self.sim.reset(mask)
        index = np.flatnonzero(mask)
        self._step_count[index] = 0
        self._command[index] = self.sample_commands(len(index))
        self._last_action[index] = 0.0
        done = torch.zeros((b, 1), dtype=torch.bool, device=self.device)
        zeros = torch.zeros((b, 1), device=self.device)
        return TensorDict({"observation": self._tensor(self._observation()), "command": self._tensor(self._command),
                           "tracking_error": zeros.clone(),
                           "reward_terms": {term: zeros.clone() for term in REWARD_TERMS},
                           "done": done, "terminated": done.clone(), "truncated": done.clone()},
                          batch_size=self.batch_size, device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action").detach().cpu().numpy().astype(np.float64)
        action = np.clip(action.reshape(self.batch_size[0], -1), -1.0, 1.0)
        targets = self.interface.joint_targets(action)
        result = self.sim.run(targets[:, None])
        qpos, qvel = self.sim.qpos, self.sim.qvel
        failed = result.failed[:, -1]
        self.failures += int(failed.sum())
        motion = self.interface.base_motion(qpos, qvel)
        terms = reward_terms(motion, self._command, self.interface.torques(targets, qpos, qvel),
                             self.interface.torque_limit, action, self._last_action, failed,
                             linear_sigma=self.linear_sigma, yaw_sigma=self.yaw_sigma)
        weighted = {term: self.reward_weights[term] * value for term, value in terms.items()}
        reward = sum(weighted.values())
        tracking_error = np.linalg.norm(self._command[:, :2] - motion["com_velocity_local"], axis=-1)

        self._step_count += 1
        self._last_action = action
        resample = (self._step_count % self.command_steps == 0) & ~failed
        self._command[resample] = self.sample_commands(int(resample.sum()))
        truncated = (self._step_count >= self.episode_steps) & ~failed
        b = self.batch_size
        terminated = self._tensor(failed, torch.bool)[:, None]
        truncated = self._tensor(truncated, torch.bool)[:, None]
        return TensorDict({"observation": self._tensor(self._observation()),
                           "command": self._tensor(self._command),
                           "tracking_error": self._tensor(tracking_error)[:, None],
                           "reward_terms": {term: self._tensor(v)[:, None] for term, v in weighted.items()},
                           "reward": self._tensor(reward)[:, None],
                           "done": terminated | truncated, "terminated": terminated, "truncated": truncated},
                          batch_size=b, device=self.device)

    def close(self, *, raise_if_closed: bool = True) -> None:
        self.sim.close()
        super().close(raise_if_closed=raise_if_closed)

    def _set_seed(self, seed: int | None) -> None:
        self.sim.seed(seed)
        self._rng = np.random.default_rng(seed)

