"""The robot description: everything the rest of hierloco needs to know about a legged robot.

A :class:`RobotSpec` names a model builder (a function returning a :class:`mujoco.MjSpec`), the legs with their
joints (ordered from the body to the foot) and foot sites, the standing pose, the gait groups and the thresholds
that define a fall. :func:`compile_model` turns it into the :class:`mujoco.MjModel` every simulator in hierloco
uses, so that A1, Daisy and a user's own robot all look the same downstream:

- a floor and a free joint on the base body are added when the robot has none;
- every leg joint is driven by a MuJoCo position actuator (PD servo), in leg order, so ``ctrl[i]`` is the joint
  target of ``robot.joint_names[i]``; torque ``motor`` actuators are converted with the description's gains;
- each foot gets a touch sensor on a site of hierloco's own, centred on the foot's collision geom and a quarter
  larger than it (plus the contact margin), so that stance registers even when the model's own foot site is
  exactly the size of the foot (the contact point then lies on or just outside the site, and MuJoCo's touch
  sensor misses it);
- each leg joint gets a (normally inactive) lock that holds it at its standing angle, which is how legs are
  disabled in the adverse setting;
- physics runs at ``PHYSICS_TIMESTEP`` and with solver warm-starting off, so that a state fully determines the
  future (chained batched rollouts and step-by-step simulation agree exactly).

What can be derived need not be given: the standing height comes from forward kinematics of the standing pose
(:func:`derive_standing_height`), the gait period from the robot's size and gait (:func:`derive_gait_period`), the
foot lift from the hips' height (:func:`derive_swing_height`); the rules come from searching the expert
controller's parameters on seven robots (``docs/robots.md``).
:func:`robot_fingerprint` digests a description and its compiled model, for cache keys.

Example:
    >>> from hierloco.envs.robots import get_robot, compile_model
    >>> model = compile_model(get_robot("a1"))
    >>> model.nu
    12
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import json
import math
import numbers
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import mujoco
import numpy as np

from hierloco.io import brief

PHYSICS_TIMESTEP = 0.002  # s
CONTROL_TIMESTEP = 0.01  # s (100 Hz low-level control)
PHYSICS_STEPS_PER_CONTROL = 5
STEPS_PER_ACTION = 100  # control steps of one latent action (N in Li et al., RA-L 2021)
GRAVITY = 9.81  # m/s^2

FLOOR_NAME = "floor"
TOUCH_SENSOR_PREFIX = "touch_"
TOUCH_SITE_PREFIX = "hierloco_touch_"
TOUCH_SITE_SCALE = 1.25  # touch site radius / foot geom bounding radius
LOCK_PREFIX = "lock_"
MIN_LEGS = 3
MIN_SWING_STEPS = 2  # control steps per swing phase, at least
STATIC_STANCE_LEGS = 3  # a gait with at least this many legs in stance at every moment is statically stable
TROT_PERIOD_FACTOR = 0.6  # derived trot period: this times pi sqrt(h / g); twice that for statically stable gaits
SWING_HEIGHT_FRACTION = 0.15  # derived foot lift: this fraction of the hips' height above the floor

BUILTIN_SOURCE = "builtin"
PYTHON_SOURCE = "python"
YAML_SOURCE_PREFIX = "yaml:"
ENTRY_POINT_SOURCE_PREFIX = "entry_point:"
MODIFIED_MARK = " (modified: "


def missing_name_message(kind: str, name: str, candidates: Iterable[str]) -> str:
    """``"no joint named 'FR_hipp' (close: 'FR_hip')"``: a name that is not there, with the close ones (ignoring
    case), or the names there are."""
    candidates = sorted({c for c in candidates if c})
    lowered = {}
    for candidate in candidates:
        lowered.setdefault(candidate.lower(), candidate)
    close = [lowered[c] for c in difflib.get_close_matches(str(name).lower(), list(lowered), n=4, cutoff=0.5)]
    if close:
        hint = "close: " + ", ".join(repr(c) for c in close)
    elif candidates:
        hint = f"{kind}s: " + ", ".join(repr(c) for c in candidates[:12]) + (", ..." if len(candidates) > 12 else "")
    else:
        hint = f"there are no {kind}s"
    return f"no {kind} named {name!r} ({hint})"


def check_leg_count(where: str, legs: Sequence[str]) -> None:
    """Refuses fewer than ``MIN_LEGS`` legs, saying why."""
    if len(legs) < MIN_LEGS:
        raise ValueError(f"{where}: legs: has {len(legs)} legs {list(legs)}; hierloco's expert gaits (Raibert "
                         f"footsteps alternating between gait groups) need at least {MIN_LEGS} legs")


def is_number(value) -> bool:
    """A real number (int, float, NumPy scalar), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _finite(value) -> bool:
    return is_number(value) and math.isfinite(value)


@dataclass(frozen=True)
class Leg:
    """One leg: its name, its joints ordered from the body outwards, and the site at its foot."""

    name: str
    joints: tuple[str, ...]
    foot_site: str


