"""Robots, the locomotion environments (dm_control and TorchRL), transforms and the batched simulator."""

from hierloco.envs.robots import RobotSpec, compile_model, get_robot, register_robot, robot_from_mjcf
from hierloco.envs.torchrl_env import make_env
from hierloco.envs.transforms import CoMState, DisableLegs

__all__ = ["CoMState", "DisableLegs", "RobotSpec", "compile_model", "get_robot", "make_env", "register_robot",
           "robot_from_mjcf"]
