"""The model-based pipeline shared by the LAT, LIB and IK recipes: a low level -> CoM dynamics data -> dynamics
model -> MPC on every task, each stage cached in the run directory. Only recipe code reads the config.

A recipe supplies ``prepare(cfg, run, logger, reports) -> LowLevelRecipe``: how to make its low level for a number of
robots, and the config that identifies it (so that the dynamics stages are redone when the low level changes).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from hierloco.components.com_model import TrainedCoMModel, train_com_model
from hierloco.components.dynamics_data import TransitionData, collect_transitions
from hierloco.components.evaluation import latent_grid_paths, run_task
from hierloco.components.expert_library import ExpertLibrary, build_expert_library
from hierloco.components.low_level import LowLevel
from hierloco.components.planners import PLANNERS
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP, ROBOTS, get_robot
from hierloco.envs.tasks import TASKS, make_task
from hierloco.envs.world_model import CoMWorldModelEnv
from hierloco.io import write_text
from hierloco.loggers import RunLogger
from hierloco.plots import plot_gait_diagram, plot_latent_map, plot_task_paths, plot_velocity_tracking
from hierloco.render import render_frames, save_video
from hierloco.results import episode_rows, write_results
from hierloco.runs import RunDirectory

SETTINGS = ("normal", "legs_disabled")
CONTINUOUS_PLANNERS = ("random_shooting", "cem", "mppi")


@dataclass
class LowLevelRecipe:
    """What a recipe brings to the pipeline: ``make(num_robots) -> LowLevel`` and the config identifying it."""

    make: Callable[[int], LowLevel]
    config: dict


# ---------------------------------------------------------------------------------------------------- config
def section(cfg: DictConfig, name: str) -> dict:
    return OmegaConf.to_container(cfg[name], resolve=True)


def check_positive(values: dict) -> list[str]:
    return [f"{key} must be a positive number, got {value!r}" for key, value in values.items()
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0
                    and math.isfinite(value))]


def validate(cfg: DictConfig, planners=CONTINUOUS_PLANNERS, extra: list[str] | None = None) -> None:
    """Refuses a bad config with a message naming every problem, before any work."""
    problems = list(extra or [])
    if cfg.robot not in ROBOTS:
        problems.append(f"unknown robot {cfg.robot!r} (registered: {sorted(ROBOTS)})")
    for setting in cfg.settings:
        if setting not in SETTINGS:
            problems.append(f"unknown setting {setting!r} (settings: {list(SETTINGS)})")
    if "planner" in cfg and cfg.planner.name not in planners:
        problems.append(f"unknown planner {cfg.planner.name!r} ({', '.join(planners)})")
    for name, spec in {**cfg.eval.tasks, **(cfg.eval.generalization or {})}.items():
        kind = (spec or {}).get("task", name)
        if kind not in TASKS:
            problems.append(f"unknown task {kind!r} for {name!r} (tasks: {sorted(TASKS)})")
    problems += check_positive({"experts.steps_per_action": cfg.experts.steps_per_action})
    if "dynamics" in cfg:
        problems += check_positive({
            "dynamics.num_transitions": cfg.dynamics.num_transitions, "dynamics.num_robots": cfg.dynamics.num_robots,
            "dynamics.hidden": cfg.dynamics.hidden, "dynamics.episode_length": cfg.dynamics.episode_length})
        if not 0 < cfg.dynamics.holdout < 1:
            problems.append(f"dynamics.holdout must be in (0, 1), got {cfg.dynamics.holdout}")
    if "planner" in cfg:
        problems += check_positive({"planner.num_candidates": cfg.planner.num_candidates,
                                    "planner.horizon": cfg.planner.horizon})
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


def eval_section(cfg) -> dict:
    """What the evaluation's numbers depend on: the ``eval`` section without its figure and video switches."""
    return {k: v for k, v in section(cfg, "eval").items() if k not in ("figures", "videos")}


def disabled_legs(cfg, setting) -> tuple[str, ...]:
    return get_robot(cfg.robot).rear_legs if setting == "legs_disabled" else ()


def save_json(obj, path: Path) -> None:
    write_text(path, json.dumps(obj))


def load_json(path: Path):
    return json.loads(path.read_text())


# ---------------------------------------------------------------------------------------------------- stages
def experts_config(cfg) -> dict:
    return {"robot": cfg.robot, "seed": cfg.seed, **section(cfg, "experts")}


def stage_experts(cfg, run: RunDirectory) -> ExpertLibrary:
    """The expert library (SPEC 5.1)."""
    def build():
        return build_expert_library(cfg.robot, cfg.experts.num_experts, steps_per_action=cfg.experts.steps_per_action,
                                    seed=cfg.seed, settle_time=cfg.experts.settle_time, progress=cfg.progress)
    return run.stage("experts", experts_config(cfg), build, lambda lib, path: lib.save(path), ExpertLibrary.load,
                     "experts.npz")


def dynamics_config(cfg, low_level: LowLevelRecipe, setting: str) -> dict:
    return {"low_level": low_level.config, "setting": setting, **section(cfg, "dynamics")}