@dataclass(frozen=True, kw_only=True)
class RobotSpec:
    """A legged robot, described for hierloco.

    Every check runs here, before any simulation: a bad description is a :class:`ValueError` naming the field
    (and the joint or leg).

    Args:
        name: registry name, e.g. ``"a1"``.
        build_spec: returns a fresh :class:`mujoco.MjSpec` of the robot (floor and free joint optional).
        legs: the legs (at least 3: hierloco's expert gaits alternate footholds between gait groups), in the order
            their joints appear in every joint vector.
        base_body: name of the free-floating body whose frame is the robot's CoM frame.
        standing_pose: joint angles in rad, one per joint of ``joint_names``.
        gait_groups: groups of leg names that are in stance together (trot pairs, tripods), in gait order; at
            least two groups, every leg in exactly one.
        command_low, command_high: the box of nominal CoM commands ``(vx, vy, yaw_rate)`` in m/s, m/s, rad/s,
            in the robot's local (yaw) frame.
        rear_legs: the legs disabled in the adverse setting.
        standing_height: height of the base above the floor in the standing pose, in m (default: derived,
            :func:`derive_standing_height`).
        gait_period: duration of one gait cycle in s; a latent action holds a whole number of them (default:
            derived from the robot's size and gait, :func:`derive_gait_period`).
        min_height: the robot has fallen when its base is lower than this, in m (default: half the standing
            height).
        swing_height: foot lift of the expert gait, in m (``None``: derived, :func:`derive_swing_height`).
        max_roll, max_pitch: the robot has fallen when its roll or pitch exceeds these, in rad.
        kp: position gain per joint in N m / rad, used when the model drives its joints with torque motors
            (and for the actuators hierloco builds itself).
        torque_limit: actuator torque limit per joint in N m (``None`` keeps the model's own).
        provisional_torque_joints: the leg joints whose ``torque_limit`` is provisional: neither the description
            nor the MJCF file gives them one, and the robot check
            (:func:`hierloco.envs.robots.check.robot_for_check`) set a starting value from the standing load for
            its search to find the smallest that walks (``docs/robots.md``). Empty for every robot loaded as
            described.
        joint_damping: damping per joint in N m s / rad (``None`` keeps the model's own).
        foot_friction: sliding friction of the feet's contacts (``None`` keeps the model's own).
        mass_scale: every body's mass and inertia times this (a payload, heavier parts than modelled).
        servo_latency: the servos act on each joint target this many s after it was sent (a multiple of the 2 ms
            physics step; the batched simulator, :class:`hierloco.envs.batched_sim.BatchedSimulator`).
        com_noise: standard deviations of the measured CoM state: position (m), yaw (rad), velocity (m/s), as a
            state estimator's noise (the latent-action env's observations, :mod:`hierloco.envs.latent_env`).
        description: a line for reports.
        source: where the description came from, for reports: ``"builtin"``, ``"python"``,
            ``"yaml:<path>"``, ``"entry_point:<name> = <module:object>"`` (see :attr:`reference`).

    Example:
        >>> from hierloco.envs.robots import A1
        >>> A1.num_joints, A1.leg_names
        (12, ('FR', 'FL', 'RR', 'RL'))
        >>> A1.replace(gait_period=0.5).source
        'builtin (modified: gait_period)'
    """

    name: str
    build_spec: Callable[[], mujoco.MjSpec]
    legs: tuple[Leg, ...]
    base_body: str
    standing_pose: tuple[float, ...]
    gait_groups: tuple[tuple[str, ...], ...]
    command_low: tuple[float, float, float]
    command_high: tuple[float, float, float]
    rear_legs: tuple[str, ...]
    standing_height: float | None = None
    gait_period: float | None = None
    min_height: float | None = None
    swing_height: float | None = 0.06
    max_roll: float = 0.5
    max_pitch: float = 0.5
    kp: tuple[float, ...] | None = None
    torque_limit: tuple[float, ...] | None = None
    joint_damping: tuple[float, ...] | None = None
    foot_friction: float | None = None
    mass_scale: float = 1.0
    servo_latency: float = 0.0
    com_noise: tuple[float, float, float] = (0.0, 0.0, 0.0)
    provisional_torque_joints: tuple[str, ...] = ()
    description: str = field(default="", compare=False)
    source: str = field(default=PYTHON_SOURCE, compare=False)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"robot name must be a non-empty string, got {self.name!r}")
        where = f"robot {self.name!r}"
        if not callable(self.build_spec):
            raise ValueError(f"{where}: build_spec must be a callable returning a mujoco.MjSpec")
        self._check_legs(where)
        joints = self.joint_names
        if len(self.standing_pose) != len(joints):
            raise ValueError(f"{where}: standing_pose has {len(self.standing_pose)} angles for {len(joints)} joints")
        for joint, angle in zip(joints, self.standing_pose):
            if not _finite(angle):
                raise ValueError(f"{where}: standing_pose of joint {joint!r} must be a finite number of rad, "
                                 f"got {angle!r}")
        for name in ("kp", "torque_limit", "joint_damping"):
            values = getattr(self, name)
            if values is None:
                continue
            if len(values) != len(joints):
                raise ValueError(f"{where}: {name} has {len(values)} values for {len(joints)} joints")
            for joint, value in zip(joints, values):
                if not (_finite(value) and value > 0):
                    raise ValueError(f"{where}: {name} of joint {joint!r} must be a finite positive number, "
                                     f"got {value!r}")
        object.__setattr__(self, "provisional_torque_joints", tuple(self.provisional_torque_joints))
        if self.provisional_torque_joints:
            unknown = [j for j in self.provisional_torque_joints if j not in joints]
            if unknown:
                raise ValueError(f"{where}: provisional_torque_joints: "
                                 f"{missing_name_message('joint', unknown[0], joints)}")
            if self.torque_limit is None:
                raise ValueError(f"{where}: provisional_torque_joints needs the provisional values in torque_limit")
        self._check_gait_groups(where)
        for name in ("command_low", "command_high"):
            values = getattr(self, name)
            if len(values) != 3 or not all(_finite(v) for v in values):
                raise ValueError(f"{where}: {name} must be 3 finite numbers (vx m/s, vy m/s, yaw_rate rad/s), "
                                 f"got {brief(values)}")
        if any(lo > hi for lo, hi in zip(self.command_low, self.command_high)):
            raise ValueError(f"{where}: command_low {self.command_low} exceeds command_high {self.command_high}")
        for name in ("max_roll", "max_pitch") + tuple(
                n for n in ("standing_height", "gait_period", "swing_height") if getattr(self, n) is not None):
            value = getattr(self, name)
            if not (_finite(value) and value > 0):
                raise ValueError(f"{where}: {name} must be a finite positive number, got {value!r}")
        if self.foot_friction is not None and not (_finite(self.foot_friction) and self.foot_friction > 0):
            raise ValueError(f"{where}: foot_friction must be a finite positive number, got {self.foot_friction!r}")
        if not (_finite(self.mass_scale) and self.mass_scale > 0):
            raise ValueError(f"{where}: mass_scale must be a finite positive number, got {self.mass_scale!r}")
        if not (_finite(self.servo_latency) and 0 <= self.servo_latency <= 0.5):
            raise ValueError(f"{where}: servo_latency must be a number of s in [0, 0.5], got {self.servo_latency!r}")
        if len(tuple(self.com_noise)) != 3 or not all(_finite(v) and v >= 0 for v in self.com_noise):
            raise ValueError(f"{where}: com_noise must be 3 numbers >= 0 (position m, yaw rad, velocity m/s), "
                             f"got {self.com_noise!r}")
        object.__setattr__(self, "com_noise", tuple(float(v) for v in self.com_noise))
        if self.min_height is not None and not (_finite(self.min_height) and self.min_height >= 0):
            raise ValueError(f"{where}: min_height must be a finite number >= 0, got {self.min_height!r}")
        # derive what was not given (one compiled model for both)
        if self.standing_height is None or self.gait_period is None or self.swing_height is None:
            height, hip_height = _standing_geometry(self)
            if self.standing_height is None:
                if not height > 0:
                    raise ValueError(f"{where}: cannot derive standing_height: in the standing pose the lowest foot "
                                     f"is {-height:.3f} m above the base; give standing_height")
                object.__setattr__(self, "standing_height", float(height))
            if self.gait_period is None:
                object.__setattr__(self, "gait_period", _period_for_hip_height(self, hip_height))
            if self.swing_height is None:
                if not hip_height > 0:
                    raise ValueError(f"{where}: cannot derive swing_height: the legs' first joints are not above "
                                     "the feet in the standing pose; give swing_height")
                object.__setattr__(self, "swing_height", _swing_for_hip_height(hip_height))
        if self.min_height is None:
            object.__setattr__(self, "min_height", float(self.standing_height) / 2)
        if not self.standing_height > self.min_height:
            raise ValueError(f"{where}: need standing_height ({self.standing_height}) > min_height "
                             f"({self.min_height})")

    def _check_legs(self, where: str) -> None:
        names = [leg.name for leg in self.legs]
        check_leg_count(where, names)
        if len(set(names)) != len(names):
            raise ValueError(f"{where}: two legs share a name: {names}")
        for leg in self.legs:
            if not leg.joints:
                raise ValueError(f"{where}: leg {leg.name!r} has no joints")
        joints = self.joint_names
        if len(set(joints)) != len(joints):
            repeated = sorted({j for j in joints if joints.count(j) > 1})
            raise ValueError(f"{where}: joints {repeated} appear twice in legs")

    def _check_gait_groups(self, where: str) -> None:
        names = self.leg_names
        if len(self.gait_groups) < 2 or any(len(group) == 0 for group in self.gait_groups):
            raise ValueError(f"{where}: gait_groups must be at least two non-empty groups of legs, "
                             f"got {self.gait_groups}")
        for group in self.gait_groups:
            for leg in group:
                if leg not in names:
                    raise ValueError(f"{where}: gait_groups: group {list(group)} names an unknown leg: "
                                     f"{missing_name_message('leg', leg, names)}")
        listed = [leg for group in self.gait_groups for leg in group]
        if sorted(listed) != sorted(names):
            missing = sorted(set(names) - set(listed))
            twice = sorted({leg for leg in listed if listed.count(leg) > 1})
            raise ValueError(f"{where}: gait_groups {self.gait_groups} must hold every leg exactly once "
                             f"(missing {missing}, twice {twice})")
        for leg in self.rear_legs:
            if leg not in names:
                raise ValueError(f"{where}: rear_legs {list(self.rear_legs)}: {missing_name_message('leg', leg, names)}")

    @property
    def leg_names(self) -> tuple[str, ...]:
        return tuple(leg.name for leg in self.legs)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """All leg joints, leg by leg: the order of every joint vector (targets, positions, actions)."""
        return tuple(joint for leg in self.legs for joint in leg.joints)

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def reference(self) -> str:
        """The string :func:`hierloco.envs.robots.get_robot` turns back into this robot in any process: the YAML
        file's absolute path for a robot loaded from YAML (and not modified since), else the registry name."""
        if self.source.startswith(YAML_SOURCE_PREFIX) and MODIFIED_MARK not in self.source:
            return self.source[len(YAML_SOURCE_PREFIX):]
        return self.name

    def leg_joint_indices(self, legs: Sequence[str]) -> np.ndarray:
        """Indices into the joint vector of the joints of ``legs``."""
        unknown = [leg for leg in legs if leg not in self.leg_names]
        if unknown:
            raise ValueError(f"robot {self.name!r} has no legs {unknown}; its legs are {list(self.leg_names)}")
        indices, start = [], 0
        for leg in self.legs:
            if leg.name in legs:
                indices.extend(range(start, start + len(leg.joints)))
            start += len(leg.joints)
        return np.asarray(indices, dtype=np.int64)

    def replace(self, **changes) -> "RobotSpec":
        """A copy with some fields changed (e.g. a different gait period); its :attr:`source` says so.

        Derived values are kept; pass ``standing_height=None`` or ``gait_period=None`` to derive them again.
        """
        if "source" not in changes:
            changed = sorted(changes)
            base, _, previous = self.source.partition(MODIFIED_MARK)
            if previous:
                changed = sorted(set(changed) | set(previous.rstrip(")").split(", ")))
            changes["source"] = f"{base}{MODIFIED_MARK}{', '.join(changed)})"
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Obstacle:
    """A box standing on the floor: centre ``(x, y)`` in m, half-sizes ``(hx, hy, hz)`` in m, heading ``yaw`` in
    rad."""

    x: float
    y: float
    half_size: tuple[float, float, float]
    yaw: float = 0.0


