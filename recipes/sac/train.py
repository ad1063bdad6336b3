"""SAC baseline (Li et al., RA-L 2021, Sec. IV-B): the LAT low level (experts -> latent gait policy), then per task a
goal-conditioned SAC high level over z, trained on half of the task's targets and tested on all of them.

    python recipes/sac/train.py                       # paper scale, A1, seed 0
    python recipes/sac/train.py preset=small robot=daisy
"""

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)

import time

import numpy as np
import torch
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer
from tqdm.auto import tqdm

from hierloco.components.sac import SACAgent
from hierloco.envs.transforms import GoalObservation
from recipes.common.config import make_task_from_spec
from recipes.common.entry import recipe_main
from recipes.common.run import open_run
from utils import METHOD, checks, manifest, plan, task_env


@recipe_main(__file__)
def main(cfg) -> float:
    run = open_run(cfg, METHOD, plan, checks, manifest)  # config, every stage's key, lock: before any work

    library = run.stage("experts")                                  # G expert gaits (Sec. III-A)
    trained = run.stage("gait_policy", library)                     # pi(t, z) and one z per expert (III-B)
    low_level = make_low_level(run, trained)
    run.stage("gait_policy_check", low_level, library)

    for name in cfg.eval.tasks:                                     # one SAC high level per task (IV-B)
        agent = run.stage(f"sac_{name}", low_level, build=train_sac)  # trained on half of the task's targets
        for evaluation in run.dependents(f"sac_{name}"):            # tested on all of them, and on the
            run.stage(evaluation, agent, low_level)                 # task's generalisation variants

    return run.finish(low_level)


def make_low_level(run, trained):
    from hierloco.components.low_level import LatentLowLevel

    return LatentLowLevel(trained, run.robot, device=run.cfg.device)


def train_sac(run, params, low_level) -> SACAgent:
    """Goal-conditioned SAC on the training half of a task's targets for ``total_frames`` high-level actions."""
    task = make_task_from_spec(params["task_name"], params["task"]).training_split()  # half of the targets
    tag = params["task_name"]
    torch.manual_seed(params["seed"])
    agent = SACAgent.build(GoalObservation.SIZE, low_level.action_low, low_level.action_high, hidden=params["hidden"],
                           lr=params["lr"], gamma=params["gamma"], tau=params["tau"], seed=params["seed"])
    env = task_env(low_level, task, params["num_robots"], params["seed"], nthread=run.nthread)
    collector = Collector(env, agent.actor, frames_per_batch=params["num_robots"], total_frames=params["total_frames"],
                          init_random_frames=params["init_random_frames"], auto_register_policy_transforms=False)
    buffer = ReplayBuffer(storage=LazyTensorStorage(params["buffer_size"]), batch_size=params["batch_size"])
    start, frames, updates, rewards = time.perf_counter(), 0, 0, []
    bar = tqdm(total=params["total_frames"], desc=f"SAC {tag}", disable=not run.progress)
    for batch in collector:
        buffer.extend(batch.reshape(-1))
        frames += batch.numel()
        bar.update(batch.numel())
        reward = float(batch["next", "reward"].mean())
        rewards.append(reward)
        if frames >= params["init_random_frames"]:
            for _ in range(max(1, int(round(params["updates_per_frame"] * batch.numel())))):
                info = agent.update(buffer.sample())
                updates += 1
            run.logger.log_metrics({f"train/sac_{tag}/reward": reward,
                                    **{f"train/sac_{tag}/{k}": v for k, v in info.items()}}, step=frames)
    collector.shutdown()
    bar.close()
    env.close()
    window = max(1, len(rewards) // 10)
    agent.metadata = {"frames": frames, "updates": updates, "train_seconds": time.perf_counter() - start,
                      "first_reward": float(np.mean(rewards[:window])), "last_reward": float(np.mean(rewards[-window:]))}
    return agent


if __name__ == "__main__":
    main()