def stage_dynamics_data(cfg, run: RunDirectory, low_level: LowLevelRecipe, setting: str) -> TransitionData:
    d = cfg.dynamics

    def build():
        env = LatentActionEnv(low_level.make(d.num_robots), num_robots=d.num_robots,
                              disabled_legs=disabled_legs(cfg, setting), seed=cfg.seed)
        data = collect_transitions(env, d.num_transitions, episode_length=d.episode_length, seed=cfg.seed,
                                   progress=cfg.progress)
        env.close()
        return data
    return run.stage(f"dynamics_data_{setting}", dynamics_config(cfg, low_level, setting), build,
                     lambda data, path: data.save(path), TransitionData.load, f"dynamics_data_{setting}.npz")


def stage_dynamics_model(cfg, run: RunDirectory, low_level: LowLevelRecipe, data: TransitionData,
                         setting: str) -> TrainedCoMModel:
    d = cfg.dynamics
    features = low_level.make(1).action_features(data.action)

    def build():
        return train_com_model(data.com_state, features, data.next_com_state, hidden=d.hidden, lr=d.lr,
                               batch_size=d.batch_size, holdout=d.holdout, max_epochs=d.max_epochs,
                               patience=d.patience, duration=cfg.experts.steps_per_action * CONTROL_TIMESTEP,
                               seed=cfg.seed, device=cfg.device, progress=cfg.progress)
    return run.stage(f"dynamics_model_{setting}", dynamics_config(cfg, low_level, setting), build,
                     lambda m, path: m.save(path), TrainedCoMModel.load, f"dynamics_model_{setting}.pt")


# ---------------------------------------------------------------------------------------------------- planning
def make_world_model(cfg, model: TrainedCoMModel, low_level: LowLevel) -> CoMWorldModelEnv:
    net = model.model.to(cfg.device).eval()
    if low_level.num_choices is not None:
        return CoMWorldModelEnv(net, num_choices=low_level.num_choices, action_features=low_level.action_features,
                                device=cfg.device)
    return CoMWorldModelEnv(net, action_low=low_level.action_low, action_high=low_level.action_high,
                            action_features=low_level.action_features, device=cfg.device)


def make_planner(cfg, world_model: CoMWorldModelEnv):
    p = cfg.planner
    if p.name == "exhaustive":
        return PLANNERS["exhaustive"](world_model, planning_horizon=p.horizon)
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


def evaluate(cfg, run: RunDirectory, method: str, low_level: LowLevelRecipe, model: TrainedCoMModel, setting: str,
             logger: RunLogger) -> list:
    """Runs every task with MPC, logs ``eval/...`` metrics, writes figures; returns per-episode result rows."""
    rows = []
    for name, task in make_tasks(cfg).items():
        low = low_level.make(task.num_episodes)
        planner = make_planner(cfg, make_world_model(cfg, model, low))
        env = LatentActionEnv(low, num_robots=task.num_episodes, disabled_legs=disabled_legs(cfg, setting),
                              record=True, seed=cfg.seed)
        rollout = run_task(env, planner, task, progress=cfg.progress)
        env.close()
        rows += report_task(cfg, run, method, setting, name, task, rollout, logger, low.steps_per_action)
    return rows


def report_task(cfg, run: RunDirectory, method: str, setting: str, name: str, task, rollout, logger: RunLogger,
                steps_per_action: int) -> list:
    """Result rows, ``eval/...`` metrics, figures and the video of one evaluated task."""
    rows = episode_rows(rollout, method=method, robot=cfg.robot, setting=setting, seed=cfg.seed)
    result = rollout.result
    metrics = {f"eval/{setting}/{name}/normalized_cost": float(np.mean(result.normalized_cost)),
               f"eval/{setting}/{name}/final_error": float(np.mean(result.final_error)),
               f"eval/{setting}/{name}/falls": float(rollout.fell.sum()),
               f"time/{setting}/{name}/plan_seconds": rollout.plan_seconds}
    if task.has_success:
        metrics[f"eval/{setting}/{name}/success_rate"] = float(np.mean(result.success))
    if hasattr(task, "path_distance"):
        distance = task.path_distance(rollout.com_paths[..., :2]).mean(1)  # per episode, over 100 Hz samples
        for row, value in zip(rows, distance):
            row["path_distance"] = float(value)
        metrics[f"eval/{setting}/{name}/path_distance"] = float(distance.mean())
    logger.log_metrics(metrics)
    if cfg.eval.figures:
        figures = run.path / "figures"
        title = f"{method.upper()} {cfg.robot} ({setting}): {name}"
        plot_task_paths(task, rollout.com_paths, figures / f"{setting}_{name}_paths.png", title=title)
        if name == "velocity_tracking":
            plot_velocity_tracking(task, rollout.com_paths[0], figures / f"{setting}_{name}_velocity.png",
                                   title=title)
        if name == "goal_reaching":
            plot_gait_diagram(rollout.foot_contacts[0, : 6 * steps_per_action], get_robot(cfg.robot).leg_names,
                              figures / f"{setting}_gait_during_{name}.png", action_steps=steps_per_action,
                              title=f"{method.upper()} {cfg.robot} ({setting}): gait during {name} (pink stance, "
                                    "blue swing; dashed: new action)")
    if name in (cfg.eval.videos or []):
        write_video(cfg, run, task, rollout, setting, name, logger)
    return rows


