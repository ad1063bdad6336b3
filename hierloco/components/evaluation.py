"""Closed-loop MPC on the simulated robots: run a task's episodes with a planner and score them (SPEC 5.4, 6).

Every episode of the task runs on its own robot of a :class:`LatentActionEnv` (8 goals -> 8 robots in one batched
simulation). At each task step the planner chooses an action from the measured state with the world model (or a
learned policy acts), the robot executes it for one action (N control steps), and MPC re-plans from the new
measured state. Episodes run their
full length, so the cost covers every step; a robot that falls stays down, keeps paying the cost and is counted.

Example:
    >>> # env: a LatentActionEnv(record=True); planner: e.g. RandomShootingPlanner(CoMWorldModelEnv(model, ...))
    >>> # rollout = run_task(env, planner, GoalReaching())  # doctest: +SKIP
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from torchrl.envs import Compose, TransformedEnv
from torchrl.envs.utils import step_mdp
from tqdm.auto import tqdm

from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP
from hierloco.envs.tasks import Task, TaskResult
from hierloco.envs.transforms import TaskTransform


@dataclass
class TaskRollout:
    """What happened in a task's episodes.

    Attributes:
        result: per-episode costs and metrics (:class:`TaskResult`).
        actions: ``E x T x A`` chosen actions.
        com_paths: ``E x (T * N) x 5`` CoM states at 100 Hz (when the env records), else ``None``.
        foot_contacts: ``E x (T * N) x L`` (when the env records), else ``None``.
        qpos: ``E x (T * N) x nq`` generalised positions at 100 Hz (when the env records), for videos.
        fell: ``E`` bool, whether the robot fell (or blew up) during the episode.
        plan_seconds: mean wall-clock of one policy (planner) call.
    """

    result: TaskResult
    actions: np.ndarray
    com_paths: np.ndarray | None
    foot_contacts: np.ndarray | None
    qpos: np.ndarray | None
    fell: np.ndarray
    plan_seconds: float


def run_task(env: LatentActionEnv, policy, task: Task, episodes=None, transforms: Sequence = (),
             progress: bool = False) -> TaskRollout:
    """Runs every episode of ``task`` on ``env``'s robots with ``policy``, one robot per episode (``episodes``:
    which episode each robot runs).

    ``policy`` is an MPC planner (its world model env is re-targeted to ``task`` and its warm start reset) or any
    TensorDict policy, e.g. a SAC actor; ``transforms`` go after the task transform (e.g. a goal observation)."""
    count = env.batch_size[0]
    episodes = torch.arange(count) % task.num_episodes if episodes is None else torch.as_tensor(episodes)
    if episodes.numel() != count:
        raise ValueError(f"{count} robots for {episodes.numel()} episodes")
    if hasattr(getattr(policy, "env", None), "set_task"):
        policy.env.set_task(task)
    if hasattr(policy, "reset"):
        policy.reset()
    task_env = TransformedEnv(env, Compose(TaskTransform(task, episodes), *transforms))
    td = task_env.reset()
    steps, plan_time = [], 0.0
    for _ in tqdm(range(task.num_steps), desc=task.name, disable=not progress, leave=False):
        start = time.perf_counter()
        td = policy(td)
        plan_time += time.perf_counter() - start
        td = task_env.step(td)
        steps.append(td.exclude("next").update({"next": td.get("next")}).clone())
        td = step_mdp(td)
    rollout = torch.stack(steps, dim=1)  # E x T
    states = torch.cat([rollout["com_state"], rollout["next", "com_state"][:, -1:]], 1)
    result = task.evaluate(states, episodes)
    paths = contacts = qpos = None
    if env.record:
        paths = rollout["next", "com_path"].flatten(1, 2).numpy()
        contacts = rollout["next", "foot_contacts"].flatten(1, 2).numpy()
        qpos = rollout["next", "qpos"].flatten(1, 2).numpy()
    fell = rollout["next", "terminated"].squeeze(-1).any(1).numpy()
    actions = rollout["action"].reshape(count, task.num_steps, -1).float().numpy()
    return TaskRollout(result, actions, paths, contacts, qpos, fell, plan_time / task.num_steps)


def latent_grid_paths(low_level, *, grid: int = 7, num_actions: int = 3, seed: int = 0):
    """Walks a ``grid x grid`` lattice of 2-D actions over the low level's box from standing, each held for
    ``num_actions`` actions. Returns the latents ``G x 2`` and the CoM paths ``G x (num_actions * N) x 5``."""
    if low_level.action_dim != 2:
        raise ValueError(f"the latent map needs a 2-D action space, this one has {low_level.action_dim} dimensions")
    axes = [np.linspace(lo, hi, grid) for lo, hi in zip(low_level.action_low, low_level.action_high)]
    latents = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 2)
    from hierloco.envs.batched_sim import BatchedSimulator

    sim = BatchedSimulator(low_level.robot, len(latents), seed=seed)
    paths = [low_level.run(sim, latents).com_state for _ in range(num_actions)]
    sim.close()
    return latents, np.concatenate(paths, 1)


def check_gait_policy(low_level, library, latents: np.ndarray, *, num_pairs: int = 50, num_actions: int = 4,
                      seed: int = 0) -> dict:
    """How well ``pi(., z)`` reproduces and interpolates the experts, in simulation (SPEC 5.2).

    Runs ``pi(., z_g)`` open loop for every expert latent, and ``pi(., (z_a + z_b) / 2)`` for ``num_pairs`` random
    pairs, each for ``num_actions`` actions from standing, and measures the mean CoM velocity over the last
    ``num_actions - 1`` actions (in each action's start frame). Returns:

    - ``reproduction_error``: ``G`` velocity errors (m/s) against each expert's recorded velocity, and
      ``reproduced_fraction``: the fraction within 0.05 m/s;
    - ``interpolation_walks``: the fraction of midpoints that walk without falling, and
      ``interpolation_between``: the fraction that also move between the two experts (within 0.05 m/s of the
      segment joining their velocities).
    """
    from hierloco.components.expert_library import action_motion
    from hierloco.envs.batched_sim import BatchedSimulator

    rng = np.random.default_rng(seed)
    latents = np.asarray(latents, dtype=np.float64)
    pairs = np.array([rng.choice(len(latents), 2, replace=False) for _ in range(num_pairs)])
    queries = np.concatenate([latents, 0.5 * (latents[pairs[:, 0]] + latents[pairs[:, 1]])])
    sim = BatchedSimulator(low_level.robot, len(queries), seed=seed)
    n = low_level.steps_per_action
    results = [low_level.run(sim, queries) for _ in range(num_actions)]
    sim.close()
    fell = np.any([r.failed[:, -1] for r in results], axis=0)
    duration = n * CONTROL_TIMESTEP
    velocities = []
    for previous, current in zip(results[:-1], results[1:]):
        states = np.concatenate([previous.com_state[:, -1:], current.com_state], 1)
        velocities.append(action_motion(states, duration)[1])
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
