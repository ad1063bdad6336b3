"""The latent-action environment: a TorchRL env whose step is one whole high-level action on B robots (Li et al.,
RA-L 2021, Sec. III-A: the high level acts at about 1 Hz, the low level at 100 Hz).

For LAT the action is a latent z in the learned latent box and a step runs ``pi(., z)`` for N control steps (1 s)
on every robot through the batched simulator; with another low level the action is an expert index (LIB) or a
velocity command (IK). Observations are the CoM state ``com_state`` = ``(x, y, yaw, vx, vy)`` (world frame) and
``com_velocity_local`` (local yaw frame) at the end of the action, and ``body_state`` (roll, pitch in rad and
the base's height above the ground below it in m: what the trunk feels of the ground,
:attr:`~hierloco.envs.batched_sim.BatchedSimulator.body_state`). A robot that falls (or whose physics blows up)
during the action is terminated. With a robot whose ``com_noise`` is set (a perturbed "hardware" copy,
:mod:`hierloco.envs.robots.hardware`) both are measured with that noise, as a state estimator would, and the true
state is ``com_state_true``. Rewards come from a task (see :mod:`hierloco.envs.tasks`); without one they are 0.

The env writes ``is_init`` (``B x 1`` bool, TorchRL's episode-start flag, as
:class:`~torchrl.envs.transforms.InitTracker` writes it): true in the state a reset returns for the robots reset,
false after a step. So a planner run on the bare env, by ``env.rollout`` or a TorchRL ``Collector``, knows when each
robot's episode starts over without any transform (:mod:`hierloco.components.planners.base`), and a collector finds
the flag it would otherwise append an ``InitTracker`` for. The batch is ``[B]`` for every ``B``, 1 included (the
conventions of :mod:`hierloco.envs`).

Example:
    >>> from torchrl.envs.utils import check_env_specs
    >>> from hierloco.components.expert_library import build_expert_library
    >>> from hierloco.components.low_level import ExpertReplayLowLevel
    >>> env = LatentActionEnv(ExpertReplayLowLevel(build_expert_library("daisy", 3, progress=False)), num_robots=2)
    >>> check_env_specs(env)
"""

from __future__ import annotations

import math
import numbers
from typing import Sequence

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.frames import world_to_local
from hierloco.envs.low_level import LowLevel


