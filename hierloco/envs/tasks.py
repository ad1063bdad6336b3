"""The locomotion tasks and their metric (Li et al., RA-L 2021, Sec. IV-A): velocity tracking, goal reaching,
trajectory tracking.

A task is a set of episodes (one per target set: 8 goals, one velocity schedule, one path) of ``num_steps`` task
steps; one task step is one high-level action (1 s). The robot starts at the origin facing +y and the yaw target is
always that start yaw. Costs are computed on tensors batched over any leading dimensions, so the same object scores
a planner's ``B x S`` imagined transitions and a real transition (SAC's reward is ``-cost``):

- velocity tracking ``c1 = w1 ||v_tgt - v|| + w2 |yaw_tgt - yaw|``, v the CoM velocity over the step;
- goal reaching ``c2 = w1 ||p_tgt - p|| + w2 |yaw_tgt - yaw|``, success within 0.2 m at the episode's end;
- trajectory tracking: c2 with a reference point moving along an S-shaped path at constant speed.

``[w1, w2] = [2, 1]``, yaw errors wrapped to (-pi, pi]. Each cost is the sum of two named terms
(:meth:`Task.cost_terms`): ``tracking`` (``w1`` times the velocity or position error) and ``yaw`` (``w2`` times the
yaw error). The headline metric is the normalised cost: the episode's mean per-step cost divided by that of a robot
standing still at its start.

A task also says what callers draw and report: :meth:`Task.markers` (goals or reference points),
:meth:`Task.extra_metrics` (e.g. the distance to the path) and :meth:`Task.training_split` (the half of the targets a
model-free baseline trains on). Tasks are built by name with :func:`make_task`, which refuses unknown options.

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
import numbers
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import torch
from tensordict import TensorDictBase

from hierloco.envs.frames import world_to_local, wrap_angle
from hierloco.envs.robots import START_YAW
from hierloco.registry import Registry

# The task types by name (a task's ``task:`` field in a recipe's ``eval`` section): a new type is a :class:`Task`
# subclass decorated with ``@TASKS.register("name")``; its options are its constructor's keyword arguments.
TASKS = Registry("task", context=("name",), modules=("hierloco.envs.navigation",))

W_POSITION, W_YAW = 2.0, 1.0  # [w1, w2]
SUCCESS_RADIUS = 0.2  # m
STEP_DURATION = 1.0  # s, one task step = one latent action of N = 100 steps at 100 Hz
MAX_RANDOM_TARGETS = 10_000  # random velocities, or knots of a random path: a bound on what a config may ask


def _as_tensor(x, like=None, device=None):
    """``x`` as it is when it is a tensor, else a tensor of ``like``'s dtype (float32) on ``device`` (default
    ``like``'s device, else the CPU)."""
    if isinstance(x, torch.Tensor):
        return x
    device = device if device is not None else (like.device if like is not None else "cpu")
    return torch.as_tensor(np.asarray(x), dtype=torch.float32 if like is None else like.dtype, device=device)


def _indices(episode, step, device) -> tuple[torch.Tensor, torch.Tensor]:
    """``episode`` and ``step`` as broadcast int64 tensors on ``device`` (that of the states they index)."""
    episode = _as_tensor(episode, device=device).long().to(device)
    step = _as_tensor(step, device=device).long().to(device)
    return torch.broadcast_tensors(episode, step)


def _number(name: str, value, *, positive: bool = False) -> float:
    """``value`` as a finite float (``> 0`` with ``positive``), or a ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if positive and not value > 0:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return float(value)


def _whole(name: str, value, minimum: int) -> int:
    """``value`` as an int ``>= minimum``, or a ``ValueError`` naming ``name`` (whole floats such as 5.0 pass)."""
    whole = isinstance(value, numbers.Integral) or (isinstance(value, numbers.Real) and math.isfinite(value)
                                                   and float(value).is_integer())
    if isinstance(value, bool) or not whole or value < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def _range(name: str, value, *, positive: bool = False) -> tuple[float, float]:
    """``value`` as ``(low, high)`` with ``low <= high`` (both > 0 with ``positive``), else ``ValueError``."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(f"{name} must be [low, high], got {value!r}")
    low, high = (_number(name, v, positive=positive) for v in value)
    if low > high:
        raise ValueError(f"{name} must be [low, high] with low <= high, got {list(value)!r}")
    return low, high


