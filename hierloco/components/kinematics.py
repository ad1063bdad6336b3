"""Leg kinematics for any robot description: forward kinematics, Jacobians and inverse kinematics.

Generic: the kinematic chain of each leg (body offsets, joint anchors and axes) is read from the compiled MuJoCo
model, so a user's robot needs no hand-written kinematics. Everything is in the base body frame and batched over
leading dimensions with NumPy (float64). Inverse kinematics is damped least squares within the joint limits, warm
started from a given pose; a target out of reach gives the nearest pose the iteration finds, never NaN.

Example:
    >>> import numpy as np
    >>> from hierloco.envs.robots import get_robot
    >>> kin = LegKinematics(get_robot("a1"))
    >>> feet = kin.forward(np.asarray(kin.robot.standing_pose))  # L x 3 foot positions in the base frame
    >>> q = kin.inverse(feet, kin.standing_pose)
    >>> bool(np.abs(kin.forward(q) - feet).max() < 1e-6)
    True
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from hierloco.envs.robots import RobotSpec, compile_model, get_robot, standing_qpos


def _quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)


def _axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``... x 3 x 3`` rotations by ``angle`` (``...``) about the unit ``axis`` (Rodrigues)."""
    x, y, z = axis
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


@dataclass
class _Link:
    """A fixed transform (rotation ``rot``, translation ``pos``) then, optionally, a hinge joint."""

    pos: np.ndarray
    rot: np.ndarray
    joint: int | None  # index of the joint within the leg
    anchor: np.ndarray | None  # joint anchor in this link's frame
    axis: np.ndarray | None  # unit joint axis in this link's frame