def compile_model(robot: RobotSpec, disabled_legs: Sequence[str] = (),
                  obstacles: Sequence[Obstacle] = (), limp_legs: Sequence[str] = (), terrain=None) -> mujoco.MjModel:
    """Build the simulation model of ``robot`` with the legs in ``disabled_legs`` locked at their standing angles
    and those in ``limp_legs`` unpowered (their servos exert no torque; the joints keep their damping), in a world
    with static ``obstacles`` (an arena) on ``terrain`` (a built :class:`hierloco.envs.terrain.Terrain`, from
    :func:`hierloco.envs.terrain.make_terrain`; ``None``: the floor plane alone). With ``robot.foot_friction`` the feet's contacts have that
    friction coefficient (the foot geoms take priority over what they touch).

    Returns a :class:`mujoco.MjModel` whose ``nu`` actuators are position servos on ``robot.joint_names`` in that
    order, with one touch sensor per foot (in leg order, on the sites ``hierloco_touch_<leg>``) and nothing else
    in ``sensordata``.
    """
    disabled = set(disabled_legs)
    robot.leg_joint_indices(sorted(disabled))  # validates the names
    limp = robot.leg_joint_indices(tuple(limp_legs))
    if disabled & set(limp_legs):
        raise ValueError(f"robot {robot.name!r}: legs {sorted(disabled & set(limp_legs))} are both locked and limp")
    spec = robot.build_spec()
    spec.compiler.degree = False
    spec.option.timestep = PHYSICS_TIMESTEP
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_WARMSTART

    base = spec.body(robot.base_body)
    if base is None:
        raise ValueError(f"robot {robot.name!r}: base_body: "
                         f"{missing_name_message('body', robot.base_body, [b.name for b in spec.bodies])}")
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in base.joints):
        if base.parent is not None and base.parent.name != "world":
            raise ValueError(f"robot {robot.name!r}: base body {robot.base_body!r} is not a child of the world")
        base.add_freejoint(name=f"{robot.base_body}_root")
    _ensure_floor(spec)
    if terrain is not None:  # the ground (docs/terrain.md)
        terrain.add_to(spec)
        obstacles = terrain.place_obstacles(obstacles)
    for i, obstacle in enumerate(obstacles):
        spec.worldbody.add_geom(name=f"obstacle_{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=obstacle.half_size,
                                pos=[obstacle.x, obstacle.y, obstacle.half_size[2]],
                                quat=[np.cos(obstacle.yaw / 2), 0, 0, np.sin(obstacle.yaw / 2)],
                                rgba=[0.55, 0.45, 0.35, 1], contype=1, conaffinity=1)
    _set_actuators(spec, robot)
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    _add_foot_sensors(spec, robot)
    _add_joint_locks(spec, robot, disabled)
    model = spec.compile()
    _check_model(model, robot)
    if robot.foot_friction is not None:
        feet = foot_geoms(model, robot)
        model.geom_friction[feet, 0] = robot.foot_friction
        model.geom_priority[feet] = 1  # the foot's friction is the contact's, whatever it stands on
    if robot.mass_scale != 1.0:
        model.body_mass[1:] *= robot.mass_scale  # body 0 is the world
        model.body_inertia[1:] *= robot.mass_scale
    if len(limp):
        model.actuator_gainprm[limp, 0] = 0.0  # actuators are in joint order: no stiffness, no damping, no torque
        model.actuator_biasprm[limp, :3] = 0.0
    return model


