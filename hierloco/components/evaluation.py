"""Closed-loop evaluation on the simulated robots: run a task's episodes with a planner (or a learned policy) and
score them (Li et al., RA-L 2021, Sec. III-A.2 for MPC, Sec. IV-A for the tasks and their costs).

Every episode of the task runs on its own robot of a :class:`LatentActionEnv` (8 goals -> 8 robots in one batched
simulation). At each task step the policy chooses an action from the measured state (a planner with its world
model), the robot executes it for one action (N control steps), and MPC re-plans from the new measured state.
Episodes run their full length, so the cost covers every step; a robot that falls stays down, keeps paying the cost
and is counted (:class:`hierloco.envs.transforms.ContinueAfterFalls`).

Example:
    >>> import torch
    >>> from hierloco.components.expert_library import build_expert_library
    >>> from hierloco.components.low_level import ExpertReplayLowLevel
    >>> from hierloco.components.planners import ExhaustivePlanner
    >>> from hierloco.envs.tasks import GoalReaching
    >>> from hierloco.envs.world_model import CoMWorldModelEnv
    >>> library = build_expert_library("daisy", 3, progress=False)
    >>> class Replay(torch.nn.Module):  # a stand-in CoM model: each expert moves by its recorded displacement
    ...     def predict(self, com_state, action):
    ...         moves = torch.as_tensor(library.com_states[:, -1, :2] - library.com_states[:, 0, :2]).float()
    ...         return torch.cat([com_state[..., :2] + moves[action[..., 0].long()], com_state[..., 2:]], -1)
    >>> planner = ExhaustivePlanner(CoMWorldModelEnv(Replay(), num_choices=3))
    >>> env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2, record=True)
    >>> rollout = run_task(env, planner, GoalReaching(num_goals=2, num_steps=3))
    >>> rollout.actions.shape, rollout.com_paths.shape, sorted(rollout.result.cost_terms)
    ((2, 3, 1), (2, 300, 5), ['tracking', 'yaw'])
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import torch
from torchrl.envs import Compose, TransformedEnv
from tqdm.auto import tqdm

from hierloco.components.policies import TaskPolicy
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP
from hierloco.envs.tasks import Task, TaskResult
from hierloco.envs.transforms import ContinueAfterFalls, task_transforms


@dataclass
class TaskRollout:
    """What happened in a task's episodes.

    Attributes:
        result: per-episode costs, cost terms and metrics (:class:`TaskResult`).
        actions: ``E x T x A`` chosen actions (``E x (T r) x A`` with an env that re-plans ``r`` times per task step:
            :func:`replans_per_action`).
        com_paths: ``E x (T * N) x 5`` CoM states at 100 Hz (when the env records), else ``None``.
        foot_contacts: ``E x (T * N) x L`` (when the env records), else ``None``.
        qpos: ``E x (T * N) x nq`` generalised positions at 100 Hz (when the env records), for videos.
        fell: ``E`` bool, whether the robot fell (or blew up) during the episode.
        plan_seconds: mean wall-clock of one policy (planner) call, s.
        metrics: the task's per-episode extra metrics (:meth:`Task.extra_metrics`, each ``E``) over the 100 Hz CoM
            paths, e.g. ``path_distance`` (m) for trajectory tracking; empty when the env does not record.
        fell_step: ``E`` int, the task step during which each robot first fell (``-1``: it did not).
        pushes: the pushes its robots took (:class:`hierloco.envs.terrain.PushEvent`, ``copy`` = the robot), when
            the env pushes (``docs/terrain.md``).
    """

    result: TaskResult
    actions: np.ndarray
    com_paths: np.ndarray | None
    foot_contacts: np.ndarray | None
    qpos: np.ndarray | None
    fell: np.ndarray
    plan_seconds: float
    metrics: dict[str, np.ndarray] = field(default_factory=dict)
    fell_step: np.ndarray | None = None
    pushes: list = field(default_factory=list)


class _TimedPolicy:
    """Calls ``policy``, adding its wall-clock to ``seconds`` and ticking the progress bar once per call."""

    def __init__(self, policy, bar):
        self.policy, self.bar, self.seconds = policy, bar, 0.0

    def __call__(self, tensordict):
        start = time.perf_counter()
        out = self.policy(tensordict)
        self.seconds += time.perf_counter() - start
        self.bar.update(1)
        return out


def replans_per_action(env) -> int:
    """How many times ``env`` lets a policy choose per task step: ``N / replan_steps`` for a
    :class:`LatentActionEnv` that re-plans within an action (``docs/terrain.md``), else 1."""
    replan_steps = getattr(env, "replan_steps", None)
    return 1 if replan_steps is None else env.steps_per_action // replan_steps


def run_task(env: LatentActionEnv, policy, task: Task, *, episodes=None, transforms: Sequence = (),
             progress: bool = False) -> TaskRollout:
    """Runs every episode of ``task`` on ``env``'s robots with ``policy``, one robot per episode.

    Args:
        env: the robots, one per episode (a :class:`LatentActionEnv`; ``record=True`` for the 100 Hz paths).
        policy: a :class:`hierloco.components.policies.TaskPolicy` (an MPC planner, whose
            :meth:`~hierloco.components.policies.TaskPolicy.begin_task` re-targets its world model to ``task`` and
            resets its warm start; or an :class:`~hierloco.components.policies.ActorPolicy`); any other TensorDict
            callable acts as it is.
        task: the task; its episodes run their full ``task.num_steps`` steps (``env.rollout`` with
            ``break_when_any_done=False``; a fallen robot is not reset).
        episodes: which episode each robot runs (``B``, default ``b % task.num_episodes``).
        transforms: go after the task transforms (e.g. a goal observation).
        progress: a per-step progress bar.

    With an env that re-plans ``r`` times per task step (:func:`replans_per_action`), the policy chooses ``r``
    times per task step and the task is scored on its own steps (the state at every ``r``-th env step): the costs
    compare with those of an env that plans once per step.
    """
    count = env.batch_size[0]
    episodes = (torch.arange(count, device="cpu") % task.num_episodes if episodes is None
                else torch.as_tensor(episodes, device="cpu"))
    if episodes.numel() != count:
        raise ValueError(f"{count} robots for {episodes.numel()} episodes")
    if isinstance(policy, TaskPolicy):
        policy.begin_task(task)
    replans = replans_per_action(env)
    steps = task.num_steps * replans
    task_env = TransformedEnv(env, Compose(ContinueAfterFalls(), task_transforms(task, episodes, replans=replans),
                                           *transforms))
    with tqdm(total=steps, desc=task.name, disable=not progress, leave=False) as bar:
        timed = _TimedPolicy(policy, bar)
        rollout = task_env.rollout(max_steps=steps, policy=timed, auto_reset=True,
                                   break_when_any_done=False, trust_policy=True)  # E x (T r)
    key = "com_state_true" if "com_state_true" in rollout.keys() else "com_state"  # costs on the true state
    # the task's own steps: the state at the start of every r-th env step, and the last
    states = torch.cat([rollout[key][:, ::replans], rollout["next", key][:, -1:]], 1)
    result = task.evaluate(states, episodes)
    paths = contacts = qpos = None
    metrics = {}
    if env.record:
        paths = rollout["next", "com_path"].flatten(1, 2).numpy()
        contacts = rollout["next", "foot_contacts"].flatten(1, 2).numpy()
        qpos = rollout["next", "qpos"].flatten(1, 2).numpy()
        metrics = task.extra_metrics(paths, episodes.numpy())
    fallen = rollout["next", "fallen"].squeeze(-1).numpy()  # E x (T r), true from the step a robot fell
    fell = fallen.any(1)
    actions = rollout["action"].reshape(count, steps, -1).float().numpy()
    return TaskRollout(result, actions, paths, contacts, qpos, fell, timed.seconds / steps, metrics,
                       fell_step=np.where(fell, fallen.argmax(1) // replans, -1),
                       pushes=list(getattr(getattr(env, "sim", None), "push_log", ())))


RECOVERY_WINDOW_S = 0.5  # the CoM velocity is averaged over this long (about two gait periods) to judge recovery
RECOVERY_TOLERANCE_MPS = 0.05  # recovered: back within this of the velocity error the robot had before the push


def world_metrics(rollout: TaskRollout, task: Task, *, steps_per_action: int, pushes: bool = False,
                  window_s: float = RECOVERY_WINDOW_S, tolerance_mps: float = RECOVERY_TOLERANCE_MPS
                  ) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Falls and push recovery of an evaluation off the lab floor (``docs/terrain.md``): per episode (each ``E``)
    and as a summary.

    Per episode: ``fell`` (1 when the robot fell). With ``pushes``: ``pushes`` (the pushes it took standing: one on
    a fallen robot is not counted), ``push_falls`` (pushes it did not survive: it fell before the next push, or
    before the episode's end, to the resolution of one action), ``pushes_recovered`` and ``recovery_s`` (the mean
    time, over the pushes it recovered from, until it moved as commanded again; NaN when none). Recovery: the CoM
    velocity averaged over ``window_s`` from a time on is back within ``tolerance_mps`` of the error it had over the
    ``window_s`` before the push, against the task's commanded velocity (a velocity-tracking task's target, world
    frame) or, for other tasks, against the velocity it had before the push; before the next push.

    Summary: ``fall_rate``; with pushes ``pushes``, ``push_fall_rate`` (pushes not survived / pushes, NaN without
    pushes), ``recovered_fraction`` (of the pushes survived) and ``recovery_s`` (mean over the recovered).

    Example:
        >>> import numpy as np
        >>> from hierloco.envs.tasks import VelocityTracking
        >>> from hierloco.envs.terrain import PushEvent
        >>> task = VelocityTracking(velocities=[[0.0, 0.2]], steps_per_target=4, rounds=1)
        >>> paths = np.zeros((1, 400, 5)); paths[0, :, 4] = 0.2   # tracking 0.2 m/s forward ...
        >>> paths[0, 150:180, 3] = 0.5                            # ... knocked sideways for 0.3 s at 1.5 s
        >>> rollout = TaskRollout(None, None, paths, None, None, np.zeros(1, bool), 0.0,
        ...                       fell_step=np.array([-1]), pushes=[PushEvent(0, 150, 50, 1.5, (0.5, 0.0), 0.0)])
        >>> per_episode, summary = world_metrics(rollout, task, steps_per_action=100, pushes=True)
        >>> summary["push_fall_rate"], summary["recovery_s"]
        (0.0, 0.25)
    """
    fell = np.asarray(rollout.fell, dtype=bool)
    count = len(fell)
    per_episode = {"fell": fell.astype(np.float64)}
    summary = {"fall_rate": float(fell.mean())}
    if not pushes:
        return per_episode, summary
    fell_step = (np.asarray(rollout.fell_step) if rollout.fell_step is not None
                 else np.where(fell, task.num_steps - 1, -1))
    n, steps = int(steps_per_action), task.num_steps
    window = max(1, int(round(window_s / CONTROL_TIMESTEP)))
    paths = rollout.com_paths
    commands = None
    if paths is not None and getattr(task, "target_is_velocity", False):
        episodes = torch.arange(count, device="cpu")[:, None] % task.num_episodes
        targets = task.target(episodes.expand(count, steps), torch.arange(steps, device="cpu")[None].expand(count,
                                                                                                           steps))
        commands = np.repeat(np.asarray(targets, dtype=np.float64), n, axis=1)  # E x (T * N) x 2, world frame
    taken, not_survived, recovered = np.zeros(count), np.zeros(count), np.zeros(count)
    recovery = [[] for _ in range(count)]
    for e in range(count):
        events = sorted((p.episode_step for p in rollout.pushes if p.copy == e and p.episode_step < steps * n))
        for k, step in enumerate(events):
            action = step // n
            if 0 <= fell_step[e] < action:
                continue  # already down
            taken[e] += 1
            following = events[k + 1] if k + 1 < len(events) else steps * n
            last = max(action, following // n - 1) if k + 1 < len(events) else steps - 1
            if action <= fell_step[e] <= last:
                not_survived[e] += 1
                continue
            if paths is None:
                continue
            seconds = _recovery_seconds(paths[e, :, 3:5].astype(np.float64), None if commands is None
                                        else commands[e], step, following, window, tolerance_mps)
            if np.isfinite(seconds):
                recovered[e] += 1
                recovery[e].append(seconds)
    times = [t for episode in recovery for t in episode]
    per_episode.update({"pushes": taken, "push_falls": not_survived, "pushes_recovered": recovered,
                        "recovery_s": np.array([np.mean(t) if t else np.nan for t in recovery])})
    survived = taken.sum() - not_survived.sum()
    summary.update({"pushes": float(taken.sum()),
                    "push_fall_rate": float(not_survived.sum() / taken.sum()) if taken.sum() else float("nan"),
                    "recovered_fraction": float(recovered.sum() / survived) if survived else float("nan"),
                    "recovery_s": float(np.mean(times)) if times else float("nan")})
    return per_episode, summary


def _recovery_seconds(velocity: np.ndarray, command: np.ndarray | None, push: int, until: int, window: int,
                      tolerance: float) -> float:
    """Seconds from the push at control step ``push`` until the CoM ``velocity`` (``S x 2``) averaged over
    ``window`` steps is back within ``tolerance`` of its error before the push (against ``command``, ``S x 2``, or
    its own velocity before the push), with the window ending by ``until``; NaN when it is not."""
    start = max(0, push - window)
    if push <= start:
        return float("nan")
    cumulative = np.concatenate([np.zeros((1, 2)), np.cumsum(velocity, 0)])
    before = (cumulative[push] - cumulative[start]) / (push - start)
    error_before = 0.0
    if command is not None:
        commanded = np.concatenate([np.zeros((1, 2)), np.cumsum(command, 0)])
        error_before = float(np.linalg.norm(before - (commanded[push] - commanded[start]) / (push - start)))
    last = min(until, len(velocity)) - window
    for t in range(push, last + 1):
        mean = (cumulative[t + window] - cumulative[t]) / window
        reference = before if command is None else (commanded[t + window] - commanded[t]) / window
        if np.linalg.norm(mean - reference) <= error_before + tolerance:
            return (t - push) * CONTROL_TIMESTEP
    return float("nan")


def latent_grid(action_low, action_high, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """A lattice of ``grid`` points per axis over the box ``[action_low, action_high]`` (``Z`` each): the integer
    lattice index ``G x Z`` and the latents ``G x Z``, ``G = grid ** Z``, the last axis varying fastest.

        >>> index, latents = latent_grid([-1.0, 0.0], [1.0, 2.0], 3)
        >>> index.shape, latents[:4].tolist()
        ((9, 2), [[-1.0, 0.0], [-1.0, 1.0], [-1.0, 2.0], [0.0, 0.0]])
    """
    low, high = np.asarray(action_low, dtype=np.float64), np.asarray(action_high, dtype=np.float64)
    index = np.stack(np.meshgrid(*[np.arange(grid)] * len(low), indexing="ij"), -1).reshape(-1, len(low))
    return index, low + (high - low) * index / (grid - 1)


def latent_grid_paths(low_level, *, grid: int = 7, num_actions: int = 3, seed: int = 0):
    """Walks a ``grid x grid`` lattice of 2-D actions over the low level's box from standing, each held for
    ``num_actions`` actions. Returns the latents ``G x 2`` and the CoM paths ``G x (num_actions * N) x 5``."""
    if low_level.action_dim != 2:
        raise ValueError(f"the latent map needs a 2-D action space, this one has {low_level.action_dim} dimensions")
    _, latents = latent_grid(low_level.action_low, low_level.action_high, grid)
    from hierloco.envs.batched_sim import BatchedSimulator

    sim = BatchedSimulator(low_level.robot, len(latents), seed=seed)
    paths = [low_level.run(sim, latents).com_state for _ in range(num_actions)]
    sim.close()
    return latents, np.concatenate(paths, 1)


def continuity_statistics(index: np.ndarray, velocity: np.ndarray, fell: np.ndarray) -> dict:
    """How continuously a lattice of latents maps to CoM motion: the mean distance between the CoM velocities
    (``G x 2``, m/s) of lattice neighbours (``index`` ``G x Z`` one step apart along one axis) and of all pairs of
    lattice points, over the pairs where neither robot fell (``fell``: ``G`` bool). A continuous map gives
    neighbours much closer than the average pair (their ratio well below 1); a map that jumps between neighbours
    does not.

        >>> index = np.arange(5)[:, None]
        >>> smooth = np.stack([np.linspace(0, 0.4, 5), np.zeros(5)], -1)
        >>> round(continuity_statistics(index, smooth, np.zeros(5, bool))["ratio"], 3)
        0.5
    """
    index, velocity, fell = np.asarray(index), np.asarray(velocity, dtype=np.float64), np.asarray(fell, dtype=bool)
    i, j = np.triu_indices(len(index), 1)
    walking = ~fell[i] & ~fell[j]
    distance = np.linalg.norm(velocity[i] - velocity[j], axis=-1)
    neighbours = walking & (np.abs(index[i] - index[j]).sum(-1) == 1)
    near = float(distance[neighbours].mean()) if neighbours.any() else float("nan")
    pair = float(distance[walking].mean()) if walking.any() else float("nan")
    return {"neighbour_difference": near, "pair_difference": pair, "ratio": near / pair if pair > 0 else float("nan"),
            "neighbour_pairs": int(neighbours.sum()), "pairs": int(walking.sum()), "fell_fraction": float(fell.mean())}


def latent_continuity(low_level, *, grid: int = 7, num_actions: int = 3, seed: int = 0) -> dict:
    """Li et al., RA-L 2021, Sec. III-B, Fig. 4: "close-by samples in the latent space lead to continuously varying
    CoM motion". Holds every latent of a ``grid``-point lattice over the low level's box (``grid ** Z`` robots in one
    batched simulation) for ``num_actions`` actions from standing and measures each one's mean CoM velocity over the
    actions after the first (``G x 2``, m/s, in each action's start frame); returns the lattice, the velocities,
    which robots fell and :func:`continuity_statistics` (``docs/statistics.md`` for the test over seeds)."""
    from hierloco.envs.batched_sim import BatchedSimulator

    if low_level.num_choices is not None:
        raise ValueError("latent continuity needs a continuous action space, this low level has discrete choices")
    index, latents = latent_grid(low_level.action_low, low_level.action_high, grid)
    sim = BatchedSimulator(low_level.robot, len(latents), seed=seed)
    try:
        results = [low_level.run(sim, latents) for _ in range(num_actions)]
    finally:
        sim.close()
    velocities, fell = action_velocities(results, low_level.steps_per_action)
    velocity = np.mean(velocities, 0)
    return {"grid": int(grid), "latent_dim": int(latents.shape[1]), "num_actions": int(num_actions),
            "latents": latents.tolist(), "velocity": velocity.tolist(), "fell": fell.tolist(),
            **continuity_statistics(index, velocity, fell)}


def action_velocities(results, steps_per_action: int) -> tuple[list[np.ndarray], np.ndarray]:
    """The mean CoM velocity of each action after the first (``B x 2`` each, in that action's start frame) of
    successive :class:`~hierloco.envs.batched_sim.SimulationResult` s of the same robots, and which robots fell
    (``B`` bool) by the end of any action."""
    from hierloco.components.expert_library import action_motion

    duration = steps_per_action * CONTROL_TIMESTEP
    velocities = [action_motion(np.concatenate([previous.com_state[:, -1:], current.com_state], 1), duration)[1]
                  for previous, current in zip(results[:-1], results[1:])]
    return velocities, np.any([r.failed[:, -1] for r in results], axis=0)


def replayed_fraction(library, *, robot=None, num_actions: int = 4, seed: int = 0) -> float:
    """The gait policy's check run on the experts themselves: the fraction of ``library``'s experts whose recorded
    targets, replayed open loop from standing ``num_actions`` times, walk within 0.05 m/s of their recorded
    velocity (mean over the last ``num_actions - 1`` actions). No gait policy reproduces an expert much better than
    its own targets do, so this is the ceiling of :func:`check_gait_policy`'s ``reproduced_fraction``.

    Example:
        >>> from hierloco.components.expert_library import build_expert_library
        >>> library = build_expert_library("daisy", 3, settle_time=1.0, progress=False)
        >>> replayed_fraction(library)
        1.0
    """
    from hierloco.envs.batched_sim import BatchedSimulator

    sim = BatchedSimulator(library.robot if robot is None else robot, library.num_experts, seed=seed)
    try:
        results = [sim.run(library.joint_targets) for _ in range(num_actions)]
    finally:
        sim.close()
    velocities, fell = action_velocities(results, library.steps_per_action)
    error = np.linalg.norm(np.mean(velocities, 0) - library.velocity_local, axis=-1)
    return float(np.mean((error <= 0.05) & ~fell))


def check_gait_policy(low_level, library, latents: np.ndarray, *, num_pairs: int = 50, num_actions: int = 4,
                      seed: int = 0) -> dict:
    """How well ``pi(., z)`` reproduces and interpolates the experts, in simulation (Li et al., RA-L 2021, Sec. III-B:
    ``pi(., z_g)`` must match expert g; latents between experts give new, interpolating gaits).

    Runs ``pi(., z_g)`` open loop for every expert latent, and ``pi(., (z_a + z_b) / 2)`` for ``num_pairs`` random
    pairs, each for ``num_actions`` actions from standing, and measures the mean CoM velocity over the last
    ``num_actions - 1`` actions (in each action's start frame). Returns:

    - ``reproduction_error``: ``G`` velocity errors (m/s) against each expert's recorded velocity, and
      ``reproduced_fraction``: the fraction within 0.05 m/s;
    - ``interpolation_walks``: the fraction of midpoints that walk without falling, and
      ``interpolation_between``: the fraction that also move between the two experts (within 0.05 m/s of the
      segment joining their velocities).
    """
    from hierloco.envs.batched_sim import BatchedSimulator

    rng = np.random.default_rng(seed)
    latents = np.asarray(latents, dtype=np.float64)
    pairs = np.array([rng.choice(len(latents), 2, replace=False) for _ in range(num_pairs)])
    queries = np.concatenate([latents, 0.5 * (latents[pairs[:, 0]] + latents[pairs[:, 1]])])
    sim = BatchedSimulator(low_level.robot, len(queries), seed=seed)
    results = [low_level.run(sim, queries) for _ in range(num_actions)]
    sim.close()
    velocities, fell = action_velocities(results, low_level.steps_per_action)
    velocity = np.mean(velocities, 0)
    g = len(latents)
    error = np.linalg.norm(velocity[:g] - library.velocity_local, axis=-1)
    error[fell[:g]] = np.inf
    a, b = library.velocity_local[pairs[:, 0]], library.velocity_local[pairs[:, 1]]
    mid = velocity[g:]
    t = np.clip(np.sum((mid - a) * (b - a), -1) / np.maximum(np.sum((b - a) ** 2, -1), 1e-12), 0, 1)
    to_segment = np.linalg.norm(mid - (a + t[:, None] * (b - a)), axis=-1)
    walks = ~fell[g:]
    return {"reproduction_error": error.tolist(), "reproduced_fraction": float(np.mean(error <= 0.05)),
            "interpolation_walks": float(walks.mean()),
            "interpolation_between": float(np.mean(walks & (to_segment <= 0.05))),
            "interpolation_distance_to_segment": to_segment.tolist()}
