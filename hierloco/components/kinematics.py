"""Leg kinematics for any robot description: forward kinematics, Jacobians and inverse kinematics.

Generic: the kinematic chain of each leg (body offsets, joint anchors and axes) is read from the compiled MuJoCo
model, so a user's robot needs no hand-written kinematics. Everything is in the base body frame and batched over
leading dimensions with NumPy (float64). Inverse kinematics is damped least squares within the joint limits, warm
started from a given pose; a target out of reach gives the nearest pose the iteration finds, never NaN.

Two solvers implement that one law (``solver=``):

- ``"reference"``: leg by leg, with a LAPACK solve per foot, iterating until every foot of the batch has converged.
  The expert library is recorded with it, so its arithmetic is kept exactly.
- ``"vectorised"``: all legs with the same number of joints at once, each joint axis turned into the local z axis
  so that a joint rotation is two column updates, the 3 x 3 damped system solved in closed form, and each batch
  element stopping as soon as its own feet have converged (or settled, out of reach), and only the stuck feet
  restarted. It agrees with the reference within the tolerance and is 5-7x faster on the same ``B x k x L`` batch
  of reachable feet (``benchmarks/bench_ik.py``), far more when some feet are out of reach.

Example:
    >>> import numpy as np
    >>> from hierloco.envs.robots import get_robot
    >>> kin = LegKinematics(get_robot("a1"))
    >>> feet = kin.forward(np.asarray(kin.robot.standing_pose))  # L x 3 foot positions in the base frame
    >>> q = kin.inverse(feet, kin.standing_pose)
    >>> bool(np.abs(kin.forward(q) - feet).max() < 1e-6)
    True
    >>> fast = LegKinematics("a1", solver="vectorised")
    >>> bool(np.abs(fast.forward(fast.inverse(feet)) - feet).max() < 1e-6)
    True
"""

from __future__ import annotations

from dataclasses import dataclass, field

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


@dataclass
class _ChainGroup:
    """The legs with ``n`` joints, in the canonical form of the vectorised solver (``Lg`` legs).

    Each leg is ``n`` joints in chain order; before joint ``j`` a fixed transform (``rotations[j]`` ``Lg x 3 x 3``,
    ``translations[j]`` ``Lg x 3``) leads from the previous joint's frame (after its rotation; the base frame for
    ``j = 0``) to a frame at joint ``j``'s anchor whose z axis is the joint axis; ``foot`` (``Lg x 3``) is the foot in
    the last joint's frame. ``joints`` (``Lg x n``) indexes each leg's joints in ``J``.
    """

    legs: np.ndarray
    joints: np.ndarray
    rotations: list
    translations: list
    foot: np.ndarray
    low: np.ndarray  # n x 1 x Lg
    high: np.ndarray
    restarts: np.ndarray  # K x n x Lg restart poses (a grid over each leg's joint box)
    first_columns: list = field(init=False)  # joint 0's frame, constant: three 3 x 1 x Lg columns
    first_position: np.ndarray = field(init=False)  # 3 x 1 x Lg
    translation_plans: list = field(init=False)  # per joint j >= 1, a _plan over the current columns
    rotation_plans: list = field(init=False)  # per joint j >= 1, three _plans (one per new column)
    foot_plan: tuple = field(init=False)

    def __post_init__(self):
        self.first_columns = [self.rotations[0][:, :, k].T[:, None, :].copy() for k in range(3)]
        self.first_position = self.translations[0].T[:, None, :].copy()
        self.translation_plans = [_plan(t.T) for t in self.translations]
        self.rotation_plans = [[_plan(r[:, :, k].T) for k in range(3)] for r in self.rotations]
        self.foot_plan = _plan(self.foot.T)

    @property
    def num_joints(self) -> int:
        return self.joints.shape[1]

    def select(self, positions: np.ndarray) -> "_ChainGroup":
        """The group of the legs at ``positions`` (indices into this group's legs, repeats allowed)."""
        return _ChainGroup(legs=self.legs[positions], joints=self.joints[positions],
                           rotations=[r[positions] for r in self.rotations],
                           translations=[t[positions] for t in self.translations], foot=self.foot[positions],
                           low=self.low[..., positions], high=self.high[..., positions],
                           restarts=self.restarts[..., positions])