VIDEO_FPS = 20


def write_video(cfg, run: RunDirectory, task, rollout, setting: str, name: str, logger: RunLogger) -> None:
    """The first episode of ``task`` as ``videos/<setting>_<name>.mp4`` (MuJoCo offscreen, 20 fps), goals or the
    reference path drawn on the floor; also sent to wandb when it is a backend."""
    stride = int(round(1.0 / (VIDEO_FPS * CONTROL_TIMESTEP)))
    markers = getattr(task, "goals", None)
    markers = markers[:1].numpy() if markers is not None else getattr(task, "references", None)
    markers = None if markers is None else np.asarray(markers)[:: max(1, len(markers) // 40)]
    frames = render_frames(cfg.robot, rollout.qpos[0, ::stride], disabled_legs=disabled_legs(cfg, setting),
                           markers=markers)
    save_video(frames, run.path / "videos" / f"{setting}_{name}.mp4", fps=VIDEO_FPS)
    logger.log_video(f"eval/{setting}/{name}/video", frames, fps=VIDEO_FPS)


def latent_map(cfg, run: RunDirectory, method: str, low_level: LowLevel) -> Path | None:
    """The 2-D latent map figure (only for a 2-D continuous action space)."""
    if low_level.action_dim != 2 or low_level.num_choices is not None or not cfg.eval.figures:
        return None
    latents, paths = latent_grid_paths(low_level, seed=cfg.seed)
    path = run.path / "figures" / "latent_map.png"
    plot_latent_map(latents, paths, path, title=f"{method.upper()} {cfg.robot}: CoM paths over a grid of 2-D "
                                                "actions (3 s each)")
    return path


# ---------------------------------------------------------------------------------------------------- main
def open_run(cfg: DictConfig, method: str) -> tuple[RunDirectory, RunLogger]:
    """The run directory and the loggers of a recipe run."""
    torch.manual_seed(cfg.seed)
    run = RunDirectory(cfg.run_dir)
    logger = RunLogger(f"{method}_{cfg.robot}_seed{cfg.seed}", run.path / "logs", backends=cfg.logger.backends,
                       project=cfg.logger.project, wandb_mode=cfg.logger.wandb_mode,
                       config=OmegaConf.to_container(cfg, resolve=True))
    return run, logger


def finish_run(cfg: DictConfig, method: str, run: RunDirectory, logger: RunLogger, episodes: list, reports: dict,
               start: float) -> str:
    """Writes the report, the results tables and the config; prints the table; returns it."""
    reports["stage_seconds"] = run.timings
    reports["reused_stages"] = run.reused
    reports["total_seconds"] = time.perf_counter() - start
    write_text(run.path / "report.json", json.dumps(reports, indent=2, default=float))
    for stage, seconds in run.timings.items():
        logger.log_scalar(f"time/{stage}", seconds)
    table = write_results(run.path, episodes)
    write_text(run.path / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))
    logger.close()
    print(f"\n{method.upper()} on {cfg.robot} (seed {cfg.seed}), run directory {run.path}\n")
    print(table)
    print("stage wall-clock (s): " + ", ".join(f"{k} {v:.1f}" + (" (cached)" if run.reused[k] else "")
                                              for k, v in run.timings.items()))
    print(f"figures in {run.path / 'figures'}/, results in {run.path / 'results.csv'}")
    return table


def run_pipeline(cfg: DictConfig, method: str, prepare: Callable) -> str:
    """The whole model-based pipeline; returns the results table. ``prepare(cfg, run, logger, reports)`` builds
    the recipe's low level (running its own cached stages) and returns a :class:`LowLevelRecipe`."""
    start = time.perf_counter()
    run, logger = open_run(cfg, method)
    reports: dict = {}
    low_level = prepare(cfg, run, logger, reports)
    episodes = []
    for setting in cfg.settings:
        data = stage_dynamics_data(cfg, run, low_level, setting)
        model = stage_dynamics_model(cfg, run, low_level, data, setting)
        reports[f"dynamics_data_{setting}"] = data.metadata
        reports[f"dynamics_model_{setting}"] = model.metadata
        for name, rmse in zip(("dx", "dy", "dyaw", "vx", "vy"), model.metadata["heldout_rmse"]):
            logger.log_scalar(f"train/dynamics_{setting}/heldout_rmse_{name}", rmse)
        eval_config = {"dynamics": dynamics_config(cfg, low_level, setting), "planner": section(cfg, "planner"),
                       "eval": eval_section(cfg)}
        episodes += run.stage(f"evaluation_{setting}", eval_config,
                              lambda: evaluate(cfg, run, method, low_level, model, setting, logger),
                              save_json, load_json, f"evaluation_{setting}.json")
    latent_map(cfg, run, method, low_level.make(1))
    return finish_run(cfg, method, run, logger, episodes, reports, start)
