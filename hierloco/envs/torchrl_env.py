"""``make_env``: the TorchRL locomotion environment of a robot at 100 Hz (Li et al., RA-L 2021, Sec. III-A).

Example:
    >>> from hierloco.envs import make_env
    >>> from torchrl.envs.utils import check_env_specs
    >>> env = make_env("daisy", seed=0)
    >>> check_env_specs(env)
"""

from __future__ import annotations

from typing import Sequence

import torch
from torchrl.envs import CatTensors, Compose, DoubleToFloat, DTypeCastTransform, TransformedEnv

from hierloco.envs.locomotion import INIT_JOINT_NOISE, LocomotionEnv, make_dm_env
from hierloco.envs.robots import RobotSpec, get_robot
from hierloco.envs.transforms import CoMState, DisableLegs

OBSERVATION_KEYS = ("com_position", "com_velocity", "orientation", "joint_positions", "joint_velocities",
                    "foot_contacts")
"""The keys :func:`make_env` concatenates, in this order, into its flat ``observation``."""


def make_env(
    robot: str | RobotSpec,
    *,
    disabled_legs: Sequence[str] = (),
    time_limit: float = 10.0,
    seed: int | None = None,
    init_joint_noise: float = INIT_JOINT_NOISE,
    device: str = "cpu",
    terrain=None,
) -> TransformedEnv:
    """A TorchRL env of ``robot`` (a registered name or a :class:`RobotSpec`) at 100 Hz.

    The action is the joint-target vector (rad, ``robot.joint_names`` order); observations are float32 and
    include ``com_state`` (``x, y, yaw, vx, vy``, world frame) and ``com_velocity_local``, and a flat
    ``observation`` (``9 + 2 J + L``: J joints, L legs) for policies that take one vector: the concatenation, in this
    order (:data:`OBSERVATION_KEYS`), of ``com_position`` (3, world, m), ``com_velocity`` (3, world, m/s),
    ``orientation`` (3, roll/pitch/yaw, rad), ``joint_positions`` (J, rad), ``joint_velocities`` (J, rad/s) and
    ``foot_contacts`` (L, 1 in contact, 0 not), each also kept under its own key (``foot_contacts`` there as bool,
    true in contact: the conventions of :mod:`hierloco.envs`). ``disabled_legs`` adds a
    :class:`DisableLegs` transform. A fall sets ``terminated``, the time limit (s) ``truncated``; the base env is a
    :class:`hierloco.envs.locomotion.LocomotionEnv` (``env.base_env.physics`` is the dm_control Physics).

    Joint targets outside the joint range are clamped to it, as in the batched simulator. A NaN target ends the step
    as terminated with reward 0 (the previous targets are held for that step) and warns; an infinite target raises
    ``ValueError`` (the batched simulator refuses both).

    ``terrain`` is the ground (a name, a mapping with a name, a file or a :class:`hierloco.envs.terrain.Terrain`;
    default flat, ``docs/terrain.md``): the robot starts standing on it and falls relative to it.
    """
    robot = get_robot(robot)
    robot.leg_joint_indices(disabled_legs)  # names checked before any work
    base = LocomotionEnv(make_dm_env(robot, disabled_legs=disabled_legs, time_limit=time_limit,
                                        init_joint_noise=init_joint_noise, terrain=terrain), device=device)
    transforms = [DoubleToFloat(), CoMState(),
                  CatTensors(list(OBSERVATION_KEYS), out_key="observation", del_keys=False, sort=False),
                  DTypeCastTransform(torch.float32, torch.bool, in_keys=["foot_contacts"])]
    if disabled_legs:
        transforms.append(DisableLegs(robot, disabled_legs))
    env = TransformedEnv(base, Compose(*transforms))
    if seed is not None:
        env.set_seed(seed)
    return env