def _axis_to_z(axis: np.ndarray) -> np.ndarray:
    """A rotation ``A`` with ``A @ e_z = axis`` (a signed permutation when ``axis`` is a coordinate axis)."""
    axis = np.asarray(axis, dtype=np.float64)
    for i in range(3):
        for sign in (1.0, -1.0):
            if np.array_equal(axis, sign * np.eye(3)[i]):
                others = [(i + 1) % 3, (i + 2) % 3]
                rot = np.zeros((3, 3))
                rot[i, 2] = sign
                rot[others[0], 0] = 1.0
                rot[others[1], 1] = sign  # det = +1: (e_a, sign e_b, sign e_i) is right-handed
                return rot
    z = axis / np.linalg.norm(axis)
    helper = np.eye(3)[np.argmin(np.abs(z))]
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], -1)


def _plan(coefficients: np.ndarray) -> tuple:
    """How to form ``sum_i column_i * coefficients[i]`` (``coefficients``: ``3 x Lg``, one per leg): the terms
    ``(i, factor)`` that are not zero for every leg, ``factor`` ``None`` where it is one for every leg."""
    return tuple((i, None if np.all(c == 1.0) else c.copy()) for i, c in enumerate(coefficients) if np.any(c))


def _apply(columns, plan):
    """``sum_i columns[i] * factor_i`` over a :func:`_plan` (``None`` for an empty plan)."""
    total = None
    for i, factor in plan:
        term = columns[i] if factor is None else columns[i] * factor
        total = term if total is None else total + term
    return total


