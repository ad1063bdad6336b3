"""Factories of the IK recipe: the expert controller driven by velocity commands (the rest is the shared pipeline)."""

from __future__ import annotations

from common import pipeline
from hierloco.components.low_level import CommandLowLevel
from hierloco.envs.robots import get_robot
from hierloco.runs import RunDirectory

METHOD = "ik"


def validate(cfg) -> None:
    pipeline.validate(cfg)


def prepare(cfg, run: RunDirectory, logger, reports: dict) -> pipeline.LowLevelRecipe:
    """The Raibert controller with leg IK, one velocity command per action, over the robot's command box."""
    robot = get_robot(cfg.robot)
    steps = cfg.experts.steps_per_action
    config = {"controller": {"robot": robot.name, "steps_per_action": steps, "command_low": list(robot.command_low),
                             "command_high": list(robot.command_high), "gait_period": robot.gait_period}}
    return pipeline.LowLevelRecipe(make=lambda num_robots: CommandLowLevel(robot, num_robots, steps), config=config)
