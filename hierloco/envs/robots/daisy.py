"""HEBI Daisy hexapod, built procedurally from its published physical facts.

Six legs at 30, -30, 90, -90, 150 and -150 deg around the body centre (FL, FR, ML, MR, RL, RR), each with a base
yaw joint (axis z), a shoulder pitch and an elbow pitch joint (positive lifts the link), two 0.325 m links and a
sphere foot. Total mass 19.34 kg: 2.39 kg per leg and a 5 kg chassis (the paper quotes 21 kg with electronics).
In the nominal stance the feet stand on a 0.55 m radius circle and the body is 0.21 m above them.
"""

from __future__ import annotations

import math

import mujoco

from hierloco.envs.robots.spec import Leg, RobotSpec

CHASSIS_MASS = 5.0  # kg
CHASSIS_RADIUS, CHASSIS_HALF_HEIGHT = 0.2, 0.04  # m, collision cylinder
LEG_ANGLES = {"FL": 30.0, "FR": -30.0, "ML": 90.0, "MR": -90.0, "RL": 150.0, "RR": -150.0}  # deg
MOUNT_RADIUS = {"FL": 0.2375, "FR": 0.2375, "ML": 0.1875, "MR": 0.1875, "RL": 0.2375, "RR": 0.2375}  # m
UPPER_LINK, LOWER_LINK = 0.325, 0.325  # m
BASE_MASS, UPPER_MASS, LOWER_MASS = 0.6, 1.2, 0.59  # kg, 2.39 kg per leg
FOOT_RADIUS = 0.02  # m
FOOT_FRICTION = 0.8
STANCE_RADIUS = 0.55  # m, feet circle in the nominal stance
BODY_ABOVE_FEET = 0.21  # m
BASE_RANGE = (-math.pi / 3, math.pi / 3)  # rad
SHOULDER_RANGE = (-math.pi / 2, math.pi / 2)  # rad
ELBOW_RANGE = (-2.8, 0.2)  # rad
TORQUE_LIMIT = (20.0, 38.0, 20.0)  # N m (base, shoulder, elbow)
KP = (80.0, 250.0, 150.0)  # N m / rad
DAMPING = 1.0  # N m s / rad
ARMATURE = 0.01  # kg m^2


def nominal_leg_pose(mount_radius: float) -> tuple[float, float, float]:
    """Joint angles (base, shoulder, elbow) in rad putting the foot on the stance circle, elbow up."""
    reach = STANCE_RADIUS - mount_radius
    distance = math.hypot(reach, BODY_ABOVE_FEET)
    # law of cosines for the shoulder-elbow-foot triangle
    inner = math.acos((UPPER_LINK**2 + distance**2 - LOWER_LINK**2) / (2 * UPPER_LINK * distance))
    knee = math.acos((UPPER_LINK**2 + LOWER_LINK**2 - distance**2) / (2 * UPPER_LINK * LOWER_LINK))
    shoulder = math.atan2(-BODY_ABOVE_FEET, reach) + inner
    return 0.0, shoulder, -(math.pi - knee)


def build_daisy_spec() -> mujoco.MjSpec:
    """A fresh :class:`mujoco.MjSpec` of Daisy (no floor, no free joint: :func:`compile_model` adds them)."""
    spec = mujoco.MjSpec()
    spec.modelname = "daisy"
    spec.compiler.degree = False
    body = spec.worldbody.add_body(name="base", pos=[0, 0, BODY_ABOVE_FEET + FOOT_RADIUS])
    body.add_geom(name="chassis", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[CHASSIS_RADIUS, CHASSIS_HALF_HEIGHT, 0],
                  mass=CHASSIS_MASS, rgba=[0.25, 0.25, 0.3, 1], contype=1, conaffinity=0)
    body.add_site(name="imu")
    for leg, angle in LEG_ANGLES.items():
        _add_leg(body, leg, math.radians(angle), MOUNT_RADIUS[leg])
    return spec


def _visual(body, **kwargs):
    body.add_geom(contype=0, conaffinity=0, rgba=[0.85, 0.1, 0.1, 1], **kwargs)


def _add_leg(base, leg: str, angle: float, radius: float) -> None:
    limited = mujoco.mjtLimited.mjLIMITED_TRUE
    mount = base.add_body(name=f"{leg}_base", pos=[radius * math.cos(angle), radius * math.sin(angle), 0],
                          quat=[math.cos(angle / 2), 0, 0, math.sin(angle / 2)])
    mount.add_joint(name=f"{leg}_base", axis=[0, 0, 1], range=BASE_RANGE, damping=DAMPING, armature=ARMATURE,
                    limited=limited)
    _visual(mount, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.04, 0.03, 0], mass=BASE_MASS)
    upper = mount.add_body(name=f"{leg}_upper")
    upper.add_joint(name=f"{leg}_shoulder", axis=[0, -1, 0], range=SHOULDER_RANGE, damping=DAMPING,
                    armature=ARMATURE, limited=limited)
    _visual(upper, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.025, 0, 0], mass=UPPER_MASS,
            fromto=[0, 0, 0, UPPER_LINK, 0, 0])
    lower = upper.add_body(name=f"{leg}_lower", pos=[UPPER_LINK, 0, 0])
    lower.add_joint(name=f"{leg}_elbow", axis=[0, -1, 0], range=ELBOW_RANGE, damping=DAMPING, armature=ARMATURE,
                    limited=limited)
    _visual(lower, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.018, 0, 0], mass=LOWER_MASS - 0.05,
            fromto=[0, 0, 0, LOWER_LINK, 0, 0])
    lower.add_geom(name=f"{leg}_foot", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[FOOT_RADIUS, 0, 0],
                   pos=[LOWER_LINK, 0, 0], mass=0.05, friction=[FOOT_FRICTION, 0.02, 0.01],
                   rgba=[0.1, 0.1, 0.1, 1], contype=1, conaffinity=0, condim=3)
    lower.add_site(name=f"{leg}_foot", pos=[LOWER_LINK, 0, 0], size=[FOOT_RADIUS * 1.25, 0, 0])


DAISY = RobotSpec(
    name="daisy",
    build_spec=build_daisy_spec,
    legs=tuple(Leg(leg, (f"{leg}_base", f"{leg}_shoulder", f"{leg}_elbow"), f"{leg}_foot") for leg in LEG_ANGLES),
    base_body="base",
    standing_pose=tuple(angle for leg in LEG_ANGLES for angle in nominal_leg_pose(MOUNT_RADIUS[leg])),
    standing_height=BODY_ABOVE_FEET + FOOT_RADIUS,
    gait_groups=(("FL", "MR", "RL"), ("FR", "ML", "RR")),
    gait_period=1.0,
    min_height=0.1,
    command_low=(-0.3, -0.3, -0.4),
    command_high=(0.3, 0.3, 0.4),
    rear_legs=("RL", "RR"),
    swing_height=0.08,
    kp=KP * 6,
    torque_limit=TORQUE_LIMIT * 6,
    description="HEBI Daisy hexapod, 19.34 kg (2.39 kg per leg + 5 kg chassis), tripod",
    source="builtin",
)

__all__ = ["DAISY", "build_daisy_spec", "nominal_leg_pose"]
