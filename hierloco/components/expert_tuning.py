"""Searching the expert controller's free parameters for a robot (``hierloco-robot-check``; ``docs/robots.md``).

The expert gaits (Li et al., RA-L 2021, Sec. III-A) have free parameters that a robot's description fixes: the gait
period (a whole number of periods per latent action of N control steps), the foot lift, the standing height, the
servos' stiffness and damping, and the command box the experts must cover. :func:`tune_expert_parameters` searches
them for experts that walk as commanded (:func:`hierloco.components.expert_library.diagnose_expert_library`) and
for a latent gait policy that reproduces them in simulation (:func:`hierloco.components.evaluation.check_gait_policy`):

1. **screening**, in stages: candidate parameter sets are run side by side in one batched simulation
   (:class:`hierloco.envs.batched_sim.BatchedSimulator` with one robot variant per copy), each on a dozen commands
   at the box's edges and inside it, closed loop with the expert controller, recorded as the experts are, then
   their recorded joint targets replayed open loop from standing as the gait policy's check replays ``pi(., z)``.
   A candidate passes when its experts reach ``min_reach`` of the box on every axis, none falls, and at least
   ``min_reproduced_fraction`` of the replays walk within 0.05 m/s of what was recorded (no gait policy can
   reproduce an expert whose own targets do not). The stages: gait period x foot lift x two servo settings (the
   description's own gains, and the rule of ``docs/robots.md``: kp for a 0.1 rad sag under the standing load,
   joint damping 0.02 s x kp); then, unless a candidate already passes with a margin (``SCORE_CAP``), the rest of
   the servo grid around the two best gaits (:func:`servo_settings`: kp for a sag of 0.1 and 0.05 rad x joint
   damping of 0.01, 0.02 and 0.04 s x kp), and the body lowered around the best; then, only when nothing passes,
   smaller command boxes; then, for a robot whose file and description give some joints no torque limit (read by
   the check with provisional ones, :func:`hierloco.envs.robots.check.robot_for_check`), the best candidate that
   passes at each lower torque-limit level (:func:`torque_limit_levels`), the smallest that passes verified first:
   the motors' peak torque the gait needs.
2. **verification** of the best candidates, in order, while the budget lasts: the expert library exactly as the
   experts stage builds it, its tracking check, and a gait policy trained and checked in simulation
   (:func:`hierloco.components.gait_policy_fit.fit_gait_policy`, which adapts the training when the first fit falls
   short of the bar: it always tries twice the epochs). The first candidate whose gait policy passes as configured
   is the one found; when only an adapted fit passes, the next candidates are verified too while the budget
   allows another verification, and failing a better one, the adapted fit's ``policy`` overrides are part of what
   is found.
3. **what made the difference**: each change the found parameters make to the description's is undone alone, the
   others kept, and screened beside them (:func:`difference_candidates`): a change whose undoing fails the
   screening is one the robot needs; one whose undoing passes with a lower score gave it margin. A torque limit the
   description lacks is lowered to the next level instead: when that fails, the gait needs the limit found.

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> result = tune_expert_parameters(get_robot("a1"), budget_seconds=60, verify=False)  # doctest: +SKIP
    >>> result.best.params.gait_period  # doctest: +SKIP
    0.2
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from hierloco.components.evaluation import action_velocities, replayed_fraction
from hierloco.components.expert_library import (
    MIN_REACH,
    AxisTracking,
    ExpertQualityError,
    ExpertTrackingReport,
    _axis_tracking,
    action_motion,
    build_expert_library,
    diagnose_expert_library,
)
from hierloco.components.experts import RaibertController, foothold_reach
from hierloco.envs.batched_sim import BatchedSimulator, SimulationResult
from hierloco.envs.frames import world_to_local
from hierloco.envs.robots import (
    CONTROL_TIMESTEP,
    STEPS_PER_ACTION,
    RobotSpec,
    admissible_gait_periods,
    compile_model,
    get_robot,
    joint_qvel_indices,
)
from hierloco.envs.robots.check import (
    SUGGESTED_SAG,
    TORQUE_LIMIT_FACTORS,
    standing_statics,
    torque_limit_level,
)

REPRODUCTION_TOLERANCE = 0.05  # m/s: a replay or a policy reproduces an expert within this (check_gait_policy)
MIN_REPRODUCED_FRACTION = 0.8  # the gait-policy check's default bar (checks.min_reproduced_fraction)
MIN_GAIT_PERIOD = 0.15  # s: shorter periods are not searched (swing phases of a few control steps)
MAX_REACH_SHORTFALL = 0.01  # m: a candidate whose footholds are further out of reach is not run
SATURATION_ANGLE = 0.05  # rad: a servo's kp is at most its torque limit over this error
SWING_FRACTIONS = (0.12, 0.2, 0.3)  # foot lift as a fraction of the hips' height
LOWERINGS = (0.1, 0.2)  # the body lowered by these fractions of the feet's depth below the hips
SAG_TARGETS = (0.1, 0.05)  # rad: kp scaled up so that the joint sagging most under the standing load sags this much
DAMPING_TIMES = (0.01, 0.02, 0.04)  # s: joint damping tried as this times kp
RULE_SAG, RULE_DAMPING_TIME = SUGGESTED_SAG, 0.02  # docs/robots.md's rule for servos, screened beside the own
MIN_KP_STEP = 1.1  # a kp level less than this factor above the description's is the description's
BOX_SCALES = (0.75, 0.5)  # smaller command boxes, tried only when nothing passes
POLICY_THREADS = 1  # torch threads of the verified gait policy: on 2 shared cores (load 7-9), 50 epochs of 2 x 512
# took 13-16 s and 5-6 CPU s on one thread, 54-55 s and 23-25 CPU s on two
SCORE_CAP = 1.25  # candidates with this much margin on both bars are equally good; then the fewest changes win


# ---------------------------------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class ExpertParameters:
    """The expert controller's free parameters of a robot, as the description holds them.

    Attributes:
        gait_period: s. swing_height: foot lift in m. standing_height: m, base above the floor standing.
        standing_pose: rad, one angle per joint. kp: N m / rad per joint. joint_damping: N m s / rad per joint.
        command_low, command_high: the command box ``(vx m/s, vy m/s, yaw_rate rad/s)``.
        torque_limit: N m per joint, the motors' peak torque; ``None``: the robot's own (its description's or its
            file's; for a robot with provisional limits, :attr:`RobotSpec.provisional_torque_joints`, the
            provisional ones: its description gives none).
    """

    gait_period: float
    swing_height: float
    standing_height: float
    standing_pose: tuple[float, ...]
    kp: tuple[float, ...]
    joint_damping: tuple[float, ...]
    command_low: tuple[float, float, float]
    command_high: tuple[float, float, float]
    torque_limit: tuple[float, ...] | None = None

    @classmethod
    def of(cls, robot: RobotSpec) -> "ExpertParameters":
        """The parameters ``robot`` walks with now (gains and damping from its compiled model when its
        description gives none; ``torque_limit`` ``None``, the robot's own)."""
        model = compile_model(robot)
        kp = robot.kp if robot.kp is not None else tuple(float(k) for k in model.actuator_gainprm[:, 0])
        damping = (robot.joint_damping if robot.joint_damping is not None else
                   tuple(float(d) for d in model.dof_damping[joint_qvel_indices(model, robot)]))
        return cls(gait_period=float(robot.gait_period), swing_height=float(robot.swing_height),
                   standing_height=float(robot.standing_height), standing_pose=tuple(robot.standing_pose),
                   kp=tuple(kp), joint_damping=tuple(damping), command_low=tuple(robot.command_low),
                   command_high=tuple(robot.command_high))

    def apply(self, robot: RobotSpec) -> RobotSpec:
        """``robot`` with these parameters (a fall below half the new standing height, unless it gives its own;
        with a ``torque_limit``, that limit and none of it provisional)."""
        min_height = robot.min_height if robot.min_height < self.standing_height else self.standing_height / 2
        torque = {} if self.torque_limit is None else {"torque_limit": self.torque_limit,
                                                       "provisional_torque_joints": ()}
        return robot.replace(gait_period=self.gait_period, swing_height=self.swing_height,
                             standing_height=self.standing_height, standing_pose=self.standing_pose, kp=self.kp,
                             joint_damping=self.joint_damping, command_low=self.command_low,
                             command_high=self.command_high, min_height=min_height, **torque)

    def changed(self, other: "ExpertParameters") -> list[str]:
        """The names of the parameters that differ from ``other``'s."""
        names = []
        for name in self.__dataclass_fields__:
            if getattr(self, name) is None or getattr(other, name) is None:  # torque_limit: the robot's own
                if (getattr(self, name) is None) != (getattr(other, name) is None):
                    names.append(name)
                continue
            a, b = np.asarray(getattr(self, name), float), np.asarray(getattr(other, name), float)
            if a.shape != b.shape or not np.allclose(a, b, rtol=1e-6, atol=1e-9):
                names.append(name)
        return names

    def yaml_lines(self, robot: RobotSpec, *, only: Sequence[str] | None = None) -> list[str]:
        """The parameters as lines of a robot YAML file (``docs/robots.md``), in ``robot``'s leg order; ``only``
        restricts them to those names (always with gait_period and standing_height, so that derived values are
        pinned)."""
        names = list(self.__dataclass_fields__)
        if only is not None:
            names = [n for n in names if n in set(only) | {"gait_period", "standing_height"}]
        lines = []
        for name in names:
            value = getattr(self, name)
            if value is None:
                continue
            if name in ("standing_pose", "kp", "joint_damping", "torque_limit"):
                lines.append(f"{name}: {per_joint_yaml(robot, value, digits=4 if name == 'standing_pose' else 3)}")
            elif name in ("command_low", "command_high"):
                lines.append(f"{name}: [{', '.join(_number(v, 3) for v in value)}]")
            else:
                lines.append(f"{name}: {_number(value, 4)}")
        return lines


def _number(value: float, digits: int) -> str:
    text = f"{float(value):.{digits}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def per_joint_yaml(robot: RobotSpec, values: Sequence[float], digits: int = 3) -> str:
    """Per-joint values in the shortest YAML form :func:`hierloco.envs.robots.robot_from_mjcf` reads: one number,
    one leg's list (used for every leg), or a mapping leg -> list.

        >>> from hierloco.envs.robots import get_robot
        >>> per_joint_yaml(get_robot("a1"), [0.0, 0.9, -1.8] * 4)
        '[0, 0.9, -1.8]'
    """
    text = [_number(v, digits) for v in values]
    if len(set(text)) == 1:
        return text[0]
    legs, start = [], 0
    for leg in robot.legs:
        legs.append(text[start:start + len(leg.joints)])
        start += len(leg.joints)
    if all(leg == legs[0] for leg in legs):
        return "[" + ", ".join(legs[0]) + "]"
    return "{" + ", ".join(f"{leg.name}: [{', '.join(values_)}]" for leg, values_ in zip(robot.legs, legs)) + "}"


# ---------------------------------------------------------------------------------------------------- candidates
@dataclass(frozen=True)
class Candidate:
    """A parameter set to screen, with a short label of what it changes."""

    params: ExpertParameters
    label: str


def lowered_posture(robot: RobotSpec, params: ExpertParameters, lowering: float) -> tuple[float, tuple] | None:
    """``(standing_height, standing_pose)`` with the body lowered by ``lowering`` of the feet's mean depth below
    the hips, the feet where they stand (leg IK within the joint limits), or ``None`` when the legs cannot."""
    from hierloco.components.kinematics import LegKinematics

    base = params.apply(robot)
    statics = standing_statics(base)
    depth = float(np.mean([leg.foot_drop for leg in statics.legs]))
    drop = lowering * depth
    kinematics = LegKinematics(base)
    q0 = np.asarray(params.standing_pose, float)
    feet = kinematics.forward(q0)
    target = feet + np.array([0.0, 0.0, drop])
    q = kinematics.inverse(target, q0)
    if np.abs(kinematics.forward(q) - target).max() > 1e-3:
        return None
    return params.standing_height - drop, tuple(float(v) for v in q)


def _scaled_box(params: ExpertParameters, scale: float) -> tuple[tuple, tuple]:
    low, high = np.asarray(params.command_low), np.asarray(params.command_high)
    centre, half = (low + high) / 2, (high - low) / 2
    return tuple((centre - scale * half).round(4).tolist()), tuple((centre + scale * half).round(4).tolist())


def gait_candidates(robot: RobotSpec, params: ExpertParameters, steps_per_action: int = STEPS_PER_ACTION, *,
                    gait_periods: Sequence[float] | None = None, swing_heights: Sequence[float] | None = None
                    ) -> list[Candidate]:
    """Stage 1: every admissible gait period of at least ``MIN_GAIT_PERIOD`` s x the foot lifts (the
    description's and ``SWING_FRACTIONS`` of the hips' height), or the ``gait_periods`` and ``swing_heights``
    given."""
    periods = [p for p in admissible_gait_periods(len(robot.gait_groups), steps_per_action) if p >= MIN_GAIT_PERIOD]
    if gait_periods is not None:
        periods = [float(p) for p in gait_periods]
    hips = float(np.mean([leg.hip_height for leg in standing_statics(params.apply(robot)).legs]))
    swings = [params.swing_height]
    for fraction in SWING_FRACTIONS:
        lift = round(fraction * hips, 3)
        if all(abs(lift - s) > 0.15 * s for s in swings):
            swings.append(lift)
    if swing_heights is not None:
        swings = [float(h) for h in swing_heights]
    return [Candidate(replace(params, gait_period=p, swing_height=s), f"gait_period {p:g} s, swing_height {s:g} m")
            for p in periods for s in sorted(swings)]


@dataclass(frozen=True)
class ServoSetting:
    """Servo gains and joint damping, with a short label.

    Attributes:
        kp: N m / rad per joint. joint_damping: N m s / rad per joint. label: what it changes (empty for the
            description's own). torque_limit: N m per joint (``None``: the robot's own, searched only where its
            limits are provisional).
    """

    kp: tuple[float, ...]
    joint_damping: tuple[float, ...]
    label: str
    torque_limit: tuple[float, ...] | None = None

    def on(self, base: Candidate) -> Candidate:
        """``base`` with these servos."""
        return Candidate(replace(base.params, kp=self.kp, joint_damping=self.joint_damping,
                                 torque_limit=self.torque_limit), base.label + self.label)


def _round_significant(value: float, digits: int = 2) -> float:
    return float(f"{value:.{digits}g}")


def servo_settings(robot: RobotSpec, params: ExpertParameters) -> list[ServoSetting]:
    """The servo grid around ``params`` (the robot standing as they describe it): first the description's own,
    second the rule of ``docs/robots.md`` (kp for a ``RULE_SAG`` sag, damping ``RULE_DAMPING_TIME`` x kp), then
    the rest of kp x joint damping:

    - kp: the description's, and the description's scaled up so that the joint sagging most under the standing
      load (static torque / kp, :func:`hierloco.envs.robots.check.standing_statics`) sags ``SAG_TARGETS`` rad
      (two significant digits; capped so that a ``SATURATION_ANGLE`` error saturates no motor; a level less than
      ``MIN_KP_STEP`` above the description's is the description's);
    - joint damping: the description's, and ``DAMPING_TIMES`` s x kp;
    - torque limits: the robot's own, unless some are provisional (the file and the description give them none:
      :func:`hierloco.envs.robots.check.robot_for_check`). Then the grid is kp x joint damping at ``params``'
      limit (the provisional one to start with), followed by the same at each lower level of
      :func:`torque_limit_levels`, highest first (kp levels and their cap computed at the first limit).

    Example:
        >>> from hierloco.envs.robots import get_robot
        >>> robot = get_robot("a1")
        >>> settings = servo_settings(robot, ExpertParameters.of(robot))
        >>> settings[0].label, settings[1].label
        ('', ', joint_damping 2 (0.02 s x kp)')
    """
    levels = torque_limit_levels(robot)
    start = params.torque_limit if params.torque_limit is not None else (robot.torque_limit if levels else None)
    tuned = params.apply(robot)
    model = compile_model(tuned)
    statics = standing_statics(tuned, model)
    static = np.array([t for leg in statics.legs for t in leg.static_torque])
    kp0, damping0 = np.asarray(params.kp, float), np.asarray(params.joint_damping, float)
    limited = model.actuator_forcerange[:, 1] > model.actuator_forcerange[:, 0]
    cap = np.where(limited, np.abs(model.actuator_forcerange).max(1), np.inf) / SATURATION_ANGLE
    sag = float(np.max(static / kp0))
    kp_levels = [(kp0, "", None)]
    for target in SAG_TARGETS:
        factor = sag / target
        if factor >= MIN_KP_STEP:
            kp = np.maximum(np.minimum([_round_significant(k * factor) for k in kp0], cap), kp0)
            if not np.allclose(kp, kp0):  # not capped back to the description's
                kp_levels.append((kp, f", kp {per_joint_text(robot, kp)} (sag {target:g} rad)", target))
    rule_kp = RULE_SAG if any(target == RULE_SAG for _, _, target in kp_levels) else None
    settings: dict[tuple, ServoSetting] = {}
    rule = None
    for kp, kp_label, target in kp_levels:
        dampings = [(damping0, "", None)]
        for time_ in DAMPING_TIMES:
            damping = np.array([_round_significant(v) for v in time_ * kp])
            dampings.append((damping, f", joint_damping {per_joint_text(robot, damping)} ({time_:g} s x kp)", time_))
        for damping, damping_label, time_ in dampings:
            key = (tuple(np.round(kp, 6)), tuple(np.round(damping, 6)))
            if key not in settings:
                settings[key] = ServoSetting(tuple(float(k) for k in kp), tuple(float(d) for d in damping),
                                             kp_label + damping_label, start)
            if rule is None and target == rule_kp and time_ == RULE_DAMPING_TIME:
                rule = settings[key]
    ordered = list(settings.values())
    ordered.remove(rule)
    ordered = [ordered[0], rule, *ordered[1:]]
    lower = [(limit, factor) for limit, factor in reversed(levels) if _below(limit, start)]
    return ordered + [replace(setting, torque_limit=limit, label=setting.label + torque_limit_label(robot, limit, factor))
                      for limit, factor in lower for setting in ordered]


def torque_limit_levels(robot: RobotSpec) -> list[tuple[tuple[float, ...], float]]:
    """The torque-limit levels searched for a robot with provisional limits, lowest first: ``(N m per joint,
    factor)``, the provisional joints at ``factor`` x the largest static torque standing for each of
    ``TORQUE_LIMIT_FACTORS`` (:func:`hierloco.envs.robots.check.torque_limit_level`), the others at their own.
    Empty for a robot whose limits are all given.

    Example:
        >>> from hierloco.envs.robots import A1
        >>> torque_limit_levels(A1)  # its file gives every joint a limit
        []
        >>> robot = A1.replace(provisional_torque_joints=A1.joint_names)  # as if it gave none
        >>> [(limit[0], factor) for limit, factor in torque_limit_levels(robot)]
        [(14.0, 1.5), (19.0, 2.0), (29.0, 3.0), (38.0, 4.0), (57.0, 6.0)]
    """
    if not robot.provisional_torque_joints:
        return []
    return [(torque_limit_level(robot, factor), float(factor)) for factor in TORQUE_LIMIT_FACTORS]


def torque_limit_label(robot: RobotSpec, limit: Sequence[float], factor: float | None = None) -> str:
    """``", torque_limit 36 N m (2 x the torque standing)"``: a candidate's label for a torque-limit level."""
    times = f" ({factor:g} x the torque standing)" if factor is not None else ""
    return f", torque_limit {per_joint_text(robot, limit)} N m{times}"


def _below(limit: Sequence[float] | None, other: Sequence[float] | None) -> bool:
    """Whether the torque limits ``limit`` are lower than ``other``'s (at some joint, and nowhere higher)."""
    if limit is None or other is None:
        return False
    a, b = np.asarray(limit, float), np.asarray(other, float)
    return bool(np.all(a <= b * (1 + 1e-9)) and np.any(a < b * (1 - 1e-9)))


def per_joint_text(robot: RobotSpec, values: Sequence[float]) -> str:
    """Per-joint values as :func:`per_joint_yaml` writes them, for a label."""
    return per_joint_yaml(robot, values, digits=3)


def posture_candidates(robot: RobotSpec, base: Candidate) -> list[Candidate]:
    """Stage 3, around ``base``: the body lowered (``LOWERINGS``) with the feet where they stand (leg IK)."""
    out = []
    for lowering in LOWERINGS:
        lowered = lowered_posture(robot, base.params, lowering)
        if lowered is not None:
            height, pose = lowered
            out.append(Candidate(replace(base.params, standing_height=float(height), standing_pose=tuple(pose)),
                                 base.label + f", body lowered {lowering:.0%}"))
    return out


def box_candidates(base: Candidate) -> list[Candidate]:
    """Stage 3, around ``base``: the command box shrunk about its centre (``BOX_SCALES``)."""
    out = []
    for scale in BOX_SCALES:
        low, high = _scaled_box(base.params, scale)
        out.append(Candidate(replace(base.params, command_low=low, command_high=high),
                             base.label + f", command box x{scale:g}"))
    return out


# ---------------------------------------------------------------------------------------------------- screening
@dataclass(frozen=True)
class CandidateScore:
    """How one candidate's experts did in the screening.

    Attributes:
        candidate: the parameters and their label.
        axes: per command axis, how the achieved velocities follow the commanded ones (``AxisTracking``).
        worst_reach: the smallest reach over axes and sides (fraction of the box half-width).
        replayed_fraction: the fraction of experts whose recorded targets, replayed open loop from standing,
            walk within ``REPRODUCTION_TOLERANCE`` of their recorded velocity.
        fell: experts that fell (closed loop or replayed). num_commands: the experts run.
        shortfall: m, how far the gait's footholds are out of the legs' reach (not run when over
            ``MAX_REACH_SHORTFALL``).
    """

    candidate: Candidate
    axes: tuple[AxisTracking, ...] = ()
    worst_reach: float = -math.inf
    replayed_fraction: float = 0.0
    fell: int = 0
    num_commands: int = 0
    shortfall: float = 0.0
    min_reach: float = MIN_REACH
    min_reproduced_fraction: float = MIN_REPRODUCED_FRACTION

    @property
    def score(self) -> float:
        """``min(worst_reach / min_reach, replayed_fraction / bar)``, times the fraction that did not fall."""
        if not self.num_commands:
            return -math.inf
        walked = 1.0 - self.fell / self.num_commands
        replay = self.replayed_fraction / self.min_reproduced_fraction if self.min_reproduced_fraction > 0 else 1.0
        return min(self.worst_reach / self.min_reach, replay) * walked  # a bar of 0 asks nothing of the replay

    @property
    def passes(self) -> bool:
        return bool(self.num_commands and self.fell == 0 and self.worst_reach >= self.min_reach
                    and self.replayed_fraction >= self.min_reproduced_fraction)

    def describe(self) -> str:
        if not self.num_commands:
            return (f"{self.candidate.label}: not run, its footholds are {self.shortfall:.3f} m out of the legs' "
                    "reach")
        return (f"{self.candidate.label}: reach {self.worst_reach:+.2f} (need {self.min_reach:.2f}), replayed "
                f"{self.replayed_fraction:.0%} (need {self.min_reproduced_fraction:.0%}), fell {self.fell} of "
                f"{self.num_commands}")


def screening_commands(params: ExpertParameters, *, num_random: int = 6, seed: int = 0) -> np.ndarray:
    """``C x 3`` commands: both edges of each axis of the box (the others at the centre), then ``num_random``
    uniform in it."""
    low, high = np.asarray(params.command_low, float), np.asarray(params.command_high, float)
    centre = (low + high) / 2
    edges = []
    for axis in range(3):
        for bound in (low, high):
            command = centre.copy()
            command[axis] = bound[axis]
            edges.append(command)
    rng = np.random.default_rng(seed)
    return np.concatenate([np.asarray(edges), rng.uniform(low, high, size=(num_random, 3))])


def screen_candidates(robot: RobotSpec, candidates: Sequence[Candidate], *, settle_time: float = 2.0,
                      steps_per_action: int = STEPS_PER_ACTION, num_random: int = 6, seed: int = 0,
                      replay_actions: int = 4, min_reach: float = MIN_REACH,
                      min_reproduced_fraction: float = MIN_REPRODUCED_FRACTION,
                      nthread: int | None = None) -> list[CandidateScore]:
    """Runs every candidate's experts side by side in one batched simulation and scores them (see the module
    docstring), in the order given.

    Each candidate runs ``6 + num_random`` commands (:func:`screening_commands`): ``settle_time`` s closed loop
    with the expert controller (leg IK: the vectorised solver), one gait period frozen, one action recorded, as
    :func:`hierloco.components.expert_library.build_expert_library` does; then the recorded actions replayed open
    loop ``replay_actions`` times from standing.
    """
    scores: list[CandidateScore | None] = [None] * len(candidates)
    runnable = []
    for i, candidate in enumerate(candidates):
        tuned = candidate.params.apply(robot)
        shortfall = float(foothold_reach(tuned).shortfall.max())
        if shortfall > MAX_REACH_SHORTFALL:
            scores[i] = CandidateScore(candidate, shortfall=shortfall, min_reach=min_reach,
                                       min_reproduced_fraction=min_reproduced_fraction)
        else:
            runnable.append((i, tuned, shortfall))
    if not runnable:
        return scores
    commands = [screening_commands(candidates[i].params, num_random=num_random, seed=seed) for i, _, _ in runnable]
    per = len(commands[0])
    copies = [tuned for _, tuned, _ in runnable for _ in range(per)]
    all_commands = np.concatenate(commands)
    sim = BatchedSimulator(robot, len(copies), copy_robots=copies, nthread=nthread, seed=seed)
    try:
        groups = _controller_groups(runnable, per, settle_time)
        targets, result = _run_closed_loop_groups(sim, groups, all_commands, steps_per_action)
        n = steps_per_action
        patterns = np.empty((len(copies), n, robot.num_joints))
        states = np.empty((len(copies), n + 1, 5))
        failed = np.zeros(len(copies), bool)
        for controller, index, settle_steps in groups:
            record = settle_steps + controller.steps_per_period
            patterns[index] = targets[index, record:record + n]
            states[index] = result.com_state[index, record - 1:record + n]
            failed[index] = result.failed[index, record + n - 1]
        _, velocity, yaw_rate = action_motion(states, n * CONTROL_TIMESTEP)
        achieved = np.concatenate([velocity, yaw_rate[:, None]], -1)
        sim.reset()
        replays = [sim.run(patterns) for _ in range(replay_actions)]
        velocities, replay_fell = action_velocities(replays, n)
        error = np.linalg.norm(np.mean(velocities, 0) - velocity, axis=-1)
        reproduced = (error <= REPRODUCTION_TOLERANCE) & ~replay_fell & ~failed
    finally:
        sim.close()
    for k, (i, _, shortfall) in enumerate(runnable):
        rows = slice(k * per, (k + 1) * per)
        params = candidates[i].params
        ok = ~failed[rows]
        cmd, got = all_commands[rows], achieved[rows]
        if ok.sum() >= 2:
            axes = tuple(_axis_tracking(a, cmd[ok, a], got[ok, a], params.command_low[a], params.command_high[a],
                                        min_reach) for a in range(3))
            reaches = [r for axis in axes for r in (axis.reach_low, axis.reach_high) if math.isfinite(r)]
            worst = min(reaches) if reaches else math.inf
        else:
            axes, worst = (), -math.inf
        scores[i] = CandidateScore(candidates[i], axes=axes, worst_reach=float(worst),
                                   replayed_fraction=float(reproduced[rows].mean()),
                                   fell=int((failed[rows] | replay_fell[rows]).sum()), num_commands=per,
                                   shortfall=shortfall, min_reach=min_reach,
                                   min_reproduced_fraction=min_reproduced_fraction)
    return scores


def _controller_groups(runnable, per: int, settle_time: float) -> list[tuple[RaibertController, np.ndarray, int]]:
    """One expert controller per distinct gait (period, lift, posture, box), over the copies that walk it."""
    by_key: dict[tuple, list[int]] = {}
    robots = {}
    for k, (_, tuned, _) in enumerate(runnable):
        key = (tuned.gait_period, tuned.swing_height, tuned.standing_height, tuned.standing_pose, tuned.command_low,
               tuned.command_high)
        by_key.setdefault(key, []).extend(range(k * per, (k + 1) * per))
        robots.setdefault(key, tuned)
    groups = []
    for key, index in by_key.items():
        tuned = robots[key]
        controller = RaibertController(tuned, len(index), ik_solver="vectorised")
        period_steps = controller.steps_per_period
        settle_steps = int(np.ceil(settle_time / tuned.gait_period - 1e-9)) * period_steps
        groups.append((controller, np.asarray(index), settle_steps))
    return groups


def _run_closed_loop_groups(sim: BatchedSimulator, groups, commands: np.ndarray, steps_per_action: int):
    """:func:`hierloco.components.experts.run_closed_loop` (feedback every step, the command ramped over the
    settling up to 1 s, the feedback frozen after it) with one controller per group of copies and one simulator
    call per control step for all of them. Returns ``B x T x J`` joint targets and the per-step result."""
    total = max(settle + c.steps_per_period + steps_per_action for c, _, settle in groups)
    state = sim.com_state
    velocity = world_to_local(state[:, 3:5], state[:, 2])[:, None]
    yaw_rate = np.zeros((sim.num_robots, 1))
    targets = np.empty((sim.num_robots, total, sim.robot.num_joints))
    results = []
    for n in range(total):
        action = np.empty((sim.num_robots, 1, sim.robot.num_joints))
        for controller, index, settle in groups:
            if n == settle:
                controller.freeze()
            ramp = min(settle, 100)
            scale = min(1.0, (n + 1) / ramp) if ramp else 1.0
            action[index] = controller.act_chunk(commands[index, None, :] * scale, velocity[index], yaw_rate[index])
        out = sim.run(action)
        velocity, yaw_rate = out.com_velocity_local, out.yaw_rate
        targets[:, n] = action[:, 0]
        results.append(out)
    return targets, SimulationResult.concatenate(results)


def rank(scores: Sequence[CandidateScore], reference: ExpertParameters) -> list[CandidateScore]:
    """Best first: candidates that pass, then by score (capped at ``SCORE_CAP``: beyond that margin, the fewest
    changes from ``reference`` win), then by uncapped score."""
    return sorted(scores, key=lambda s: (not s.passes, -min(s.score, SCORE_CAP),
                                         len(s.candidate.params.changed(reference)), -s.score))


# ---------------------------------------------------------------------------------------------------- the search
@dataclass
class Verification:
    """A candidate checked as the pipeline will run it: the expert library, its tracking, the gait policy.

    Attributes:
        candidate: what was verified. report: the library's tracking report (``None`` when it was not built).
        replayed_fraction: the library's own targets replayed open loop, within 0.05 m/s.
        reproduced_fraction: the gait policy's check (``None`` when no policy was trained).
        policy_attempts: the gait-policy fits tried (:class:`hierloco.components.gait_policy_fit.GaitPolicyFit`).
        problem: why it does not walk, in one line (empty when it does). seconds: how long it took.
    """

    candidate: Candidate
    report: ExpertTrackingReport | None = None
    replayed_fraction: float | None = None
    reproduced_fraction: float | None = None
    policy_attempts: list = field(default_factory=list)
    problem: str = ""
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.problem

    @property
    def policy_adapted(self) -> dict | None:
        """The gait-policy fit that reached the bar when the configured one did not (its ``overrides``: the
        recipe's ``policy.*`` values that train it), else ``None``."""
        if not self.ok or len(self.policy_attempts) < 2:
            return None
        return self.policy_attempts[-1]

    @property
    def progress(self) -> tuple:
        """How far it got, for choosing the verification to show when none passes: the stage reached (library
        built, its tracking passed, its replay passed, a gait policy trained), then that stage's number."""
        if self.report is None:
            return (0, 0.0)
        if not self.report.ok:
            return (1, self.report.worst_reach)
        if self.reproduced_fraction is None:
            return (2, self.replayed_fraction or 0.0)
        return (3, self.reproduced_fraction)

    def limit_lines(self) -> list[str]:
        """What limits it, from its own numbers only (the library it built, its replay, its gait policy)."""
        if self.report is None:
            return [self.problem]
        lines = [axis.describe() for axis in self.report.axes if not axis.ok] + [self.problem]
        if not self.report.ok:
            lines.append(f"the experts' own targets, replayed open loop: {self.replayed_fraction:.0%} within "
                         f"{REPRODUCTION_TOLERANCE} m/s")
        return lines


@dataclass(frozen=True)
class Difference:
    """One change of the parameters found, undone alone (the others kept) and screened beside them.

    Attributes:
        name: the parameter (``standing_height`` stands for the height and its pose, ``command box`` for both
            edges). before, after: its value in the description and in what was found, as text.
        undone: the screening of the parameters found with this change undone. found: theirs, in the same batch.
        how: how it was undone, for the line (a torque limit the description lacks cannot be: the next lower
            level is screened instead, so that "needed" says the gait needs that peak torque).
    """

    name: str
    before: str
    after: str
    undone: CandidateScore
    found: CandidateScore
    how: str = "undone"

    @property
    def needed(self) -> bool:
        """Undoing it fails the screening: this change made the difference."""
        return not self.undone.passes

    @property
    def margin(self) -> bool:
        """Undoing it still passes, with less margin (a lower score, capped at ``SCORE_CAP``)."""
        return not self.needed and min(self.undone.score, SCORE_CAP) < min(self.found.score, SCORE_CAP) - 1e-9

    def describe(self) -> str:
        if self.needed:
            verdict = "it made the difference"
            if self.name == "torque_limit":
                verdict += (": the motors' peak torque the gait needs (none in the file nor the description; check "
                            "it against your motors)")
        elif self.margin:
            verdict = (f"passes without it with less margin (score {self.undone.score:.2f}, with it "
                       f"{min(self.found.score, SCORE_CAP):.2f}{'+' if self.found.score > SCORE_CAP else ''})")
        else:
            verdict = "not needed alone"
        return f"{self.name} {self.before} -> {self.after}: {self.how}, " \
               f"{self.undone.describe().split(': ', 1)[-1]}; {verdict}"


DIFFERENCE_GROUPS = (("gait_period", ("gait_period",)), ("swing_height", ("swing_height",)),
                     ("standing_height", ("standing_height", "standing_pose")), ("kp", ("kp",)),
                     ("joint_damping", ("joint_damping",)), ("command box", ("command_low", "command_high")),
                     ("torque_limit", ("torque_limit",)))


def _value_text(robot: RobotSpec, params: ExpertParameters, names: Sequence[str]) -> str:
    if names[0] == "torque_limit":
        limit = params.torque_limit
        return "none" if limit is None else f"{per_joint_text(robot, limit)} N m"
    if names[0] in ("kp", "joint_damping"):
        return per_joint_text(robot, getattr(params, names[0]))
    if names[0] == "command_low":
        return f"{_number(params.command_low[0], 3)}..{_number(params.command_high[0], 3)} m/s, " \
               f"{_number(params.command_low[1], 3)}..{_number(params.command_high[1], 3)} m/s, " \
               f"{_number(params.command_low[2], 3)}..{_number(params.command_high[2], 3)} rad/s"
    unit = " s" if names[0] == "gait_period" else " m"
    return _number(getattr(params, names[0]), 4) + unit


def _undone_text(robot: RobotSpec, name: str, candidate: Candidate) -> str:
    if name == "torque_limit":
        return f"at the next lower level, {per_joint_text(robot, candidate.params.torque_limit)} N m"
    return "undone"


def difference_candidates(robot: RobotSpec, found: ExpertParameters, reference: ExpertParameters
                          ) -> list[tuple[str, str, str, Candidate]]:
    """For each change ``found`` makes to ``reference`` (``DIFFERENCE_GROUPS``), ``(name, before, after,
    candidate)``: ``found`` with that change alone undone; a torque limit the description lacks (its provisional
    limits) is lowered instead to the next level of :func:`torque_limit_levels` (below the lowest, 1 x the torque
    standing: a motor that only just holds the robot up)."""
    changed = set(found.changed(reference))
    out = []
    for name, names in DIFFERENCE_GROUPS:
        if not changed & set(names):
            continue
        if name == "torque_limit":
            lower = [limit for limit, _ in torque_limit_levels(robot) if _below(limit, found.torque_limit)]
            if not lower and robot.provisional_torque_joints:
                lower = [level for level in [torque_limit_level(robot, 1.0)] if _below(level, found.torque_limit)]
            if not lower or reference.torque_limit is not None:
                continue
            out.append((name, _value_text(robot, reference, names), _value_text(robot, found, names),
                        Candidate(replace(found, torque_limit=lower[-1]), f"{name} lowered")))
            continue
        undone = replace(found, **{n: getattr(reference, n) for n in names})
        out.append((name, _value_text(robot, reference, names), _value_text(robot, found, names),
                    Candidate(undone, f"{name} undone")))
    return out


@dataclass
class TuningResult:
    """What :func:`tune_expert_parameters` found.

    Attributes:
        robot: the robot searched. reference: its own parameters. found: whether a candidate was verified.
        best: the best candidate's screening score (``None`` when nothing could be run).
        verifications: the candidates verified, in order. screened: every screening score, per stage.
        limits: when nothing is found, what limits it (lines, each saying whether its numbers are verified or
            screened). seconds: the wall-clock. differences: each change of the parameters found undone alone
            (:class:`Difference`).
    """

    robot: RobotSpec
    reference: ExpertParameters
    found: bool
    best: CandidateScore | None
    verifications: list[Verification]
    screened: dict[str, list[CandidateScore]]
    limits: list[str]
    seconds: float
    min_reproduced_fraction: float = MIN_REPRODUCED_FRACTION
    differences: list[Difference] = field(default_factory=list)

    @property
    def verified(self) -> Verification | None:
        """The candidate found: the first verified whose gait policy passes as configured, else the first whose
        adapted fit passes."""
        passing = [v for v in self.verifications if v.ok]
        return next((v for v in passing if v.policy_adapted is None), passing[0] if passing else None)

    @property
    def shown(self) -> Verification | None:
        """The verification the result is about: the one found, else the one that got furthest (``None`` when
        none ran)."""
        if self.verified is not None:
            return self.verified
        return max(self.verifications, key=lambda v: v.progress, default=None)

    @property
    def params(self) -> ExpertParameters | None:
        """The parameters found (the verified candidate's), else those of the verification shown, else the best
        screened."""
        if self.shown is not None:
            return self.shown.candidate.params
        return self.best.candidate.params if self.best is not None else None

    @property
    def policy_overrides(self) -> dict:
        """The recipe's ``policy.*`` overrides the found candidate's gait policy needs (empty when the configured
        training reproduces its experts)."""
        verified = self.verified
        return dict((verified.policy_adapted or {}).get("overrides", {})) if verified is not None else {}

    def override_lines(self) -> list[str]:
        """``policy.epochs=300``-style command-line overrides of a recipe, one per line."""
        return [f"policy.{key}={value:g}" if isinstance(value, (int, float)) else f"policy.{key}={value}"
                for key, value in self.policy_overrides.items()]

    def tuned_robot(self) -> RobotSpec:
        """The robot with the parameters found (its own when nothing was found)."""
        params = self.params if self.found else None
        return self.robot if params is None else params.apply(self.robot)

    def summary(self) -> dict:
        """A JSON-able record (for a run's ``run.json``): whether found, the parameters and the YAML lines, what
        changed and which changes made the difference, the tuned robot's fingerprint, the verifications (tracking,
        replay, gait-policy fits), the screening counts and the wall-clock."""
        from dataclasses import asdict

        from hierloco.envs.robots import robot_fingerprint

        params = self.params
        parameters = asdict(params) if params is not None else None
        if parameters is not None and parameters["torque_limit"] is None:
            del parameters["torque_limit"]  # the robot's own: as before torque limits were searched
        return {
            "found": self.found, "seconds": round(self.seconds, 1),
            "parameters": parameters,
            "changed": params.changed(self.reference) if params is not None else [],
            "yaml": params.yaml_lines(self.robot, only=params.changed(self.reference)) if params is not None else [],
            "tuned_fingerprint": robot_fingerprint(self.tuned_robot()),
            "policy_overrides": self.policy_overrides,
            "differences": [{"name": d.name, "before": d.before, "after": d.after, "needed": d.needed,
                             "margin": d.margin, "undone": d.undone.describe()} for d in self.differences],
            "screened": {stage: {"candidates": len(scores), "pass": sum(s.passes for s in scores)}
                         for stage, scores in self.screened.items()},
            "verifications": [{"label": v.candidate.label, "problem": v.problem,
                               "tracking": v.report.summary() if v.report is not None else None,
                               "replayed_fraction": v.replayed_fraction,
                               "reproduced_fraction": v.reproduced_fraction, "policy_attempts": v.policy_attempts,
                               "seconds": round(v.seconds, 1)} for v in self.verifications],
            "limits": self.limits,
        }


def _gait_key(params: ExpertParameters) -> tuple:
    return (params.gait_period, params.swing_height, params.standing_height, params.command_low, params.command_high)


def tune_expert_parameters(
    robot: str | RobotSpec,
    *,
    budget_seconds: float = 300.0,
    num_experts: int = 30,
    settle_time: float = 3.0,
    screening_settle_time: float = 2.0,
    steps_per_action: int = STEPS_PER_ACTION,
    policy: dict | None = None,
    min_reach: float = MIN_REACH,
    min_reproduced_fraction: float = MIN_REPRODUCED_FRACTION,
    verify: bool = True,
    max_verifications: int = 3,
    gait_periods: Sequence[float] | None = None,
    swing_heights: Sequence[float] | None = None,
    seed: int = 0,
    nthread: int | None = None,
    log: Callable[[str], None] | None = None,
) -> TuningResult:
    """Searches ``robot``'s expert-controller parameters (see the module docstring) within ``budget_seconds``.

    Args:
        robot: a registered name, a YAML path or a :class:`RobotSpec`.
        budget_seconds: s of wall-clock; no stage or verification starts after it, nor one that would not end
            within it (the one running finishes: its gait policy gets one longer fit whatever the budget, then
            adapts further only within it). The torque-limit screening of a robot with provisional limits and
            the screening of what made the difference run whatever the budget (one batch each).
        num_experts, settle_time: the expert library verified (the experts stage's ``num_experts``,
            ``settle_time``; default: the small preset's).
        screening_settle_time: s of closed-loop walking before each screened expert is recorded.
        policy: keyword arguments of :func:`hierloco.components.gait_policy.train_gait_policy` for the verified
            gait policy (default: the small preset's, 150 epochs of 2 x 512).
        min_reach: the experts' tracking bar (``checks.min_expert_reach``).
        min_reproduced_fraction: the gait policy's bar (``checks.min_reproduced_fraction``).
        verify: build the library and train the gait policy for the best candidates (else screening only).
        max_verifications: at most this many candidates verified.
        gait_periods, swing_heights: s and m, restrict the first stage to these (default: every admissible period
            of at least ``MIN_GAIT_PERIOD`` s, the description's foot lift and ``SWING_FRACTIONS`` of the hips'
            height).
        log: called with a line per step (progress for a terminal).

    ``robot`` may have provisional torque limits (:attr:`RobotSpec.provisional_torque_joints`, as
    :func:`hierloco.envs.robots.check.robot_for_check` reads a file without them): the search then also finds the
    smallest torque limit that walks (see the module docstring), a parameter of what it found.

    Returns:
        a :class:`TuningResult`.
    """
    start = time.perf_counter()
    robot = get_robot(robot)
    log = log or (lambda line: None)
    reference = ExpertParameters.of(robot)
    screen = dict(settle_time=screening_settle_time, steps_per_action=steps_per_action, seed=seed,
                  min_reach=min_reach, min_reproduced_fraction=min_reproduced_fraction, nthread=nthread)
    left = lambda: budget_seconds - (time.perf_counter() - start)  # noqa: E731
    screened: dict[str, list[CandidateScore]] = {}

    def run_stage(name: str, candidates: list[Candidate]) -> list[CandidateScore]:
        tic = time.perf_counter()
        scores = screen_candidates(robot, candidates, **screen)
        screened[name] = scores
        best = rank(scores, reference)[0]
        log(f"  {name}: {len(candidates)} candidates, {sum(s.passes for s in scores)} pass "
            f"({time.perf_counter() - tic:.0f} s); best: {best.describe()}")
        return scores

    def everything() -> list[CandidateScore]:
        return [s for name, scores in screened.items() for s in scores]

    # 1. gait period x foot lift x (the description's servos, the docs' rule)
    settings = servo_settings(robot, reference)
    gaits = gait_candidates(robot, reference, steps_per_action, gait_periods=gait_periods,
                            swing_heights=swing_heights)
    run_stage("gait period x swing height x servo gains", [s.on(g) for g in gaits for s in settings[:2]])
    def settled() -> bool:  # a candidate passes with the margin beyond which the fewest changes win
        return any(s.passes and s.score >= SCORE_CAP for s in everything())

    # 2. the rest of the servo grid around the two best gaits, unless one already passes with that margin
    if left() > 0 and not settled():
        bases, seen = [], set()
        for score in rank(everything(), reference):
            key = _gait_key(score.candidate.params)
            if score.num_commands and key not in seen:
                seen.add(key)
                bases.append(next(g for g in gaits if _gait_key(g.params) == key))
            if len(bases) == 2:
                break
        stage2 = []
        for base in bases:  # at the first torque limit (the robot's own, or the provisional one)
            grid = servo_settings(robot, base.params)
            stage2 += [s.on(base) for s in grid[2:] if s.torque_limit == grid[0].torque_limit]
        if stage2:
            run_stage("servo gains x joint damping", stage2)
    # 3. the body lowered around the best, likewise
    if left() > 0 and not settled():
        tops = [s for s in rank(everything(), reference) if s.num_commands][:1]
        lowered = [c for s in tops for c in posture_candidates(robot, s.candidate)]
        if lowered:
            run_stage("standing height", lowered)
    # 4. smaller command boxes, only when nothing passes
    if not any(s.passes for s in everything()) and left() > 0:
        tops = [s for s in rank(everything(), reference) if s.num_commands][:3]
        if tops:
            run_stage("smaller command boxes", [c for s in tops for c in box_candidates(s.candidate)])
    # 5. for provisional torque limits, the best candidate at each lower level: the smallest that passes first
    lowest = []
    levels = torque_limit_levels(robot)
    tops = [s for s in rank(everything(), reference) if s.passes][:1]
    if levels and tops:  # like what made the difference, whatever the budget: the limit is a motor requirement
        top = tops[0].candidate
        lower = [Candidate(replace(top.params, torque_limit=limit), top.label + torque_limit_label(robot, limit, f))
                 for limit, f in levels if _below(limit, top.params.torque_limit)]
        if lower:
            scores = run_stage("torque limit", lower)
            lowest = [s for s in scores if s.passes]  # lowest limit first
            log(f"    smallest torque limit that passes: "
                f"{per_joint_text(robot, (lowest[0] if lowest else tops[0]).candidate.params.torque_limit)} N m")
    ranked = rank(everything(), reference)
    ranked = lowest + [s for s in ranked if not any(s is t for t in lowest)]
    best = ranked[0] if ranked and ranked[0].num_commands else None
    verifications: list[Verification] = []
    if verify and best is not None:
        for score in [s for s in ranked if s.passes][:max_verifications] or [best]:
            if left() <= 0 or (verifications and left() < verifications[-1].seconds):
                break  # another verification would overrun the budget
            verification = verify_candidate(robot, score.candidate, num_experts=num_experts,
                                            settle_time=settle_time, steps_per_action=steps_per_action,
                                            policy=policy, min_reach=min_reach,
                                            min_reproduced_fraction=min_reproduced_fraction, seed=seed,
                                            budget_seconds=left(), log=log)
            verifications.append(verification)
            if verification.ok and verification.policy_adapted is None:
                break  # else look on, while the budget lasts, for one the configured training reproduces
    found = any(v.ok for v in verifications) if verify else bool(best is not None and best.passes)
    result = TuningResult(robot=robot, reference=reference, found=found, best=best, verifications=verifications,
                          screened=screened, limits=[], seconds=0.0, min_reproduced_fraction=min_reproduced_fraction)
    if found:  # 5. which change made the difference: each undone alone, screened
        undone = difference_candidates(robot, result.params, reference)
        if undone:
            tic = time.perf_counter()
            found_score, *scores = screen_candidates(
                robot, [Candidate(result.params, "found"), *(c for *_, c in undone)], **screen)
            result.differences = [Difference(name, before, after, score, found_score,
                                             how=_undone_text(robot, name, candidate))
                                  for (name, before, after, candidate), score in zip(undone, scores)]
            log(f"  what made the difference: {len(undone)} change{'s' if len(undone) > 1 else ''} undone one at a "
                f"time, {sum(d.needed for d in result.differences)} needed ({time.perf_counter() - tic:.0f} s)")
    else:
        result.limits = _limits(best, verifications)
    result.seconds = time.perf_counter() - start
    return result


def verify_candidate(robot: RobotSpec, candidate: Candidate, *, num_experts: int, settle_time: float,
                     steps_per_action: int, policy: dict | None, min_reach: float, min_reproduced_fraction: float,
                     seed: int, budget_seconds: float, log: Callable[[str], None]) -> Verification:
    """Checks one candidate as the pipeline runs it: :func:`build_expert_library` (the reference IK), its tracking
    report, the library replayed open loop, and :func:`hierloco.components.gait_policy_fit.fit_gait_policy` (on
    ``POLICY_THREADS`` torch thread)."""
    from hierloco.components.gait_policy_fit import fit_gait_policy
    from hierloco.components.sac import torch_threads

    tic = time.perf_counter()
    tuned = candidate.params.apply(robot)
    verification = Verification(candidate)
    log(f"  verifying {candidate.label}: {num_experts} experts, {settle_time:g} s settling")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            library = build_expert_library(tuned, num_experts, steps_per_action=steps_per_action, seed=seed,
                                           settle_time=settle_time, progress=False)
    except ExpertQualityError as error:
        verification.problem = f"the experts stage stops: {' '.join(str(error).split())}"
        verification.seconds = time.perf_counter() - tic
        return verification
    report = diagnose_expert_library(library, robot=tuned, min_reach=min_reach)
    verification.report = report
    verification.replayed_fraction = replayed_fraction(library, robot=tuned, seed=seed)
    if not report.ok:
        verification.problem = (f"its {num_experts} experts do not walk as commanded (worst reach "
                                f"{report.worst_reach:.2f}, need {min_reach:.2f})")
    elif verification.replayed_fraction < min_reproduced_fraction:
        verification.problem = (f"the experts' own targets, replayed open loop, reproduce "
                                f"{verification.replayed_fraction:.0%} of them (need {min_reproduced_fraction:.0%}): "
                                "no gait policy can do better")
    else:
        remaining = budget_seconds - (time.perf_counter() - tic)
        with torch_threads(POLICY_THREADS):
            fit = fit_gait_policy(library, robot=tuned, min_reproduced_fraction=min_reproduced_fraction,
                                  budget_seconds=max(remaining, 0.0), min_attempts=2, seed=seed, **(policy or {}))
        verification.reproduced_fraction = fit.reproduced_fraction
        verification.policy_attempts = fit.attempts
        for attempt in fit.attempts:
            log(f"    gait policy ({attempt['name']}): reproduces {attempt['reproduced_fraction']:.0%} "
                f"({attempt['seconds']:.0f} s)")
        if not fit.ok:
            verification.problem = (f"the gait policy reproduces {fit.reproduced_fraction:.0%} of the experts "
                                    f"(need {min_reproduced_fraction:.0%}) after {len(fit.attempts)} fits")
    verification.seconds = time.perf_counter() - tic
    return verification


def _limits(best: CandidateScore | None, verifications: list[Verification]) -> list[str]:
    """What limits the search, in lines: the verification that got furthest, from its own numbers (``verified``),
    then the best screened candidate when it does not pass (``screened``)."""
    if best is None:
        return ["no candidate could be run: the gait's footholds are out of the legs' reach for every gait period"]
    lines = []
    shown = max(verifications, key=lambda v: v.progress, default=None)
    if shown is not None:
        lines += [f"verified ({shown.candidate.label}): {line}" for line in shown.limit_lines()]
    if not best.passes:
        where = f"screened ({best.candidate.label})"
        if best.fell:
            lines.append(f"{where}: {best.fell} of {best.num_commands} experts fell")
        for axis in best.axes:
            if not axis.ok:
                lines.append(f"{where}: {axis.describe()}")
        if best.replayed_fraction < best.min_reproduced_fraction:
            lines.append(f"{where}: replayed open loop, {best.replayed_fraction:.0%} of the experts walk as "
                         f"recorded (need {best.min_reproduced_fraction:.0%}): the gait is not steady without "
                         "feedback")
    return lines


__all__ = ["Candidate", "CandidateScore", "DIFFERENCE_GROUPS", "Difference", "ExpertParameters", "ServoSetting",
           "TuningResult", "Verification", "box_candidates", "difference_candidates", "gait_candidates",
           "lowered_posture", "per_joint_text", "per_joint_yaml", "posture_candidates", "rank", "screen_candidates",
           "screening_commands", "servo_settings", "torque_limit_label", "torque_limit_levels",
           "tune_expert_parameters", "verify_candidate"]
