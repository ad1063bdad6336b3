"""Low levels: what turns one high-level action into N control steps of joint targets on the batched simulator.

A low level (:class:`hierloco.envs.low_level.LowLevel`, re-exported here) has an action space (a box, or a finite
set) and a ``run(sim, actions)`` that executes one action on every copy of a :class:`BatchedSimulator`. The
latent-action environment, the CoM dynamics data and the planners work with any of them:

- :class:`LatentLowLevel` (LAT): the action is a latent z; all N targets come from ``pi(., z)`` in one forward pass.
- :class:`ExpertReplayLowLevel` (LIB): the action is an expert index; the expert's recorded pattern is replayed.
- :class:`CommandLowLevel` (IK): the action is a desired CoM velocity; the Raibert controller runs closed loop.

Example:
    >>> import numpy as np
    >>> from hierloco.components.expert_library import build_expert_library
    >>> from hierloco.envs.batched_sim import BatchedSimulator
    >>> library = build_expert_library("daisy", 3, progress=False)
    >>> low = ExpertReplayLowLevel(library)
    >>> out = low.run(BatchedSimulator("daisy", 2), np.array([[0], [2]]))
    >>> out.com_state.shape
    (2, 100, 5)
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict.nn import TensorDictModule
from torch import nn

from hierloco.components.expert_library import ExpertLibrary
from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.components.gait_policy import TrainedGaitPolicy
from hierloco.envs.low_level import LOW_LEVELS, LowLevel
from hierloco.envs.robots import RobotSpec, get_robot

__all__ = ["CommandLowLevel", "ExpertReplayLowLevel", "LatentJointTargets", "LatentLowLevel", "LowLevel"]


class LatentJointTargets(nn.Module):
    """``latent`` ``B x Z`` and ``phase`` ``B x 1`` (t = n / N in (0, 1]) -> joint targets ``B x J`` (rad): the
    policy ``pi(t, z)`` with ``z`` clipped to the latent box ``[low, high]``."""

    def __init__(self, policy, low, high):
        super().__init__()
        self.policy = policy
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32, device="cpu"))
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float32, device="cpu"))

    def forward(self, latent: torch.Tensor, phase: torch.Tensor) -> torch.Tensor:
        z = torch.maximum(torch.minimum(latent.to(self.low.dtype), self.high), self.low)
        return self.policy(phase.to(self.low.dtype), z)


@LOW_LEVELS.register("latent")
class LatentLowLevel(LowLevel):
    """LAT: ``pi(., z)`` for a latent ``z`` in the learned latent box, open loop."""

    kind = "latent"

    @classmethod
    def from_run(cls, run, *, num_robots: int = 1, device: str = "cpu", **options) -> "LatentLowLevel":
        return cls(TrainedGaitPolicy.load(run.artifact("gait_policy.pt")), run.robot, device=device)

    def __init__(self, trained: TrainedGaitPolicy, robot: str | RobotSpec, device: str = "cpu"):
        self.trained = trained
        self.policy = trained.policy.to(device).eval()
        self.device = device
        self.robot = get_robot(robot)
        self.steps_per_action = self.policy.steps_per_action
        # pi(t, z) sees the phase only through harmonics of the gait frequency: its targets repeat every period
        periods = self.policy.periods_per_action
        self.period_steps = self.steps_per_action // periods if self.steps_per_action % periods == 0 else None
        self.action_low = trained.latent_low.numpy().astype(np.float64)
        self.action_high = trained.latent_high.numpy().astype(np.float64)

    def as_module(self, latent_key="latent", phase_key="phase", out_key="action") -> TensorDictModule:
        """The low level at one control step as a TensorDict module: reads ``latent`` (``B x Z``, clipped to the
        latent box) and ``phase`` (``B x 1``, t = n / N in (0, 1] for the n-th of the action's N steps), writes the
        joint targets ``action`` (``B x J``, rad, the robot's joint order): what a 100 Hz env takes
        (:class:`hierloco.envs.latent_wrapper.LatentActionWrapper` runs it over ``make_env``).

        Example:
            >>> import torch
            >>> from tensordict import TensorDict
            >>> from hierloco.components.gait_policy import train_gait_policy
            >>> trained = train_gait_policy(np.zeros((2, 100, 12)), hidden=8, epochs=1, progress=False)
            >>> module = LatentLowLevel(trained, "a1").as_module()
            >>> td = TensorDict({"latent": torch.zeros(4, 3), "phase": torch.full((4, 1), 0.01)}, [4])
            >>> module(td)["action"].shape
            torch.Size([4, 12])
        """
        module = LatentJointTargets(self.policy, self.action_low, self.action_high).to(self.device)
        return TensorDictModule(module, in_keys=[latent_key, phase_key], out_keys=[out_key])

    def patterns(self, latents: np.ndarray) -> np.ndarray:
        """``B x Z`` latents -> ``B x N x J`` joint targets (rad)."""
        with torch.no_grad():
            z = torch.as_tensor(latents, dtype=torch.float32, device=self.device)
            return self.policy.pattern(z).double().cpu().numpy()

    def run(self, sim, actions):
        return sim.run(self.patterns(self._check(sim, actions)))

    def _run_first(self, sim, actions, steps):
        """The first ``steps`` (whole gait periods) of each action's pattern: the next action's first step follows
        in phase, as the pattern's step after a whole period would."""
        return sim.run(self.patterns(self._check(sim, actions))[:, :steps])


@LOW_LEVELS.register("expert_replay")
class ExpertReplayLowLevel(LowLevel):
    """LIB: replays expert ``g``'s recorded N-step pattern; the action is the index ``g`` in ``[0, G)``."""

    kind = "expert_replay"

    @classmethod
    def from_run(cls, run, *, num_robots: int = 1, device: str = "cpu", **options) -> "ExpertReplayLowLevel":
        return cls(ExpertLibrary.load(run.artifact("experts.npz")))

    def __init__(self, library: ExpertLibrary):
        self.library = library
        self.robot = get_robot(library.robot)
        self.steps_per_action = library.steps_per_action
        self.num_choices = library.num_experts
        self.action_low = np.zeros(1)
        self.action_high = np.full(1, library.num_experts - 1.0)

    def action_features(self, actions):
        """``... x 1`` expert indices -> ``... x G`` one-hot vectors (NumPy or torch)."""
        if isinstance(actions, torch.Tensor):
            index = actions[..., 0].round().long().clamp(0, self.num_choices - 1)
            return torch.nn.functional.one_hot(index, self.num_choices).to(torch.float32)
        index = np.clip(np.rint(np.asarray(actions)[..., 0]).astype(np.int64), 0, self.num_choices - 1)
        return np.eye(self.num_choices)[index]

    def run(self, sim, actions):
        index = np.rint(self._check(sim, actions)[:, 0]).astype(np.int64)
        if index.min() < 0 or index.max() >= self.num_choices:
            raise ValueError(f"expert indices must be in [0, {self.num_choices}), got {index}")
        return sim.run(self.library.joint_targets[index])


@LOW_LEVELS.register("command")
class CommandLowLevel(LowLevel):
    """IK (Li et al., RA-L 2021, Sec. IV): the Raibert controller tracks a desired ``(vx, vy, yaw_rate)`` for one
    action, closed loop.

    The controller keeps its gait clock and feet across actions, so successive commands chain smoothly. By default
    it re-plans once per swing phase, or per half of it when that phase is longer than 0.25 s (A1: every 10 control
    steps, the touchdown point chosen at lift-off as in Raibert's controller; Daisy: every 25), and each interval
    costs one vectorised IK call and one simulator call; it tracks its commands as well as the per-step loop
    (``benchmarks/expert_tracking.py``). ``feedback_steps=1, ik_solver="reference"`` is the per-step loop the
    experts are recorded with.

    Args:
        robot: a registered name or a :class:`RobotSpec`.
        num_robots: B.
        steps_per_action: N control steps per command.
        command_low, command_high: the command box ``(vx, vy, yaw_rate)`` (default: the robot's).
        feedback_steps: control steps between feedback updates (default:
            :meth:`RaibertController.swing_chunk_steps`, a swing phase split into parts of at most 0.25 s).
        footstep_law: ``"integral"`` or ``"plain"`` (see :class:`RaibertController`).
        ik_solver: ``"vectorised"`` or ``"reference"`` (see :class:`LegKinematics`).
        **controller_kwargs: the other :class:`RaibertController` options (gains, gait period, ...).

    Example:
        >>> from hierloco.envs.batched_sim import BatchedSimulator
        >>> low = CommandLowLevel("a1", num_robots=2)
        >>> low.run(BatchedSimulator("a1", 2), np.array([[0.2, 0.0, 0.0], [0.0, 0.1, 0.2]])).joint_targets.shape
        (2, 100, 12)
    """

    kind = "command"

    @classmethod
    def from_run(cls, run, *, num_robots: int = 1, device: str = "cpu", **options) -> "CommandLowLevel":
        return cls(run.robot, num_robots, **options)

    def __init__(self, robot: str | RobotSpec, num_robots: int, steps_per_action: int = 100,
                 command_low=None, command_high=None, *, feedback_steps: int | None = None,
                 footstep_law: str = "integral", ik_solver: str = "vectorised", **controller_kwargs):
        self.robot = get_robot(robot)
        self.steps_per_action = int(steps_per_action)
        if self.steps_per_action < 1:
            raise ValueError(f"steps_per_action must be positive, got {steps_per_action}")
        self.controller = RaibertController(self.robot, num_robots, footstep_law=footstep_law, ik_solver=ik_solver,
                                            **controller_kwargs)
        self.feedback_steps = int(self.controller.swing_chunk_steps() if feedback_steps is None else feedback_steps)
        if self.feedback_steps < 1:
            raise ValueError(f"feedback_steps must be a positive number of control steps, got {feedback_steps}")
        self.action_low = np.asarray(self.robot.command_low if command_low is None else command_low, float)
        self.action_high = np.asarray(self.robot.command_high if command_high is None else command_high, float)

    def reset(self, mask=None):
        self.controller.reset(mask)

    def describe(self) -> dict:
        return {**super().describe(), "feedback_steps": self.feedback_steps,
                "footstep_law": self.controller.footstep_law, "ik_solver": self.controller.kinematics.solver}

    def run(self, sim, actions):
        if sim.num_robots != self.controller.num_robots:
            raise ValueError(f"controller built for {self.controller.num_robots} robots, simulator has "
                             f"{sim.num_robots}")
        return run_closed_loop(sim, self.controller, self._check(sim, actions), self.steps_per_action,
                               feedback_steps=self.feedback_steps)
