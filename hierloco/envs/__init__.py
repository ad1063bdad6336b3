"""Robots, the locomotion environments (dm_control and TorchRL), transforms, the batched simulator, the
latent-action, velocity-command and world-model environments, the tasks and navigation arenas.

Importing it does not import :mod:`hierloco.components` (the low levels, models and planners that plug into these
environments).

The names below load their module on first use, so importing one submodule (``hierloco.envs.faults``,
``hierloco.components.com_model``) does not import the rest.
"""

from __future__ import annotations

from hierloco._lazy import lazy_names

_WHERE = {
    "Arena": "hierloco.envs.navigation",
    "BatchedSimulator": "hierloco.envs.batched_sim",
    "CoMState": "hierloco.envs.transforms",
    "CoMWorldModelEnv": "hierloco.envs.world_model",
    "ContinueAfterFalls": "hierloco.envs.transforms",
    "DisableLegs": "hierloco.envs.transforms",
    "GoalObservation": "hierloco.envs.transforms",
    "GoalReaching": "hierloco.envs.tasks",
    "LatentActionEnv": "hierloco.envs.latent_env",
    "LatentActionWrapper": "hierloco.envs.latent_wrapper",
    "LocomotionEnv": "hierloco.envs.locomotion",
    "LocomotionPhysics": "hierloco.envs.locomotion",
    "LocomotionTask": "hierloco.envs.locomotion",
    "LowLevel": "hierloco.envs.low_level",
    "OBSERVATION_KEYS": "hierloco.envs.torchrl_env",
    "Obstacle": "hierloco.envs.robots",
    "RISKS": "hierloco.envs.world_model",
    "RobotSpec": "hierloco.envs.robots",
    "SimulationResult": "hierloco.envs.batched_sim",
    "TASKS": "hierloco.envs.tasks",
    "Task": "hierloco.envs.tasks",
    "TaskEpisode": "hierloco.envs.transforms",
    "TaskResult": "hierloco.envs.tasks",
    "TaskReward": "hierloco.envs.transforms",
    "TaskTransform": "hierloco.envs.transforms",
    "TrajectoryTracking": "hierloco.envs.tasks",
    "VelocityCommandEnv": "hierloco.envs.velocity_command_env",
    "VelocityTracking": "hierloco.envs.tasks",
    "available_cores": "hierloco.envs.batched_sim",
    "clamp_joint_targets": "hierloco.envs.locomotion",
    "clearance": "hierloco.envs.navigation",
    "cluttered_arena": "hierloco.envs.navigation",
    "compile_model": "hierloco.envs.robots",
    "get_robot": "hierloco.envs.robots",
    "joint_target_limits": "hierloco.envs.locomotion",
    "make_dm_env": "hierloco.envs.locomotion",
    "make_env": "hierloco.envs.torchrl_env",
    "make_task": "hierloco.envs.tasks",
    "periods_per_action": "hierloco.envs.locomotion",
    "plan_path": "hierloco.envs.navigation",
    "register_robot": "hierloco.envs.robots",
    "reset_joint_noise": "hierloco.envs.locomotion",
    "robot_from_mjcf": "hierloco.envs.robots",
    "robot_has_fallen": "hierloco.envs.locomotion",
    "s_path": "hierloco.envs.tasks",
    "task_options": "hierloco.envs.tasks",
    "task_transforms": "hierloco.envs.transforms",
}


__getattr__, __dir__ = lazy_names(__name__, _WHERE, globals())

__all__ = sorted(_WHERE)
