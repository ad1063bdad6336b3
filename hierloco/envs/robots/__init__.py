"""Robots: the :class:`RobotSpec` description, the built-in A1 and Daisy, users' own robots (MJCF, YAML, entry
points) and a registry by name (see ``docs/robots.md``)."""

from __future__ import annotations

from hierloco.envs.robots.a1 import A1
from hierloco.envs.robots.daisy import DAISY
from hierloco.envs.robots.hardware import HARDWARE, hardware_options, perturbed
from hierloco.envs.robots.mjcf import robot_from_mjcf
from hierloco.envs.robots.registry import (
    ENTRY_POINT_GROUP,
    ROBOTS,
    available_robots,
    get_robot,
    register_robot,
    robot_reference,
)
from hierloco.envs.robots.spec import (
    CONTROL_TIMESTEP,
    LOCK_PREFIX,
    PHYSICS_STEPS_PER_CONTROL,
    PHYSICS_TIMESTEP,
    START_YAW,
    STEPS_PER_ACTION,
    TOUCH_SENSOR_PREFIX,
    TOUCH_SITE_PREFIX,
    Leg,
    Obstacle,
    RobotSpec,
    admissible_gait_periods,
    compile_model,
    derive_gait_period,
    derive_standing_height,
    derive_swing_height,
    stance_legs,
    foot_geoms,
    joint_qpos_indices,
    joint_qvel_indices,
    robot_fingerprint,
    standing_qpos,
)
from hierloco.envs.robots.yaml_robot import load_robot_yaml

register_robot(A1)
register_robot(DAISY)

__all__ = [
    "A1", "DAISY", "ROBOTS", "CONTROL_TIMESTEP", "ENTRY_POINT_GROUP", "LOCK_PREFIX", "TOUCH_SENSOR_PREFIX",
    "TOUCH_SITE_PREFIX", "PHYSICS_STEPS_PER_CONTROL", "PHYSICS_TIMESTEP", "START_YAW", "STEPS_PER_ACTION", "Leg",
    "Obstacle", "RobotSpec", "admissible_gait_periods", "available_robots", "compile_model", "derive_gait_period",
    "derive_standing_height", "derive_swing_height", "foot_geoms", "get_robot", "joint_qpos_indices", "joint_qvel_indices",
    "load_robot_yaml", "register_robot", "robot_fingerprint", "robot_from_mjcf", "robot_reference",
    "stance_legs", "standing_qpos", "HARDWARE", "hardware_options", "perturbed",
]