class LegKinematics:
    """Forward and inverse kinematics of every leg of ``robot``, in the base body frame.

    Args:
        robot: a registered name or a :class:`RobotSpec`.
        damping: damped least-squares damping, in m.
        iterations: maximum IK iterations per call.
        tolerance: IK stops when every foot is this close to its target, in m.
        max_step: largest joint change per iteration, in rad (a trust region for far targets).
    """

    def __init__(self, robot: str | RobotSpec, *, damping: float = 1e-3, iterations: int = 50,
                 tolerance: float = 1e-6, max_step: float = 0.2):
        self.robot = get_robot(robot)
        self.damping = damping
        self.iterations = iterations
        self.tolerance = tolerance
        self.max_step = max_step
        self.far_damping = 0.5
        model = compile_model(self.robot)
        base = model.body(self.robot.base_body).id
        data = mujoco.MjData(model)
        data.qpos[:] = standing_qpos(model, self.robot, yaw=0.0)
        mujoco.mj_forward(model, data)
        # the whole robot's centre of mass in the base frame, standing
        self.com_offset = data.xmat[base].reshape(3, 3).T @ (data.subtree_com[base] - data.xpos[base])
        self.chains: list[list[_Link]] = []
        self.foot_offsets: list[np.ndarray] = []
        lows, highs = [], []
        for leg in self.robot.legs:
            joint_ids = [model.joint(name).id for name in leg.joints]
            site = model.site(leg.foot_site).id
            body = model.site_bodyid[site]
            path = []
            while body != base:
                if body == 0:
                    raise ValueError(f"robot {self.robot.name!r}: foot {leg.foot_site!r} is not below the base body")
                path.append(body)
                body = model.body_parentid[body]
            chain = []
            for body in reversed(path):
                chain.append(_Link(model.body_pos[body].copy(), _quat_to_matrix(model.body_quat[body]), None, None, None))
                for j in range(model.body_jntnum[body]):
                    jid = model.body_jntadr[body] + j
                    if jid not in joint_ids:
                        raise ValueError(f"robot {self.robot.name!r}: joint {model.joint(jid).name!r} on leg "
                                         f"{leg.name!r} is not listed in the leg's joints")
                    chain.append(_Link(np.zeros(3), np.eye(3), joint_ids.index(jid), model.jnt_pos[jid].copy(),
                                       model.jnt_axis[jid] / np.linalg.norm(model.jnt_axis[jid])))
            if sorted(link.joint for link in chain if link.joint is not None) != list(range(len(joint_ids))):
                raise ValueError(f"robot {self.robot.name!r}: leg {leg.name!r} joints are not all on the foot's chain")
            self.chains.append(chain)
            self.foot_offsets.append(model.site_pos[site].copy())
            lows.extend(model.jnt_range[jid][0] if model.jnt_limited[jid] else -np.inf for jid in joint_ids)
            highs.extend(model.jnt_range[jid][1] if model.jnt_limited[jid] else np.inf for jid in joint_ids)
        self.joint_low = np.asarray(lows)
        self.joint_high = np.asarray(highs)
        self.leg_slices = []
        start = 0
        for leg in self.robot.legs:
            self.leg_slices.append(slice(start, start + len(leg.joints)))
            start += len(leg.joints)
        self.standing_pose = np.asarray(self.robot.standing_pose, dtype=np.float64)

    @property
    def num_legs(self) -> int:
        return len(self.robot.legs)

    def _leg_forward(self, leg: int, q: np.ndarray, with_jacobian: bool):
        """Foot ``... x 3`` (and Jacobian ``... x 3 x n``) of one leg for its joint angles ``... x n``."""
        batch = q.shape[:-1]
        rot = np.broadcast_to(np.eye(3), (*batch, 3, 3))
        pos = np.zeros((*batch, 3))
        anchors, axes = [None] * q.shape[-1], [None] * q.shape[-1]
        for link in self.chains[leg]:
            if link.joint is None:
                pos = pos + rot @ link.pos
                rot = rot @ link.rot
            else:
                anchor = pos + rot @ link.anchor
                axis = rot @ link.axis
                anchors[link.joint], axes[link.joint] = anchor, axis
                turn = _axis_rotation(link.axis, q[..., link.joint])
                pos = anchor + (rot @ turn) @ (-link.anchor)
                rot = rot @ turn
        foot = pos + rot @ self.foot_offsets[leg]
        if not with_jacobian:
            return foot, None
        jac = np.stack([np.cross(axes[j], foot - anchors[j]) for j in range(q.shape[-1])], -1)
        return foot, jac

    def forward(self, joint_positions: np.ndarray) -> np.ndarray:
        """Foot positions ``... x L x 3`` in the base frame (m) for joint angles ``... x J`` (rad)."""
        q = np.asarray(joint_positions, dtype=np.float64)
        return np.stack([self._leg_forward(i, q[..., s], False)[0] for i, s in enumerate(self.leg_slices)], -2)

    def jacobian(self, joint_positions: np.ndarray) -> list[np.ndarray]:
        """Per leg, the foot Jacobian ``... x 3 x n_leg`` in the base frame, d(foot)/d(joint angles)."""
        q = np.asarray(joint_positions, dtype=np.float64)
        return [self._leg_forward(i, q[..., s], True)[1] for i, s in enumerate(self.leg_slices)]

    def inverse(self, foot_positions: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
        """Joint angles ``... x J`` (rad, within limits) placing the feet at ``... x L x 3`` (base frame, m).

        Damped least squares from ``initial`` (default: the standing pose), clipped to the joint limits at every
        iteration. Unreachable targets end at the closest pose the iteration reaches.
        """
        target = np.asarray(foot_positions, dtype=np.float64)
        if target.shape[-2:] != (self.num_legs, 3):
            raise ValueError(f"foot_positions must be ... x {self.num_legs} x 3, got {target.shape}")
        if not np.all(np.isfinite(target)):
            raise ValueError("foot_positions contain NaN or inf")
        batch = target.shape[:-2]
        q = np.broadcast_to(self.standing_pose if initial is None else initial, (*batch, self.robot.num_joints))
        q = np.clip(q.astype(np.float64, copy=True), self.joint_low, self.joint_high)
        for i, s in enumerate(self.leg_slices):
            q[..., s] = self._leg_inverse(i, target[..., i, :], q[..., s], self.joint_low[s], self.joint_high[s])
        return q

    def _leg_inverse(self, leg, target, q, low, high):
        q = self._descend(leg, target, q, low, high)
        # targets not reached (out of reach, or a local minimum at the limits): restart from a coarse grid of
        # poses over the joint box and keep the closest result
        error = np.linalg.norm(self._leg_forward(leg, q, False)[0] - target, axis=-1)
        stuck = error > 10 * self.tolerance + 1e-4
        if np.any(stuck):
            starts = self._restart_poses(low, high)  # K x n
            far_target = target[stuck]  # M x 3
            k, m = len(starts), len(far_target)
            trial = self._descend(leg, np.repeat(far_target, k, 0), np.tile(starts, (m, 1)), low, high,
                                  iterations=4 * self.iterations)
            trial_error = np.linalg.norm(self._leg_forward(leg, trial, False)[0] - np.repeat(far_target, k, 0), axis=-1)
            best = trial_error.reshape(m, k).argmin(1)
            improved = trial_error.reshape(m, k)[np.arange(m), best] < error[stuck]
            chosen = trial.reshape(m, k, -1)[np.arange(m), best]
            fixed = q[stuck]
            fixed[improved] = chosen[improved]
            q[stuck] = fixed
        return q

    @staticmethod
    def _restart_poses(low, high, per_joint: int = 4) -> np.ndarray:
        low, high = np.maximum(low, -np.pi), np.minimum(high, np.pi)
        axes = [lo + (hi - lo) * (np.arange(per_joint) + 0.5) / per_joint for lo, hi in zip(low, high)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(low))

    def _descend(self, leg, target, q, low, high, iterations=None):
        """Damped least squares; joints at a limit that the step pushes further out are frozen for that step."""
        damping2 = self.damping**2
        q = q.copy()
        for _ in range(iterations or self.iterations):
            foot, jac = self._leg_forward(leg, q, True)
            error = target - foot
            if np.all(np.abs(error) < self.tolerance):
                break
            # damping grows with the error: Gauss-Newton near the target, gradient-like far from it
            lam2 = damping2 + (self.far_damping * np.linalg.norm(error, axis=-1))[..., None, None] ** 2
            step = self._dls_step(jac, error, lam2)
            blocked = ((q <= low) & (step < 0)) | ((q >= high) & (step > 0))
            if np.any(blocked):
                step = self._dls_step(jac * ~blocked[..., None, :], error, lam2)
            largest = np.abs(step).max(-1, keepdims=True)
            step = step * np.minimum(1.0, self.max_step / np.maximum(largest, 1e-12))
            q = np.clip(q + step, low, high)
        return q

    @staticmethod
    def _dls_step(jac, error, damping2):
        jac_t = np.swapaxes(jac, -1, -2)
        jjt = jac @ jac_t + damping2 * np.eye(3)
        return (jac_t @ np.linalg.solve(jjt, error[..., None]))[..., 0]
