"""SAC-SAC's low level: a SAC policy at 100 Hz that tracks a commanded CoM velocity (Li et al., RA-L 2021,
baselines: "a low-level policy designed to reach sub-goals" trained with model-free RL, then a goal-conditioned SAC
high level over its command).

- :func:`train_sac_low_level` trains the policy with TorchRL's ``SACLoss`` on
  :class:`hierloco.envs.velocity_command_env.VelocityCommandEnv` (B robots per step), checkpoints periodically
  (atomically: agent, optimiser, replay buffer, learning curve) and resumes from the checkpoint when restarted.
- :class:`TrainedSACLowLevel` is the artifact (policy + observation/action interface + metadata with the learning
  curve); :class:`SACLowLevel` is the :class:`~hierloco.components.low_level.LowLevel` whose action is the velocity
  command, executed closed loop by the deterministic actor for N control steps on every robot, so that the
  latent-action env, the dynamics data, MPC and the SAC high level run on it unchanged.
- :func:`evaluate_velocity_tracking` measures any velocity-command low level (this one or the IK expert) on a grid
  of commands: commanded vs achieved velocity and falls.

Example:
    >>> trained = train_sac_low_level("a1", total_frames=512, num_robots=8, init_random_frames=256, batch_size=64,
    ...                               hidden=32, progress=False)
    >>> low = SACLowLevel(trained, steps_per_action=10)
    >>> report = evaluate_velocity_tracking(low, command_grid("a1", 2), num_actions=2, settle_actions=1)
    >>> len(report["rows"]), sorted(report["summary"])[:2]
    (8, ['fall_rate', 'linear_error_max'])
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import torch

from hierloco.envs.low_level import LOW_LEVELS, LowLevel
from hierloco.components.sac import PAPER_BATCH_SIZE, PAPER_HIDDEN, PAPER_LR, SACAgent, torch_threads, train_sac
from hierloco.envs.batched_sim import BatchedSimulator, SimulationResult
from hierloco.envs.robots import CONTROL_TIMESTEP, RobotSpec, get_robot
from hierloco.envs.velocity_command_env import REWARD_TERMS, VelocityCommandEnv, VelocityCommandInterface
from hierloco.io import load_checkpoint, save_checkpoint

CHECKPOINT_KIND, CHECKPOINT_FORMAT = "sac_low_level", 1


@dataclass
class TrainedSACLowLevel:
    """A trained velocity-command policy: the SAC agent, the interface it was trained with, and ``metadata``
    (training settings, frames, updates, wall-clock, ``learning_curve``)."""

    agent: SACAgent
    interface: VelocityCommandInterface
    metadata: dict

    def save(self, path: str | os.PathLike) -> None:
        """Writes a checkpoint (agent with optimiser, interface, metadata) to ``path`` atomically."""
        save_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, {
            "agent": self.agent.state(), "interface": self.interface.describe(), "metadata": self.metadata})

    @classmethod
    def load(cls, path: str | os.PathLike, map_location="cpu") -> "TrainedSACLowLevel":
        payload = load_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, map_location)
        interface = VelocityCommandInterface.for_robot(**payload["interface"])
        return cls(SACAgent.from_state(payload["agent"]), interface, payload["metadata"])


def tracking_diagnostics(next_td) -> dict:
    """Per-frame means of one step of :class:`VelocityCommandEnv`: ``reward``, ``tracking_error`` (m/s),
    ``falls_per_1000_frames`` and each weighted ``reward/<term>``."""
    return {"reward": float(next_td["reward"].mean()), "tracking_error": float(next_td["tracking_error"].mean()),
            "falls_per_1000_frames": 1000.0 * float(next_td["terminated"].float().mean()),
            **{f"reward/{term}": float(next_td["reward_terms", term].mean()) for term in REWARD_TERMS}}


def train_sac_low_level(
    robot: str | RobotSpec,
    *,
    total_frames: int,
    num_robots: int = 64,
    hidden: int = PAPER_HIDDEN,
    num_layers: int = 2,
    lr: float = PAPER_LR,
    batch_size: int = PAPER_BATCH_SIZE,
    gamma: float = 0.99,
    tau: float = 0.005,
    alpha_init: float = 0.1,
    updates_per_frame: float = 1 / 32,
    init_random_frames: int = 10_000,
    buffer_size: int = 200_000,
    action_scale: float = 0.3,
    command_interval: float = 3.0,
    episode_length: float = 10.0,
    reward_weights: Mapping[str, float] | None = None,
    init_joint_noise: float = 0.02,
    log_every: int = 10_000,
    checkpoint_path: str | os.PathLike | None = None,
    checkpoint_every: int = 100_000,
    compile_update: bool | str = False,
    torch_threads_during: int | None = 1,
    nthread: int | None = None,
    seed: int = 0,
    device="cpu",
    progress: bool = False,
    logger=None,
    terrain=None,
    pushes=None,
    randomization=None,
) -> TrainedSACLowLevel:
    """Trains a SAC policy to track velocity commands on ``num_robots`` robots at once (:func:`train_sac` on
    :class:`VelocityCommandEnv`).

    Each env step advances every robot by one 100 Hz control step (``num_robots`` frames); after
    ``init_random_frames`` uniformly random frames the actor explores, with ``updates_per_frame`` SAC updates of
    ``batch_size`` transitions per frame.

    Args:
        robot: a registered robot name or a :class:`RobotSpec`.
        total_frames: robot control steps to collect (summed over robots).
        num_robots: B, robots stepped together.
        hidden, num_layers, lr, batch_size, gamma, tau, alpha_init: the SAC agent (paper networks and optimiser
            by default) and its updates.
        updates_per_frame: SAC updates per collected frame (1/32 with 64 robots: two updates per env step).
        init_random_frames: frames of uniformly random actions before learning starts.
        buffer_size: replay capacity in transitions.
        action_scale, command_interval, episode_length, reward_weights, init_joint_noise: the environment
            (:class:`VelocityCommandEnv`).
        log_every: frames between learning-curve points (and logger calls).
        checkpoint_path: where the training state goes every ``checkpoint_every`` frames and at the end; if it
            exists when training starts, training resumes from it (it must come from the same settings).
        compile_update: compile the SAC update (:meth:`SACAgent.build`).
        torch_threads_during: torch threads while training (:func:`torch_threads`).
        nthread: simulation threads. seed: networks, commands, reset noise and exploration.
        terrain, pushes, randomization: the world it learns in (:class:`VelocityCommandEnv`, ``docs/terrain.md``;
            default flat, no pushes, nominal dynamics); those not at their default are in ``settings``.
        device: where the agent, its updates and the replay buffer live (the simulation runs on the CPU).
        progress: show a progress bar (off by default; the recipes turn it on). logger: anything with
            ``log_metrics(dict, step=)`` (:class:`hierloco.loggers.RunLogger`); metrics are ``train/sac_low_level/...``.

    Returns:
        The trained low level; ``metadata`` holds the settings, ``frames``, ``updates``, ``train_seconds`` and the
        ``learning_curve``: every ``log_every`` frames the ``frames``, the mean ``reward`` per step, the mean
        ``tracking_error`` (m/s), ``falls_per_1000_frames``, each ``reward/<term>`` and the last loss terms.
    """
    robot = get_robot(robot)
    settings = {"robot": robot.name, "num_robots": int(num_robots), "hidden": int(hidden),
                "num_layers": int(num_layers),
                "lr": float(lr), "batch_size": int(batch_size), "gamma": float(gamma), "tau": float(tau),
                "alpha_init": float(alpha_init), "updates_per_frame": float(updates_per_frame),
                "init_random_frames": int(init_random_frames), "buffer_size": int(buffer_size),
                "action_scale": float(action_scale), "command_interval": float(command_interval),
                "episode_length": float(episode_length), "reward_weights": dict(reward_weights or {}),
                "init_joint_noise": float(init_joint_noise), "seed": int(seed)}
    from hierloco.envs.terrain import make_pushes, make_randomization, make_terrain

    world = {"terrain": make_terrain(terrain), "pushes": make_pushes(pushes),
             "randomization": make_randomization(randomization)}
    settings.update({name: part.key() for name, part in world.items() if part.key()})
    env = VelocityCommandEnv(robot, num_robots, action_scale=action_scale, command_interval=command_interval,
                             episode_length=episode_length, reward_weights=reward_weights,
                             init_joint_noise=init_joint_noise, seed=seed, nthread=nthread, **world)
    j = robot.num_joints
    agent = SACAgent.build(env.interface.observation_size, [-1.0] * j, [1.0] * j, hidden=hidden,
                           num_layers=num_layers, lr=lr, gamma=gamma, tau=tau, alpha_init=alpha_init,
                           observation_key="observation", compile_update=compile_update, seed=seed, device=device)
    try:
        report = train_sac(env, agent, total_frames=total_frames, init_random_frames=init_random_frames,
                           updates_per_frame=updates_per_frame, batch_size=batch_size, buffer_size=buffer_size,
                           log_every=log_every, diagnostics=tracking_diagnostics, checkpoint_path=checkpoint_path,
                           checkpoint_every=checkpoint_every, settings=settings,
                           torch_threads_during=torch_threads_during, seed=seed, progress=progress, logger=logger,
                           tag="sac_low_level")
    finally:
        env.close()
    agent.metadata = {"kind": "sac_low_level", "frames": report["frames"]}
    return TrainedSACLowLevel(agent, env.interface, {"robot": robot.name, "settings": settings, **report})


@LOW_LEVELS.register("sac_command")
class SACLowLevel(LowLevel):
    """SAC-SAC's low level: the action is a velocity command ``(vx, vy, yaw_rate)`` (local frame, m/s and rad/s),
    executed by the trained actor (its deterministic action) closed loop for ``steps_per_action`` control steps on
    every copy of the simulator.

    Like :class:`~hierloco.components.low_level.CommandLowLevel` it keeps each robot's phase clock and previous
    action across actions, so successive commands chain smoothly; :meth:`reset` restarts them for reset robots.

    Args:
        trained: a :class:`TrainedSACLowLevel`.
        steps_per_action: N control steps (100 Hz) per command.
        command_low, command_high: the action box (default the robot's command box).
        stochastic: act with samples of the policy (what it was trained with) instead of its squashed mean; the
            samples come from the low level's own random stream (``seed``), so a run is reproducible and the
            global torch RNG is left as it was.
        seed: the seed of that stream.
    """

    kind = "sac_command"

    @classmethod
    def from_run(cls, run, *, num_robots: int = 1, device: str = "cpu", **options) -> "SACLowLevel":
        return cls(TrainedSACLowLevel.load(run.artifact("sac_low_level.pt")), **options)

    def __init__(self, trained: TrainedSACLowLevel, steps_per_action: int = 100,
                 command_low: Sequence[float] | None = None, command_high: Sequence[float] | None = None,
                 stochastic: bool = False, seed: int = 0):
        if int(steps_per_action) < 1:
            raise ValueError(f"steps_per_action must be at least 1, got {steps_per_action}")
        self.stochastic = bool(stochastic)
        self._rng_state = torch.Generator().manual_seed(int(seed)).get_state() if self.stochastic else None
        self.trained = trained
        # it acts at 100 Hz on the CPU beside the simulation, whatever the device it was trained on
        self.agent = trained.agent if trained.agent.device.type == "cpu" else SACAgent.from_state(trained.agent.state())
        self.interface = trained.interface
        self.robot = trained.interface.robot
        self.steps_per_action = int(steps_per_action)
        self.action_low = np.asarray(self.robot.command_low if command_low is None else command_low, float)
        self.action_high = np.asarray(self.robot.command_high if command_high is None else command_high, float)
        self._time: np.ndarray | None = None  # B clock times in s
        self._last_action: np.ndarray | None = None  # B x J

    def reset(self, mask: np.ndarray | None = None) -> None:
        if self._time is None:
            return
        index = slice(None) if mask is None else np.flatnonzero(np.asarray(mask, dtype=bool))
        self._time[index] = 0.0
        self._last_action[index] = 0.0

    def describe(self) -> dict:
        return {**super().describe(), "interface": self.interface.describe(),
                "policy_frames": self.trained.metadata.get("frames"), "stochastic": self.stochastic}

    def _act(self, observation: np.ndarray) -> np.ndarray:
        agent = self.agent
        if not self.stochastic:
            return agent.act(torch.from_numpy(observation)).double().numpy()
        with torch.random.fork_rng(devices=[]):  # this low level's own stream; the global one is restored after
            torch.set_rng_state(self._rng_state)
            action = agent.act(torch.from_numpy(observation), deterministic=False)
            self._rng_state = torch.get_rng_state()
        return action.double().numpy()

    def run(self, sim: BatchedSimulator, actions: np.ndarray) -> SimulationResult:
        commands = self._check(sim, actions)
        if self._time is None or len(self._time) != sim.num_robots:
            self._time = np.zeros(sim.num_robots)
            self._last_action = np.zeros((sim.num_robots, self.robot.num_joints))
        results = []
        with torch_threads(1):  # B small forward passes: one thread is fastest (see torch_threads)
            for _ in range(self.steps_per_action):
                observation = self.interface.observe(sim.qpos, sim.qvel, commands, self._time, self._last_action)
                action = self._act(observation)
                results.append(sim.run(self.interface.joint_targets(action)[:, None]))
                self._time += CONTROL_TIMESTEP
                self._last_action = action
        return SimulationResult.concatenate(results)


def command_grid(robot: str | RobotSpec, points_per_axis: int = 3, command_low=None, command_high=None) -> np.ndarray:
    """``points_per_axis ** 3 x 3`` commands ``(vx, vy, yaw_rate)`` evenly over the command box (default the
    robot's), corners included."""
    robot = get_robot(robot)
    if int(points_per_axis) < 1:
        raise ValueError(f"points_per_axis must be at least 1, got {points_per_axis}")
    low = np.asarray(robot.command_low if command_low is None else command_low, float)
    high = np.asarray(robot.command_high if command_high is None else command_high, float)
    axes = [np.linspace(lo, hi, int(points_per_axis)) if points_per_axis > 1 else np.array([(lo + hi) / 2])
            for lo, hi in zip(low, high)]
    return np.array(list(itertools.product(*axes)))


def evaluate_velocity_tracking(low_level: LowLevel, commands: np.ndarray, *, num_actions: int = 4,
                               settle_actions: int = 1, seed: int = 0, nthread: int | None = None) -> dict:
    """Holds each command for ``num_actions`` actions on its own robot and compares commanded and achieved motion.

    The achieved velocity is the mean local-frame CoM velocity and yaw rate over the actions after the first
    ``settle_actions`` (the start-up transient); a robot that falls is counted in the fall rate and left out of the
    error means.

    Args:
        low_level: a velocity-command low level (:class:`SACLowLevel`, or
            :class:`~hierloco.components.low_level.CommandLowLevel` built for ``len(commands)`` robots).
        commands: ``C x 3`` commands ``(vx, vy, yaw_rate)`` (e.g. :func:`command_grid`).

    Returns:
        ``rows``: per command ``command``, ``achieved`` (``(vx, vy, yaw_rate)``), ``linear_error`` (m/s),
        ``yaw_rate_error`` (rad/s), ``fell``; ``summary``: ``linear_error_mean``, ``linear_error_max``,
        ``yaw_rate_error_mean``, ``fall_rate`` and the same errors for standing still (``*_standing``, the error
        of a robot that does not move) for scale.
    """
    commands = np.asarray(commands, dtype=np.float64)
    if commands.ndim != 2 or commands.shape[1] != 3 or len(commands) == 0:
        raise ValueError(f"commands must be C x 3, got shape {commands.shape}")
    if not (0 <= settle_actions < num_actions):
        raise ValueError(f"need 0 <= settle_actions < num_actions, got {settle_actions}, {num_actions}")
    sim = BatchedSimulator(low_level.robot, len(commands), seed=seed, nthread=nthread)
    low_level.reset()
    results = [low_level.run(sim, commands) for _ in range(num_actions)]
    sim.close()
    fell = np.stack([r.failed.any(1) for r in results], 1).any(1)
    kept = results[settle_actions:]
    velocity = np.concatenate([r.com_velocity_local for r in kept], 1).mean(1)
    yaw_rate = np.concatenate([r.yaw_rate for r in kept], 1).mean(1)
    linear_error = np.linalg.norm(commands[:, :2] - velocity, axis=-1)
    yaw_error = np.abs(commands[:, 2] - yaw_rate)
    rows = [{"command": c.tolist(), "achieved": [float(v[0]), float(v[1]), float(w)], "linear_error": float(e),
             "yaw_rate_error": float(y), "fell": bool(f)}
            for c, v, w, e, y, f in zip(commands, velocity, yaw_rate, linear_error, yaw_error, fell)]
    upright = ~fell
    pick = upright if upright.any() else np.ones_like(upright)
    summary = {"linear_error_mean": float(linear_error[pick].mean()),
               "linear_error_max": float(linear_error[pick].max()),
               "yaw_rate_error_mean": float(yaw_error[pick].mean()), "fall_rate": float(fell.mean()),
               "linear_error_standing": float(np.linalg.norm(commands[:, :2], axis=-1).mean()),
               "yaw_rate_error_standing": float(np.abs(commands[:, 2]).mean()), "num_commands": len(commands)}
    return {"rows": rows, "summary": summary}
