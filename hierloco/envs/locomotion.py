"""The dm_control locomotion environment: a Physics with named accessors, a Task, and the rules every simulator of
hierloco shares (Li et al., RA-L 2021, Sec. III-A: a 100 Hz low level; the episode rules are in ``docs/index.md``).

Control runs at 100 Hz (``CONTROL_TIMESTEP``), physics at 0.002 s, the action is the vector of joint targets in
``robot.joint_names`` order, tracked by MuJoCo position actuators. Every episode starts at the origin facing +y in
the standing pose with seeded joint-angle noise. A fall (roll or pitch over the robot's limit, base below its
minimum height) or a physics blow-up ends the episode as terminated; the time limit ends it as truncated.

The shared rules, used here and by :class:`hierloco.envs.batched_sim.BatchedSimulator`:

- :func:`robot_has_fallen`: the fall criterion;
- :func:`reset_joint_noise`: the uniform noise on the standing joint angles at reset (each simulator keeps its own
  default scale: 0.05 rad here, 0.02 rad in the latent-action env, none in the batched simulator);
- :func:`clamp_joint_targets`: joint targets outside an actuator's control range (the joint range) are clamped to
  it, exactly as MuJoCo would; NaN targets end the episode here (terminated, reward 0) and are refused by the
  batched simulator; infinite targets are refused by both;
- :func:`periods_per_action`: how many whole gait periods one high-level action holds.

Example:
    >>> from hierloco.envs.locomotion import make_dm_env
    >>> env = make_dm_env("a1", time_limit=1.0, seed=0)
    >>> timestep = env.reset()
    >>> sorted(timestep.observation)[:3]
    ['com_position', 'com_velocity', 'foot_contacts']
"""

from __future__ import annotations

import collections
import contextlib
import math
import numbers
import warnings
from typing import Sequence

import mujoco
import numpy as np
from dm_control import mujoco as dm_mujoco
from dm_control.mujoco import wrapper as dm_wrapper
from dm_control.rl import control
from dm_control.suite import base
from torchrl.envs.libs.dm_control import DMControlWrapper

from hierloco.envs.frames import quat_to_roll_pitch_yaw, world_to_local
from hierloco.envs.robots import (
    CONTROL_TIMESTEP,
    RobotSpec,
    compile_model,
    get_robot,
    joint_qpos_indices,
    joint_qvel_indices,
)
from hierloco.envs.terrain import make_terrain, standing_qpos_on

INIT_JOINT_NOISE = 0.05  # rad, uniform noise on the standing joint angles at reset
FOOT_CONTACT_FORCE = 1.0  # N, a foot touching with more than this is in stance


# ---------------------------------------------------------------------------------------------------- shared rules
def robot_has_fallen(robot: RobotSpec, roll, pitch, height):
    """Whether ``robot`` has fallen: ``|roll| > robot.max_roll`` or ``|pitch| > robot.max_pitch`` (rad), or the base
    height below ``robot.min_height`` (m). Floats give a NumPy bool; arrays (any shape, broadcast) a bool array.

    Example:
        >>> from hierloco.envs.robots import get_robot
        >>> robot_has_fallen(get_robot("a1"), np.array([0.0, 0.9]), 0.0, 0.27).tolist()
        [False, True]
    """
    return (np.abs(roll) > robot.max_roll) | (np.abs(pitch) > robot.max_pitch) | (np.asarray(height) < robot.min_height)


def reset_joint_noise(rng, scale: float, num_robots: int, num_joints: int, locked_joints=()) -> np.ndarray:
    """``num_robots x num_joints`` uniform noise in ``[-scale, scale]`` rad on the standing joint angles at reset,
    zero on ``locked_joints`` (disabled legs start, and stay, at their standing angles).

    ``rng`` is a ``numpy.random.Generator`` or ``RandomState`` (dm_control's task RNG); with ``scale == 0`` nothing
    is drawn. Raises ``ValueError`` for a negative or non-finite scale.

    Example:
        >>> noise = reset_joint_noise(np.random.default_rng(0), 0.05, 2, 3, locked_joints=[2])
        >>> noise.shape, bool(np.abs(noise).max() <= 0.05), noise[:, 2].tolist()
        ((2, 3), True, [0.0, 0.0])
    """
    scale = check_joint_noise(scale)
    if scale == 0 or num_robots == 0:
        return np.zeros((num_robots, num_joints))
    noise = rng.uniform(-scale, scale, (num_robots, num_joints))
    noise[:, list(locked_joints)] = 0.0
    return noise


