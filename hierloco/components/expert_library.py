"""The expert library: G expert gaits, each one latent action (N control steps) of joint targets (SPEC 5.1).

:func:`build_expert_library` samples G commands ``(vx, vy, yaw_rate)`` in the robot's command box, runs the
:class:`RaibertController` on each (all G in one batched simulation) until it is at steady state, then records one
action's worth of joint targets, starting on a gait-cycle boundary, with the CoM motion it achieved. The feedback
is frozen one gait period before recording, so each expert is an exactly periodic open-loop pattern. An expert that
falls or blows up is replaced by a fresh command; no failed gait enters the library.

Example:
    >>> lib = build_expert_library("daisy", num_experts=4, seed=0, progress=False)
    >>> lib.joint_targets.shape  # G x N x J
    (4, 100, 18)
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np
from tqdm.auto import tqdm

from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.frames import world_to_local
from hierloco.envs.robots import CONTROL_TIMESTEP, RobotSpec, get_robot
from hierloco.io import ArtifactError, load_arrays, save_arrays

LIBRARY_FORMAT = 1


@dataclass
class ExpertLibrary:
    """G recorded expert gaits of one robot.

    Attributes:
        commands: ``G x 3`` commanded ``(vx, vy, yaw_rate)`` in the local frame (m/s, m/s, rad/s).
        joint_targets: ``G x N x J`` joint targets in rad, one action starting on a gait-cycle boundary.
        com_states: ``G x (N + 1) x 5`` world ``(x, y, yaw, vx, vy)`` at the start and after each step.
        foot_contacts: ``G x N x L`` bool.
        velocity_local: ``G x 2`` mean CoM velocity over the action in its start frame, m/s.
        yaw_rate: ``G`` mean yaw rate over the action, rad/s.
        displacement_local: ``G x 3`` ``(dx, dy, dyaw)`` over the action in the start frame (m, m, rad).
        metadata: robot, N, gait period, seed, settle time, disabled legs, rejected commands.
    """

    commands: np.ndarray
    joint_targets: np.ndarray
    com_states: np.ndarray
    foot_contacts: np.ndarray
    velocity_local: np.ndarray
    yaw_rate: np.ndarray
    displacement_local: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def num_experts(self) -> int:
        return self.commands.shape[0]

    @property
    def steps_per_action(self) -> int:
        return self.joint_targets.shape[1]

    @property
    def robot(self) -> str:
        return self.metadata["robot"]

    def save(self, path: str | os.PathLike) -> None:
        """Writes the library to ``path`` (``.npz``) atomically."""
        arrays = {name: value for name, value in asdict(self).items() if name != "metadata"}
        save_arrays(path, arrays, {**self.metadata, "format": LIBRARY_FORMAT, "kind": "expert_library"})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ExpertLibrary":
        arrays, metadata = load_arrays(path)
        if metadata.get("kind") != "expert_library" or metadata.get("format") != LIBRARY_FORMAT:
            raise ArtifactError(f"{path} is not an expert library of format {LIBRARY_FORMAT}")
        metadata = {k: v for k, v in metadata.items() if k not in ("format", "kind")}
        missing = set(cls.__dataclass_fields__) - set(arrays) - {"metadata"}
        if missing:
            raise ArtifactError(f"corrupted expert library {path}: missing {sorted(missing)}")
        return cls(**arrays, metadata=metadata)


def action_motion(com_states: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motion over one action from ``... x (T + 1) x 5`` world CoM states.

    Returns the displacement ``... x 3`` ``(dx, dy, dyaw)`` in the start frame (m, rad), the mean velocity
    ``... x 2`` in that frame (m/s) and the mean yaw rate ``...`` (rad/s) over ``duration`` seconds.
    """
    start, end = com_states[..., 0, :], com_states[..., -1, :]
    yaw = np.unwrap(com_states[..., 2], axis=-1)
    dxy = world_to_local(end[..., :2] - start[..., :2], start[..., 2])
    dyaw = yaw[..., -1] - yaw[..., 0]
    return np.concatenate([dxy, dyaw[..., None]], -1), dxy / duration, dyaw / duration


