"""Navigation in a cluttered arena: plan a collision-free path, then follow it with LAT (``docs/index.md``, Navigation).

    python recipes/navigation/run.py                     # A1, the paper-scale LAT run (trained first if needed)
    python recipes/navigation/run.py robot=daisy arena.seed=2 arena.num_obstacles=14

Writes ``navigation.json`` (tracking cost, distance to the path, clearance from the obstacles, goal reached),
``navigation.png`` (arena, planned path, CoM path) and ``navigation.mp4`` in ``out_dir``.
"""

from __future__ import annotations

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
import json
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from hierloco.pipeline import studies  # noqa: E402
from hierloco.pipeline.config import ConfigError  # noqa: E402
from hierloco.pipeline.study import study_main  # noqa: E402
from hierloco.components.evaluation import run_task  # noqa: E402
from hierloco.envs.latent_env import LatentActionEnv  # noqa: E402
from hierloco.envs.navigation import (  # noqa: E402
    FOOTPRINT_MARGIN, clearance, cluttered_arena, footprint_radius, plan_path,
)
from hierloco.envs.robots import get_robot  # noqa: E402
from hierloco.envs.tasks import TrajectoryTracking  # noqa: E402
from hierloco.io import write_text  # noqa: E402
from hierloco.plots import plot_navigation  # noqa: E402
from hierloco.trained import load_run  # noqa: E402
from hierloco.render import render_frames, save_video  # noqa: E402


def validate(cfg: DictConfig) -> float:
    """Checks the config; returns the inflation in m (by default from the robot's footprint)."""
    problems = []
    inflation = None
    try:
        robot = get_robot(cfg.robot)
        inflation = footprint_radius(robot) + FOOTPRINT_MARGIN if cfg.inflation is None else cfg.inflation
    except (ValueError, OSError) as error:
        problems.append(str(error))
    if not ((inflation is None or inflation >= 0) and cfg.speed > 0 and cfg.arena.num_obstacles >= 0):
        problems.append("need inflation >= 0 m (or null), speed > 0 m/s and arena.num_obstacles >= 0")
    if problems:
        raise ConfigError("bad config: " + "; ".join(problems))
    return inflation


@study_main(__file__)
def main(cfg: DictConfig) -> None:
    inflation = validate(cfg)
    arena = cluttered_arena(seed=cfg.arena.seed, num_obstacles=cfg.arena.num_obstacles, goal=tuple(cfg.arena.goal))
    path = plan_path(arena, inflation=inflation)  # before any training: an impossible arena fails fast
    lat_dir = Path(cfg.lat_run_dir)
    studies.run_here(studies.Job("lat", str(lat_dir), [f"preset={cfg.lat_preset}", f"robot={cfg.robot}",
                                                       f"seed={cfg.seed}", f"progress={str(cfg.progress).lower()}"]))
    trained = load_run(lat_dir)  # the gait policy, the CoM model and the planner of the LAT run
    low_level = trained.low_level()
    planner = trained.planner(name="random_shooting", horizon=cfg.planner.horizon,
                              num_candidates=cfg.planner.num_candidates)
    task = TrajectoryTracking(path=path, speed=cfg.speed, extra_steps=cfg.extra_steps, name="navigation")
    env = LatentActionEnv(low_level, num_robots=1, record=True, seed=cfg.seed, obstacles=arena.obstacles)
    rollout = run_task(env, planner, task, progress=cfg.progress)
    env.close()
    com = rollout.com_paths[0, :, :2]
    result = {"robot": cfg.robot, "seed": cfg.seed, "arena_seed": cfg.arena.seed,
              "num_obstacles": len(arena.obstacles), "inflation": inflation, "path_length": task.length,
              "normalized_cost": float(rollout.result.normalized_cost[0]),
              "mean_path_distance": float(rollout.metrics["path_distance"][0]),
              "final_distance_to_goal": float(np.linalg.norm(com[-1] - np.asarray(arena.goal))),
              "goal_reached": bool(np.linalg.norm(com[-1] - np.asarray(arena.goal)) <= 0.2),
              "min_planned_clearance": float(clearance(arena, path).min()),
              "min_com_clearance": float(clearance(arena, com).min()), "fell": bool(rollout.fell[0])}
    out = Path(cfg.out_dir)
    write_text(out / "navigation.json", json.dumps(result, indent=2))
    plot_navigation(arena, path, com, out / "navigation.png", inflation=inflation,
                    title=f"LAT {cfg.robot}: navigation (arena {cfg.arena.seed})")
    from hierloco import render_backend

    why = render_backend.unavailable() if cfg.video else None
    if why is not None:
        print(f"no video: {why}")
    elif cfg.video:
        frames = render_frames(cfg.robot, rollout.qpos[0, ::5], obstacles=arena.obstacles,
                               markers=path[:: max(1, len(path) // 40)], distance=3.0, elevation=-45)
        save_video(frames, out / "navigation.mp4", fps=20)
    print(json.dumps(result, indent=2))
    print(f"navigation results, figure and video in {out}/")


if __name__ == "__main__":
    main()