class LatentActionEnv(EnvBase):
    """B robots stepped one high-level action at a time.

    Args:
        low_level: turns actions into joint targets, a :class:`hierloco.envs.low_level.LowLevel` (the latent gait
            policy, expert replay and the Raibert controller are in :mod:`hierloco.components.low_level`).
        num_robots: B, the env's batch size (``[B]``, also for one robot).
        disabled_legs: legs locked at their standing angles (the paper's adverse setting).
        limp_legs: legs whose servos are off (another fault model, see :mod:`hierloco.envs.faults`).
        init_joint_noise: rad of uniform noise on the standing joint angles at reset.
        record: also return, per action, the ``N`` CoM states ``com_path`` (``B x N x 5``), foot contacts
            ``foot_contacts`` (``B x N x L`` bool, true in contact) and generalised positions ``qpos``
            (``B x N x nq``, float64), for plots and videos.
        seed: seeds the reset noise.
        nthread: simulation threads.
        obstacles: static boxes in the world (a navigation arena).
        robot: the robot simulated, when it is not the low level's own: a copy of it with other physics (the same
            joints), e.g. :func:`hierloco.envs.robots.hardware.perturbed`.
        terrain, pushes, randomization: the ground, pushes on the trunk and randomised dynamics, passed to the
            batched simulator (:class:`hierloco.envs.batched_sim.BatchedSimulator`, ``docs/terrain.md``).
        replan_steps: control steps a step runs (default the low level's whole action, ``N``): fewer, whole gait
            periods that divide ``N`` (:meth:`~hierloco.envs.low_level.LowLevel.replan_problem`), run only the first
            part of each action, so that a planner chooses again ``N / replan_steps`` times per action
            (``docs/terrain.md``, "Re-planning within an action"); ``com_path`` and the other 100 Hz records are
            then ``B x replan_steps x ...``.
    """

    def __init__(self, low_level: LowLevel, num_robots: int = 1, *, disabled_legs: Sequence[str] = (),
                 init_joint_noise: float = 0.02, record: bool = False, seed: int | None = None,
                 nthread: int | None = None, obstacles: Sequence = (), device: str = "cpu",
                 limp_legs: Sequence[str] = (), robot=None, terrain=None, pushes=None, randomization=None,
                 replan_steps: int | None = None):
        whole = (isinstance(num_robots, numbers.Real) and not isinstance(num_robots, bool)
                 and math.isfinite(num_robots) and float(num_robots).is_integer())
        if not whole or num_robots < 1:
            raise ValueError(f"num_robots must be a whole number >= 1, got {num_robots!r}")
        super().__init__(batch_size=torch.Size([int(num_robots)]), device=device)
        self.low_level = low_level
        self.robot = low_level.robot if robot is None else robot
        if self.robot.joint_names != low_level.robot.joint_names:
            raise ValueError(f"robot {self.robot.name!r} has joints {list(self.robot.joint_names)}, the low level's "
                             f"robot {low_level.robot.name!r} {list(low_level.robot.joint_names)}")
        self.com_noise = np.asarray(self.robot.com_noise, dtype=np.float64)
        self._noise_rng = np.random.default_rng(seed)
        self.record = record
        self.sim = BatchedSimulator(self.robot, int(num_robots), disabled_legs=disabled_legs,
                                    init_joint_noise=init_joint_noise, seed=seed, nthread=nthread,
                                    obstacles=obstacles, limp_legs=limp_legs, terrain=terrain, pushes=pushes,
                                    randomization=randomization)
        self.steps_per_action = low_level.steps_per_action
        self.replan_steps = self.steps_per_action if replan_steps is None else replan_steps
        problem = low_level.replan_problem(self.replan_steps)
        if problem is not None:
            self.sim.close()
            raise ValueError(problem)
        b = int(num_robots)
        flag = Categorical(2, (b, 1), dtype=torch.bool, device=self.device)
        observation = {"com_state": Unbounded((b, 5), device=self.device),
                       "com_velocity_local": Unbounded((b, 2), device=self.device),
                       "body_state": Unbounded((b, 3), device=self.device),
                       "is_init": flag.clone()}
        if self.com_noise.any():
            observation["com_state_true"] = Unbounded((b, 5), device=self.device)
        if record:
            n, legs = self.replan_steps, len(self.robot.legs)
            observation["com_path"] = Unbounded((b, n, 5), device=self.device)
            observation["foot_contacts"] = Categorical(2, (b, n, legs), dtype=torch.bool, device=self.device)
            observation["qpos"] = Unbounded((b, n, self.sim.model.nq), dtype=torch.float64, device=self.device)
        self.observation_spec = Composite(observation, shape=(b,), device=self.device)
        if low_level.num_choices is not None:
            self.action_spec = Categorical(low_level.num_choices, (b, 1), dtype=torch.int64, device=self.device)
        else:
            low = torch.as_tensor(low_level.action_low, dtype=torch.float32, device=self.device)
            high = torch.as_tensor(low_level.action_high, dtype=torch.float32, device=self.device)
            self.action_spec = Bounded(low.expand(b, -1), high.expand(b, -1), (b, len(low)), device=self.device)
        self.reward_spec = Unbounded((b, 1), device=self.device)
        self.done_spec = Composite(done=flag, terminated=flag.clone(), truncated=flag.clone(), shape=(b,),
                                   device=self.device)
        self.failures = 0  # robots that fell or blew up, over the env's life

    def _observation(self, result=None) -> dict:
        if result is None:
            state = self.sim.com_state
            velocity_local = world_to_local(state[:, 3:5], state[:, 2])
        else:
            state, velocity_local = result.com_state[:, -1], result.com_velocity_local[:, -1]
        obs = {}
        if self.com_noise.any():
            obs["com_state_true"] = torch.as_tensor(state, dtype=torch.float32, device=self.device)
            std = np.repeat(self.com_noise, (2, 1, 2))  # x, y (m), yaw (rad), vx, vy (m/s)
            state = state + std * self._noise_rng.standard_normal(state.shape)
            velocity_local = world_to_local(state[:, 3:5], state[:, 2])
        obs.update({"com_state": torch.as_tensor(state, dtype=torch.float32, device=self.device),
                    "com_velocity_local": torch.as_tensor(velocity_local, dtype=torch.float32, device=self.device),
                    "body_state": torch.as_tensor(self.sim.body_state, dtype=torch.float32, device=self.device)})
        if self.record:
            if result is None:  # at reset: standing still, all feet down
                n, legs = self.replan_steps, len(self.robot.legs)
                path = np.repeat(state[:, None], n, 1)
                contacts = np.ones((len(state), n, legs), dtype=bool)
                qpos = np.repeat(self.sim.qpos[:, None], n, 1)
            else:
                path, contacts, qpos = result.com_state, result.foot_contacts, result.qpos
            obs["com_path"] = torch.as_tensor(path, dtype=torch.float32, device=self.device)
            obs["foot_contacts"] = torch.as_tensor(contacts, device=self.device)
            obs["qpos"] = torch.as_tensor(qpos, dtype=torch.float64, device=self.device)
        return obs

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(-1).cpu().numpy()
        self.sim.reset(mask)
        self.low_level.reset(mask)
        b = self.batch_size
        done = torch.zeros((*b, 1), dtype=torch.bool, device=self.device)
        started = (torch.ones_like(done) if mask is None
                   else torch.as_tensor(mask, dtype=torch.bool, device=self.device).reshape(*b, 1))
        return TensorDict({**self._observation(), "is_init": started, "done": done, "terminated": done.clone(),
                           "truncated": done.clone()}, batch_size=b, device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action").detach().cpu().numpy().astype(np.float64)
        action = action.reshape(self.batch_size[0], -1)
        result = (self.low_level.run(self.sim, action) if self.replan_steps == self.steps_per_action
                  else self.low_level.run_steps(self.sim, action, self.replan_steps))
        failed = result.failed[:, -1]
        self.failures += int(failed.sum())
        terminated = torch.as_tensor(failed, device=self.device)[:, None]
        b = self.batch_size
        return TensorDict({**self._observation(result), "is_init": torch.zeros_like(terminated),
                           "reward": torch.zeros((*b, 1), device=self.device),
                           "done": terminated.clone(), "terminated": terminated,
                           "truncated": torch.zeros_like(terminated)}, batch_size=b, device=self.device)

    def close(self, *, raise_if_closed: bool = True) -> None:
        self.sim.close()
        super().close(raise_if_closed=raise_if_closed)

    def _set_seed(self, seed: int | None) -> None:
        self.sim.seed(seed)
        self._noise_rng = np.random.default_rng(seed)
