"""Factories of the SAC recipe: its plan of stages, the training env and the evaluation of a trained policy (each
task trains on its own ``training_split()``, half of its targets). The LAT low level comes from the shared stages (``recipes/common/stages.py``); the
SAC training loop is in ``train.py``."""

from __future__ import annotations

import torch
from torchrl.envs import Compose, TransformedEnv

from hierloco.components.evaluation import run_task
from hierloco.components.policies import ActorPolicy
from hierloco.components.sac import SACAgent
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.tasks import Task
from hierloco.envs.transforms import GoalObservation, task_transforms
from recipes.common import config, report, stages
from recipes.common.config import make_task_from_spec, section

METHOD = "sac"


def checks(c: config.Checker, robot) -> None:
    config.check_experts(c, robot)
    config.check_policy(c)
    config.check_eval(c)
    config.check_logger(c)
    for key in ("sac.total_frames", "sac.num_robots", "sac.batch_size", "sac.hidden", "sac.buffer_size"):
        c.integer(key)
    c.integer("sac.init_random_frames", minimum=0)
    for key in ("sac.lr", "sac.updates_per_frame", "sac.tau"):
        c.positive(key)
    c.fraction("sac.gamma")
    if list(c.cfg.settings) != ["normal"]:
        c.fail(f"the SAC recipe runs the normal setting only, got settings={list(c.cfg.settings)}")


def plan(cfg, robot) -> list[stages.Stage]:
    """Experts -> gait policy -> its check -> per main task: a SAC agent, and its evaluation on every task of the
    same kind (the main task and its generalisation variants)."""
    from hierloco.envs.robots import robot_fingerprint

    experts = stages.experts_stage(cfg, robot_fingerprint(robot))
    policy = stages.gait_policy_stage(cfg, experts)
    low_level = stages.latent_low_level(policy)
    planned = [experts, policy, stages.gait_policy_check_stage(cfg, policy)]
    specs = stages.task_specs(cfg)
    for name in cfg.eval.tasks:
        agent = sac_stage(cfg, name, specs[name], low_level)
        planned.append(agent)
        for other, spec in specs.items():
            if task_kind(other, spec) == task_kind(name, specs[name]):
                planned.append(sac_evaluation_stage(cfg, other, spec, agent))
    return planned


def task_kind(name: str, spec: dict) -> str:
    return (spec or {}).get("task", name)


def sac_stage(cfg, name: str, spec: dict, low_level: dict) -> stages.Stage:
    params = {"seed": cfg.seed, "device": cfg.device, "task_name": name, "task": spec, **section(cfg, "sac")}
    return stages.Stage(f"sac_{name}", params, {"low_level": low_level}, f"sac_{name}.pt", SACAgent,
                        None)  # built by the training loop in train.py


def sac_evaluation_stage(cfg, name: str, spec: dict, agent: stages.Stage) -> stages.Stage:
    params = {"seed": cfg.seed, "setting": "normal", "task_name": name, "task": spec}
    after = {"agent": agent.digest}
    key_digest = stages.digest({"params": params, "after": after})
    return stages.Stage(f"evaluation_normal_{name}", params, after, f"evaluation/normal/{name}-{key_digest}.npz",
                        stages.TaskEvaluation, build_evaluation)


def task_env(low_level, task: Task, num_robots: int, seed: int, nthread: int | None = None) -> TransformedEnv:
    """``num_robots`` robots on ``task``, robot ``b`` on episode ``b % episodes``, with the goal observation."""
    episodes = torch.arange(num_robots) % task.num_episodes
    env = LatentActionEnv(low_level, num_robots=num_robots, seed=seed, nthread=nthread)
    return TransformedEnv(env, Compose(task_transforms(task, episodes), GoalObservation(task)))


def build_evaluation(run, params, agent: SACAgent, low_level) -> stages.TaskEvaluation:
    """The trained policy (its mean action) on every target of a task, one robot per episode."""
    task = make_task_from_spec(params["task_name"], params["task"])
    env = LatentActionEnv(low_level, num_robots=task.num_episodes, record=True, seed=params["seed"],
                          nthread=run.nthread)
    try:
        rollout = run_task(env, ActorPolicy(agent.actor), task, transforms=[GoalObservation(task)],
                           progress=run.progress)
    finally:
        env.close()
    return report.task_evaluation(rollout, task, method=run.method, robot=run.robot.name, setting="normal",
                                  seed=params["seed"])


def manifest(cfg, robot) -> dict:
    return {"low_level": {"kind": "latent"}}