def check_joint_noise(scale) -> float:
    """``scale`` as a float, or a ``ValueError`` when it is not a finite number >= 0 (rad)."""
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not (math.isfinite(scale) and scale >= 0):
        raise ValueError(f"init_joint_noise must be a finite number of rad >= 0, got {scale!r}")
    return float(scale)


def joint_target_limits(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)``, each ``J``: the control range of the model's position actuators, which
    :func:`hierloco.envs.robots.compile_model` sets to the joint ranges (``-inf``/``inf`` for unlimited ones), in
    ``robot.joint_names`` order."""
    limited = np.asarray(model.actuator_ctrllimited, dtype=bool)
    ctrl_range = np.asarray(model.actuator_ctrlrange, dtype=np.float64)
    return np.where(limited, ctrl_range[:, 0], -np.inf), np.where(limited, ctrl_range[:, 1], np.inf)


def clamp_joint_targets(targets, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """``... x J`` joint targets (rad) clamped to ``[low, high]`` (see :func:`joint_target_limits`): what MuJoCo
    applies to a limited actuator, made explicit so that every simulator treats out-of-range targets alike (a
    target of 1e12 rad is the upper joint limit). NaN stays NaN; callers refuse or handle it first."""
    return np.clip(np.asarray(targets, dtype=np.float64), low, high)


def periods_per_action(robot: str | RobotSpec, steps_per_action: int) -> int:
    """The whole number of ``robot``'s gait periods in one high-level action of ``steps_per_action`` control steps
    (100 Hz); a ``ValueError`` naming both when the action does not hold a whole number (at least one) of periods.

    Example:
        >>> periods_per_action("a1", 100), periods_per_action("daisy", 100)  # A1: 0.2 s trot, Daisy: 1 s tripod
        (5, 1)
    """
    robot = get_robot(robot)
    if isinstance(steps_per_action, bool) or not isinstance(steps_per_action, (int, np.integer)):
        raise ValueError(f"steps_per_action must be a whole number of control steps, got {steps_per_action!r}")
    periods = steps_per_action * CONTROL_TIMESTEP / robot.gait_period
    if steps_per_action < 1 or abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
        raise ValueError(f"steps_per_action={steps_per_action} ({steps_per_action * CONTROL_TIMESTEP:.2f} s) must "
                         f"hold a whole number of {robot.name}'s {robot.gait_period} s gait periods")
    return int(round(periods))


# ---------------------------------------------------------------------------------------------------- dm_control
class LocomotionPhysics(dm_mujoco.Physics):
    """A dm_control Physics for a legged robot, with named accessors in stated frames and units.

    ``unstable`` is true once the episode cannot go on: the physics blew up (NaN, MuJoCo instability warnings) or
    the agent sent NaN joint targets. ``terrain`` is the ground (:mod:`hierloco.envs.terrain`; flat by default).
    """

    robot: RobotSpec
    unstable: bool = False

    @classmethod
    def from_robot(cls, robot: str | RobotSpec, disabled_legs: Sequence[str] = (), terrain=None
                   ) -> "LocomotionPhysics":
        robot = get_robot(robot)
        terrain = make_terrain(terrain)
        physics = cls.from_model(dm_wrapper.MjModel(compile_model(robot, disabled_legs, terrain=terrain)))
        physics.robot = robot
        physics.terrain = terrain
        physics._standing_qpos = standing_qpos_on(terrain, physics.model.ptr, robot)
        physics._ground_reach = 0.0
        if not terrain.is_flat:
            from hierloco.envs.navigation import footprint_radius

            physics._ground_reach = footprint_radius(robot) / 2
        physics._qpos_idx = joint_qpos_indices(physics.model.ptr, robot)
        physics._qvel_idx = joint_qvel_indices(physics.model.ptr, robot)
        physics._foot_sites = [physics.model.ptr.site(leg.foot_site).id for leg in robot.legs]
        physics._locked_joints = robot.leg_joint_indices(tuple(disabled_legs))
        physics._target_low, physics._target_high = joint_target_limits(physics.model.ptr)
        return physics

    @contextlib.contextmanager
    def check_invalid_state(self):
        """Records a physics blow-up (NaN, MuJoCo instability warnings) instead of raising mid-episode."""
        np.copyto(self._warnings_before, self._warnings)
        yield
        blown_up = np.any(self._warnings > self._warnings_before) or not np.all(np.isfinite(self.data.qpos))
        if blown_up and not self.unstable:
            warnings.warn(f"{self.robot.name}: physics became unstable at t={self.data.time:.3f} s; "
                          "the episode terminates", RuntimeWarning, stacklevel=2)
        self.unstable = self.unstable or bool(blown_up)

    def reset(self, keyframe_id=None):
        super().reset(keyframe_id)
        self.unstable = False

    def com_position(self) -> np.ndarray:
        """Base (CoM frame) position ``(x, y, z)`` in the world frame, in m."""
        return self.data.qpos[0:3].copy()

    def com_velocity(self) -> np.ndarray:
        """Base linear velocity ``(vx, vy, vz)`` in the world frame, in m/s."""
        return self.data.qvel[0:3].copy()

    def roll_pitch_yaw(self) -> np.ndarray:
        """Base orientation as ZYX angles ``(roll, pitch, yaw)`` in rad."""
        return quat_to_roll_pitch_yaw(self.data.qpos[3:7])

    def yaw(self) -> float:
        """Heading of the base in the world, in rad."""
        return float(self.roll_pitch_yaw()[2])

    def com_velocity_local(self) -> np.ndarray:
        """Base planar velocity ``(forward, left)`` in the robot's local (yaw) frame, in m/s."""
        return world_to_local(self.data.qvel[0:2], self.yaw())

    def joint_positions(self) -> np.ndarray:
        """Leg joint angles in ``robot.joint_names`` order, in rad."""
        return self.data.qpos[self._qpos_idx].copy()

    def joint_velocities(self) -> np.ndarray:
        """Leg joint velocities in ``robot.joint_names`` order, in rad/s."""
        return self.data.qvel[self._qvel_idx].copy()

    def foot_positions(self) -> np.ndarray:
        """Foot site positions ``L x 3`` in the world frame, in m, in leg order."""
        return self.data.site_xpos[self._foot_sites].copy()

    def foot_contacts(self) -> np.ndarray:
        """Whether each foot touches the ground (``L``, bool), in leg order."""
        return self.data.sensordata[: len(self.robot.legs)] > FOOT_CONTACT_FORCE

    def has_fallen(self) -> bool:
        """Roll or pitch beyond the robot's limits, or the base below its minimum height (:func:`robot_has_fallen`)
        above the lowest ground near it (:meth:`hierloco.envs.terrain.Terrain.ground_below`)."""
        roll, pitch, _ = self.roll_pitch_yaw()
        height = self.data.qpos[2]
        if not self.terrain.is_flat:
            height = height - float(self.terrain.ground_below(self.data.qpos[0], self.data.qpos[1],
                                                              self._ground_reach))
        return bool(robot_has_fallen(self.robot, roll, pitch, height))


