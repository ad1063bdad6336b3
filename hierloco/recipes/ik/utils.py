"""Factories of the IK recipe: its plan of stages (the shared dynamics and evaluation stages over velocity commands),
its low level (the expert controller, closed loop) and its config checks."""

from __future__ import annotations

import inspect

from hierloco.pipeline import config, stages
from hierloco.pipeline.plan import Plan

METHOD = "ik"


def checks(c: config.Checker, robot) -> None:
    from hierloco.components.experts import RaibertController
    from hierloco.components.low_level import CommandLowLevel

    config.check_experts(c, robot, library=False)
    config.check_dynamics(c)
    config.check_planner(c, "box")
    config.check_eval(c)
    config.check_logger(c)
    accepted = [p for cls in (CommandLowLevel, RaibertController) for p in inspect.signature(cls.__init__).parameters
                if p not in ("self", "robot", "num_robots", "steps_per_action", "controller_kwargs")]
    unknown = [option for option in c.cfg.controller if option not in accepted]
    for option in unknown:
        c.fail(f"controller has no option {option!r} (its options: {', '.join(accepted)})")
    if robot is not None and not unknown:
        try:  # the controller checks its own values
            CommandLowLevel(robot, 1, c.cfg.steps_per_action, **config.section(c.cfg, "controller"))
        except (TypeError, ValueError) as error:
            c.fail(f"controller: {error}")


def low_level_key(cfg, robot) -> dict:
    from hierloco.envs.robots import robot_fingerprint

    return {"kind": "command", "robot": robot_fingerprint(robot), "steps_per_action": cfg.steps_per_action,
            "controller": config.section(cfg, "controller")}


def plan(cfg, robot) -> Plan:
    """Per setting: dynamics data over velocity commands, model, one evaluation per task."""
    return Plan(settings=stages.per_setting_stages(cfg, low_level_key(cfg, robot), robot))


def manifest(cfg, robot) -> dict:
    return {"low_level": {"kind": "command", "options": {"steps_per_action": cfg.steps_per_action,
                                                         **config.section(cfg, "controller")}}}


def make_low_level(run):
    """The Raibert controller with leg IK for ``num_robots`` robots, one velocity command per action, over the
    robot's command box (it keeps a gait clock per robot, so each env gets its own)."""
    from hierloco.components.low_level import CommandLowLevel

    options = config.section(run.cfg, "controller")
    return lambda num_robots: CommandLowLevel(run.robot, num_robots, run.cfg.steps_per_action, **options)
