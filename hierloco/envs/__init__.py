"""Robots, the locomotion environments (dm_control and TorchRL), transforms, the batched simulator, the
latent-action, velocity-command and world-model environments, the tasks and navigation arenas.

Importing it does not import :mod:`hierloco.components` (the low levels, models and planners that plug into these
environments).
"""

from hierloco.envs.batched_sim import BatchedSimulator, SimulationResult, available_cores
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.latent_wrapper import LatentActionWrapper
from hierloco.envs.locomotion import (
    LocomotionEnv,
    LocomotionPhysics,
    LocomotionTask,
    clamp_joint_targets,
    joint_target_limits,
    make_dm_env,
    periods_per_action,
    reset_joint_noise,
    robot_has_fallen,
)
from hierloco.envs.low_level import LowLevel
from hierloco.envs.navigation import Arena, clearance, cluttered_arena, plan_path
from hierloco.envs.robots import Obstacle, RobotSpec, compile_model, get_robot, register_robot, robot_from_mjcf
from hierloco.envs.tasks import (
    TASKS,
    GoalReaching,
    Task,
    TaskResult,
    TrajectoryTracking,
    VelocityTracking,
    make_task,
    s_path,
    task_options,
)
from hierloco.envs.torchrl_env import OBSERVATION_KEYS, make_env
from hierloco.envs.transforms import (
    CoMState,
    ContinueAfterFalls,
    DisableLegs,
    GoalObservation,
    TaskEpisode,
    TaskReward,
    TaskTransform,
    task_transforms,
)
from hierloco.envs.velocity_command_env import VelocityCommandEnv
from hierloco.envs.world_model import RISKS, CoMWorldModelEnv

__all__ = [
    "OBSERVATION_KEYS", "RISKS", "LatentActionWrapper", "TASKS", "Arena", "BatchedSimulator", "CoMState", "CoMWorldModelEnv", "ContinueAfterFalls", "DisableLegs",
    "GoalObservation", "GoalReaching", "LatentActionEnv", "LocomotionEnv", "LocomotionPhysics", "LocomotionTask",
    "LowLevel", "Obstacle", "RobotSpec", "SimulationResult", "Task", "TaskEpisode", "TaskResult", "TaskReward",
    "TaskTransform", "TrajectoryTracking", "VelocityCommandEnv", "VelocityTracking", "available_cores", "clamp_joint_targets",
    "clearance", "cluttered_arena", "compile_model", "get_robot", "joint_target_limits", "make_dm_env", "make_env",
    "make_task", "periods_per_action", "plan_path", "register_robot", "reset_joint_noise", "robot_from_mjcf",
    "robot_has_fallen", "s_path", "task_options", "task_transforms",
]
