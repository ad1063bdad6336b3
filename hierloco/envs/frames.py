"""Frames and angles shared by the simulators, the transforms, the models and the tasks.

Every function works on NumPy arrays and on torch tensors alike, batched over leading dimensions. Conventions:
world frame z up; a robot's local (yaw) frame has x forward and y left and shares the world z; yaw is the heading
of the local x axis in the world, in rad; quaternions are ``(w, x, y, z)`` as in MuJoCo.

Example:
    >>> import numpy as np
    >>> v_local = world_to_local(np.array([0.0, 1.0]), np.pi / 2)  # +y in the world, robot facing +y
    >>> np.round(v_local, 6).tolist()
    [1.0, 0.0]
"""

from __future__ import annotations

import math

import numpy as np
import torch


def _xp(x):
    return torch if isinstance(x, torch.Tensor) else np


def wrap_angle(angle):
    """Angles wrapped to (-pi, pi], in rad."""
    xp = _xp(angle)
    wrapped = xp.remainder(angle + math.pi, 2 * math.pi) - math.pi
    return xp.where(wrapped <= -math.pi, wrapped + 2 * math.pi, wrapped)


def quat_to_roll_pitch_yaw(quat):
    """``... x 4`` quaternions ``(w, x, y, z)`` -> ``... x 3`` intrinsic ZYX angles ``(roll, pitch, yaw)`` in rad."""
    xp = _xp(quat)
    w, x, y, z = quat[..., 0], quat[..., 1], quat[..., 2], quat[..., 3]
    roll = xp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    sin_pitch = xp.clip(2 * (w * y - z * x), -1.0, 1.0)
    pitch = xp.arcsin(sin_pitch)
    yaw = xp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return xp.stack([roll, pitch, yaw], -1)


def rotate_xy(vec_xy, angle):
    """``... x 2`` planar vectors rotated by ``angle`` (rad, broadcast over the leading dimensions)."""
    xp = _xp(vec_xy)
    c, s = xp.cos(angle), xp.sin(angle)
    x, y = vec_xy[..., 0], vec_xy[..., 1]
    return xp.stack([c * x - s * y, s * x + c * y], -1)


def world_to_local(vec_xy, yaw):
    """``... x 2`` world-frame planar vectors expressed in the local frame of a robot with heading ``yaw``."""
    return rotate_xy(vec_xy, -yaw)


def local_to_world(vec_xy, yaw):
    """``... x 2`` local-frame planar vectors expressed in the world frame, for a robot with heading ``yaw``."""
    return rotate_xy(vec_xy, yaw)


def com_state_from_base(position, quat, velocity):
    """The CoM state ``... x 5`` = ``(x, y, yaw, vx, vy)`` in the world frame (m, rad, m/s).

    Args:
        position: ``... x 3`` base position in the world, in m.
        quat: ``... x 4`` base orientation ``(w, x, y, z)``.
        velocity: ``... x 3`` base linear velocity in the world, in m/s.
    """
    xp = _xp(position)
    yaw = quat_to_roll_pitch_yaw(quat)[..., 2]
    return xp.concatenate([position[..., :2], yaw[..., None], velocity[..., :2]], -1)


def yaw_rate_from_base(quat, angular_velocity_local):
    """``...`` yaw rate in rad/s (world z component of the body angular velocity) from the base orientation
    ``... x 4`` and its angular velocity ``... x 3`` in the body frame (as in a free joint's ``qvel[3:6]``)."""
    w, x, y, z = quat[..., 0], quat[..., 1], quat[..., 2], quat[..., 3]
    wx, wy, wz = angular_velocity_local[..., 0], angular_velocity_local[..., 1], angular_velocity_local[..., 2]
    return 2 * (x * z - w * y) * wx + 2 * (y * z + w * x) * wy + (1 - 2 * (x * x + y * y)) * wz
