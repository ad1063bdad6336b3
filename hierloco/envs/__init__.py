"""Robots, the locomotion environments (dm_control and TorchRL), transforms, the batched simulator, the
latent-action, velocity-command and world-model environments, the tasks and navigation arenas."""

from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import Obstacle, RobotSpec, compile_model, get_robot, register_robot, robot_from_mjcf
from hierloco.envs.tasks import GoalReaching, TrajectoryTracking, VelocityTracking, make_task
from hierloco.envs.torchrl_env import make_env
from hierloco.envs.transforms import CoMState, DisableLegs, GoalObservation, TaskTransform
from hierloco.envs.velocity_command_env import VelocityCommandEnv
from hierloco.envs.world_model import CoMWorldModelEnv

__all__ = ["BatchedSimulator", "CoMState", "CoMWorldModelEnv", "DisableLegs", "GoalObservation", "GoalReaching",
           "LatentActionEnv", "Obstacle", "RobotSpec", "TaskTransform", "TrajectoryTracking", "VelocityCommandEnv",
           "VelocityTracking",
           "compile_model", "get_robot", "make_env", "make_task", "register_robot", "robot_from_mjcf"]