def _spread_angles(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` angles (rad): one uniform in each of ``count`` equal sectors of the circle, in a random order. Every
    angle has the same distribution and any half of them (a training split) covers the circle as the other half
    does, where independent uniform draws may leave whole sectors empty."""
    return rng.permutation(2 * np.pi * (np.arange(count) + rng.uniform(0.0, 1.0, count)) / count)


def _points(name: str, value, what: str, min_points: int = 1) -> np.ndarray:
    """``value`` as a finite ``K x 2`` float64 array (``K >= min_points``), or a ``ValueError`` naming ``name``."""
    try:
        points = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a list of {what}, got {value!r}") from None
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < min_points:
        raise ValueError(f"{name} must be a list of at least {min_points} {what}, got {value!r}")
    if not np.isfinite(points).all():
        raise ValueError(f"{name} must be finite {what}, got {value!r}")
    return points


class Task:
    """Base class of the tasks. A new type subclasses it with ``target`` and ``tracking_error`` (``docs/extending.md``).

    Attributes:
        kind: the registry name of the task's type (``"goal_reaching"``, ...).
        name: this task's name (constructor keyword ``name``, default ``kind``), used in results and metric names.
        num_episodes: target sets. num_steps: task steps per episode. step_duration: seconds per task step.
        cost_term_names: the names of the cost terms, in order (``cost`` is their sum).
        obstacles: static boxes that are part of the task's world (a navigation arena,
            :class:`hierloco.envs.navigation.Navigation`); an evaluation builds them into its robots' world.
    """

    kind: str = "task"
    name: str = "task"  # replaced per instance by __init__
    num_episodes: int = 1
    num_steps: int = 1
    step_duration: float = STEP_DURATION
    start_yaw: float = START_YAW
    has_success: bool = True  # whether ``final_error <= 0.2`` means success
    figures: tuple[str, ...] = ("paths",)  # what a run draws of it: "paths", "velocity" (plot), "gait" (diagram),
    #                                        "arena" (a navigation task's top view)
    obstacles: tuple = ()  # static boxes (hierloco.envs.robots.Obstacle) in the robots' world while it is evaluated
    cost_term_names: tuple[str, ...] = ("tracking", "yaw")

    def __init__(self, name: str | None = None):
        if name is not None and (not isinstance(name, str) or not name):
            raise ValueError(f"name must be a non-empty string, got {name!r}")
        self.name = self.kind if name is None else name

    def target(self, episode: torch.Tensor, step: torch.Tensor) -> torch.Tensor:
        """``... x 2`` target (a velocity in m/s or a position in m, world frame) at task step ``step``."""
        raise NotImplementedError

    def on(self, name: str, device) -> torch.Tensor:
        """The task's constant tensor ``name`` (kept on the CPU) on ``device``, copied there once: a planner on a
        GPU indexes its targets there at every call, and a compiled (CUDA-graphed) scoring sees no CPU tensor.
        :meth:`to_device` makes every copy ahead of such a call."""
        tensor = getattr(self, name)
        if tensor.device == torch.device(device):
            return tensor
        copies = self.__dict__.setdefault("_device_copies", {})
        key = (name, str(device))
        if key not in copies:
            copies[key] = tensor.to(device)
        return copies[key]

    def to_device(self, device) -> "Task":
        """Copies every constant tensor of the task to ``device`` once (see :meth:`on`); the task itself stays as it
        is, on the CPU, for the simulated robots' side."""
        for name, value in list(vars(self).items()):
            if isinstance(value, torch.Tensor):
                self.on(name, device)
        return self

    def tracking_error(self, state, next_state, target) -> torch.Tensor:
        """``...`` the error of the transition ``state -> next_state`` (``... x 5`` world) against ``target``
        (``... x 2``, from :meth:`target`): m/s for a velocity target, m for a position."""
        raise NotImplementedError

    target_is_velocity: bool = False

    def relative_target(self, com_state, episode, step) -> torch.Tensor:
        """``... x 2`` the target of task step ``step`` in the robot's local frame: a velocity (m/s) as it is, a
        position (m) relative to the robot. What a goal-conditioned policy observes."""
        state = _as_tensor(com_state)
        episode, step = _indices(episode, step, state.device)
        target = self.target(episode, step.clamp(0, self.num_steps - 1)).to(state.dtype)
        if not self.target_is_velocity:
            target = target - state[..., :2]
        return world_to_local(target, state[..., 2])

    def cost_terms(self, com_state, next_com_state, episode, step) -> dict[str, torch.Tensor]:
        """The named terms ``...`` of the cost of the transition ``com_state -> next_com_state`` (``... x 5`` world)
        that ends task step ``step`` (0-based) of ``episode``; all arguments broadcast together.

        ``tracking`` is ``w1`` times the task's error (m/s for velocity tracking, m otherwise), ``yaw`` is ``w2``
        times the wrapped yaw error to the start yaw (rad). Targets and costs are on the states' device.
        """
        state, next_state = _as_tensor(com_state), _as_tensor(next_com_state)
        episode, step = _indices(episode, step, next_state.device)
        return self.cost_terms_to_target(state, next_state, self.target(episode, step).to(next_state.dtype))

    def cost_terms_to_target(self, com_state: torch.Tensor, next_com_state: torch.Tensor,
                             target: torch.Tensor) -> dict[str, torch.Tensor]:
        """:meth:`cost_terms` against an explicit ``... x 2`` target of this task's kind (a velocity in m/s or a
        position in m, world frame), for tensors ``... x 5``: usable where the target is an input (an exported
        planner)."""
        yaw_error = wrap_angle(self.start_yaw - next_com_state[..., 2]).abs()
        return {"tracking": W_POSITION * self.tracking_error(com_state, next_com_state, target),
                "yaw": W_YAW * yaw_error}

    def cost_to_target(self, com_state: torch.Tensor, next_com_state: torch.Tensor,
                       target: torch.Tensor) -> torch.Tensor:
        """The cost ``...`` of :meth:`cost_terms_to_target` (the sum of its terms)."""
        return self.total_cost(self.cost_terms_to_target(com_state, next_com_state, target))

    @staticmethod
    def total_cost(terms: dict[str, torch.Tensor]) -> torch.Tensor:
        """The cost: the sum of the terms of :meth:`cost_terms`, in their order."""
        values = iter(terms.values())
        total = next(values)
        for value in values:
            total = total + value
        return total

    def cost(self, com_state, next_com_state, episode, step) -> torch.Tensor:
        """Cost ``...`` of the transition ``com_state -> next_com_state`` (``... x 5`` world) that ends task step
        ``step`` (0-based) of ``episode``: the sum of :meth:`cost_terms`; all arguments broadcast together."""
        return self.total_cost(self.cost_terms(com_state, next_com_state, episode, step))

    def __call__(self, com_state, next_com_state, action, info) -> torch.Tensor:
        """A task is a cost callable of a world model (:class:`hierloco.envs.world_model.CoMWorldModelEnv`, its
        default cost): :meth:`cost` of the transition at ``info["task_episode"]`` and ``info["task_step"]``; the
        action is not scored."""
        return self.cost(com_state, next_com_state, info["task_episode"], info["task_step"])

    def reward(self, tensordict: TensorDictBase, state_key="com_state", episode_key="task_episode",
               step_key="task_step") -> torch.Tensor:
        """``-cost`` of the transitions in ``tensordict`` (``state_key`` and ``("next", state_key)``), ``... x 1``."""
        cost = self.cost(tensordict.get(state_key), tensordict.get(("next", state_key)),
                         tensordict.get(episode_key).squeeze(-1), tensordict.get(step_key).squeeze(-1))
        return -cost.unsqueeze(-1)

    def start_state(self, device="cpu") -> torch.Tensor:
        """``5`` the CoM state of the robot at the start: at the origin facing +y, still."""
        return torch.tensor([0.0, 0.0, self.start_yaw, 0.0, 0.0], device=device)

    def standing_costs(self) -> torch.Tensor:
        """``E x T`` per-step costs of a robot standing still at its start (the normaliser of the metric)."""
        episodes = torch.arange(self.num_episodes, device="cpu")[:, None].expand(-1, self.num_steps)
        steps = torch.arange(self.num_steps, device="cpu")[None, :].expand(self.num_episodes, -1)
        start = self.start_state().expand(self.num_episodes, self.num_steps, 5)
        return self.cost(start, start, episodes, steps)

    def evaluate(self, com_states, episodes=None) -> "TaskResult":
        """Scores whole episodes: ``E x (T + 1) x 5`` world CoM states (start, then after each step).

        ``episodes`` (``E``) says which episode each row is (default ``0..E-1``). Returns per-episode results.
        """
        states = _as_tensor(com_states).double().cpu()
        if states.ndim != 3 or states.shape[-1] != 5:
            raise ValueError(f"{self.name}: com_states must be E x (T + 1) x 5, got shape {tuple(states.shape)}")
        num, steps_plus_one, _ = states.shape
        if steps_plus_one - 1 != self.num_steps:
            raise ValueError(f"{self.name}: expected {self.num_steps + 1} states per episode, got {steps_plus_one}")
        episodes = (torch.arange(num, device="cpu") if episodes is None
                    else _as_tensor(episodes).long().reshape(-1).cpu())
        if episodes.shape != (num,) or bool(((episodes < 0) | (episodes >= self.num_episodes)).any()):
            raise ValueError(f"{self.name}: episodes must be {num} indices in [0, {self.num_episodes}), "
                             f"got {episodes.tolist()}")
        steps = torch.arange(self.num_steps, device="cpu")[None, :].expand(num, -1)
        terms = self.cost_terms(states[:, :-1], states[:, 1:], episodes[:, None], steps)
        costs = self.total_cost(terms)
        standing = self.standing_costs().double()[episodes]
        normalized = costs.mean(1) / standing.mean(1)
        final_error = self.final_error(states, episodes)
        success = (final_error <= SUCCESS_RADIUS).double() if self.has_success else torch.full_like(final_error, np.nan)
        return TaskResult(self.name, costs.numpy(), normalized.numpy(), final_error.numpy(), success.numpy(),
                          states.numpy(), {term: value.mean(1).numpy() for term, value in terms.items()})

    def final_error(self, com_states: torch.Tensor, episodes: torch.Tensor) -> torch.Tensor:
        """``E`` task-specific error at the end of each episode (m, or m/s for velocity tracking)."""
        last = torch.full_like(episodes, self.num_steps - 1)
        episodes, last = torch.broadcast_tensors(episodes, last)
        return self.tracking_error(com_states[:, -2], com_states[:, -1], self.target(episodes, last).double())

    def markers(self, episode: int | None = None) -> np.ndarray:
        """``K x 2`` points to draw with the task (world frame, m): its goals or reference points; those of
        ``episode`` alone when given. None for a velocity task (``0 x 2``)."""
        return np.zeros((0, 2))

    def extra_metrics(self, com_paths, episodes=None) -> dict[str, np.ndarray]:
        """Task-specific per-episode metrics (each ``E``) from ``E x S x >=2`` world-frame CoM paths (m, e.g. the
        100 Hz paths of :class:`hierloco.components.evaluation.TaskRollout`, ``S`` = ``num_steps`` x N) of the
        episodes ``episodes`` (``E``, default ``0 .. E-1`` modulo :attr:`num_episodes`); none by default."""
        return {}

    def training_split(self) -> "Task":
        """The same task on half of its targets, named ``<name>_train``: what a model-free baseline trains on before
        it is tested on all of them (Li et al., RA-L 2021, Sec. IV-B). See each task for its rule."""
        raise NotImplementedError(f"{self.name}: no training split for {type(self).__name__}")

    @property
    def training_episodes(self) -> list[int] | None:
        """The episodes of this task whose targets :meth:`training_split` keeps, or None when the split cuts inside
        an episode (one velocity schedule, one path), so no episode is all held-out targets."""
        return None


@dataclass
class TaskResult:
    """Per-episode results: ``costs`` (``E x T``), ``normalized_cost``, ``final_error``, ``success`` (``E``, 1/0, NaN
    for tasks without a success criterion), the ``E x (T + 1) x 5`` CoM states and ``cost_terms``: per term of
    :meth:`Task.cost_terms`, its mean per step over each episode (``E``; they add up to ``costs.mean(1)``)."""

    task: str
    costs: np.ndarray
    normalized_cost: np.ndarray
    final_error: np.ndarray
    success: np.ndarray
    com_states: np.ndarray
    cost_terms: dict[str, np.ndarray] = field(default_factory=dict)


@TASKS.register("velocity_tracking")
class VelocityTracking(Task):
    """Track world-frame CoM velocities: each target held ``steps_per_target`` steps, the schedule ``rounds`` times.

    Default: (0, 0.2), (0.2, 0), (0, -0.2), (-0.2, 0) m/s, 5 steps each, twice round (40 steps). With
    ``num_random`` = K > 0 the schedule is K velocities drawn from ``targets_seed`` instead: headings one in each
    of K equal sectors of the circle, uniform within it, in a random order (:func:`_spread_angles`), speeds uniform
    in ``speed_range_mps``, so its two halves come from one distribution (``docs/tasks.md``, fair held-out
    targets).

    Training split: the first half of the schedule (``ceil(K / 2)`` targets; for the default (0, 0.2) and (0.2, 0),
    one on each axis), repeated for at least as many steps as the whole task.

        >>> task = VelocityTracking(num_random=8, speed_range_mps=(0.1, 0.3), targets_seed=45, rounds=1)
        >>> task.num_steps, bool(task.velocities.norm(dim=-1).min() >= 0.1)
        (40, True)
    """

    kind = "velocity_tracking"
    has_success = False  # final_error is the velocity error of the last step (m/s)
    figures = ("paths", "velocity")
    target_is_velocity = True

    def __init__(self, velocities: Sequence[Sequence[float]] = ((0.0, 0.2), (0.2, 0.0), (0.0, -0.2), (-0.2, 0.0)),
                 steps_per_target: int = 5, rounds: int = 2, num_random: int = 0,
                 speed_range_mps: Sequence[float] = (0.1, 0.3), targets_seed: int = 0, name: str | None = None):
        super().__init__(name)
        if _whole("num_random", num_random, 0) > MAX_RANDOM_TARGETS:
            raise ValueError(f"num_random must be at most {MAX_RANDOM_TARGETS}, got {num_random!r}")
        if num_random:
            low, high = _range("speed_range_mps", speed_range_mps)
            rng = np.random.default_rng(_whole("targets_seed", targets_seed, 0))
            headings, speeds = _spread_angles(rng, num_random), rng.uniform(low, high, num_random)
            velocities = np.stack([speeds * np.cos(headings), speeds * np.sin(headings)], -1)
        points = _points("velocities", velocities, "(vx, vy) pairs in m/s")
        self.velocities = torch.as_tensor(points.astype(np.float32), device="cpu")
        self.steps_per_target = _whole("steps_per_target", steps_per_target, 1)
        self.rounds = _whole("rounds", rounds, 1)
        self.num_steps = len(self.velocities) * self.steps_per_target * self.rounds

    def training_split(self) -> "VelocityTracking":
        half = self.velocities[: (len(self.velocities) + 1) // 2]
        rounds = math.ceil(self.num_steps / (len(half) * self.steps_per_target))
        return VelocityTracking(velocities=half.numpy(), steps_per_target=self.steps_per_target, rounds=rounds,
                                name=f"{self.name}_train")

    def target(self, episode, step):
        index = (step // self.steps_per_target) % len(self.velocities)
        return self.on("velocities", index.device)[index]

    def tracking_error(self, state, next_state, target):
        velocity = (next_state[..., :2] - state[..., :2]) / self.step_duration
        return torch.linalg.vector_norm(target - velocity, dim=-1)


@TASKS.register("goal_reaching")
class GoalReaching(Task):
    """Reach goals evenly spread on a circle around the start, one episode of ``num_steps`` per goal.

    Default: 8 goals on a 2 m circle at 0, 45, ..., 315 deg (``angle_offset`` rad turns them), 30 steps each;
    ``goals`` (``K x 2``, m) replaces the circle. With ``targets_seed`` the ``num_goals`` goals are drawn from it
    instead: directions one in each of ``num_goals`` equal sectors, uniform within it, in a random order
    (:func:`_spread_angles`), distances uniform within ``radius`` x (1 -+ ``radius_spread``), so the training goals
    and the held-out ones come from one distribution (``docs/tasks.md``, fair held-out targets).

    Training split: every other goal (0, 2, 4, ...; for the default 8 goals those on the x and y axes).

        >>> task = GoalReaching(radius=2.0, radius_spread=0.25, targets_seed=45)
        >>> len(task.goals), bool(((task.goals.norm(dim=-1) >= 1.5) & (task.goals.norm(dim=-1) <= 2.5)).all())
        (8, True)
    """

    kind = "goal_reaching"
    figures = ("paths", "gait")

    def __init__(self, radius: float = 2.0, num_goals: int = 8, num_steps: int = 30, angle_offset: float = 0.0,
                 goals: Sequence[Sequence[float]] | None = None, targets_seed: int | None = None,
                 radius_spread: float = 0.25, name: str | None = None):
        super().__init__(name)
        if goals is None and targets_seed is not None:
            radius = _number("radius", radius, positive=True)
            spread = _number("radius_spread", radius_spread)
            if not 0 <= spread < 1:
                raise ValueError(f"radius_spread must be in [0, 1), got {radius_spread!r}")
            count = _whole("num_goals", num_goals, 1)
            rng = np.random.default_rng(_whole("targets_seed", targets_seed, 0))
            angles = _spread_angles(rng, count)
            radii = rng.uniform(radius * (1 - spread), radius * (1 + spread), count)
            goals = np.stack([radii * np.cos(angles), radii * np.sin(angles)], -1)
        if goals is None:
            radius = _number("radius", radius, positive=True)
            num_goals = _whole("num_goals", num_goals, 1)
            angle_offset = _number("angle_offset", angle_offset)
            angles = angle_offset + 2 * math.pi * torch.arange(num_goals, device="cpu") / num_goals
            goals = torch.stack([radius * torch.cos(angles), radius * torch.sin(angles)], -1)
        points = _points("goals", goals, "(x, y) positions in m")
        self.goals = torch.as_tensor(points.astype(np.float32), device="cpu")
        self.num_episodes = len(self.goals)
        self.num_steps = _whole("num_steps", num_steps, 1)

    def target(self, episode, step):
        return self.on("goals", episode.device)[episode]

    def markers(self, episode: int | None = None) -> np.ndarray:
        """The goals ``K x 2`` (m), or goal ``episode`` alone (``1 x 2``)."""
        goals = self.goals.numpy().astype(np.float64)
        return goals if episode is None else goals[int(episode)][None]

    def extra_metrics(self, com_paths, episodes=None) -> dict[str, np.ndarray]:
        """``steps_to_goal``: per episode, the action (1-based) during which the CoM first came within 0.2 m of the
        goal, NaN if it never did (the paper's hardware metric, Li et al., Sec. IV-D: "all goals in 16.0 +- 1.4
        steps"). ``com_paths``: ``E x S x >=2`` with ``S`` = ``num_steps`` x N samples."""
        paths = np.asarray(com_paths)[..., :2]
        episodes = np.arange(len(paths)) % self.num_episodes if episodes is None else np.asarray(episodes)
        goals = self.goals.numpy().astype(np.float64)[episodes]
        within = np.linalg.norm(paths - goals[:, None], axis=-1) <= SUCCESS_RADIUS
        per_action = max(1, paths.shape[1] // self.num_steps)
        first = np.argmax(within, axis=1)
        return {"steps_to_goal": np.where(within.any(1), first // per_action + 1.0, np.nan)}

    @property
    def training_episodes(self) -> list[int]:
        """Every other goal: ``[0, 2, 4, ...]``.

            >>> GoalReaching().training_episodes
            [0, 2, 4, 6]
        """
        return list(range(0, self.num_episodes, 2))

    def training_split(self) -> "GoalReaching":
        return GoalReaching(goals=self.goals[self.training_episodes].numpy(), num_steps=self.num_steps,
                            name=f"{self.name}_train")

    def tracking_error(self, state, next_state, target):
        return torch.linalg.vector_norm(target - next_state[..., :2], dim=-1)


def s_path(num_points: int = 2001) -> np.ndarray:
    """``num_points x 2`` points of the S-shaped reference path (m): ``(1 - cos a, 1.5 sin a)`` then
    ``(3 - cos a, -1.5 sin a)`` for ``a`` in ``[0, pi]``; it leaves the origin along +y and is about 7.9 m long."""
    a = np.linspace(0.0, np.pi, num_points // 2 + 1)
    first = np.stack([1 - np.cos(a), 1.5 * np.sin(a)], -1)
    second = np.stack([3 - np.cos(a), -1.5 * np.sin(a)], -1)
    return np.concatenate([first, second[1:]])


def random_path(seed: int, *, length_m: float = 8.0, max_curvature_per_m: float = 1.0, knot_spacing_m: float = 0.5,
                num_points: int = 2001) -> np.ndarray:
    """``num_points x 2`` points (m) of a random smooth path from the origin, leaving along +y (the robots' start
    heading): its curvature is drawn uniformly in ``[-max_curvature_per_m, max_curvature_per_m]`` at knots every
    ``knot_spacing_m`` of arc length (from ``seed``) and interpolated linearly between them, so every stretch of it
    comes from one distribution: its first half (a model-free baseline's training split) is no mirror of its second
    (``docs/tasks.md``, fair held-out targets).

        >>> path = random_path(45, length_m=6.0)
        >>> path.shape, bool(np.allclose(path[0], 0.0))
        ((2001, 2), True)
        >>> round(float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()), 3)
        6.0
    """
    length_m = _number("length_m", length_m, positive=True)
    max_curvature_per_m = _number("max_curvature_per_m", max_curvature_per_m)
    knot_spacing_m = _number("knot_spacing_m", knot_spacing_m, positive=True)
    if length_m / knot_spacing_m > MAX_RANDOM_TARGETS:  # a crafted config must not ask for billions of knots
        raise ValueError(f"length_m / knot_spacing_m must be at most {MAX_RANDOM_TARGETS}, got {length_m} m / "
                         f"{knot_spacing_m} m")
    rng = np.random.default_rng(_whole("seed", seed, 0))
    knots = np.arange(0.0, length_m + knot_spacing_m, knot_spacing_m)
    curvature_knots = rng.uniform(-abs(max_curvature_per_m), abs(max_curvature_per_m), len(knots))
    arc = np.linspace(0.0, length_m, num_points)
    curvature = np.interp(arc, knots, curvature_knots)
    step = np.diff(arc)
    heading = START_YAW + np.concatenate([[0.0], np.cumsum(0.5 * (curvature[1:] + curvature[:-1]) * step)])
    middle = 0.5 * (heading[1:] + heading[:-1])  # the heading over each step (midpoint rule: lengths are exact)
    moves = np.stack([np.cos(middle), np.sin(middle)], -1) * step[:, None]
    return np.concatenate([np.zeros((1, 2)), np.cumsum(moves, axis=0)])


@TASKS.register("trajectory_tracking")
class TrajectoryTracking(Task):
    """Follow a reference point moving along ``path`` (default the S path) at ``speed`` m/s.

    The episode lasts until the reference reaches the end of the path, plus ``extra_steps``. ``final_error`` is the
    distance to the end of the path; :meth:`path_distance` gives the distance from the CoM to the path, reported per
    episode by :meth:`extra_metrics` as ``path_distance`` (the mean over the CoM path, m).

    ``path_seed`` replaces the S path by :func:`random_path` (``path_length_m`` long, curvature up to
    ``max_curvature_per_m``), whose halves come from one distribution (``docs/tasks.md``, fair held-out targets).

    Training split: the first half of the path's points, at the same speed, with the same ``extra_steps``.
    """

    kind = "trajectory_tracking"

    def __init__(self, path: np.ndarray | None = None, speed: float = 0.1, extra_steps: int = 10,
                 path_seed: int | None = None, path_length_m: float = 8.0, max_curvature_per_m: float = 1.0,
                 name: str | None = None):
        super().__init__(name)
        if path is None and path_seed is not None:
            path = random_path(path_seed, length_m=path_length_m, max_curvature_per_m=max_curvature_per_m)
        points = s_path() if path is None else _points("path", path, "(x, y) points in m", min_points=2)
        if not np.linalg.norm(np.diff(points, axis=0), axis=1).sum() > 0:
            raise ValueError("path must be finite points (m) with a positive length")
        speed = _number("speed", speed, positive=True)
        self.extra_steps = _whole("extra_steps", extra_steps, 0)
        self.path = torch.as_tensor(points, dtype=torch.float32, device="cpu")
        self.arc_length = torch.as_tensor(np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0),
                                                                                          axis=1))]),
                                          dtype=torch.float32, device="cpu")
        self.length = float(self.arc_length[-1])
        self.speed = float(speed)
        self.num_steps = int(math.ceil(self.length / (self.speed * self.step_duration))) + self.extra_steps
        times = (torch.arange(self.num_steps, device="cpu") + 1) * self.step_duration
        self.references = self.point_at(torch.clamp(self.speed * times, max=self.length))  # T x 2

    def point_at(self, arc: torch.Tensor) -> torch.Tensor:
        """``... x 2`` path points at arc lengths ``...`` (m), linearly interpolated."""
        index = torch.clamp(torch.searchsorted(self.arc_length, arc.contiguous()), 1, len(self.arc_length) - 1)
        s0, s1 = self.arc_length[index - 1], self.arc_length[index]
        w = ((arc - s0) / (s1 - s0).clamp_min(1e-9))[..., None]
        return self.path[index - 1] * (1 - w) + self.path[index] * w

    def target(self, episode, step):
        return self.on("references", step.device)[step.clamp(0, self.num_steps - 1)]

    def tracking_error(self, state, next_state, target):
        return torch.linalg.vector_norm(target - next_state[..., :2], dim=-1)

    def final_error(self, com_states, episodes):
        end = self.path[-1].to(com_states.device, com_states.dtype)
        return torch.linalg.vector_norm(com_states[:, -1, :2] - end, dim=-1)

    def path_distance(self, positions) -> np.ndarray:
        """Distance (m) from each ``... x 2`` position to the path."""
        positions = _as_tensor(positions).double()
        dense = self.point_at(torch.linspace(0, self.length, 4000, device="cpu")).double()
        return torch.cdist(positions.reshape(-1, 2), dense).min(-1).values.reshape(positions.shape[:-1]).numpy()

    def markers(self, episode: int | None = None) -> np.ndarray:
        """The reference points ``T x 2`` (m), one per task step, along the path (the same for every episode)."""
        return self.references.numpy().astype(np.float64)

    def extra_metrics(self, com_paths, episodes=None) -> dict[str, np.ndarray]:
        """``path_distance``: per episode, the mean distance (m) from the CoM (``E x S x >=2`` paths) to the path."""
        return {"path_distance": self.path_distance(np.asarray(com_paths)[..., :2]).mean(1)}

    def training_split(self) -> "TrajectoryTracking":
        path = self.path.numpy()
        return TrajectoryTracking(path=path[: len(path) // 2 + 1], speed=self.speed, extra_steps=self.extra_steps,
                                  name=f"{self.name}_train")


def task_options(kind: str) -> list[str]:
    """The keyword options of the task type registered as ``kind`` (its constructor's arguments, ``name`` last)."""
    return [*TASKS.options(kind), "name"]


def make_task(kind: str, /, **options) -> Task:
    """A task by registry name ``kind``, with keyword ``options`` (those of its constructor, see
    :func:`task_options`; ``name=`` names this task, default ``kind``).

    Raises ``ValueError`` for an unknown task, an unknown option (naming it and the valid ones) or a bad value,
    before any work.

    Example:
        >>> task = make_task("goal_reaching", radius=1.5, num_goals=4, name="goal_reaching_1.5m")
        >>> task.name, task.goals.norm(dim=-1).tolist()
        ('goal_reaching_1.5m', [1.5, 1.5, 1.5, 1.5])

    ``make_task("goal_reaching", radus=2)`` raises ``ValueError: goal_reaching: unknown option 'radus'; valid
    options: radius, num_goals, num_steps, angle_offset, goals, targets_seed, radius_spread, name``.
    """
    cls = TASKS[kind]
    if not (isinstance(cls, type) and issubclass(cls, Task)):
        raise ValueError(f"task {kind!r} is not a hierloco.envs.tasks.Task subclass")
    valid = task_options(kind)
    unknown = [key for key in options if key not in valid]
    if unknown:
        listed = ", ".join(repr(key) for key in unknown)
        raise ValueError(f"{kind}: unknown option{'s' if len(unknown) > 1 else ''} {listed}; valid options: "
                         f"{', '.join(valid)}")
    return cls(**options)