def sample_commands(robot: RobotSpec, num: int, rng: np.random.Generator) -> np.ndarray:
    """``num x 3`` commands uniform in the robot's command box."""
    return rng.uniform(robot.command_low, robot.command_high, size=(num, 3))


def build_expert_library(
    robot: str | RobotSpec,
    num_experts: int = 50,
    *,
    steps_per_action: int = 100,
    seed: int = 0,
    settle_time: float = 3.0,
    disabled_legs: Sequence[str] = (),
    commands: np.ndarray | None = None,
    max_rounds: int = 5,
    progress: bool = True,
) -> ExpertLibrary:
    """Builds a library of ``num_experts`` gaits (see the module docstring).

    Args:
        steps_per_action: N, control steps per latent action; ``N * 0.01 s`` must hold a whole number of gait
            periods.
        settle_time: s of closed-loop walking before recording (rounded up to whole gait periods).
        commands: ``G x 3`` commands to use instead of sampling them (e.g. for tests).
    """
    robot = get_robot(robot)
    if int(num_experts) < 1:
        raise ValueError(f"num_experts must be at least 1, got {num_experts}")
    periods = steps_per_action * CONTROL_TIMESTEP / robot.gait_period
    if steps_per_action < 1 or abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
        raise ValueError(f"steps_per_action={steps_per_action} ({steps_per_action * CONTROL_TIMESTEP:.2f} s) must "
                         f"hold a whole number of {robot.name}'s {robot.gait_period} s gait periods")
    rng = np.random.default_rng(seed)
    wanted = sample_commands(robot, num_experts, rng) if commands is None else np.asarray(commands, float)
    if wanted.shape != (num_experts, 3):
        raise ValueError(f"commands must be {num_experts} x 3, got {wanted.shape}")
    period_steps = int(round(robot.gait_period / CONTROL_TIMESTEP))
    settle_steps = int(np.ceil(settle_time / robot.gait_period)) * period_steps
    records, rejected = [], 0
    pending = wanted
    bar = tqdm(total=num_experts, desc=f"experts ({robot.name})", disable=not progress)
    for _ in range(max_rounds):
        sim = BatchedSimulator(robot, len(pending), disabled_legs=disabled_legs, seed=int(rng.integers(2**31)))
        controller = RaibertController(robot, len(pending))
        # settle closed loop, freeze the feedback, let one gait period pass, record one action
        record = settle_steps + period_steps
        out = run_closed_loop(sim, controller, pending, record + steps_per_action,
                              ramp_steps=min(settle_steps, 100), freeze_after=settle_steps)
        sim.close()
        ok = ~out.failed[:, -1]
        for g in np.flatnonzero(ok):
            records.append((pending[g], out.joint_targets[g, record:], out.com_state[g, record - 1:],
                            out.foot_contacts[g, record:]))
        bar.update(int(ok.sum()))
        rejected += int((~ok).sum())
        if ok.all():
            break
        pending = sample_commands(robot, int((~ok).sum()), rng)
    bar.close()
    if len(records) < num_experts:
        raise RuntimeError(f"{robot.name}: only {len(records)} of {num_experts} experts walked without falling")
    cmds, targets, states, contacts = (np.stack(x) for x in zip(*records))
    displacement, velocity, yaw_rate = action_motion(states, steps_per_action * CONTROL_TIMESTEP)
    metadata = {
        "robot": robot.name, "steps_per_action": int(steps_per_action), "gait_period": robot.gait_period,
        "seed": int(seed), "settle_time": settle_steps * CONTROL_TIMESTEP, "disabled_legs": list(disabled_legs),
        "joint_names": list(robot.joint_names), "rejected_commands": rejected,
    }
    return ExpertLibrary(commands=cmds, joint_targets=targets, com_states=states, foot_contacts=contacts,
                         velocity_local=velocity, yaw_rate=yaw_rate, displacement_local=displacement,
                         metadata=metadata)


def replay(sim: BatchedSimulator, joint_targets: np.ndarray, num_actions: int):
    """Replays ``B x N x J`` one-action patterns open loop ``num_actions`` times in a row on ``sim``."""
    return sim.run(np.tile(joint_targets, (1, num_actions, 1)))


__all__ = ["ExpertLibrary", "action_motion", "build_expert_library", "replay", "sample_commands"]
