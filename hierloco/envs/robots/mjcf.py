"""Describe a user's own legged robot from an MJCF file.

Many published MJCF robots drive their joints with torque ``motor`` actuators and have neither a free joint nor a
floor; :func:`compile_model` turns motors into position servos with the gains given here and adds what is
missing. A foot can be named by a site, or by a body, in which case a site is added at that body's foot geom.

Example:
    >>> robot = robot_from_mjcf(  # doctest: +SKIP
    ...     "my_quadruped.xml", name="myquad", base_body="torso",
    ...     legs={"FR": ["fr_hip", "fr_thigh", "fr_knee"], ...}, feet={"FR": "fr_foot", ...},
    ...     standing_pose=[0, 0.8, -1.6] * 4, standing_height=0.3, gait_groups=[["FR", "RL"], ["FL", "RR"]],
    ...     kp=[80] * 12)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import mujoco

from hierloco.envs.robots.spec import Leg, RobotSpec


class _MjcfBuilder:
    """A picklable ``build_spec``: parses the MJCF text and adds the foot sites the description asks for."""

    def __init__(self, xml: str, base_dir: str | None, foot_bodies: Mapping[str, str]):
        self.xml = xml
        self.base_dir = base_dir
        self.foot_bodies = dict(foot_bodies)

    def __call__(self) -> mujoco.MjSpec:
        spec = mujoco.MjSpec.from_string(self.xml)
        if self.base_dir:
            spec.meshdir = os.path.join(self.base_dir, spec.meshdir or "")
            spec.texturedir = os.path.join(self.base_dir, spec.texturedir or "")
        for site_name, body_name in self.foot_bodies.items():
            body = spec.body(body_name)
            if body is None:
                raise ValueError(f"MJCF robot: no foot body named {body_name!r}")
            pos, radius = [0.0, 0.0, 0.0], 0.03
            spheres = [g for g in body.geoms if g.type == mujoco.mjtGeom.mjGEOM_SPHERE]
            if spheres:
                pos, radius = list(spheres[0].pos), float(spheres[0].size[0])
            body.add_site(name=site_name, pos=pos, size=[radius * 1.25, 0, 0])
        return spec

    def __eq__(self, other):
        return isinstance(other, _MjcfBuilder) and (self.xml, self.foot_bodies) == (other.xml, other.foot_bodies)

    def __hash__(self):
        return hash((self.xml, tuple(sorted(self.foot_bodies.items()))))


def robot_from_mjcf(
    xml: str | os.PathLike,
    *,
    name: str,
    base_body: str,
    legs: Mapping[str, Sequence[str]],
    feet: Mapping[str, str],
    standing_pose: Sequence[float],
    standing_height: float,
    gait_groups: Sequence[Sequence[str]],
    gait_period: float = 0.5,
    min_height: float | None = None,
    command_low: Sequence[float] = (-0.2, -0.2, -0.4),
    command_high: Sequence[float] = (0.2, 0.2, 0.4),
    rear_legs: Sequence[str] | None = None,
    swing_height: float = 0.05,
    kp: Sequence[float] | None = None,
    torque_limit: Sequence[float] | None = None,
    joint_damping: Sequence[float] | None = None,
) -> RobotSpec:
    """A :class:`RobotSpec` for the robot in ``xml`` (a file path or the MJCF text itself).

    Args:
        legs: leg name -> its hinge joint names, from the body outwards (legs keep this order).
        feet: leg name -> a site name, or a body name (a site is then added at that body's sphere geom).
        standing_pose: joint angles in rad, leg by leg. standing_height: base height in m in that pose.
        gait_groups: legs in stance together (e.g. trot pairs). rear_legs: legs disabled in the adverse setting
            (default: the last two legs). min_height: fall height in m (default: half the standing height).
        kp, torque_limit, joint_damping: per joint, in leg order; ``kp`` is required when the file drives its
            joints with torque motors.
    """
    text, base_dir = _read_xml(xml)
    probe = mujoco.MjSpec.from_string(text)
    site_names = {s.name for s in probe.sites}
    body_names = {b.name for b in probe.bodies}
    if set(feet) != set(legs):
        raise ValueError(f"MJCF robot {name!r}: feet {sorted(feet)} must name exactly the legs {sorted(legs)}")
    foot_sites, foot_bodies = {}, {}
    for leg, foot in feet.items():
        if foot in site_names:
            foot_sites[leg] = foot
        elif foot in body_names:
            foot_sites[leg] = f"{leg}_foot_site"
            foot_bodies[foot_sites[leg]] = foot
        else:
            raise ValueError(f"MJCF robot {name!r}: foot {foot!r} of leg {leg!r} is neither a site nor a body")
    legs_tuple = tuple(Leg(leg, tuple(joints), foot_sites[leg]) for leg, joints in legs.items())
    return RobotSpec(
        name=name,
        build_spec=_MjcfBuilder(text, base_dir, foot_bodies),
        legs=legs_tuple,
        base_body=base_body,
        standing_pose=tuple(float(a) for a in standing_pose),
        standing_height=float(standing_height),
        gait_groups=tuple(tuple(g) for g in gait_groups),
        gait_period=float(gait_period),
        min_height=float(standing_height) / 2 if min_height is None else float(min_height),
        command_low=tuple(float(c) for c in command_low),
        command_high=tuple(float(c) for c in command_high),
        rear_legs=tuple(rear_legs) if rear_legs is not None else tuple(legs)[-2:],
        swing_height=float(swing_height),
        kp=None if kp is None else tuple(float(k) for k in kp),
        torque_limit=None if torque_limit is None else tuple(float(t) for t in torque_limit),
        joint_damping=None if joint_damping is None else tuple(float(d) for d in joint_damping),
        description=f"user MJCF robot {name}",
    )


def _read_xml(xml: str | os.PathLike) -> tuple[str, str | None]:
    text = str(xml)
    if text.lstrip().startswith("<"):
        return text, None
    path = Path(xml)
    if not path.is_file():
        raise FileNotFoundError(f"MJCF robot: no such file {str(path)!r}")
    return path.read_text(), str(path.parent.resolve())
