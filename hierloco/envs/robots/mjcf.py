"""Describe a user's own legged robot from an MJCF file.

Many published MJCF robots drive their joints with torque ``motor`` actuators and have neither a free joint nor a
floor; :func:`compile_model` turns motors into position servos with the gains given here and adds what is
missing. A foot can be named by a site, or by a body, in which case a site is added at that body's foot geom.
Every name is checked against the file before anything is built, and a missing one is reported with the close
names the file does have. The same keyword arguments, with ``mjcf:`` for the file, make a robot's YAML
description (:func:`hierloco.envs.robots.load_robot_yaml`; see ``docs/robots.md``).

Example:
    >>> robot = robot_from_mjcf(  # doctest: +SKIP
    ...     "my_quadruped.xml", name="myquad", base_body="torso",
    ...     legs={"FR": ["fr_hip", "fr_thigh", "fr_knee"], ...}, feet={"FR": "fr_foot", ...},
    ...     standing_pose=[0, 0.8, -1.6], gait_groups=[["FR", "RL"], ["FL", "RR"]], kp=80)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import mujoco

from hierloco.envs.robots.spec import (
    PYTHON_SOURCE,
    Leg,
    RobotSpec,
    actuation_problem,
    check_leg_count,
    is_number,
    missing_name_message,
)
from hierloco.io import brief

MJCF_SOURCE_PREFIX = "mjcf:"


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
    standing_pose: Sequence[float] | Mapping[str, Sequence[float]],
    gait_groups: Sequence[Sequence[str]],
    standing_height: float | None = None,
    gait_period: float | None = None,
    min_height: float | None = None,
    command_low: Sequence[float] = (-0.2, -0.2, -0.4),
    command_high: Sequence[float] = (0.2, 0.2, 0.4),
    rear_legs: Sequence[str] | None = None,
    swing_height: float | None = None,
    max_roll: float = 0.5,
    max_pitch: float = 0.5,
    kp: float | Sequence[float] | None = None,
    torque_limit: float | Sequence[float] | None = None,
    joint_damping: float | Sequence[float] | None = None,
    description: str | None = None,
    source: str | None = None,
) -> RobotSpec:
    """A :class:`RobotSpec` for the robot in ``xml`` (a file path or the MJCF text itself).

    The file may drive its joints with torque ``motor`` actuators (give ``kp``: they become position servos with
    that gain and the motors' torque range), or have no actuators at all (give ``kp`` and ``torque_limit``: a
    servo is never left without a torque limit), and may lack a free joint and a floor (both are added). Per-joint
    values (``standing_pose``, ``kp``, ``torque_limit``, ``joint_damping``) are given in leg order as one value
    per joint, as one leg's values (used for every leg, when all legs have that many joints), as a single
    number (``kp``, ``torque_limit``, ``joint_damping``), or as a mapping leg name -> that leg's values.

    Args:
        xml: path of the MJCF file (meshes and textures are found relative to it), or the MJCF text.
        name: registry name of the robot.
        base_body: the body whose frame is the robot's CoM frame (a child of the world).
        legs: leg name -> its hinge joint names, from the body outwards (legs keep this order); at least 3 legs.
        feet: leg name -> a site name, or a body name (a site is then added at that body's sphere geom).
        standing_pose: joint angles in rad.
        gait_groups: legs in stance together (e.g. trot pairs ``[["FR", "RL"], ["FL", "RR"]]``), at least two.
        standing_height: base height in m in the standing pose (default: derived so the feet touch the floor,
            :func:`hierloco.envs.robots.derive_standing_height`).
        gait_period: s (default: derived from the robot's size, :func:`hierloco.envs.robots.derive_gait_period`).
        min_height: fall height in m (default: half the standing height).
        command_low, command_high: the command box ``(vx, vy, yaw_rate)`` in m/s, m/s, rad/s.
        rear_legs: legs disabled in the adverse setting (default: the last two legs).
        swing_height: foot lift in m (default: derived from the hips' height,
            :func:`hierloco.envs.robots.derive_swing_height`). max_roll, max_pitch: fall thresholds in rad.
        kp: position gain in N m / rad; required when the file drives a joint with a torque motor or with nothing.
        torque_limit: N m (default: the file's motor range); required when the file gives a joint none.
        joint_damping: N m s / rad (default: the file's).
        description: a line for reports. source: where the description came from (default: the file's path).

    Raises:
        ValueError: a name not in the file (with the close names it has), a wrong count or a bad number;
            FileNotFoundError: no such file.

    Example:
        >>> from hierloco.envs.robots import robot_from_mjcf
        >>> robot = robot_from_mjcf("tests/fixtures/quadruped20/quadruped20.xml",  # doctest: +SKIP
        ...     name="quadruped20", base_body="trunk",
        ...     legs={leg: [f"{leg}_hip_joint", f"{leg}_thigh_joint", f"{leg}_calf_joint"]
        ...           for leg in ("FR", "FL", "RR", "RL")},
        ...     feet={leg: f"{leg}_foot" for leg in ("FR", "FL", "RR", "RL")},
        ...     standing_pose=[0.0, 0.8, -1.6], gait_groups=[["FR", "RL"], ["FL", "RR"]], kp=150)
        >>> robot.standing_height, robot.gait_period  # doctest: +SKIP
        (0.3748..., 0.5)
    """
    where = f"MJCF robot {name!r}"
    text, base_dir, path = _read_xml(xml)
    try:
        probe = mujoco.MjSpec.from_string(text)
    except ValueError as error:
        raise ValueError(f"{where}: cannot parse the MJCF: {error}") from error
    site_names = [s.name for s in probe.sites]
    body_names = [b.name for b in probe.bodies]
    joints = {j.name: j for j in probe.joints}
    if base_body not in body_names:
        raise ValueError(f"{where}: base_body: {missing_name_message('body', base_body, body_names)}")
    check_leg_count(where, list(legs))
    if set(feet) != set(legs):
        raise ValueError(f"{where}: feet {sorted(feet)} must name exactly the legs {sorted(legs)}")
    for leg, leg_joints in legs.items():
        if isinstance(leg_joints, str) or not leg_joints:
            raise ValueError(f"{where}: legs[{leg!r}] must be a non-empty list of joint names, "
                             f"got {brief(leg_joints)}")
        for joint in leg_joints:
            if joint not in joints:
                raise ValueError(f"{where}: legs[{leg!r}]: {missing_name_message('joint', joint, joints)}")
            if joints[joint].type != mujoco.mjtJoint.mjJNT_HINGE:
                raise ValueError(f"{where}: legs[{leg!r}]: joint {joint!r} is not a hinge")
    foot_sites, foot_bodies = {}, {}
    for leg, foot in feet.items():
        if foot in site_names:
            foot_sites[leg] = foot
        elif foot in body_names:
            foot_sites[leg] = f"{leg}_foot_site"
            foot_bodies[foot_sites[leg]] = foot
        else:
            raise ValueError(f"{where}: feet[{leg!r}]: {foot!r} is neither a site nor a body "
                             f"({missing_name_message('site or body', foot, site_names + body_names)})")
    legs_tuple = tuple(Leg(leg, tuple(joints_), foot_sites[leg]) for leg, joints_ in legs.items())
    per_joint = {key: _per_joint(where, key, value, legs_tuple) for key, value in (
        ("standing_pose", standing_pose), ("kp", kp), ("torque_limit", torque_limit),
        ("joint_damping", joint_damping))}
    if per_joint["standing_pose"] is None:
        raise ValueError(f"{where}: standing_pose is required")
    problem = actuation_problem(probe, [j for leg in legs_tuple for j in leg.joints],
                                kp_given=per_joint["kp"] is not None,
                                torque_limit_given=per_joint["torque_limit"] is not None)
    if problem is not None:  # now, not at the first simulation: a servo needs a gain and a torque limit
        raise ValueError(f"{where}: {problem}")
    return RobotSpec(
        name=name,
        build_spec=_MjcfBuilder(text, base_dir, foot_bodies),
        legs=legs_tuple,
        base_body=base_body,
        gait_groups=tuple(tuple(g) for g in gait_groups),
        standing_height=None if standing_height is None else float(standing_height),
        gait_period=None if gait_period is None else float(gait_period),
        min_height=None if min_height is None else float(min_height),
        command_low=tuple(float(c) for c in command_low),
        command_high=tuple(float(c) for c in command_high),
        rear_legs=tuple(rear_legs) if rear_legs is not None else tuple(legs)[-2:],
        swing_height=None if swing_height is None else float(swing_height),
        max_roll=float(max_roll),
        max_pitch=float(max_pitch),
        description=description if description is not None else f"user MJCF robot {name}",
        source=source if source is not None else (f"{MJCF_SOURCE_PREFIX}{path}" if path else PYTHON_SOURCE),
        **per_joint,
    )


def _per_joint(where: str, key: str, value, legs: tuple[Leg, ...]) -> tuple[float, ...] | None:
    """One float per joint, in leg order, from any of the forms :func:`robot_from_mjcf` accepts."""
    if value is None:
        return None
    per_leg = {len(leg.joints) for leg in legs}
    total = sum(len(leg.joints) for leg in legs)
    forms = f"{total} numbers (one per joint)" + (f", {min(per_leg)} (one leg, for every leg)"
                                                  if len(per_leg) == 1 else "")
    try:
        if isinstance(value, Mapping):
            if set(value) != {leg.name for leg in legs}:
                raise ValueError(f"{where}: {key} must give every leg {[leg.name for leg in legs]}, "
                                 f"got {sorted(value)}")
            values = []
            for leg in legs:
                entry = list(value[leg.name])
                if len(entry) != len(leg.joints):
                    raise ValueError(f"{where}: {key}[{leg.name!r}] has {len(entry)} values for "
                                     f"{len(leg.joints)} joints")
                values += entry
        elif is_number(value) and key != "standing_pose":
            values = [value] * total
        else:
            values = list(value)
            if len(values) != total and len(per_leg) == 1 and len(values) == len(legs[0].joints):
                values = values * len(legs)
    except TypeError:
        raise ValueError(f"{where}: {key} must be {forms} or a mapping leg -> values, got {brief(value)}") from None
    if len(values) != total:
        raise ValueError(f"{where}: {key} has {len(values)} values for {total} joints; give {forms}")
    for joint, v in zip((j for leg in legs for j in leg.joints), values):
        if not is_number(v):
            raise ValueError(f"{where}: {key} of joint {joint!r} must be a number, got {brief(v)}")
    return tuple(float(v) for v in values)


def _read_xml(xml: str | os.PathLike) -> tuple[str, str | None, str | None]:
    """(MJCF text, directory for its assets, absolute file path) of a path or of MJCF text."""
    text = str(xml)
    if text.lstrip().startswith("<"):
        return text, None, None
    path = Path(xml)
    if not path.is_file():
        raise FileNotFoundError(f"MJCF robot: no such file {str(path)!r}")
    path = path.resolve()
    return path.read_text(), str(path.parent), str(path)
