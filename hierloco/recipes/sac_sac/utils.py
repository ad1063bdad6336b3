"""Factories of the SAC-SAC recipe: its plan of stages (the SAC low level, its tracking report, then the SAC high
level per task as in ``recipes/sac``), its low level and its config checks."""

from __future__ import annotations

from typing import TYPE_CHECKING

from hierloco.pipeline import config, stages
from hierloco.pipeline.plan import JsonReport, Plan, Stage
from hierloco.recipes.sac_sac.report import write_low_level_report
from hierloco.recipes.sac import utils as sac

if TYPE_CHECKING:  # imported when a stage runs, not when the recipe plans
    from hierloco.components.sac_low_level import TrainedSACLowLevel

METHOD = "sac_sac"


class TrackingReport(JsonReport):
    SCHEMA = {"rows": list, "summary": dict}


def checks(c: config.Checker, robot) -> None:
    config.check_experts(c, robot, library=False)
    sac.check_high_level(c)
    c.choice("low_level_actor", ("stochastic", "deterministic"), "low-level actor")
    for key in ("low_level.total_frames", "low_level.num_robots", "low_level.hidden", "low_level.batch_size",
                "low_level.buffer_size", "low_level.checkpoint_every", "tracking.points_per_axis",
                "tracking.num_actions"):
        c.integer(key)
    c.integer("low_level.init_random_frames", minimum=0)
    for key in ("low_level.lr", "low_level.updates_per_frame", "low_level.action_scale", "low_level.command_interval",
                "low_level.episode_length"):
        c.positive(key)


def plan(cfg, robot) -> Plan:
    """SAC low level -> its tracking report -> per main task: a SAC high level over the command, its evaluations."""
    from hierloco.envs.robots import robot_fingerprint

    low = Stage("sac_low_level", {"seed": cfg.seed, **config.section(cfg, "low_level"), **low_level_device(cfg),
                                  **config.world(cfg, "training").params()},  # terrain, randomization
                {"robot": robot_fingerprint(robot)}, "sac_low_level.pt",
                "hierloco.components.sac_low_level:TrainedSACLowLevel", build_low_level)
    report = Stage("sac_low_level_tracking", {"seed": cfg.seed, "steps_per_action": cfg.steps_per_action,
                                              "actor": cfg.low_level_actor, **config.section(cfg, "tracking")},
                   {"sac_low_level": low.digest}, "sac_low_level_tracking.json", TrackingReport, build_tracking)
    low_level = {"kind": "sac_command", "sac_low_level": low.digest, "steps_per_action": cfg.steps_per_action,
                 "actor": cfg.low_level_actor}
    return Plan(low_level=low, low_level_tracking=report, tasks=sac.high_level_stages(cfg, low_level))


def low_level_device(cfg) -> dict:
    """``{"device": ...}`` when the low level trains elsewhere than on the CPU, else ``{}``: its key held no device
    before it could train on a GPU, so CPU runs and records keep their keys."""
    device = stages.training_device(cfg)
    return {} if device == "cpu" else {"device": device}


def build_low_level(run, params) -> TrainedSACLowLevel:
    """SAC on many robots at once, one 100 Hz control step per env step; checkpointed as it trains, so a killed run
    resumes from its last checkpoint (the checkpoint is removed once the stage is saved)."""
    from hierloco.components.sac_low_level import train_sac_low_level

    checkpoint = run.path / "sac_low_level.training.pt"
    options = {key: value for key, value in params.items() if key not in config.WORLD_KEYS}
    trained = train_sac_low_level(run.robot, checkpoint_path=checkpoint, nthread=run.nthread, progress=run.progress,
                                  logger=run.logger, log_every=max(params["num_robots"], params["total_frames"] // 50),
                                  **options, **stages.stage_world(run, params, "training").options())
    run.dir.count_interrupted_seconds(trained.metadata["seconds"]["before_resume"])
    checkpoint.unlink(missing_ok=True)  # the training state (with its replay buffer) is not needed any more
    return trained


def build_tracking(run, params, low_level) -> TrackingReport:
    """The low level on its own: commanded against achieved velocity on a grid over the command box, and falls."""
    from hierloco.components.sac_low_level import command_grid, evaluate_velocity_tracking

    commands = command_grid(run.robot, params["points_per_axis"])
    report = evaluate_velocity_tracking(low_level(len(commands)), commands, num_actions=params["num_actions"],
                                        seed=params["seed"], nthread=run.nthread)
    walking_video(run, low_level(1), run.path / "videos" / "sac_low_level_walking.mp4")
    trained = low_level(1).trained
    settings = {"seed": run.cfg.seed, **config.section(run.cfg, "low_level")}
    write_low_level_report(run.path, run.robot.name, trained.metadata, report, settings, name="sac_low_level_report.md",
                           train_seconds=run.dir.builds().get("sac_low_level", {}).get("seconds"),
                           actor=params["actor"])
    return TrackingReport(report)


def walking_video(run, low_level, path) -> None:
    """The low level walking forward, left, backward and right (two actions each, the box's half speeds), rendered
    to ``path``."""
    import numpy as np

    from hierloco.envs.batched_sim import BatchedSimulator
    from hierloco.render import render_frames, save_video

    half = 0.5 * np.asarray(run.robot.command_high)
    sim = BatchedSimulator(run.robot, 1, nthread=1)
    qpos = [low_level.run(sim, np.array([[half[0] * vx, half[1] * vy, 0.0]])).qpos[0]
            for vx, vy in [(1, 0), (1, 0), (0, 1), (0, 1), (-1, 0), (-1, 0), (0, -1), (0, -1)]]
    sim.close()
    save_video(render_frames(run.robot, np.concatenate(qpos)[::5]), path, fps=20)


def low_level_options(cfg) -> dict:
    """How the trained policy runs as the low level (``SACLowLevel``'s options), as the recipe and ``load_run``
    build it."""
    return {"steps_per_action": cfg.steps_per_action, "stochastic": cfg.low_level_actor == "stochastic",
            "seed": cfg.seed}


def manifest(cfg, robot) -> dict:
    return {"low_level": {"kind": "sac_command", "options": low_level_options(cfg)}}


def make_low_level(run, trained: TrainedSACLowLevel):
    """The trained velocity policy as a low level; it keeps a clock per robot (and, stochastic, its own random
    stream), so each env gets its own."""
    from hierloco.components.sac_low_level import SACLowLevel

    return lambda num_robots: SACLowLevel(trained, **low_level_options(run.cfg))