class LocomotionTask(base.Task):
    """Stand or walk: the joint targets come from the agent; reward 1 per step while upright, 0 once the robot has
    fallen or the step failed (a physics blow-up, NaN targets).

    Task-specific costs and rewards (velocity tracking, goal reaching, ...) live in :mod:`hierloco.envs.tasks`;
    this task defines the episode: the initial state, the observation and when the robot has fallen. Joint targets
    outside the joint range are clamped to it (:func:`clamp_joint_targets`); NaN targets end the episode
    (terminated, reward 0, the previous targets held for that last step); infinite targets raise ``ValueError``.
    """

    def __init__(self, init_joint_noise: float = INIT_JOINT_NOISE, random=None):
        super().__init__(random=random)
        self.init_joint_noise = check_joint_noise(init_joint_noise)

    def initialize_episode(self, physics: LocomotionPhysics) -> None:
        robot = physics.robot
        qpos = physics._standing_qpos.copy()
        noise = reset_joint_noise(self.random, self.init_joint_noise, 1, robot.num_joints, physics._locked_joints)
        qpos[physics._qpos_idx] += noise[0]
        physics.data.qpos[:] = qpos
        physics.data.qvel[:] = 0.0
        physics.data.ctrl[:] = robot.standing_pose
        physics.unstable = False
        super().initialize_episode(physics)

    def get_observation(self, physics: LocomotionPhysics) -> collections.OrderedDict:
        obs = collections.OrderedDict()
        obs["com_position"] = physics.com_position()
        obs["com_velocity"] = physics.com_velocity()
        obs["orientation"] = physics.roll_pitch_yaw()
        obs["joint_positions"] = physics.joint_positions()
        obs["joint_velocities"] = physics.joint_velocities()
        obs["foot_contacts"] = physics.foot_contacts().astype(np.float64)
        return obs

    def before_step(self, action, physics: LocomotionPhysics) -> None:
        targets = np.asarray(action, dtype=np.float64)
        if np.isinf(targets).any():
            raise ValueError(f"{physics.robot.name}: joint targets contain inf (joints "
                             f"{np.flatnonzero(np.isinf(targets)).tolist()}); give targets in rad")
        if np.isnan(targets).any():
            if not physics.unstable:
                warnings.warn(f"{physics.robot.name}: NaN joint targets at t={physics.data.time:.3f} s; the episode "
                              "terminates", RuntimeWarning, stacklevel=2)
            physics.unstable = True
            targets = physics.data.ctrl.copy()  # hold the previous targets for this last step
        physics.set_control(clamp_joint_targets(targets, physics._target_low, physics._target_high))

    def get_reward(self, physics: LocomotionPhysics) -> float:
        return 0.0 if physics.unstable or physics.has_fallen() else 1.0

    def get_termination(self, physics: LocomotionPhysics):
        if physics.unstable or physics.has_fallen():
            return 0.0
        return None


