"""Robots: the :class:`RobotSpec` description, the built-in A1 and Daisy, and a registry by name."""

from __future__ import annotations

from hierloco.envs.robots.a1 import A1
from hierloco.envs.robots.daisy import DAISY
from hierloco.envs.robots.fingerprint import robot_fingerprint
from hierloco.envs.robots.mjcf import robot_from_mjcf
from hierloco.envs.robots.spec import (
    CONTROL_TIMESTEP,
    LOCK_PREFIX,
    TOUCH_SENSOR_PREFIX,
    PHYSICS_STEPS_PER_CONTROL,
    PHYSICS_TIMESTEP,
    START_YAW,
    Leg,
    Obstacle,
    RobotSpec,
    compile_model,
    joint_qpos_indices,
    joint_qvel_indices,
    standing_qpos,
)

ROBOTS: dict[str, RobotSpec] = {}


def register_robot(robot: RobotSpec) -> RobotSpec:
    """Make ``robot`` available by its name to :func:`get_robot` (and so to every recipe)."""
    ROBOTS[robot.name] = robot
    return robot


def get_robot(robot: str | RobotSpec) -> RobotSpec:
    """The robot description for a registered name, or ``robot`` itself if it is already a description."""
    if isinstance(robot, RobotSpec):
        return robot
    if robot not in ROBOTS:
        raise ValueError(f"unknown robot {robot!r}; registered robots: {sorted(ROBOTS)}")
    return ROBOTS[robot]


register_robot(A1)
register_robot(DAISY)

__all__ = [
    "A1", "DAISY", "ROBOTS", "CONTROL_TIMESTEP", "LOCK_PREFIX", "TOUCH_SENSOR_PREFIX", "PHYSICS_STEPS_PER_CONTROL",
    "PHYSICS_TIMESTEP", "START_YAW", "Leg", "Obstacle", "RobotSpec", "compile_model", "get_robot",
    "joint_qpos_indices", "joint_qvel_indices", "register_robot", "robot_fingerprint", "robot_from_mjcf", "standing_qpos",
]