class LegKinematics:
    """Forward and inverse kinematics of every leg of ``robot``, in the base body frame.

    Args:
        robot: a registered name or a :class:`RobotSpec`.
        damping: damped least-squares damping, in m.
        iterations: maximum IK iterations per call.
        tolerance: IK stops when every foot is this close to its target, in m.
        max_step: largest joint change per iteration, in rad (a trust region for far targets).
        solver: ``"reference"`` or ``"vectorised"`` (see the module docstring), for :meth:`forward` and
            :meth:`inverse`.
    """

    SOLVERS = ("reference", "vectorised")

    def __init__(self, robot: str | RobotSpec, *, damping: float = 1e-3, iterations: int = 50,
                 tolerance: float = 1e-6, max_step: float = 0.2, solver: str = "reference"):
        if solver not in self.SOLVERS:
            raise ValueError(f"unknown IK solver {solver!r}; choose one of {self.SOLVERS}")
        self.solver = solver
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
        self.groups = self._chain_groups()

    def _chain_groups(self) -> list[_ChainGroup]:
        """The legs grouped by their number of joints, each chain rewritten in the vectorised solver's form."""
        canonical = []
        for leg, chain in enumerate(self.chains):
            rot, pos = np.eye(3), np.zeros(3)  # the pending fixed transform from the last joint's frame
            rotations, translations, joints = [], [], []
            for link in chain:
                if link.joint is None:
                    pos, rot = pos + rot @ link.pos, rot @ link.rot
                    continue
                align = _axis_to_z(link.axis)
                rotations.append(rot @ align)
                translations.append(pos + rot @ link.anchor)
                joints.append(self.leg_slices[leg].start + link.joint)
                rot, pos = align.T, -align.T @ link.anchor
            canonical.append((rotations, translations, joints, pos + rot @ self.foot_offsets[leg]))
        groups = []
        for n in sorted({len(c[2]) for c in canonical}):
            legs = np.array([i for i, c in enumerate(canonical) if len(c[2]) == n])
            joints = np.array([canonical[i][2] for i in legs])
            starts = np.stack([self._restart_poses(self.joint_low[j], self.joint_high[j]) for j in joints], -1)
            groups.append(_ChainGroup(
                legs=legs, joints=joints,
                rotations=[np.stack([canonical[i][0][j] for i in legs]) for j in range(n)],
                translations=[np.stack([canonical[i][1][j] for i in legs]) for j in range(n)],
                foot=np.stack([canonical[i][3] for i in legs]),
                low=self.joint_low[joints].T[:, None, :], high=self.joint_high[joints].T[:, None, :],
                restarts=starts))
        return groups

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
        if self.solver == "vectorised":
            batch = q.shape[:-1]
            flat = q.reshape(-1, q.shape[-1])
            feet = np.empty((flat.shape[0], self.num_legs, 3))
            for group in self.groups:
                foot, _ = self._group_forward(group, np.moveaxis(flat[:, group.joints], -1, 0), False)
                feet[:, group.legs] = np.moveaxis(foot, 0, -1)
            return feet.reshape(*batch, self.num_legs, 3)
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
        if self.solver == "vectorised":
            flat_q, flat_target = q.reshape(-1, q.shape[-1]), target.reshape(-1, self.num_legs, 3)
            for group in self.groups:
                qg = np.ascontiguousarray(np.moveaxis(flat_q[:, group.joints], -1, 0))  # n x M x Lg
                tg = np.ascontiguousarray(np.moveaxis(flat_target[:, group.legs], -1, 0))  # 3 x M x Lg
                flat_q[:, group.joints] = np.moveaxis(self._group_inverse(group, tg, qg), 0, -1)
            return flat_q.reshape(q.shape)
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

    # ------------------------------------------------------------------ vectorised solver
    def _group_forward(self, group: _ChainGroup, q: np.ndarray, with_jacobian: bool):
        """Feet ``3 x M x Lg`` (and the Jacobian ``n x 3 x M x Lg``) of the group's legs for joint angles
        ``n x M x Lg``. A rotation is kept as its three columns (``3 x M x Lg``)."""
        columns, position = group.first_columns, group.first_position
        anchors, axes = [], []
        for j in range(group.num_joints):
            if j > 0:
                shift = _apply(columns, group.translation_plans[j])
                position = position if shift is None else position + shift
                columns = [_apply(columns, plan) for plan in group.rotation_plans[j]]
            if with_jacobian:
                anchors.append(position)
                axes.append(columns[2])
            c, s = np.cos(q[j]), np.sin(q[j])
            columns = [columns[0] * c + columns[1] * s, columns[1] * c - columns[0] * s, columns[2]]
        shift = _apply(columns, group.foot_plan)
        foot = position if shift is None else position + shift
        if not with_jacobian:
            return foot, None
        jac = np.empty((group.num_joints, *foot.shape))
        for j, (anchor, axis) in enumerate(zip(anchors, axes)):
            lever = foot - anchor
            jac[j, 0] = axis[1] * lever[2] - axis[2] * lever[1]
            jac[j, 1] = axis[2] * lever[0] - axis[0] * lever[2]
            jac[j, 2] = axis[0] * lever[1] - axis[1] * lever[0]
        return foot, jac

    @staticmethod
    def _closed_form_step(jac: np.ndarray, error: np.ndarray, damping2: np.ndarray) -> np.ndarray:
        """``J^T (J J^T + damping2 I)^-1 error`` for ``n x 3 x ...`` Jacobians and ``3 x ...`` errors, by the
        adjugate of the symmetric 3 x 3 system."""
        a00 = np.einsum("j...,j...->...", jac[:, 0], jac[:, 0]) + damping2
        a11 = np.einsum("j...,j...->...", jac[:, 1], jac[:, 1]) + damping2
        a22 = np.einsum("j...,j...->...", jac[:, 2], jac[:, 2]) + damping2
        a01 = np.einsum("j...,j...->...", jac[:, 0], jac[:, 1])
        a02 = np.einsum("j...,j...->...", jac[:, 0], jac[:, 2])
        a12 = np.einsum("j...,j...->...", jac[:, 1], jac[:, 2])
        m00, m11, m22 = a11 * a22 - a12 * a12, a00 * a22 - a02 * a02, a00 * a11 - a01 * a01
        m01, m02, m12 = a02 * a12 - a01 * a22, a01 * a12 - a02 * a11, a01 * a02 - a00 * a12
        e0, e1, e2 = error
        inv_det = 1.0 / (a00 * m00 + a01 * m01 + a02 * m02)
        y0 = (m00 * e0 + m01 * e1 + m02 * e2) * inv_det
        y1 = (m01 * e0 + m11 * e1 + m12 * e2) * inv_det
        y2 = (m02 * e0 + m12 * e1 + m22 * e2) * inv_det
        return jac[:, 0] * y0 + jac[:, 1] * y1 + jac[:, 2] * y2

    def _group_descend(self, group: _ChainGroup, target: np.ndarray, q: np.ndarray, iterations: int) -> np.ndarray:
        """The damped least-squares iteration of :meth:`_descend` on ``n x M x Lg`` poses towards ``3 x M x Lg``
        targets. Each of the M elements stops on its own, once every one of its feet is within the tolerance or
        has settled (its distance to the target is the same, within the tolerance, as one or two iterations
        before: the nearest pose to an unreachable target, or a two-step cycle against a joint limit). Each foot
        ends at the closest of the poses it went through."""
        best_q = q.copy()
        best = np.full(q.shape[1:], np.inf)  # M x Lg
        active = np.arange(q.shape[1])
        qa, ta = q, target
        low, high = group.low, group.high
        before = previous = None
        for iteration in range(iterations + 1):
            foot, jac = self._group_forward(group, qa, iteration < iterations)
            error = ta - foot
            distance2 = np.einsum("i...,i...->...", error, error)  # M x Lg
            distance = np.sqrt(distance2)
            rows, legs = np.nonzero(distance < best[active])
            best[active[rows], legs] = distance[rows, legs]
            best_q[:, active[rows], legs] = qa[:, rows, legs]
            if iteration == iterations:
                break
            settled = (np.abs(error) < self.tolerance).all(0)
            if previous is not None:
                settled |= np.abs(previous - distance) < self.tolerance
            if before is not None:
                settled |= np.abs(before - distance) < self.tolerance
            done = settled.all(-1)
            if done.any():
                keep = ~done
                if not keep.any():
                    break
                active, qa, ta, error, jac, distance2, distance, previous = (
                    active[keep], qa[:, keep], ta[:, keep], error[:, keep], jac[:, :, keep], distance2[keep],
                    distance[keep], None if previous is None else previous[keep])
            before, previous = previous, distance
            lam2 = self.damping**2 + self.far_damping**2 * distance2
            step = self._closed_form_step(jac, error, lam2)
            blocked = ((qa <= low) & (step < 0)) | ((qa >= high) & (step > 0))
            if blocked.any():
                step = self._closed_form_step(jac * ~blocked[:, None], error, lam2)
            largest = np.abs(step).max(0)
            step = step * np.minimum(1.0, self.max_step / np.maximum(largest, 1e-12))
            qa = np.clip(qa + step, low, high)
        return best_q

    def _group_inverse(self, group: _ChainGroup, target: np.ndarray, q: np.ndarray) -> np.ndarray:
        """:meth:`_leg_inverse` for a whole group: descend, then restart each stuck foot from the grid of poses
        (leg by leg, the ``K`` restarts of all its stuck feet side by side)."""
        q = self._group_descend(group, target, q, self.iterations)
        error = np.linalg.norm(self._group_forward(group, q, False)[0] - target, axis=0)  # M x Lg
        stuck = error > 10 * self.tolerance + 1e-4
        for leg in np.flatnonzero(stuck.any(0)):
            rows = np.flatnonzero(stuck[:, leg])
            single = group.select([leg])
            k, m = len(single.restarts), len(rows)
            trial_target = np.repeat(target[:, rows, leg:leg + 1], k, axis=1)  # 3 x (m K) x 1
            trial = np.tile(np.moveaxis(single.restarts, 0, 1), (1, m, 1))  # n x (m K) x 1
            trial = self._group_descend(single, trial_target, trial, 4 * self.iterations)
            trial_error = np.linalg.norm(self._group_forward(single, trial, False)[0] - trial_target, axis=0)
            best = trial_error.reshape(m, k).argmin(1)
            chosen = trial[:, :, 0].reshape(-1, m, k)[:, np.arange(m), best]  # n x m
            improved = trial_error.reshape(m, k)[np.arange(m), best] < error[rows, leg]
            q[:, rows[improved], leg] = chosen[:, improved]
        return q


