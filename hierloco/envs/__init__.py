"""Robots, the locomotion environments (dm_control and TorchRL), transforms, the batched simulator, the
latent-action, velocity-command and world-model environments, the tasks and navigation arenas.

Importing it does not import :mod:`hierloco.components` (the low levels, models and planners that plug into these
environments).

The names below load their module on first use, so importing one submodule (``hierloco.envs.faults``,
``hierloco.components.com_model``) does not import the rest.

Conventions, the same in every env here:

- Batch: an env's batch is its robots. The envs of the batched simulator (:class:`LatentActionEnv`,
  :class:`VelocityCommandEnv`) have batch ``[B]`` for every number of robots ``B``, 1 included (as TorchRL's batched
  envs: ``SerialEnv(1, ...)`` has batch ``[1]``), so code written for ``B`` robots runs unchanged for one;
  :func:`make_env` is one robot without a robot dimension (batch ``[]``), and :class:`LatentActionWrapper` keeps the
  batch of the env it wraps. :class:`CoMWorldModelEnv` is not batch-locked: any leading dimensions (a planner's
  ``B x S`` candidates).
- Per-robot flags and counters end in a dimension of 1: ``done``, ``terminated``, ``truncated`` and ``is_init``
  (bool), ``task_episode`` and ``task_step`` (int64), ``reward`` (float32), each ``B x 1`` (``1`` in
  :func:`make_env`).
- Dtypes: observations are float32 (``qpos`` float64, to replay a motion exactly), flags bool, indices int64.
  ``foot_contacts`` is bool, true in contact, wherever it stands under its own key (:func:`make_env`,
  :class:`LatentActionEnv` with ``record=True``, :class:`BatchedSimulator` results); :func:`make_env`'s flat
  ``observation`` holds it as 0/1 float32, as every entry of that vector is a float.

Example:
    >>> import torch
    >>> from hierloco.components.low_level import CommandLowLevel
    >>> from hierloco.envs import LatentActionEnv, make_env
    >>> td = make_env("a1", seed=0).reset()
    >>> td.batch_size, td["foot_contacts"].dtype, td["observation"].dtype
    (torch.Size([]), torch.bool, torch.float32)
    >>> torch.equal(td["observation"][-4:], td["foot_contacts"].float())
    True
    >>> td = LatentActionEnv(CommandLowLevel("a1", num_robots=1), num_robots=1, record=True).reset()
    >>> td.batch_size, td["done"].shape, td["foot_contacts"].dtype
    (torch.Size([1]), torch.Size([1, 1]), torch.bool)
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
    "DynamicsRandomization": "hierloco.envs.terrain",
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
    "Pushes": "hierloco.envs.terrain",
    "RISKS": "hierloco.envs.world_model",
    "RobotSpec": "hierloco.envs.robots",
    "SimulationResult": "hierloco.envs.batched_sim",
    "TASKS": "hierloco.envs.tasks",
    "TERRAINS": "hierloco.envs.terrain",
    "Task": "hierloco.envs.tasks",
    "TaskEpisode": "hierloco.envs.transforms",
    "TaskResult": "hierloco.envs.tasks",
    "TaskReward": "hierloco.envs.transforms",
    "TaskTransform": "hierloco.envs.transforms",
    "Terrain": "hierloco.envs.terrain",
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
    "make_terrain": "hierloco.envs.terrain",
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
