"""The robot check: is a description fit to walk, and with which expert-controller parameters (``docs/robots.md``).

Two parts:

- :func:`description_problems` reads the description alone, in milliseconds (forward kinematics and statics of the
  standing pose, no simulation): the standing pose inside the joint limits, every foot well below its hip and on
  the floor, and the motors strong enough to hold the robot's weight on the legs a gait leaves in stance. Each
  problem is one line with the numbers and the fix. :func:`hierloco.components.expert_library.build_expert_library`
  runs it first, so a folded pose is refused at once instead of grinding in leg IK.
- the command line (``python -m hierloco.envs.robots.check robot.yaml``, or ``hierloco-robot-check``;
  ``check/__main__.py``) runs those
  checks, then searches the expert controller's free parameters (gait period, foot lift, standing height, servo
  gains and joint damping, command box) for experts that walk as commanded and a latent gait policy that
  reproduces them (:func:`hierloco.components.expert_tuning.tune_expert_parameters`), and prints the verified
  per-axis tracking table and the gait policy's reproduction, which change made the difference, the parameters
  found as YAML lines to paste into the robot's file and any recipe overrides as lines to paste on its command
  line. Exit status 0 when found, 2 otherwise (and for bad input: one ``error: ...`` line). A robot whose file and
  description give some leg joints no torque limit, which loading refuses, is read with provisional limits
  (:func:`robot_for_check`), and the search finds the smallest ``torque_limit`` that walks: the motors' peak torque
  the gait needs.

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> description_problems(get_robot("a1"))
    []
    >>> folded = get_robot("a1").replace(standing_pose=(0.0, 2.6, -2.6) * 4, standing_height=None, min_height=None)
    >>> print(description_problems(folded)[0])  # doctest: +ELLIPSIS
    standing pose: the feet are only 0.0... m below their hips (legs FR, FL, RR, RL; ...
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from hierloco.envs.robots.spec import (
    RobotSpec,
    _geom_bottom,
    compile_model,
    foot_geoms,
    joint_qpos_indices,
    stance_legs,
)
from hierloco.errors import Finding

MIN_FOOT_DROP = 0.25  # a foot below its hip by at least this fraction of the leg's reach, in the standing pose
FOOT_DROP_SUGGESTED = 0.6  # the suggested pose puts the feet this fraction of the reach below the hips
FLOOR_TOLERANCE = 0.01  # m: a foot on the floor has its bottom within this of the floor (standing pose)
MAX_STATIC_TORQUE = 0.75  # static torque holding the robot on its stance legs, as a fraction of the torque limit
MAX_STATIC_SAG = 0.25  # rad: a servo holding that torque is off its target by torque / kp, at most this
SUGGESTED_SAG = 0.1  # rad: the sag of the servos that walk (docs/robots.md, choosing kp): kp ~ static torque / this
LIMIT_MARGIN = 1e-6  # rad
# torque_limit levels searched for joints the file and the description give none, as multiples of the robot's largest
# static torque standing (N m, standing_statics; one level for every such joint: a joint whose foot stands straight
# under it holds nothing standing, quadruped20's thigh 0 N m, yet walking loads it). 1.5 just clears the
# description check (MAX_STATIC_TORQUE: the limit at least 1.33 x the static torque); the motors of the robots here
# that walk are 1.5 to 3.7 x it at their joints (A1 3.5; quadruped9 2.8 and 3.7; quadruped20 1.9 and 2.4; quadruped40
# 1.5 and 2.2; quadruped50 1.6 and 2.6; hexapod10 1.5 and 2.3; Daisy 0.9 to 1.9, its hips hold little)
TORQUE_LIMIT_FACTORS = (1.5, 2.0, 3.0, 4.0, 6.0)
# the search starts from the largest: such a motor does not limit the gait it looks for (a servo with kp for a
# 0.05 rad sag, the stiffest searched, saturates only past a 0.3 rad error)
PROVISIONAL_TORQUE_FACTOR = TORQUE_LIMIT_FACTORS[-1]


@dataclass(frozen=True)
class LegStatics:
    """One leg in the standing pose, with the base level at the description's standing height.

    Attributes:
        leg: the leg's name.
        hip_height: m, the leg's first joint above the floor.
        foot_height: m, the bottom of the foot's collision geom above the floor (0: touching it).
        foot_drop: m, how far the foot (its site) is below the first joint.
        reach: m, the leg's length: the distances from joint to joint and from the last joint to the foot, summed.
        static_torque: N m per joint of the leg, holding its share of the weight (see :class:`StandingStatics`).
        torque_limit: N m per joint (``inf`` for a motor without one).
        kp: N m / rad per joint, the servos' stiffness (a servo holding ``static_torque`` is off its target by
            ``static_torque / kp``).
    """

    leg: str
    hip_height: float
    foot_height: float
    foot_drop: float
    reach: float
    static_torque: tuple[float, ...]
    torque_limit: tuple[float, ...]
    kp: tuple[float, ...] = ()


@dataclass(frozen=True)
class StandingStatics:
    """The robot standing: its mass, the fewest legs its gait leaves in stance, and every leg's numbers.

    Each stance leg carries ``mass * g / stance_legs`` upward at its foot; ``static_torque`` is what each joint then
    exerts (``|(axis x (foot - anchor)) . F|``), a lower bound on what walking asks of it.
    """

    robot: str
    mass: float
    standing_height: float
    feet_on_floor_height: float
    stance_legs: int
    legs: tuple[LegStatics, ...]

    @property
    def load_per_foot(self) -> float:
        """N on each stance foot."""
        return self.mass * 9.81 / self.stance_legs


def standing_statics(robot: RobotSpec, model: mujoco.MjModel | None = None) -> StandingStatics:
    """The numbers :func:`description_problems` judges (forward kinematics of the standing pose, no simulation).

    Example:
        >>> from hierloco.envs.robots import get_robot
        >>> statics = standing_statics(get_robot("a1"))
        >>> statics.stance_legs, round(statics.legs[0].foot_drop, 3)
        (2, 0.249)
    """
    model = compile_model(robot) if model is None else model
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    data.qpos[0:7] = (0.0, 0.0, float(robot.standing_height), 1.0, 0.0, 0.0, 0.0)
    data.qpos[joint_qpos_indices(model, robot)] = robot.standing_pose
    mujoco.mj_kinematics(model, data)
    feet = foot_geoms(model, robot)
    bottoms = [_geom_bottom(model, data, g) for g in feet]
    mass = float(model.body_mass[1:].sum())
    stance = max(stance_legs(robot), 1)
    force = np.array([0.0, 0.0, mass * 9.81 / stance])
    limited = model.actuator_forcelimited.astype(bool) | (model.actuator_forcerange[:, 1] > model.actuator_forcerange[:, 0])
    limits = np.where(limited, np.abs(model.actuator_forcerange).max(1) * np.abs(model.actuator_gear[:, 0]), np.inf)
    legs, start = [], 0
    for leg, bottom in zip(robot.legs, bottoms):
        joints = [model.joint(name).id for name in leg.joints]
        anchors = data.xanchor[joints]
        axes = data.xaxis[joints]
        foot = data.site_xpos[model.site(leg.foot_site).id]
        points = np.concatenate([anchors, foot[None]])
        reach = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
        torque = np.abs(np.einsum("jk,k->j", np.cross(axes, foot - anchors), force))
        n = len(joints)
        legs.append(LegStatics(leg=leg.name, hip_height=float(anchors[0, 2]), foot_height=float(bottom),
                               foot_drop=float(anchors[0, 2] - foot[2]), reach=reach,
                               static_torque=tuple(float(t) for t in torque),
                               torque_limit=tuple(float(t) for t in limits[start:start + n]),
                               kp=tuple(float(k) for k in model.actuator_gainprm[start:start + n, 0])))
        start += n
    derived = float(robot.standing_height) - min(bottoms)
    return StandingStatics(robot=robot.name, mass=mass, standing_height=float(robot.standing_height),
                           feet_on_floor_height=derived, stance_legs=stance, legs=tuple(legs))


def largest_static_torque(robot: RobotSpec) -> tuple[float, str]:
    """``(N m, joint)``: the largest static torque of :func:`standing_statics`, and the joint that holds it."""
    statics = standing_statics(robot)
    torque, joint = max((t, name) for leg, spec in zip(statics.legs, robot.legs)
                        for t, name in zip(leg.static_torque, spec.joints))
    return float(torque), joint


def torque_limit_level(robot: RobotSpec, factor: float) -> tuple[float, ...]:
    """The torque limits (N m per joint) of ``robot`` with its ``provisional_torque_joints`` at ``factor`` x its
    largest static torque standing (two significant digits), the other joints at their own limits.

    Example:
        >>> from hierloco.envs.robots import A1
        >>> largest_static_torque(A1)  # doctest: +ELLIPSIS
        (9.56..., 'RR_knee')
        >>> torque_limit_level(A1.replace(provisional_torque_joints=("FR_knee",)), 2.0)[:3]
        (33.5, 33.5, 19.0)
    """
    torque, _ = largest_static_torque(robot)
    level = float(f"{factor * torque:.2g}")
    provisional = set(robot.provisional_torque_joints)
    return tuple(level if joint in provisional else float(limit)
                 for joint, limit in zip(robot.joint_names, robot.torque_limit))


def robot_for_check(reference) -> RobotSpec:
    """The robot as the check reads it: :func:`hierloco.envs.robots.get_robot`'s, except a YAML robot that is
    refused only because its file and description give some leg joints no torque limit. That one is read with a
    provisional limit for those joints (``PROVISIONAL_TORQUE_FACTOR`` x the largest static torque standing, two
    significant digits; the file's own limits elsewhere), which it lists in
    :attr:`~hierloco.envs.robots.RobotSpec.provisional_torque_joints`: the search
    (:func:`hierloco.components.expert_tuning.tune_expert_parameters`) then looks for the smallest limit that
    walks, to be pasted as ``torque_limit``. Anything else is refused as by ``get_robot``.

    Example:
        >>> robot_for_check("a1").provisional_torque_joints  # a robot with limits: get_robot's
        ()
        >>> robot = robot_for_check("tests/fixtures/quadruped20_nolimit/quadruped20_nolimit.yaml")  # doctest: +SKIP
        >>> robot.torque_limit[:3], len(robot.provisional_torque_joints)  # doctest: +SKIP
        ((110.0, 110.0, 110.0), 12)
    """
    from hierloco.envs.robots import get_robot

    try:
        return get_robot(reference)
    except ValueError:
        robot = _with_provisional_torque_limits(reference)
        if robot is None:
            raise
        return robot


def _with_provisional_torque_limits(reference) -> RobotSpec | None:
    """:func:`robot_for_check`'s robot, or ``None`` when ``reference`` is refused for another reason."""
    import os
    from pathlib import Path

    from hierloco.envs.robots.mjcf import robot_from_mjcf
    from hierloco.envs.robots.spec import YAML_SOURCE_PREFIX, actuation_problem, file_actuators
    from hierloco.envs.robots.yaml_robot import is_robot_file, read_robot_yaml

    if not isinstance(reference, (str, os.PathLike)) or not is_robot_file(reference):
        return None
    path = Path(reference).absolute()
    try:
        kwargs, mjcf = read_robot_yaml(path)
        if "torque_limit" in kwargs:
            return None
        probe = mujoco.MjSpec.from_string(mjcf.read_text())
        joints = [joint for leg in kwargs["legs"].values() for joint in leg]
        if actuation_problem(probe, joints, kp_given="kp" in kwargs, torque_limit_given=True) is not None:
            return None  # a missing gain stays a refusal
        found = file_actuators(probe, joints)
        missing = tuple(j for j in joints if found.get(j, (None, 0.0, None))[2] is None)
        if not missing:
            return None
        kwargs.setdefault("description", f"{kwargs['name']} ({path.name})")
        placeholder = [found[j][2] if j not in missing else 1.0 for j in joints]  # N m: statics need none
        robot = robot_from_mjcf(mjcf, source=f"{YAML_SOURCE_PREFIX}{path}", torque_limit=placeholder, **kwargs)
        robot = robot.replace(provisional_torque_joints=missing, source=robot.source)
        if not largest_static_torque(robot)[0] > 0:
            return None
        return robot.replace(torque_limit=torque_limit_level(robot, PROVISIONAL_TORQUE_FACTOR), source=robot.source)
    except (ValueError, OSError, KeyError, TypeError):
        return None


def provisional_torque_text(robot: RobotSpec) -> str | None:
    """One line on the provisional torque limits of ``robot`` (``None`` when it has none)."""
    joints = robot.provisional_torque_joints
    if not joints:
        return None
    torque, joint = largest_static_torque(robot)
    limit = max(robot.torque_limit[robot.joint_names.index(j)] for j in joints)
    return (f"torque limits: the file and the description give {len(joints)} of {robot.num_joints} leg joints none; "
            f"the search starts them at {limit:g} N m ({PROVISIONAL_TORQUE_FACTOR:g} x the largest torque standing, "
            f"{torque:.1f} N m at joint {joint!r}) and looks for the smallest of "
            f"{', '.join(f'{f:g}' for f in TORQUE_LIMIT_FACTORS)} x that torque that walks: the motors' peak torque "
            "the gait needs")


def _legs(names) -> str:
    names = list(names)
    return ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")


def _numbers(values, digits: int = 2) -> str:
    return "[" + ", ".join(f"{v:.{digits}f}" for v in values) + "]"


def suggested_standing_pose(robot: RobotSpec, drop_fraction: float = FOOT_DROP_SUGGESTED) -> tuple[float, ...] | None:
    """A standing pose with every foot ``drop_fraction`` of its leg's reach below its hip, straight under where
    the foot is now (inverse kinematics from the given pose, within the joint limits), or ``None`` when the legs
    cannot reach it within 1 cm.

    Example:
        >>> from hierloco.envs.robots import get_robot
        >>> pose = suggested_standing_pose(get_robot("a1"))
        >>> len(pose)
        12
    """
    from hierloco.components.kinematics import LegKinematics

    statics = standing_statics(robot)
    kinematics = LegKinematics(robot)
    q0 = np.asarray(robot.standing_pose, dtype=float)
    feet = kinematics.forward(q0)  # L x 3 in the base frame
    hips = np.array([leg.hip_height for leg in statics.legs]) - robot.standing_height  # base frame z
    target = feet.copy()
    target[:, 2] = hips - drop_fraction * np.array([leg.reach for leg in statics.legs])
    q = kinematics.inverse(target, q0)
    if np.abs(kinematics.forward(q) - target).max() > 0.01:
        return None
    return tuple(float(v) for v in q)


def _pose_text(robot: RobotSpec, pose) -> str:
    per_leg = [tuple(round(v, 2) for v in pose[s]) for s in _leg_slices(robot)]
    if len(set(per_leg)) == 1:
        return _numbers(per_leg[0])
    return "{" + ", ".join(f"{leg.name}: {_numbers(angles)}" for leg, angles in zip(robot.legs, per_leg)) + "}"


def _leg_slices(robot: RobotSpec) -> list[slice]:
    slices, start = [], 0
    for leg in robot.legs:
        slices.append(slice(start, start + len(leg.joints)))
        start += len(leg.joints)
    return slices


class RobotDescriptionError(Finding, ValueError):
    """A robot whose description keeps it from standing and walking (:func:`description_problems`): a finding about
    the robot, recorded by the pipeline like the experts' own (``docs/pipeline.md``)."""


def description_problems(robot: RobotSpec) -> list[str]:
    """What in ``robot``'s description keeps it from standing and walking, one line per problem, with the numbers
    and the fix; empty when there is none. Milliseconds: forward kinematics and statics of the standing pose.

    Checks (``docs/robots.md``):

    - the standing pose is inside every joint's range;
    - every foot is at least ``MIN_FOOT_DROP`` of its leg's reach below its hip (a folded pose cannot carry the body
      nor lift a foot);
    - every foot touches the floor at the standing height (within ``FLOOR_TOLERANCE``);
    - standing on the fewest legs the gait keeps in stance, no joint needs more than ``MAX_STATIC_TORQUE`` of its
      torque limit to hold the weight (walking adds to it), nor sags more than ``MAX_STATIC_SAG`` under it (a servo
      of gain kp is off its target by torque / kp).

    Example:
        >>> from hierloco.envs.robots import get_robot
        >>> description_problems(get_robot("daisy"))
        []
    """
    model = compile_model(robot)
    problems = []
    # joint limits
    outside = []
    for name, angle in zip(robot.joint_names, robot.standing_pose):
        joint = model.joint(name)
        if model.jnt_limited[joint.id]:
            low, high = model.jnt_range[joint.id]
            if not low - LIMIT_MARGIN <= angle <= high + LIMIT_MARGIN:
                outside.append((name, angle, low, high))
    if outside:
        name, angle, low, high = outside[0]
        others = f" (and {len(outside) - 1} more joints)" if len(outside) > 1 else ""
        problems.append(f"standing pose: joint {name!r} at {angle:+.3f} rad is outside its range "
                        f"[{low:+.3f}, {high:+.3f}] rad{others}: give standing_pose angles inside the joint ranges "
                        f"(e.g. {min(max(angle, low + 0.05 * (high - low)), high - 0.05 * (high - low)):+.3f} for "
                        f"{name!r})")
    statics = standing_statics(robot, model)
    # folded legs
    folded = [leg for leg in statics.legs if leg.foot_drop < MIN_FOOT_DROP * leg.reach]
    if folded:
        worst = min(folded, key=lambda leg: leg.foot_drop / leg.reach)
        suggestion = suggested_standing_pose(robot)
        fix = (f"give a standing_pose with the feet further down, e.g. {_pose_text(robot, suggestion)} (feet "
               f"{FOOT_DROP_SUGGESTED:.0%} of the reach below the hips)" if suggestion is not None else
               "give a standing_pose with the legs extended below the hips")
        problems.append(
            f"standing pose: the feet are only {worst.foot_drop:.3f} m below their hips (legs {_legs(l.leg for l in folded)}; "
            f"leg {worst.leg}: hip {worst.hip_height:.3f} m, foot {worst.hip_height - worst.foot_drop:.3f} m above "
            f"the floor, with {worst.reach:.3f} m of leg), need at least {MIN_FOOT_DROP * worst.reach:.3f} m "
            f"({MIN_FOOT_DROP:.0%} of the reach): a folded leg can neither carry the body nor lift its foot; {fix}")
    # feet on the floor
    low_feet = [leg for leg in statics.legs if leg.foot_height < -FLOOR_TOLERANCE]
    high_feet = [leg for leg in statics.legs if leg.foot_height > FLOOR_TOLERANCE]
    if low_feet or high_feet:
        heights = {leg.leg: leg.foot_height for leg in statics.legs}
        lowest = min(heights.values())
        if max(heights.values()) - lowest > FLOOR_TOLERANCE:
            problems.append(
                f"standing pose: the feet are not level: bottoms at {_numbers(heights.values(), 3)} m for legs "
                f"{_legs(heights)} (at most {FLOOR_TOLERANCE} m apart): give a standing_pose that puts every foot "
                "on the floor (the same leg angles for legs built alike)")
        else:
            problems.append(
                f"standing_height: at {statics.standing_height:.3f} m the feet are "
                f"{abs(lowest):.3f} m {'below' if lowest < 0 else 'above'} the floor: give standing_height: "
                f"{statics.feet_on_floor_height:.3f} (the feet on the floor), or leave it out to derive it")
    # torques
    overloaded = []
    for leg in statics.legs:
        for name, torque, limit in zip(next(l.joints for l in robot.legs if l.name == leg.leg), leg.static_torque,
                                       leg.torque_limit):
            if torque > MAX_STATIC_TORQUE * limit:
                overloaded.append((torque / limit, name, torque, limit))
    if overloaded:
        ratio, name, torque, limit = max(overloaded)
        problems.append(
            f"torque: holding {statics.mass:.1f} kg on {statics.stance_legs} stance legs "
            f"({statics.load_per_foot:.0f} N per foot) takes {torque:.1f} N m at joint {name!r}, {ratio:.0%} of its "
            f"{limit:.1f} N m limit ({len(overloaded)} joints above {MAX_STATIC_TORQUE:.0%}; walking needs more): give "
            f"torque_limit of at least {torque / MAX_STATIC_TORQUE:.1f} N m for it, a lighter robot, or a pose "
            "with the feet closer under the joints")
    sagging = []
    for leg in statics.legs:
        names = next(l.joints for l in robot.legs if l.name == leg.leg)
        for name, torque, kp in zip(names, leg.static_torque, leg.kp):
            if kp > 0 and torque / kp > MAX_STATIC_SAG:
                sagging.append((torque / kp, name, torque, kp))
    if sagging:
        sag, name, torque, kp = max(sagging)
        problems.append(
            f"kp: holding {statics.mass:.1f} kg on {statics.stance_legs} stance legs, joint {name!r} sags "
            f"{sag:.2f} rad off its target ({torque:.1f} N m at kp {kp:g} N m/rad; {len(sagging)} joints over "
            f"{MAX_STATIC_SAG} rad): give kp of at least {torque / (0.5 * MAX_STATIC_SAG):.0f} N m/rad (a sag of "
            f"{0.5 * MAX_STATIC_SAG} rad)")
    return problems




# ---------------------------------------------------------------------------------------------------- command line
EXIT_FOUND, EXIT_NOT_FOUND = 0, 2


def description_summary(robot: RobotSpec) -> str:
    """One line of the numbers :func:`description_problems` judged, for a description that passes."""
    statics = standing_statics(robot)
    drop = min(leg.foot_drop / leg.reach for leg in statics.legs)
    ratio = max((t / limit for leg in statics.legs for t, limit in zip(leg.static_torque, leg.torque_limit)),
                default=0.0)
    sags = [(t / kp, t) for leg in statics.legs for t, kp in zip(leg.static_torque, leg.kp) if kp > 0]
    sag, torque = max(sags, default=(0.0, 0.0))
    hint = (f"; servos that walk sag about {SUGGESTED_SAG} rad, kp {torque / SUGGESTED_SAG:.0f} N m/rad at that "
            "joint (docs/robots.md: choosing kp)" if sag > 1.5 * SUGGESTED_SAG else "")
    limit = " provisional" if robot.provisional_torque_joints else ""
    return (f"standing pose inside the joint limits; feet {min(leg.foot_drop for leg in statics.legs):.3f} m or more "
            f"below the hips ({drop:.0%} of the reach, need {MIN_FOOT_DROP:.0%}) and on the floor; holding "
            f"{statics.mass:.1f} kg on {statics.stance_legs} stance legs takes at most {ratio:.0%} of a joint's{limit} "
            f"torque limit (need {MAX_STATIC_TORQUE:.0%} or less) and the servos sag {sag:.2f} rad at most (need "
            f"{MAX_STATIC_SAG} or less){hint}")


__all__ = ["EXIT_FOUND", "EXIT_NOT_FOUND", "FLOOR_TOLERANCE", "LegStatics", "MAX_STATIC_SAG", "MAX_STATIC_TORQUE",
           "MIN_FOOT_DROP", "PROVISIONAL_TORQUE_FACTOR", "RobotDescriptionError", "SUGGESTED_SAG", "StandingStatics",
           "TORQUE_LIMIT_FACTORS", "description_problems", "description_summary", "largest_static_torque",
           "provisional_torque_text", "robot_for_check", "standing_statics", "suggested_standing_pose",
           "torque_limit_level"]
