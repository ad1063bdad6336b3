"""Factories of the SAC recipe: the training variant of each task, the training env, the SAC training loop and the
evaluation of the trained policy on every target. The LAT low level comes from ``recipes/common/latent.py``."""

from __future__ import annotations

import time

import numpy as np
import torch
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.envs import Compose, TransformedEnv
from tqdm.auto import tqdm

from common import pipeline
from hierloco.components.evaluation import run_task
from hierloco.components.sac import SACAgent
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.tasks import GoalReaching, Task, TrajectoryTracking, VelocityTracking
from hierloco.envs.transforms import GoalObservation, TaskTransform

METHOD = "sac"


def validate(cfg) -> None:
    s = cfg.sac
    extra = pipeline.check_positive({"experts.num_experts": cfg.experts.num_experts, "policy.epochs": cfg.policy.epochs,
                                     "sac.total_frames": s.total_frames, "sac.num_robots": s.num_robots,
                                     "sac.batch_size": s.batch_size, "sac.hidden": s.hidden, "sac.lr": s.lr,
                                     "sac.buffer_size": s.buffer_size, "sac.updates_per_frame": s.updates_per_frame})
    if not 0 < cfg.sac.gamma < 1:
        extra.append(f"sac.gamma must be in (0, 1), got {cfg.sac.gamma}")
    if list(cfg.settings) != ["normal"]:
        extra.append(f"the SAC recipe runs the normal setting only, got settings={list(cfg.settings)}")
    pipeline.validate(cfg, extra=extra)


def training_task(task: Task) -> Task:
    """The same task on half of its targets (SAC is trained on these and tested on all): every other goal, every
    other target velocity, the first half of the path."""
    if isinstance(task, GoalReaching):
        half = GoalReaching(goals=task.goals[::2].numpy(), num_steps=task.num_steps)
    elif isinstance(task, VelocityTracking):
        half = VelocityTracking(velocities=task.velocities[::2].numpy(), steps_per_target=task.steps_per_target,
                                rounds=2 * task.num_steps // (len(task.velocities) * task.steps_per_target))
    elif isinstance(task, TrajectoryTracking):
        path = task.path.numpy()
        half = TrajectoryTracking(path=path[: len(path) // 2 + 1], speed=task.speed,
                                  extra_steps=task.num_steps - int(np.ceil(task.length / task.speed)))
    else:
        raise ValueError(f"no training variant for task {task.name!r}")
    half.name = f"{task.name}_train"
    return half


def task_env(low_level, task: Task, num_robots: int, seed: int, record: bool = False) -> TransformedEnv:
    """``num_robots`` robots on ``task``, robot ``b`` on episode ``b % episodes``, with the goal observation."""
    episodes = torch.arange(num_robots) % task.num_episodes
    env = LatentActionEnv(low_level, num_robots=num_robots, record=record, seed=seed)
    return TransformedEnv(env, Compose(TaskTransform(task, episodes), GoalObservation(task)))


def train_sac(cfg, low_level, task: Task, logger, tag: str) -> tuple[SACAgent, dict]:
    """Trains a goal-conditioned SAC high level on ``task`` for ``sac.total_frames`` actions."""
    s = cfg.sac
    torch.manual_seed(cfg.seed)
    agent = SACAgent.build(GoalObservation.SIZE, low_level.action_low, low_level.action_high, hidden=s.hidden,
                           lr=s.lr, gamma=s.gamma, tau=s.tau, seed=cfg.seed)
    env = task_env(low_level, task, s.num_robots, cfg.seed)
    collector = Collector(env, agent.actor, frames_per_batch=s.num_robots, total_frames=s.total_frames,
                          init_random_frames=s.init_random_frames, auto_register_policy_transforms=False)
    buffer = ReplayBuffer(storage=LazyTensorStorage(s.buffer_size), batch_size=s.batch_size)
    start, frames, updates, returns = time.perf_counter(), 0, 0, []
    bar = tqdm(total=s.total_frames, desc=f"SAC {tag}", disable=not cfg.progress)
    for batch in collector:
        buffer.extend(batch.reshape(-1))
        frames += batch.numel()
        bar.update(batch.numel())
        reward = float(batch["next", "reward"].mean())
        returns.append(reward)
        if frames >= s.init_random_frames:
            for _ in range(max(1, int(round(s.updates_per_frame * batch.numel())))):
                info = agent.update(buffer.sample())
                updates += 1
            logger.log_metrics({f"train/sac_{tag}/reward": reward, **{f"train/sac_{tag}/{k}": v
                                                                       for k, v in info.items()}}, step=frames)
    collector.shutdown()
    bar.close()
    env.close()
    window = max(1, len(returns) // 10)
    return agent, {"frames": frames, "updates": updates, "train_seconds": time.perf_counter() - start,
                   "first_reward": float(np.mean(returns[:window])), "last_reward": float(np.mean(returns[-window:]))}


def evaluate_sac(cfg, run, agent: SACAgent, low_level, name: str, task: Task, logger) -> list:
    """The trained policy (its mean action) on every target of ``task``; result rows."""
    env = LatentActionEnv(low_level, num_robots=task.num_episodes, record=True, seed=cfg.seed)
    policy = _Deterministic(agent)
    rollout = run_task(env, policy, task, transforms=[GoalObservation(task)], progress=cfg.progress)
    env.close()
    return pipeline.report_task(cfg, run, METHOD, "normal", name, task, rollout, logger, low_level.steps_per_action)


class _Deterministic:
    """The actor acting with the mode of its action distribution (no exploration), for evaluation."""

    def __init__(self, agent: SACAgent):
        self.actor = agent.actor

    @torch.no_grad()
    def __call__(self, tensordict):
        from tensordict.nn import InteractionType, set_interaction_type

        with set_interaction_type(InteractionType.DETERMINISTIC):
            return self.actor(tensordict)
