"""The dm_control locomotion environment: a Physics with named accessors and a Task (SPEC 4).

Control runs at 100 Hz (``CONTROL_TIMESTEP``), physics at 0.002 s, the action is the vector of joint targets in
``robot.joint_names`` order, tracked by MuJoCo position actuators. Every episode starts at the origin facing +y in
the standing pose with seeded joint-angle noise. A fall (roll or pitch over the robot's limit, base below its
minimum height) or a physics blow-up ends the episode as terminated; the time limit ends it as truncated.

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
import warnings
from typing import Sequence

import numpy as np
from dm_control import mujoco as dm_mujoco
from dm_control.mujoco import wrapper as dm_wrapper
from dm_control.rl import control
from dm_control.suite import base

from hierloco.envs.frames import quat_to_roll_pitch_yaw, world_to_local
from hierloco.envs.robots import (
    CONTROL_TIMESTEP,
    RobotSpec,
    compile_model,
    get_robot,
    joint_qpos_indices,
    joint_qvel_indices,
    standing_qpos,
)

INIT_JOINT_NOISE = 0.05  # rad, uniform noise on the standing joint angles at reset
FOOT_CONTACT_FORCE = 1.0  # N, a foot touching with more than this is in stance


class LocomotionPhysics(dm_mujoco.Physics):
    """A dm_control Physics for a legged robot, with named accessors in stated frames and units."""

    robot: RobotSpec
    unstable: bool = False

    @classmethod
    def from_robot(cls, robot: str | RobotSpec, disabled_legs: Sequence[str] = ()) -> "LocomotionPhysics":
        robot = get_robot(robot)
        physics = cls.from_model(dm_wrapper.MjModel(compile_model(robot, disabled_legs)))
        physics.robot = robot
        physics._qpos_idx = joint_qpos_indices(physics.model.ptr, robot)
        physics._qvel_idx = joint_qvel_indices(physics.model.ptr, robot)
        physics._foot_sites = [physics.model.ptr.site(leg.foot_site).id for leg in robot.legs]
        physics._locked_joints = robot.leg_joint_indices(tuple(disabled_legs))
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
        """Roll or pitch beyond the robot's limits, or the base below its minimum height."""
        roll, pitch, _ = self.roll_pitch_yaw()
        robot = self.robot
        return bool(abs(roll) > robot.max_roll or abs(pitch) > robot.max_pitch
                    or self.data.qpos[2] < robot.min_height)


class LocomotionTask(base.Task):
    """Stand or walk: the joint targets come from the agent; reward 1 per step while upright.

    Task-specific costs and rewards (velocity tracking, goal reaching, ...) live in :mod:`hierloco.envs.tasks`;
    this task defines the episode: the initial state, the observation and when the robot has fallen.
    """

    def __init__(self, init_joint_noise: float = INIT_JOINT_NOISE, random=None):
        super().__init__(random=random)
        self.init_joint_noise = init_joint_noise

    def initialize_episode(self, physics: LocomotionPhysics) -> None:
        robot = physics.robot
        qpos = standing_qpos(physics.model.ptr, robot)
        noise = self.random.uniform(-self.init_joint_noise, self.init_joint_noise, robot.num_joints)
        noise[physics._locked_joints] = 0.0  # disabled legs start (and stay) at their standing angles
        qpos[physics._qpos_idx] += noise
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

    def get_reward(self, physics: LocomotionPhysics) -> float:
        return 0.0 if physics.has_fallen() else 1.0

    def get_termination(self, physics: LocomotionPhysics):
        if physics.unstable or physics.has_fallen():
            return 0.0
        return None


def make_dm_env(
    robot: str | RobotSpec,
    *,
    disabled_legs: Sequence[str] = (),
    time_limit: float = 10.0,
    seed: int | None = None,
    init_joint_noise: float = INIT_JOINT_NOISE,
) -> control.Environment:
    """A dm_control ``Environment`` of ``robot`` at 100 Hz control; ``disabled_legs`` are locked standing."""
    if not time_limit > 0:
        raise ValueError(f"time_limit must be positive seconds, got {time_limit}")
    physics = LocomotionPhysics.from_robot(robot, disabled_legs)
    task = LocomotionTask(init_joint_noise=init_joint_noise, random=seed)
    return control.Environment(physics, task, time_limit=time_limit, control_timestep=CONTROL_TIMESTEP)
