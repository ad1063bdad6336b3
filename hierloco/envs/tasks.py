"""The locomotion tasks and their metric (SPEC 6): velocity tracking, goal reaching, trajectory tracking.

A task is a set of episodes (one per target set: 8 goals, one velocity schedule, one path) of ``num_steps`` task
steps; one task step is one high-level action (1 s). The robot starts at the origin facing +y and the yaw target is
always that start yaw. Costs are computed on tensors batched over any leading dimensions, so the same object scores
a planner's ``B x S`` imagined transitions and a real transition (SAC's reward is ``-cost``):

- velocity tracking ``c1 = w1 ||v_tgt - v|| + w2 |yaw_tgt - yaw|``, v the CoM velocity over the step;
- goal reaching ``c2 = w1 ||p_tgt - p|| + w2 |yaw_tgt - yaw|``, success within 0.2 m at the episode's end;
- trajectory tracking: c2 with a reference point moving along an S-shaped path at constant speed.

``[w1, w2] = [2, 1]``, yaw errors wrapped to (-pi, pi]. The headline metric is the normalised cost: the episode's mean
per-step cost divided by that of a robot standing still at its start.

Example:
    >>> import torch
    >>> task = GoalReaching()
    >>> start = torch.tensor([0.0, 0.0, torch.pi / 2, 0.0, 0.0])
    >>> goal = task.target(torch.tensor(0), torch.tensor(0))
    >>> at_goal = torch.cat([goal, start[2:]])
    >>> float(task.cost(start, at_goal, torch.tensor(0), torch.tensor(29)))
    0.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from tensordict import TensorDictBase

from hierloco.envs.frames import world_to_local, wrap_angle
from hierloco.envs.robots import START_YAW

W_POSITION, W_YAW = 2.0, 1.0  # [w1, w2]
SUCCESS_RADIUS = 0.2  # m
STEP_DURATION = 1.0  # s, one task step = one latent action of N = 100 steps at 100 Hz


def _as_tensor(x, like=None):
    if isinstance(x, torch.Tensor):
        return x
    return torch.as_tensor(np.asarray(x), dtype=torch.float32 if like is None else like.dtype)


class Task:
    """Base class of the tasks. Subclasses define ``target`` and ``_tracking_error``.

    Attributes:
        name: registry name. num_episodes: target sets. num_steps: task steps per episode.
        step_duration: seconds per task step.
    """

    name: str = "task"
    num_episodes: int = 1
    num_steps: int = 1
    step_duration: float = STEP_DURATION
    start_yaw: float = START_YAW
    has_success: bool = True  # whether ``final_error <= 0.2`` means success

    def target(self, episode: torch.Tensor, step: torch.Tensor) -> torch.Tensor:
        """``... x 2`` target (a velocity in m/s or a position in m, world frame) at task step ``step``."""
        raise NotImplementedError

    def _tracking_error(self, state, next_state, target) -> torch.Tensor:
        raise NotImplementedError

    target_is_velocity: bool = False

    def relative_target(self, com_state, episode, step) -> torch.Tensor:
        """``... x 2`` the target of task step ``step`` in the robot's local frame: a velocity (m/s) as it is, a
        position (m) relative to the robot. What a goal-conditioned policy observes."""
        state = _as_tensor(com_state)
        episode, step = torch.broadcast_tensors(_as_tensor(episode).long(), _as_tensor(step).long())
        target = self.target(episode, step.clamp(0, self.num_steps - 1)).to(state.dtype)
        if not self.target_is_velocity:
            target = target - state[..., :2]
        return world_to_local(target, state[..., 2])

    def cost(self, com_state, next_com_state, episode, step) -> torch.Tensor:
        """Cost ``...`` of the transition ``com_state -> next_com_state`` (``... x 5`` world) that ends task step
        ``step`` (0-based) of ``episode``; all arguments broadcast together."""
        state, next_state = _as_tensor(com_state), _as_tensor(next_com_state)
        episode, step = torch.broadcast_tensors(_as_tensor(episode).long(), _as_tensor(step).long())
        return self.cost_to_target(state, next_state, self.target(episode, step).to(next_state.dtype))

    def cost_to_target(self, com_state: torch.Tensor, next_com_state: torch.Tensor,
                       target: torch.Tensor) -> torch.Tensor:
        """Cost ``...`` of ``com_state -> next_com_state`` (``... x 5`` world tensors) against an explicit ``... x 2``
        target of this task's kind (a velocity in m/s or a position in m, world frame): what :meth:`cost` computes
        for the target of a task step, usable where the target is an input (e.g. an exported planner)."""
        yaw_error = wrap_angle(self.start_yaw - next_com_state[..., 2]).abs()
        return W_POSITION * self._tracking_error(com_state, next_com_state, target) + W_YAW * yaw_error

    def reward(self, tensordict: TensorDictBase, state_key="com_state", episode_key="task_episode",
               step_key="task_step") -> torch.Tensor:
        """``-cost`` of the transitions in ``tensordict`` (``state_key`` and ``("next", state_key)``), ``... x 1``."""
        cost = self.cost(tensordict.get(state_key), tensordict.get(("next", state_key)),
                         tensordict.get(episode_key).squeeze(-1), tensordict.get(step_key).squeeze(-1))
        return -cost.unsqueeze(-1)

    def start_state(self) -> torch.Tensor:
        """``5`` the CoM state of the robot at the start: at the origin facing +y, still."""
        return torch.tensor([0.0, 0.0, self.start_yaw, 0.0, 0.0])

    def standing_costs(self) -> torch.Tensor:
        """``E x T`` per-step costs of a robot standing still at its start (the normaliser of the metric)."""
        episodes = torch.arange(self.num_episodes)[:, None].expand(-1, self.num_steps)
        steps = torch.arange(self.num_steps)[None, :].expand(self.num_episodes, -1)
        start = self.start_state().expand(self.num_episodes, self.num_steps, 5)
        return self.cost(start, start, episodes, steps)

    def evaluate(self, com_states, episodes=None) -> "TaskResult":
        """Scores whole episodes: ``E x (T + 1) x 5`` world CoM states (start, then after each step).

        ``episodes`` (``E``) says which episode each row is (default ``0..E-1``). Returns per-episode results.
        """
        states = _as_tensor(com_states).double()
        if states.ndim != 3 or states.shape[-1] != 5:
            raise ValueError(f"{self.name}: com_states must be E x (T + 1) x 5, got shape {tuple(states.shape)}")
        num, steps_plus_one, _ = states.shape
        if steps_plus_one - 1 != self.num_steps:
            raise ValueError(f"{self.name}: expected {self.num_steps + 1} states per episode, got {steps_plus_one}")
        episodes = torch.arange(num) if episodes is None else _as_tensor(episodes).long().reshape(-1)
        if episodes.shape != (num,) or bool(((episodes < 0) | (episodes >= self.num_episodes)).any()):
            raise ValueError(f"{self.name}: episodes must be {num} indices in [0, {self.num_episodes}), "
                             f"got {episodes.tolist()}")
        steps = torch.arange(self.num_steps)[None, :].expand(num, -1)
        costs = self.cost(states[:, :-1], states[:, 1:], episodes[:, None], steps)
        standing = self.standing_costs().double()[episodes]
        normalized = costs.mean(1) / standing.mean(1)
        final_error = self.final_error(states, episodes)
        success = (final_error <= SUCCESS_RADIUS).double() if self.has_success else torch.full_like(final_error, np.nan)
        return TaskResult(self.name, costs.numpy(), normalized.numpy(), final_error.numpy(), success.numpy(),
                          states.numpy())

    def final_error(self, com_states: torch.Tensor, episodes: torch.Tensor) -> torch.Tensor:
        """``E`` task-specific error at the end of each episode (m, or m/s for velocity tracking)."""
        last = torch.full_like(episodes, self.num_steps - 1)
        episodes, last = torch.broadcast_tensors(episodes, last)
        return self._tracking_error(com_states[:, -2], com_states[:, -1], self.target(episodes, last).double())


@dataclass
class TaskResult:
    """Per-episode results: ``costs`` (``E x T``), ``normalized_cost``, ``final_error``, ``success`` (``E``, 1/0, NaN
    for tasks without a success criterion)."""

    task: str
    costs: np.ndarray
    normalized_cost: np.ndarray
    final_error: np.ndarray
    success: np.ndarray
    com_states: np.ndarray


class VelocityTracking(Task):
    """Track world-frame CoM velocities: each target held ``steps_per_target`` steps, the schedule ``rounds`` times.

    Default: (0, 0.2), (0.2, 0), (0, -0.2), (-0.2, 0) m/s, 5 steps each, twice round (40 steps).
    """

    name = "velocity_tracking"
    has_success = False  # final_error is the velocity error of the last step (m/s)
    target_is_velocity = True

    def __init__(self, velocities: Sequence[Sequence[float]] = ((0.0, 0.2), (0.2, 0.0), (0.0, -0.2), (-0.2, 0.0)),
                 steps_per_target: int = 5, rounds: int = 2):
        self.velocities = torch.as_tensor(np.asarray(velocities, dtype=np.float32))
        if self.velocities.ndim != 2 or self.velocities.shape[1] != 2 or not len(self.velocities):
            raise ValueError(f"velocities must be a list of (vx, vy) pairs, got {velocities}")
        if not torch.isfinite(self.velocities).all():
            raise ValueError(f"velocities must be finite m/s, got {velocities}")
        if steps_per_target < 1 or rounds < 1:
            raise ValueError("steps_per_target and rounds must be positive")
        self.steps_per_target = int(steps_per_target)
        self.num_steps = len(self.velocities) * self.steps_per_target * int(rounds)

    def target(self, episode, step):
        index = (step // self.steps_per_target) % len(self.velocities)
        return self.velocities.to(index.device)[index]

    def _tracking_error(self, state, next_state, target):
        velocity = (next_state[..., :2] - state[..., :2]) / self.step_duration
        return torch.linalg.vector_norm(target - velocity, dim=-1)


class GoalReaching(Task):
    """Reach goals evenly spread on a circle around the start, one episode of ``num_steps`` per goal.

    Default: 8 goals on a 2 m circle at 0, 45, ..., 315 deg, 30 steps each.
    """

    name = "goal_reaching"

    def __init__(self, radius: float = 2.0, num_goals: int = 8, num_steps: int = 30, angle_offset: float = 0.0,
                 goals: Sequence[Sequence[float]] | None = None):
        if goals is None:
            if not (math.isfinite(radius) and radius > 0) or num_goals < 1:
                raise ValueError(f"need radius > 0 and num_goals >= 1, got {radius}, {num_goals}")
            angles = angle_offset + 2 * math.pi * torch.arange(num_goals) / num_goals
            goals = torch.stack([radius * torch.cos(angles), radius * torch.sin(angles)], -1)
        self.goals = torch.as_tensor(np.asarray(goals, dtype=np.float32))
        if self.goals.ndim != 2 or self.goals.shape[1] != 2:
            raise ValueError(f"goals must be a list of (x, y) positions, got {goals}")
        if not torch.isfinite(self.goals).all():
            raise ValueError(f"goals must be finite positions (m), got {goals}")
        if num_steps < 1:
            raise ValueError("num_steps must be positive")
        self.num_episodes = len(self.goals)
        self.num_steps = int(num_steps)

    def target(self, episode, step):
        return self.goals.to(episode.device)[episode]

    def _tracking_error(self, state, next_state, target):
        return torch.linalg.vector_norm(target - next_state[..., :2], dim=-1)


def s_path(num_points: int = 2001) -> np.ndarray:
    """``num_points x 2`` points of the S-shaped reference path (m): ``(1 - cos a, 1.5 sin a)`` then
    ``(3 - cos a, -1.5 sin a)`` for ``a`` in ``[0, pi]``; it leaves the origin along +y and is about 7.9 m long."""
    a = np.linspace(0.0, np.pi, num_points // 2 + 1)
    first = np.stack([1 - np.cos(a), 1.5 * np.sin(a)], -1)
    second = np.stack([3 - np.cos(a), -1.5 * np.sin(a)], -1)
    return np.concatenate([first, second[1:]])


class TrajectoryTracking(Task):
    """Follow a reference point moving along ``path`` (default the S path) at ``speed`` m/s.

    The episode lasts until the reference reaches the end of the path, plus ``extra_steps``. ``final_error`` is the
    distance to the end of the path; :meth:`path_distance` gives the mean distance from the CoM to the path.
    """

    name = "trajectory_tracking"

    def __init__(self, path: np.ndarray | None = None, speed: float = 0.1, extra_steps: int = 10):
        points = s_path() if path is None else np.asarray(path, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
            raise ValueError("path must be a P x 2 array of points, P >= 2")
        if not np.isfinite(points).all() or not np.linalg.norm(np.diff(points, axis=0), axis=1).sum() > 0:
            raise ValueError("path must be finite points (m) with a positive length")
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be positive m/s, got {speed}")
        if int(extra_steps) < 0:
            raise ValueError(f"extra_steps must be >= 0, got {extra_steps}")
        self.path = torch.as_tensor(points, dtype=torch.float32)
        self.arc_length = torch.as_tensor(np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0),
                                                                                          axis=1))]),
                                          dtype=torch.float32)
        self.length = float(self.arc_length[-1])
        self.speed = float(speed)
        self.num_steps = int(math.ceil(self.length / (self.speed * self.step_duration))) + int(extra_steps)
        times = (torch.arange(self.num_steps) + 1) * self.step_duration
        self.references = self.point_at(torch.clamp(self.speed * times, max=self.length))  # T x 2

    def point_at(self, arc: torch.Tensor) -> torch.Tensor:
        """``... x 2`` path points at arc lengths ``...`` (m), linearly interpolated."""
        index = torch.clamp(torch.searchsorted(self.arc_length, arc.contiguous()), 1, len(self.arc_length) - 1)
        s0, s1 = self.arc_length[index - 1], self.arc_length[index]
        w = ((arc - s0) / (s1 - s0).clamp_min(1e-9))[..., None]
        return self.path[index - 1] * (1 - w) + self.path[index] * w

    def target(self, episode, step):
        return self.references.to(step.device)[step.clamp(0, self.num_steps - 1)]

    def _tracking_error(self, state, next_state, target):
        return torch.linalg.vector_norm(target - next_state[..., :2], dim=-1)

    def final_error(self, com_states, episodes):
        end = self.path[-1].to(com_states.dtype)
        return torch.linalg.vector_norm(com_states[:, -1, :2] - end, dim=-1)

    def path_distance(self, positions) -> np.ndarray:
        """Distance (m) from each ``... x 2`` position to the path."""
        positions = _as_tensor(positions).double()
        dense = self.point_at(torch.linspace(0, self.length, 4000)).double()
        return torch.cdist(positions.reshape(-1, 2), dense).min(-1).values.reshape(positions.shape[:-1]).numpy()


TASKS = {"velocity_tracking": VelocityTracking, "goal_reaching": GoalReaching,
         "trajectory_tracking": TrajectoryTracking}


def make_task(name: str, **kwargs) -> Task:
    """A task by registry name, with keyword overrides."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; tasks: {sorted(TASKS)}")
    return TASKS[name](**kwargs)