class LocomotionEnv(DMControlWrapper):
    """The TorchRL wrapper of a locomotion dm_control env, with its :class:`LocomotionPhysics` in ``physics``.

    Built by :func:`hierloco.envs.make_env`; transforms that act on the simulation (e.g.
    :class:`hierloco.envs.transforms.DisableLegs`) reach it through ``env.base_env.physics``.
    """

    @property
    def physics(self) -> LocomotionPhysics:
        """The dm_control Physics of the wrapped environment (live: changes act on the next step)."""
        return self._env.physics


def make_dm_env(
    robot: str | RobotSpec,
    *,
    disabled_legs: Sequence[str] = (),
    time_limit: float = 10.0,
    seed: int | None = None,
    init_joint_noise: float = INIT_JOINT_NOISE,
    terrain=None,
) -> control.Environment:
    """A dm_control ``Environment`` of ``robot`` at 100 Hz control; ``disabled_legs`` are locked standing; the robot
    starts on ``terrain`` (:func:`hierloco.envs.terrain.make_terrain`; default flat)."""
    if not time_limit > 0:
        raise ValueError(f"time_limit must be positive seconds, got {time_limit}")
    init_joint_noise = check_joint_noise(init_joint_noise)
    physics = LocomotionPhysics.from_robot(robot, disabled_legs, terrain=terrain)
    task = LocomotionTask(init_joint_noise=init_joint_noise, random=seed)
    return control.Environment(physics, task, time_limit=time_limit, control_timestep=CONTROL_TIMESTEP)
