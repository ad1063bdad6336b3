"""The robot description: everything the rest of hierloco needs to know about a legged robot.

A :class:`RobotSpec` names a model builder (a function returning a :class:`mujoco.MjSpec`), the legs with their
joints (ordered from the body to the foot) and foot sites, the standing pose, the gait groups and the thresholds
that define a fall. :func:`compile_model` turns it into the :class:`mujoco.MjModel` every simulator in hierloco
uses, so that A1, Daisy and a user's own robot all look the same downstream:

- a floor and a free joint on the base body are added when the robot has none;
- every leg joint is driven by a MuJoCo position actuator (PD servo), in leg order, so ``ctrl[i]`` is the joint
  target of ``robot.joint_names[i]``; torque ``motor`` actuators are converted with the description's gains;
- each foot gets a touch sensor, each leg joint a (normally inactive) lock that holds it at its standing angle,
  which is how legs are disabled in the adverse setting;
- physics runs at ``PHYSICS_TIMESTEP`` and with solver warm-starting off, so that a state fully determines the
  future (chained batched rollouts and step-by-step simulation agree exactly).

Example:
    >>> from hierloco.envs.robots import get_robot, compile_model
    >>> model = compile_model(get_robot("a1"))
    >>> model.nu
    12
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable, Sequence

import mujoco
import numpy as np

PHYSICS_TIMESTEP = 0.002  # s
CONTROL_TIMESTEP = 0.01  # s (100 Hz low-level control)
PHYSICS_STEPS_PER_CONTROL = 5

FLOOR_NAME = "floor"
TOUCH_SENSOR_PREFIX = "touch_"
LOCK_PREFIX = "lock_"


@dataclass(frozen=True)
class Leg:
    """One leg: its name, its joints ordered from the body outwards, and the site at its foot."""

    name: str
    joints: tuple[str, ...]
    foot_site: str


@dataclass(frozen=True)
class RobotSpec:
    """A legged robot, described for hierloco.

    Args:
        name: registry name, e.g. ``"a1"``.
        build_spec: returns a fresh :class:`mujoco.MjSpec` of the robot (floor and free joint optional).
        legs: the legs, in the order their joints appear in every joint vector.
        base_body: name of the free-floating body whose frame is the robot's CoM frame.
        standing_pose: joint angles in rad, one per joint of ``joint_names``.
        standing_height: height of the base above the floor in the standing pose, in m.
        gait_groups: groups of leg names that are in stance together (trot pairs, tripods), in gait order.
        gait_period: duration of one gait cycle in s; a latent action holds a whole number of them.
        min_height: the robot has fallen when its base is lower than this, in m.
        command_low, command_high: the box of nominal CoM commands ``(vx, vy, yaw_rate)`` in m/s, m/s, rad/s,
            in the robot's local (yaw) frame.
        rear_legs: the legs disabled in the adverse setting.
        swing_height: foot lift of the expert gait, in m.
        max_roll, max_pitch: the robot has fallen when its roll or pitch exceeds these, in rad.
        kp: position gain per joint in N m / rad, used when the model drives its joints with torque motors
            (and for the actuators hierloco builds itself).
        torque_limit: actuator torque limit per joint in N m (``None`` keeps the model's own).
        joint_damping: damping per joint in N m s / rad added when the model has none (``None``: leave as is).
    """

    name: str
    build_spec: Callable[[], mujoco.MjSpec]
    legs: tuple[Leg, ...]
    base_body: str
    standing_pose: tuple[float, ...]
    standing_height: float
    gait_groups: tuple[tuple[str, ...], ...]
    gait_period: float
    min_height: float
    command_low: tuple[float, float, float]
    command_high: tuple[float, float, float]
    rear_legs: tuple[str, ...]
    swing_height: float = 0.06
    max_roll: float = 0.5
    max_pitch: float = 0.5
    kp: tuple[float, ...] | None = None
    torque_limit: tuple[float, ...] | None = None
    joint_damping: tuple[float, ...] | None = None
    description: str = field(default="", compare=False)

    def __post_init__(self):
        joints = self.joint_names
        if len(set(joints)) != len(joints):
            raise ValueError(f"robot {self.name!r}: a joint appears in two legs: {joints}")
        if len(self.standing_pose) != len(joints):
            raise ValueError(
                f"robot {self.name!r}: standing_pose has {len(self.standing_pose)} angles for {len(joints)} joints"
            )
        for name in ("kp", "torque_limit", "joint_damping"):
            value = getattr(self, name)
            if value is not None and len(value) != len(joints):
                raise ValueError(f"robot {self.name!r}: {name} has {len(value)} values for {len(joints)} joints")
        names = set(self.leg_names)
        for group in self.gait_groups:
            unknown = set(group) - names
            if unknown:
                raise ValueError(f"robot {self.name!r}: gait group {group} names unknown legs {sorted(unknown)}")
        if sorted(leg for group in self.gait_groups for leg in group) != sorted(names):
            raise ValueError(f"robot {self.name!r}: gait groups {self.gait_groups} must hold every leg exactly once")
        if set(self.rear_legs) - names:
            raise ValueError(f"robot {self.name!r}: rear_legs {self.rear_legs} are not legs of the robot")
        if not (self.gait_period > 0 and self.standing_height > self.min_height >= 0):
            raise ValueError(f"robot {self.name!r}: need gait_period > 0 and standing_height > min_height >= 0")
        if any(lo > hi for lo, hi in zip(self.command_low, self.command_high)):
            raise ValueError(f"robot {self.name!r}: command_low {self.command_low} exceeds command_high")

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
        """A copy with some fields changed (e.g. a different gait period)."""
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
                  obstacles: Sequence[Obstacle] = ()) -> mujoco.MjModel:
    """Build the simulation model of ``robot`` with the legs in ``disabled_legs`` locked at their standing angles,
    in a world with static ``obstacles`` (an arena).

    Returns a :class:`mujoco.MjModel` whose ``nu`` actuators are position servos on ``robot.joint_names`` in that
    order, with one touch sensor per foot (in leg order) and nothing else in ``sensordata``.
    """
    disabled = set(disabled_legs)
    robot.leg_joint_indices(sorted(disabled))  # validates the names
    spec = robot.build_spec()
    spec.compiler.degree = False
    spec.option.timestep = PHYSICS_TIMESTEP
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_WARMSTART

    base = spec.body(robot.base_body)
    if base is None:
        raise ValueError(f"robot {robot.name!r}: the model has no body named {robot.base_body!r}")
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in base.joints):
        if base.parent is not None and base.parent.name != "world":
            raise ValueError(f"robot {robot.name!r}: base body {robot.base_body!r} is not a child of the world")
        base.add_freejoint(name=f"{robot.base_body}_root")
    _ensure_floor(spec)
    for i, obstacle in enumerate(obstacles):
        spec.worldbody.add_geom(name=f"obstacle_{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=obstacle.half_size,
                                pos=[obstacle.x, obstacle.y, obstacle.half_size[2]],
                                quat=[np.cos(obstacle.yaw / 2), 0, 0, np.sin(obstacle.yaw / 2)],
                                rgba=[0.55, 0.45, 0.35, 1], contype=1, conaffinity=1)
    _set_actuators(spec, robot)
    _add_foot_sensors(spec, robot)
    _add_joint_locks(spec, robot, disabled)
    for sensor in list(spec.sensors):
        if not sensor.name.startswith(TOUCH_SENSOR_PREFIX):
            spec.delete(sensor)
    model = spec.compile()
    _check_model(model, robot)
    return model


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


def _set_actuators(spec: mujoco.MjSpec, robot: RobotSpec) -> None:
    """Replace the model's actuators by one position servo per leg joint, in ``robot.joint_names`` order."""
    existing = {}
    for act in list(spec.actuators):
        if act.trntype == mujoco.mjtTrn.mjTRN_JOINT and act.target in robot.joint_names:
            existing[act.target] = act
    found = {}
    for act in existing.values():
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
    for act in list(spec.actuators):
        spec.delete(act)

    for i, joint_name in enumerate(robot.joint_names):
        joint = spec.joint(joint_name)
        if joint is None:
            raise ValueError(f"robot {robot.name!r}: the model has no joint named {joint_name!r}")
        if joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            raise ValueError(f"robot {robot.name!r}: leg joint {joint_name!r} is not a hinge")
        kp, kv, limit = found.get(joint_name, (None, 0.0, None))
        if robot.kp is not None:
            kp = robot.kp[i]
        if kp is None:
            raise ValueError(
                f"robot {robot.name!r}: joint {joint_name!r} has no position servo; give RobotSpec.kp to convert it"
            )
        if robot.torque_limit is not None:
            limit = robot.torque_limit[i]
        if robot.joint_damping is not None:
            joint.damping = robot.joint_damping[i]
        act = spec.add_actuator(name=f"servo_{joint_name}", target=joint_name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=kp, kv=kv)
        lo, hi = joint.range if joint.limited != mujoco.mjtLimited.mjLIMITED_FALSE else (-np.pi, np.pi)
        if hi > lo:
            act.ctrlrange = [lo, hi]
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        if limit is not None:
            act.forcerange = [-limit, limit]
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE


def _add_foot_sensors(spec: mujoco.MjSpec, robot: RobotSpec) -> None:
    for leg in robot.legs:
        site = spec.site(leg.foot_site)
        if site is None:
            raise ValueError(f"robot {robot.name!r}: the model has no foot site {leg.foot_site!r} for leg {leg.name!r}")
        spec.add_sensor(
            name=f"{TOUCH_SENSOR_PREFIX}{leg.name}",
            type=mujoco.mjtSensor.mjSENS_TOUCH,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=leg.foot_site,
        )


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


START_YAW = np.pi / 2  # rad: every episode starts at the origin facing +y (SPEC 6)


def standing_qpos(model: mujoco.MjModel, robot: RobotSpec, x: float = 0.0, y: float = 0.0,
                  yaw: float = START_YAW) -> np.ndarray:
    """The full ``qpos`` of ``robot`` standing at ``(x, y)`` with heading ``yaw`` (rad)."""
    qpos = model.qpos0.copy()
    qpos[0:3] = (x, y, robot.standing_height)
    qpos[3:7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
    qpos[joint_qpos_indices(model, robot)] = robot.standing_pose
    return qpos
