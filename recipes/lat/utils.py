"""Factories and stages of the LAT recipe. Only this file reads the config; the library takes keyword arguments."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from hierloco.components.com_model import TrainedCoMModel, train_com_model
from hierloco.components.dynamics_data import TransitionData, collect_transitions
from hierloco.components.evaluation import check_gait_policy, latent_grid_paths, run_task
from hierloco.components.expert_library import ExpertLibrary, build_expert_library
from hierloco.components.gait_policy import TrainedGaitPolicy, train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.components.planners import PLANNERS
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP, ROBOTS, get_robot
from hierloco.envs.tasks import TASKS, make_task
from hierloco.envs.world_model import CoMWorldModelEnv
from hierloco.io import write_text
from hierloco.loggers import RunLogger
from hierloco.plots import plot_gait_diagram, plot_latent_map, plot_task_paths, plot_velocity_tracking
from hierloco.results import episode_rows
from hierloco.runs import RunDirectory

SETTINGS = ("normal", "legs_disabled")
METHOD = "lat"


def validate(cfg: DictConfig) -> None:
    """Refuses a bad config with a message naming the problem, before any work."""
    problems = []
    if cfg.robot not in ROBOTS:
        problems.append(f"unknown robot {cfg.robot!r} (registered: {sorted(ROBOTS)})")
    for setting in cfg.settings:
        if setting not in SETTINGS:
            problems.append(f"unknown setting {setting!r} (settings: {list(SETTINGS)})")
    if cfg.planner.name not in ("random_shooting", "cem", "mppi"):
        problems.append(f"unknown planner {cfg.planner.name!r} (random_shooting, cem, mppi)")
    for name, spec in {**cfg.eval.tasks, **(cfg.eval.generalization or {})}.items():
        kind = (spec or {}).get("task", name)
        if kind not in TASKS:
            problems.append(f"unknown task {kind!r} for {name!r} (tasks: {sorted(TASKS)})")
    positive = {"experts.num_experts": cfg.experts.num_experts, "experts.steps_per_action": cfg.experts.steps_per_action,
                "policy.epochs": cfg.policy.epochs, "policy.hidden": cfg.policy.hidden,
                "dynamics.num_transitions": cfg.dynamics.num_transitions, "dynamics.num_robots": cfg.dynamics.num_robots,
                "dynamics.hidden": cfg.dynamics.hidden, "planner.num_candidates": cfg.planner.num_candidates,
                "planner.horizon": cfg.planner.horizon, "dynamics.episode_length": cfg.dynamics.episode_length}
    for key, value in positive.items():
        if not (isinstance(value, (int, float)) and value > 0 and math.isfinite(value)):
            problems.append(f"{key} must be a positive number, got {value!r}")
    if not 1 <= cfg.policy.latent_dim <= 4:
        problems.append(f"policy.latent_dim must be 2, 3 or 4 (1 also works), got {cfg.policy.latent_dim}")
    if not 0 < cfg.dynamics.holdout < 1:
        problems.append(f"dynamics.holdout must be in (0, 1), got {cfg.dynamics.holdout}")
    if cfg.device not in ("cpu", "cuda") and not str(cfg.device).startswith("cuda:"):
        problems.append(f"device must be cpu or cuda, got {cfg.device!r}")
    elif str(cfg.device).startswith("cuda") and not torch.cuda.is_available():
        problems.append("device=cuda asked but no GPU is available")
    if cfg.robot in ROBOTS:
        robot = get_robot(cfg.robot)
        periods = cfg.experts.steps_per_action * CONTROL_TIMESTEP / robot.gait_period
        if abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
            problems.append(f"experts.steps_per_action={cfg.experts.steps_per_action} must hold a whole number of "
                            f"{robot.name}'s {robot.gait_period} s gait periods")
    if problems:
        raise ValueError("bad config:\n  " + "\n  ".join(problems))


def make_logger(cfg: DictConfig, run: RunDirectory) -> RunLogger:
    return RunLogger(f"{METHOD}_{cfg.robot}_seed{cfg.seed}", run.path / "logs", backends=cfg.logger.backends,
                     project=cfg.logger.project, wandb_mode=cfg.logger.wandb_mode,
                     config=OmegaConf.to_container(cfg, resolve=True))


def _section(cfg: DictConfig, name: str) -> dict:
    return OmegaConf.to_container(cfg[name], resolve=True)


def experts_config(cfg):
    return {"robot": cfg.robot, "seed": cfg.seed, **_section(cfg, "experts")}


def policy_config(cfg):
    return {"experts": experts_config(cfg), **_section(cfg, "policy")}


def dynamics_config(cfg, setting):
    return {"policy": policy_config(cfg), "setting": setting, **_section(cfg, "dynamics")}


def disabled_legs(cfg, setting) -> tuple[str, ...]:
    return get_robot(cfg.robot).rear_legs if setting == "legs_disabled" else ()


def stage_experts(cfg, run: RunDirectory) -> ExpertLibrary:
    def build():
        return build_expert_library(cfg.robot, cfg.experts.num_experts, steps_per_action=cfg.experts.steps_per_action,
                                    seed=cfg.seed, settle_time=cfg.experts.settle_time, progress=cfg.progress)
    return run.stage("experts", experts_config(cfg), build, lambda lib, path: lib.save(path), ExpertLibrary.load,
                     "experts.npz")


def stage_gait_policy(cfg, run: RunDirectory, library: ExpertLibrary) -> TrainedGaitPolicy:
    robot = get_robot(cfg.robot)
    periods = int(round(library.steps_per_action * CONTROL_TIMESTEP / robot.gait_period))
    p = cfg.policy

    def build():
        return train_gait_policy(library.joint_targets, latent_dim=p.latent_dim, periods_per_action=periods,
                                 num_harmonics=p.num_harmonics, hidden=p.hidden, epochs=p.epochs,
                                 batch_size=p.batch_size, lr=p.lr, latent_lr=p.latent_lr,
                                 latent_weight_decay=p.latent_weight_decay, seed=cfg.seed, device=cfg.device,
                                 progress=cfg.progress)
    return run.stage("gait_policy", policy_config(cfg), build, lambda t, path: t.save(path), TrainedGaitPolicy.load,
                     "gait_policy.pt")


def _save_json(obj, path: Path) -> None:
    write_text(path, json.dumps(obj))


def _load_json(path: Path):
    return json.loads(path.read_text())


def stage_gait_policy_check(cfg, run: RunDirectory, low_level, library: ExpertLibrary,
                            trained: TrainedGaitPolicy) -> dict:
    """Reproduction of the experts and interpolation between them by ``pi(., z)``, in simulation."""
    return run.stage("gait_policy_check", policy_config(cfg),
                     lambda: check_gait_policy(low_level, library, trained.latents.numpy(), seed=cfg.seed),
                     _save_json, _load_json, "gait_policy_check.json")


def make_low_level(cfg, trained: TrainedGaitPolicy) -> LatentLowLevel:
    return LatentLowLevel(trained, cfg.robot, device=cfg.device)


def stage_dynamics_data(cfg, run: RunDirectory, low_level, setting: str) -> TransitionData:
    d = cfg.dynamics

    def build():
        env = LatentActionEnv(low_level, num_robots=d.num_robots, disabled_legs=disabled_legs(cfg, setting),
                              seed=cfg.seed)
        return collect_transitions(env, d.num_transitions, episode_length=d.episode_length, seed=cfg.seed,
                                   progress=cfg.progress)
    return run.stage(f"dynamics_data_{setting}", dynamics_config(cfg, setting), build,
                     lambda data, path: data.save(path), TransitionData.load, f"dynamics_data_{setting}.npz")


def stage_dynamics_model(cfg, run: RunDirectory, data: TransitionData, setting: str) -> TrainedCoMModel:
    d = cfg.dynamics
    duration = cfg.experts.steps_per_action * CONTROL_TIMESTEP

    def build():
        return train_com_model(data.com_state, data.action, data.next_com_state, hidden=d.hidden, lr=d.lr,
                               batch_size=d.batch_size, holdout=d.holdout, max_epochs=d.max_epochs,
                               patience=d.patience, duration=duration, seed=cfg.seed, device=cfg.device,
                               progress=cfg.progress)
    return run.stage(f"dynamics_model_{setting}", dynamics_config(cfg, setting), build, lambda m, path: m.save(path),
                     TrainedCoMModel.load, f"dynamics_model_{setting}.pt")


def make_world_model(cfg, model: TrainedCoMModel, low_level) -> CoMWorldModelEnv:
    return CoMWorldModelEnv(model.model.to(cfg.device).eval(), action_low=low_level.action_low,
                            action_high=low_level.action_high, device=cfg.device)


def make_planner(cfg, world_model: CoMWorldModelEnv):
    p = cfg.planner
    common = dict(planning_horizon=p.horizon, num_candidates=p.num_candidates, seed=cfg.seed)
    if p.name == "cem":
        return PLANNERS["cem"](world_model, optim_steps=p.optim_steps, top_k=p.top_k, **common)
    if p.name == "mppi":
        return PLANNERS["mppi"](world_model, optim_steps=p.optim_steps, temperature=p.temperature, **common)
    return PLANNERS[p.name](world_model, **common)


def make_tasks(cfg) -> dict:
    """Task name -> task object, the main tasks then the generalisation ones."""
    tasks = {}
    for name, spec in {**cfg.eval.tasks, **(cfg.eval.generalization or {})}.items():
        spec = dict(OmegaConf.to_container(spec, resolve=True) or {})
        task = make_task(spec.pop("task", name), **spec)
        task.name = name
        tasks[name] = task
    return tasks


def evaluate(cfg, run: RunDirectory, low_level, model: TrainedCoMModel, setting: str, logger: RunLogger) -> list:
    """Runs every task with MPC, logs ``eval/...`` metrics, writes figures; returns per-episode result rows."""
    planner = make_planner(cfg, make_world_model(cfg, model, low_level))
    rows = []
    figures = run.path / "figures"
    for name, task in make_tasks(cfg).items():
        env = LatentActionEnv(low_level, num_robots=task.num_episodes, disabled_legs=disabled_legs(cfg, setting),
                              record=True, seed=cfg.seed)
        rollout = run_task(env, planner, task, progress=cfg.progress)
        env.close()
        new_rows = episode_rows(rollout, method=METHOD, robot=cfg.robot, setting=setting, seed=cfg.seed)
        result = rollout.result
        metrics = {f"eval/{setting}/{name}/normalized_cost": float(np.mean(result.normalized_cost)),
                   f"eval/{setting}/{name}/final_error": float(np.mean(result.final_error)),
                   f"eval/{setting}/{name}/falls": float(rollout.fell.sum()),
                   f"time/{setting}/{name}/plan_seconds": rollout.plan_seconds}
        if task.has_success:
            metrics[f"eval/{setting}/{name}/success_rate"] = float(np.mean(result.success))
        if hasattr(task, "path_distance"):
            distance = task.path_distance(rollout.com_paths[..., :2]).mean(1)  # per episode, over 100 Hz samples
            for row, value in zip(new_rows, distance):
                row["path_distance"] = float(value)
            metrics[f"eval/{setting}/{name}/path_distance"] = float(distance.mean())
        rows += new_rows
        logger.log_metrics(metrics)
        if cfg.eval.figures:
            title = f"LAT {cfg.robot} ({setting}): {name}"
            plot_task_paths(task, rollout.com_paths, figures / f"{setting}_{name}_paths.png", title=title)
            if name == "velocity_tracking":
                plot_velocity_tracking(task, rollout.com_paths[0], figures / f"{setting}_{name}_velocity.png",
                                       title=title)
            if name == "goal_reaching":
                plot_gait_diagram(rollout.foot_contacts[0, : 6 * low_level.steps_per_action],
                                  get_robot(cfg.robot).leg_names, figures / f"{setting}_gait_during_{name}.png",
                                  action_steps=low_level.steps_per_action,
                                  title=f"LAT {cfg.robot}: gait during {name} (pink stance, blue swing; "
                                        "dashed: new latent action)")
    return rows


def latent_map(cfg, run: RunDirectory, low_level) -> Path | None:
    """The 2-D latent map figure (only for a 2-D latent space)."""
    if low_level.action_dim != 2 or not cfg.eval.figures:
        return None
    latents, paths = latent_grid_paths(low_level, seed=cfg.seed)
    path = run.path / "figures" / "latent_map.png"
    plot_latent_map(latents, paths, path, title=f"LAT {cfg.robot}: CoM paths over a grid of 2-D latents (3 s each)")
    return path


def stage_report(run: RunDirectory, reports: dict) -> None:
    """Writes the stages' training reports (held-out errors, reconstruction RMSE, timings) as ``report.json``."""
    write_text(run.path / "report.json", json.dumps(reports, indent=2, default=float))