def foot_geoms(model: mujoco.MjModel, robot: RobotSpec) -> np.ndarray:
    """``L`` ids of the foot geoms, in leg order: per leg, of the colliding geoms (``contype`` or ``conaffinity``
    set) on the leg (the subtree of the body of its first joint), the one nearest to the foot site in the
    model's reference configuration."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    colliding = np.flatnonzero((model.geom_contype != 0) | (model.geom_conaffinity != 0))
    ids = []
    for leg in robot.legs:
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, leg.foot_site)
        top = model.jnt_bodyid[model.joint(leg.joints[0]).id]
        on_leg = [g for g in colliding if _in_subtree(model, model.geom_bodyid[g], top)]
        if not on_leg:
            raise ValueError(f"robot {robot.name!r}: leg {leg.name!r} has no colliding geom (contype or "
                             "conaffinity set) to stand on")
        distance = np.linalg.norm(data.geom_xpos[on_leg] - data.site_xpos[site], axis=1)
        ids.append(on_leg[int(np.argmin(distance))])
    return np.asarray(ids, dtype=np.int64)


def _in_subtree(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body != root and body != 0:
        body = model.body_parentid[body]
    return body == root


def _ensure_floor(spec: mujoco.MjSpec) -> None:
    has_plane = any(g.type == mujoco.mjtGeom.mjGEOM_PLANE for g in spec.worldbody.geoms)
    if not has_plane:
        # a 0.5 m checker floor, so that motion shows in renderings
        spec.add_texture(name="floor_grid", type=mujoco.mjtTexture.mjTEXTURE_2D,
                         builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.45, 0.5, 0.55], rgb2=[0.35, 0.4, 0.45],
                         width=256, height=256)
        material = spec.add_material(name="floor_grid", texrepeat=[1, 1], texuniform=True)
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor_grid"
        spec.worldbody.add_geom(
            name=FLOOR_NAME,
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0, 0, 0.05],
            friction=[1.0, 0.005, 0.0001],
            material="floor_grid",
            contype=1,
            conaffinity=1,
        )
    if not spec.worldbody.lights:
        spec.worldbody.add_light(pos=[0, 0, 4], dir=[0, 0, -1], diffuse=[0.8, 0.8, 0.8])


def file_actuators(spec: mujoco.MjSpec, joint_names: Iterable[str]) -> dict[str, tuple[float | None, float,
                                                                                       float | None]]:
    """What the MJCF file's own actuators give each joint of ``joint_names`` that one drives: joint -> ``(kp, kv,
    torque limit)``, ``kp`` (N m / rad) and ``kv`` (N m s / rad) those of a position servo (``None`` and 0 for a
    torque motor, which needs the description's ``kp``), the limit in N m from the actuator's force range (or a
    motor's control range) times its gear, ``None`` when the file sets none. A joint no actuator drives is absent."""
    wanted = set(joint_names)
    found = {}
    for act in spec.actuators:
        if act.trntype != mujoco.mjtTrn.mjTRN_JOINT or act.target not in wanted:
            continue
        # a position servo has gain kp and bias (0, -kp, -kv); anything else (motor) needs the description's kp
        is_servo = act.gaintype == mujoco.mjtGain.mjGAIN_FIXED and act.biastype == mujoco.mjtBias.mjBIAS_AFFINE
        is_servo = is_servo and act.biasprm[1] == -act.gainprm[0] and act.gainprm[0] > 0
        limit = None
        if act.forcelimited == mujoco.mjtLimited.mjLIMITED_TRUE or act.forcerange[1] > act.forcerange[0]:
            limit = float(act.forcerange[1]) * float(act.gear[0])
        elif not is_servo and act.ctrlrange[1] > act.ctrlrange[0]:
            limit = float(act.ctrlrange[1]) * float(act.gear[0])  # a motor's ctrl is its torque
        found[act.target] = (float(act.gainprm[0]) if is_servo else None, float(-act.biasprm[2]) if is_servo else 0.0,
                             limit)
    return found


def actuation_problem(spec: mujoco.MjSpec, joint_names: Sequence[str], *, kp_given: bool,
                      torque_limit_given: bool) -> str | None:
    """Why the joints ``joint_names`` of the MJCF ``spec`` cannot become position servos as described, naming the
    robot description keys that would fix it, or ``None``: a joint with neither a position servo in the file nor
    ``kp`` given has no gain; one whose actuator sets no torque range (or that no actuator drives) and no
    ``torque_limit`` given would get a servo of unlimited torque, which no motor has (``docs/robots.md``); the
    message then says that the robot check proposes one (:func:`hierloco.envs.robots.check.robot_for_check`)."""
    found = file_actuators(spec, joint_names)
    none = (None, 0.0, None)
    no_gain = set() if kp_given else {j for j in joint_names if found.get(j, none)[0] is None}
    no_limit = set() if torque_limit_given else {j for j in joint_names if found.get(j, none)[2] is None}
    if not no_gain and not no_limit:
        return None
    names = [j for j in joint_names if j in no_gain | no_limit]
    unactuated = sum(j not in found for j in names)
    listed = ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
    if unactuated:
        listed += "; no actuator in the file drives " + ("them" if unactuated == len(names)
                                                         else f"{unactuated} of them")
    lacks = " and ".join(what for what, short in (("no position servo", no_gain), ("no torque limit", no_limit))
                         if short)
    keys = " and ".join(key for key, short in (("kp (N m / rad)", no_gain),
                                               ("torque_limit (N m, the motors' peak torque)", no_limit)) if short)
    proposes = (f"; {'once kp is given, ' if no_gain else ''}hierloco-robot-check proposes a torque_limit for this "
                "file (the smallest peak torque its gait needs, to check against the motors)" if no_limit else "")
    return (f"{len(names)} of its {len(joint_names)} leg joints ({listed}) have {lacks}; give {keys} in the robot "
            "description (one number, one leg's values, one per joint, or a mapping leg -> values): hierloco never "
            f"makes a servo without a gain or a torque limit{proposes}")


def _set_actuators(spec: mujoco.MjSpec, robot: RobotSpec) -> None:
    """Replace the model's actuators by one position servo per leg joint, in ``robot.joint_names`` order, each with
    a gain and a torque limit (from the description, else from the file's actuator; a joint lacking either is
    refused: :func:`actuation_problem`)."""
    problem = actuation_problem(spec, robot.joint_names, kp_given=robot.kp is not None,
                                torque_limit_given=robot.torque_limit is not None)
    if problem is not None:
        raise ValueError(f"robot {robot.name!r}: {problem}")
    found = file_actuators(spec, robot.joint_names)
    for act in list(spec.actuators):
        spec.delete(act)

    for i, joint_name in enumerate(robot.joint_names):
        joint = spec.joint(joint_name)
        if joint is None:
            raise ValueError(f"robot {robot.name!r}: legs: "
                             f"{missing_name_message('joint', joint_name, [j.name for j in spec.joints])}")
        if joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            raise ValueError(f"robot {robot.name!r}: leg joint {joint_name!r} is not a hinge")
        kp, kv, limit = found.get(joint_name, (None, 0.0, None))
        if robot.kp is not None:
            kp = robot.kp[i]
        if robot.torque_limit is not None:
            limit = robot.torque_limit[i]
        if robot.joint_damping is not None:
            joint.damping = [robot.joint_damping[i], 0.0, 0.0]  # (linear, higher-order terms) in MuJoCo 3.x
        act = spec.add_actuator(name=f"servo_{joint_name}", target=joint_name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=kp, kv=kv)
        lo, hi = joint.range if joint.limited != mujoco.mjtLimited.mjLIMITED_FALSE else (-np.pi, np.pi)
        if hi > lo:
            act.ctrlrange = [lo, hi]
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-limit, limit]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE


def _add_foot_sensors(spec: mujoco.MjSpec, robot: RobotSpec) -> None:
    """One touch sensor per foot, on a site of its own around the foot geom (see the module docstring)."""
    site_names = [s.name for s in spec.sites]
    for leg in robot.legs:
        if spec.site(leg.foot_site) is None:
            raise ValueError(f"robot {robot.name!r}: foot site of leg {leg.name!r}: "
                             f"{missing_name_message('site', leg.foot_site, site_names)}")
    probe = spec.compile()
    margin = float(probe.geom_margin.max(initial=0.0))  # a contact forms up to this far outside the foot
    for leg, geom in zip(robot.legs, foot_geoms(probe, robot)):
        body_id = probe.geom_bodyid[geom]
        body = spec.body(probe.body(body_id).name) if probe.body(body_id).name else spec.bodies[body_id]
        site = f"{TOUCH_SITE_PREFIX}{leg.name}"
        body.add_site(name=site, pos=probe.geom_pos[geom], size=[TOUCH_SITE_SCALE * probe.geom_rbound[geom] + margin,
                                                                  0, 0],
                      group=5, rgba=[0, 0, 0, 0])
        spec.add_sensor(name=f"{TOUCH_SENSOR_PREFIX}{leg.name}", type=mujoco.mjtSensor.mjSENS_TOUCH,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)


def _add_joint_locks(spec: mujoco.MjSpec, robot: RobotSpec, disabled: set[str]) -> None:
    angles = dict(zip(robot.joint_names, robot.standing_pose))
    for leg in robot.legs:
        for joint_name in leg.joints:
            data = np.zeros(mujoco.mjNEQDATA)
            data[0] = angles[joint_name]
            spec.add_equality(
                name=f"{LOCK_PREFIX}{joint_name}",
                type=mujoco.mjtEq.mjEQ_JOINT,
                objtype=mujoco.mjtObj.mjOBJ_JOINT,
                name1=joint_name,
                data=data,
                active=leg.name in disabled,
            )


def _check_model(model: mujoco.MjModel, robot: RobotSpec) -> None:
    if model.nu != robot.num_joints:
        raise ValueError(f"robot {robot.name!r}: compiled {model.nu} actuators for {robot.num_joints} joints")
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1 or model.jnt_qposadr[free[0]] != 0:
        raise ValueError(f"robot {robot.name!r}: expected exactly one free joint, first in qpos")


def joint_qpos_indices(model: mujoco.MjModel, robot: RobotSpec) -> np.ndarray:
    """Indices into ``qpos`` of ``robot.joint_names``."""
    return np.array([model.jnt_qposadr[model.joint(name).id] for name in robot.joint_names], dtype=np.int64)


def joint_qvel_indices(model: mujoco.MjModel, robot: RobotSpec) -> np.ndarray:
    """Indices into ``qvel`` of ``robot.joint_names``."""
    return np.array([model.jnt_dofadr[model.joint(name).id] for name in robot.joint_names], dtype=np.int64)


START_YAW = np.pi / 2  # rad: every episode starts at the origin facing +y


def standing_qpos(model: mujoco.MjModel, robot: RobotSpec, x: float = 0.0, y: float = 0.0,
                  yaw: float = START_YAW) -> np.ndarray:
    """The full ``qpos`` of ``robot`` standing at ``(x, y)`` with heading ``yaw`` (rad)."""
    qpos = model.qpos0.copy()
    qpos[0:3] = (x, y, robot.standing_height)
    qpos[3:7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
    qpos[joint_qpos_indices(model, robot)] = robot.standing_pose
    return qpos


# ---------------------------------------------------------------------------------------------------- derived values
def _geom_bottom(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> float:
    """World height in m of the lowest point of ``geom`` (exact for primitives, its bounding box otherwise)."""
    z = float(data.geom_xpos[geom][2])
    up = data.geom_xmat[geom].reshape(3, 3)[2]  # world z component of each geom axis
    size = model.geom_size[geom]
    kind = model.geom_type[geom]
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return z - size[0]
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return z - abs(up[2]) * size[1] - size[0]
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return z - abs(up[2]) * size[1] - size[0] * math.sqrt(max(0.0, 1.0 - up[2] ** 2))
    if kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        return z - float(np.linalg.norm(up * size))
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return z - float(np.abs(up) @ size)
    centre, half = model.geom_aabb[geom][:3], model.geom_aabb[geom][3:]
    return z + float(up @ centre) - float(np.abs(up) @ half)


def _standing_geometry(robot: RobotSpec) -> tuple[float, float]:
    """In the standing pose with the base level: the base's height and the mean height of the legs' first joints
    above the bottom of the lowest foot geom, in m."""
    model = compile_model(robot)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    data.qpos[0:7] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    data.qpos[joint_qpos_indices(model, robot)] = robot.standing_pose
    mujoco.mj_kinematics(model, data)
    floor = min(_geom_bottom(model, data, g) for g in foot_geoms(model, robot))
    base = float(data.xpos[model.body(robot.base_body).id][2])
    hips = [float(data.xanchor[model.joint(leg.joints[0]).id][2]) for leg in robot.legs]
    return float(base - floor), float(np.mean(hips) - floor)


def derive_standing_height(robot: RobotSpec) -> float:
    """The base height in m that puts the feet on the floor: in the standing pose with the base level, how far the
    bottom of the lowest foot geom lies below the base.

    Example:
        >>> from hierloco.envs.robots import A1
        >>> round(derive_standing_height(A1), 4)  # 2 x 0.2 m cos(0.9) + 0.02 m foot radius (A1 states 0.27 m)
        0.2686
    """
    return _standing_geometry(robot)[0]


def admissible_gait_periods(num_groups: int, steps_per_action: int = STEPS_PER_ACTION) -> tuple[float, ...]:
    """Gait periods in s that the expert gaits can use: a whole number P of control steps that divides
    ``steps_per_action`` (an action holds whole gait cycles) and gives each of the ``num_groups`` groups a swing
    phase of ``P // num_groups >= MIN_SWING_STEPS`` whole steps. When some periods split exactly into the swing
    phases (two, four or five groups in 100 steps), only those; otherwise (a wave gait: three or six groups) the
    periods whose last ``P mod num_groups`` steps have every foot on the ground
    (:class:`hierloco.components.experts.RaibertController`).

    Example:
        >>> admissible_gait_periods(2)
        (0.04, 0.1, 0.2, 0.5, 1.0)
        >>> admissible_gait_periods(6)  # a hexapod's wave gait: 3, 4, 8 or 16 steps per swing
        (0.2, 0.25, 0.5, 1.0)
    """
    divisors = [p for p in range(1, int(steps_per_action) + 1)
                if steps_per_action % p == 0 and p // num_groups >= MIN_SWING_STEPS]
    exact = [p for p in divisors if p % num_groups == 0]
    return tuple(round(p * CONTROL_TIMESTEP, 10) for p in (exact or divisors))


def stance_legs(robot: RobotSpec) -> int:
    """The fewest legs in stance at any moment of the robot's gait: all legs but the largest gait group (2 for a
    trot, 3 for a tripod, 5 for a hexapod's wave gait)."""
    return len(robot.legs) - max(len(group) for group in robot.gait_groups)


def _period_for_hip_height(robot: RobotSpec, hip_height: float, steps_per_action: int = STEPS_PER_ACTION) -> float:
    periods = admissible_gait_periods(len(robot.gait_groups), steps_per_action)
    if not periods:
        raise ValueError(f"robot {robot.name!r}: no gait period splits {steps_per_action} control steps into whole "
                         f"cycles of {len(robot.gait_groups)} swing phases; give gait_period")
    if not hip_height > 0:
        raise ValueError(f"robot {robot.name!r}: cannot derive gait_period: the legs' first joints are not above the "
                         "feet in the standing pose; give gait_period")
    target = TROT_PERIOD_FACTOR * math.pi * math.sqrt(hip_height / GRAVITY)
    if stance_legs(robot) >= STATIC_STANCE_LEGS:
        target *= 2
    return min(periods, key=lambda period: abs(math.log(period / target)))


def derive_gait_period(robot: RobotSpec, steps_per_action: int = STEPS_PER_ACTION) -> float:
    """A gait period in s suited to the robot's size and gait.

    The rule, from searching the expert controller's parameters (``hierloco-robot-check``) on seven robots
    (``docs/robots.md``): ``T = 0.6 pi sqrt(h / g)`` for a gait that balances on two legs (a trot), twice that for
    a statically stable one (at least ``STATIC_STANCE_LEGS`` legs in stance at every moment: a tripod, a wave
    gait), ``h`` the mean height of the legs' first joints above the floor in the standing pose (gait times scale
    with ``sqrt(h / g)`` at equal Froude number), rounded to the nearest (in ratio) of
    :func:`admissible_gait_periods`. Trotting quadrupeds with hips lower than 0.28 m get 0.2 s, taller ones 0.5 s
    (1 s only above 1.4 m); hexapods with hips from 0.07 to 0.35 m get 0.5 s.

    Example:
        >>> from hierloco.envs.robots import A1, DAISY
        >>> derive_gait_period(A1), derive_gait_period(DAISY)  # A1 is tuned at 0.2 s, Daisy at 1 s
        (0.2, 0.5)
    """
    return _period_for_hip_height(robot, _standing_geometry(robot)[1], steps_per_action)


def _swing_for_hip_height(hip_height: float) -> float:
    return round(SWING_HEIGHT_FRACTION * hip_height, 3)


def derive_swing_height(robot: RobotSpec) -> float:
    """The foot lift in m: ``SWING_HEIGHT_FRACTION`` of the hips' height above the floor in the standing pose,
    rounded to the mm (``docs/robots.md``).

    Example:
        >>> from hierloco.envs.robots import A1
        >>> derive_swing_height(A1)  # A1 is tuned at 0.06 m
        0.04
    """
    return _swing_for_hip_height(_standing_geometry(robot)[1])


# ---------------------------------------------------------------------------------------------------- fingerprint
FINGERPRINT_VERSION = b"hierloco robot fingerprint 1"
_NOT_FINGERPRINTED = ("build_spec", "source")
# fields added after fingerprint 1: fingerprinted only when they differ from their default, so that every robot
# described before keeps its fingerprint (and its cached runs)
_FINGERPRINTED_WHEN_SET = {"mass_scale": 1.0, "servo_latency": 0.0, "com_noise": (0.0, 0.0, 0.0),
                           "provisional_torque_joints": ()}


def robot_fingerprint(robot: RobotSpec) -> str:
    """A hex sha256 digest of the robot: its compiled model (the MJB bytes of :func:`compile_model`) and every
    field of its description but the model builder and :attr:`RobotSpec.source`. Two descriptions with the same
    fingerprint simulate the same robot the same way; a changed gain, gait period or MJCF file changes it, whatever
    the name. Deterministic across processes; computed once per :class:`RobotSpec` instance.

    Example:
        >>> from hierloco.envs.robots import A1
        >>> robot_fingerprint(A1) == robot_fingerprint(A1.replace(kp=(120.0,) * 12))
        False
    """
    cached = robot.__dict__.get("_fingerprint")
    if cached is not None:
        return cached
    model = compile_model(robot)
    mjb = np.empty(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, mjb)
    fields = {f.name: getattr(robot, f.name) for f in dataclasses.fields(robot) if f.name not in _NOT_FINGERPRINTED
              and not (f.name in _FINGERPRINTED_WHEN_SET and getattr(robot, f.name) == _FINGERPRINTED_WHEN_SET[f.name])}
    fields["legs"] = [dataclasses.asdict(leg) for leg in robot.legs]
    text = json.dumps(fields, sort_keys=True, default=float).encode()
    digest = hashlib.sha256(FINGERPRINT_VERSION + b"\0" + text + b"\0" + mjb.tobytes()).hexdigest()
    object.__setattr__(robot, "_fingerprint", digest)
    return digest
