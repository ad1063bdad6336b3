"""Unitree A1 quadruped, built procedurally from its published physical facts.

Primitive geoms only: a box trunk, capsule links and sphere feet. Only the trunk and the feet collide (with the
floor); the links carry mass and inertia. Legs are ordered FR, FL, RR, RL; each has an abduction joint (axis x),
a thigh joint and a knee joint (axis y).
"""

from __future__ import annotations

import mujoco

from hierloco.envs.robots.spec import Leg, RobotSpec

TRUNK_MASS = 4.713  # kg
TRUNK_HALF_SIZE = (0.125, 0.04, 0.057)  # m, collision box
TRUNK_INERTIA = (0.0158, 0.0378, 0.0457)  # kg m^2, diagonal (A1 URDF)
HIP_OFFSET = (0.183, 0.047)  # m, abduction joint from the trunk centre
THIGH_OFFSET = 0.08505  # m, thigh joint further out in y
THIGH_LENGTH = 0.2  # m
CALF_LENGTH = 0.2  # m
HIP_MASS, THIGH_MASS, CALF_MASS = 0.696, 1.013, 0.226  # kg (calf includes the foot)
FOOT_MASS = 0.06  # kg, part of CALF_MASS
FOOT_RADIUS = 0.02  # m
FOOT_FRICTION = 0.8
ABDUCTION_RANGE = (-0.8029, 0.8029)  # rad
THIGH_RANGE = (-1.0472, 4.1888)  # rad
KNEE_RANGE = (-2.6965, -0.9163)  # rad
ABDUCTION_DAMPING, LEG_DAMPING = 1.0, 2.0  # N m s / rad
ARMATURE = 0.01  # kg m^2
KP = 100.0  # N m / rad
TORQUE_LIMIT = 33.5  # N m
STANDING_LEG_POSE = (0.0, 0.9, -1.8)  # rad
STANDING_HEIGHT = 0.27  # m, trunk above the floor

LEGS = {"FR": (1, -1), "FL": (1, 1), "RR": (-1, -1), "RL": (-1, 1)}  # (front/rear, left/right) signs


def build_a1_spec() -> mujoco.MjSpec:
    """A fresh :class:`mujoco.MjSpec` of the A1 (no floor, no free joint: :func:`compile_model` adds them)."""
    spec = mujoco.MjSpec()
    spec.modelname = "a1"
    spec.compiler.degree = False
    trunk = spec.worldbody.add_body(name="trunk", pos=[0, 0, STANDING_HEIGHT])
    trunk.explicitinertial = True
    trunk.mass = TRUNK_MASS
    trunk.inertia = TRUNK_INERTIA
    trunk.add_geom(name="trunk", type=mujoco.mjtGeom.mjGEOM_BOX, size=TRUNK_HALF_SIZE, mass=0.0,
                   rgba=[0.2, 0.2, 0.25, 1], contype=1, conaffinity=0)
    trunk.add_site(name="imu", pos=[0, 0, 0])
    for leg, (fore, side) in LEGS.items():
        _add_leg(trunk, leg, fore, side)
    return spec


def _visual(body, **kwargs):
    body.add_geom(contype=0, conaffinity=0, rgba=[0.8, 0.4, 0.1, 1], **kwargs)


def _add_leg(trunk, leg: str, fore: int, side: int) -> None:
    hip = trunk.add_body(name=f"{leg}_hip", pos=[fore * HIP_OFFSET[0], side * HIP_OFFSET[1], 0])
    hip.add_joint(name=f"{leg}_abduction", axis=[1, 0, 0], range=ABDUCTION_RANGE, damping=ABDUCTION_DAMPING,
                  armature=ARMATURE, limited=mujoco.mjtLimited.mjLIMITED_TRUE)
    _visual(hip, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.04, 0.04, 0], mass=HIP_MASS,
            fromto=[0, 0, 0, 0, side * THIGH_OFFSET, 0])
    thigh = hip.add_body(name=f"{leg}_thigh", pos=[0, side * THIGH_OFFSET, 0])
    thigh.add_joint(name=f"{leg}_thigh", axis=[0, 1, 0], range=THIGH_RANGE, damping=LEG_DAMPING,
                    armature=ARMATURE, limited=mujoco.mjtLimited.mjLIMITED_TRUE)
    _visual(thigh, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.02, 0, 0], mass=THIGH_MASS,
            fromto=[0, 0, 0, 0, 0, -THIGH_LENGTH])
    calf = thigh.add_body(name=f"{leg}_calf", pos=[0, 0, -THIGH_LENGTH])
    calf.add_joint(name=f"{leg}_knee", axis=[0, 1, 0], range=KNEE_RANGE, damping=LEG_DAMPING,
                   armature=ARMATURE, limited=mujoco.mjtLimited.mjLIMITED_TRUE)
    _visual(calf, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.013, 0, 0], mass=CALF_MASS - FOOT_MASS,
            fromto=[0, 0, 0, 0, 0, -CALF_LENGTH])
    calf.add_geom(name=f"{leg}_foot", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[FOOT_RADIUS, 0, 0],
                  pos=[0, 0, -CALF_LENGTH], mass=FOOT_MASS, friction=[FOOT_FRICTION, 0.02, 0.01],
                  rgba=[0.1, 0.1, 0.1, 1], contype=1, conaffinity=0, condim=3)
    calf.add_site(name=f"{leg}_foot", pos=[0, 0, -CALF_LENGTH], size=[FOOT_RADIUS * 1.25, 0, 0])


A1 = RobotSpec(
    name="a1",
    build_spec=build_a1_spec,
    legs=tuple(Leg(leg, (f"{leg}_abduction", f"{leg}_thigh", f"{leg}_knee"), f"{leg}_foot") for leg in LEGS),
    base_body="trunk",
    standing_pose=STANDING_LEG_POSE * len(LEGS),
    standing_height=STANDING_HEIGHT,
    gait_groups=(("FR", "RL"), ("FL", "RR")),
    gait_period=0.2,  # s: a 5 Hz trot; its short diagonal stances keep the open-loop gait balanced
    min_height=0.15,
    command_low=(-0.3, -0.3, -0.5),
    command_high=(0.3, 0.3, 0.5),
    rear_legs=("RR", "RL"),
    swing_height=0.06,
    kp=(KP,) * 12,
    torque_limit=(TORQUE_LIMIT,) * 12,
    description="Unitree A1 quadruped, 12.45 kg, trot",
    source="builtin",
)

__all__ = ["A1", "build_a1_spec"]
