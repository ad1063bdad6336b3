"""The expert library: G expert gaits, each one latent action (N control steps) of joint targets (Li et al.,
Sec. III-B).

:func:`build_expert_library` samples G commands ``(vx, vy, yaw_rate)`` in the robot's command box, runs the
:class:`RaibertController` on each (all G in one batched simulation) until it is at steady state, then records one
action's worth of joint targets, starting on a gait-cycle boundary, with the CoM motion it achieved. The feedback
is frozen one gait period before recording, so each expert is an exactly periodic open-loop pattern. An expert that
falls or blows up is replaced by a fresh command; no failed gait enters the library.

Each expert's tracking (achieved minus commanded velocity and yaw rate, over the recorded action) is kept in the
library. :func:`diagnose_expert_library` says whether the experts can represent the command box the latent space
must span, and :func:`require_expert_library_quality` stops a run with an :class:`ExpertQualityError` when they
cannot (say a robot that walks backward whatever it is commanded): how far off, in which direction, what to try.

Example:
    >>> lib = build_expert_library("daisy", 3, progress=False)
    >>> lib.joint_targets.shape  # G x N x J
    (3, 100, 18)
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np
from tqdm.auto import tqdm

from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.frames import world_to_local
from hierloco.envs.terrain import make_terrain
from hierloco.envs.robots import (
    CONTROL_TIMESTEP,
    RobotSpec,
    admissible_gait_periods,
    derive_gait_period,
    derive_standing_height,
    get_robot,
    robot_fingerprint,
)
from hierloco.errors import Finding
from hierloco.io import ArtifactError, load_arrays, save_arrays

LIBRARY_FORMAT = 1


@dataclass
class ExpertLibrary:
    """G recorded expert gaits of one robot.

    Attributes:
        commands: ``G x 3`` commanded ``(vx, vy, yaw_rate)`` in the local frame (m/s, m/s, rad/s).
        joint_targets: ``G x N x J`` joint targets in rad, one action starting on a gait-cycle boundary.
        com_states: ``G x (N + 1) x 5`` world ``(x, y, yaw, vx, vy)`` at the start and after each step.
        foot_contacts: ``G x N x L`` bool.
        velocity_local: ``G x 2`` mean CoM velocity over the action in its start frame, m/s.
        yaw_rate: ``G`` mean yaw rate over the action, rad/s.
        displacement_local: ``G x 3`` ``(dx, dy, dyaw)`` over the action in the start frame (m, m, rad).
        metadata: robot (name, reference for :func:`get_robot`, source, fingerprint), N, gait period, seed,
            settle time, disabled legs, rejected commands, command box, tracking summary
            (:meth:`ExpertTrackingReport.summary`).
        tracking_error: ``G x 3`` achieved minus commanded ``(vx, vy, yaw_rate)`` (m/s, m/s, rad/s), local frame
            (computed from the other arrays when not given).
    """

    commands: np.ndarray
    joint_targets: np.ndarray
    com_states: np.ndarray
    foot_contacts: np.ndarray
    velocity_local: np.ndarray
    yaw_rate: np.ndarray
    displacement_local: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)
    tracking_error: np.ndarray | None = None

    def __post_init__(self):
        if self.tracking_error is None:
            self.tracking_error = self.achieved - self.commands

    @property
    def achieved(self) -> np.ndarray:
        """``G x 3`` achieved ``(vx, vy, yaw_rate)`` over the recorded action (m/s, m/s, rad/s), local frame."""
        return np.concatenate([self.velocity_local, self.yaw_rate[:, None]], -1)

    @property
    def num_experts(self) -> int:
        return self.commands.shape[0]

    @property
    def steps_per_action(self) -> int:
        return self.joint_targets.shape[1]

    @property
    def robot(self) -> str:
        """The string :func:`get_robot` turns into this library's robot in any process (name or YAML path)."""
        return self.metadata.get("robot_reference", self.metadata["robot"])

    def save(self, path: str | os.PathLike) -> None:
        """Writes the library to ``path`` (``.npz``) atomically."""
        arrays = {name: value for name, value in asdict(self).items() if name != "metadata"}
        save_arrays(path, arrays, {**self.metadata, "format": LIBRARY_FORMAT, "kind": "expert_library"})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ExpertLibrary":
        arrays, metadata = load_arrays(path)
        if metadata.get("kind") != "expert_library" or metadata.get("format") != LIBRARY_FORMAT:
            raise ArtifactError(f"{path} is not an expert library of format {LIBRARY_FORMAT}")
        metadata = {k: v for k, v in metadata.items() if k not in ("format", "kind")}
        missing = set(cls.__dataclass_fields__) - set(arrays) - {"metadata", "tracking_error"}
        if missing:
            raise ArtifactError(f"corrupted expert library {path}: missing {sorted(missing)}")
        unexpected = set(arrays) - set(cls.__dataclass_fields__)
        if unexpected:
            raise ArtifactError(f"corrupted expert library {path}: unexpected arrays {sorted(unexpected)}")
        try:
            return cls(**arrays, metadata=metadata)
        except (TypeError, ValueError) as error:  # arrays that do not fit together
            raise ArtifactError(f"corrupted expert library {path}: {error}") from None


def action_motion(com_states: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motion over one action from ``... x (T + 1) x 5`` world CoM states.

    Returns the displacement ``... x 3`` ``(dx, dy, dyaw)`` in the start frame (m, rad), the mean velocity
    ``... x 2`` in that frame (m/s) and the mean yaw rate ``...`` (rad/s) over ``duration`` seconds.
    """
    start, end = com_states[..., 0, :], com_states[..., -1, :]
    yaw = np.unwrap(com_states[..., 2], axis=-1)
    dxy = world_to_local(end[..., :2] - start[..., :2], start[..., 2])
    dyaw = yaw[..., -1] - yaw[..., 0]
    return np.concatenate([dxy, dyaw[..., None]], -1), dxy / duration, dyaw / duration


def command_box(robot: RobotSpec, command_low=None, command_high=None) -> tuple[np.ndarray, np.ndarray]:
    """The box ``(low, high)``, each ``3`` ``(vx m/s, vy m/s, yaw_rate rad/s)``, that experts' commands are sampled
    in: the robot's own, or a box of one's own (each bound a list of 3 numbers, ``low <= high``; an axis with
    ``low == high`` holds that command fixed, e.g. experts that do not turn). Raises ValueError naming the problem.

        >>> from hierloco.envs.robots import get_robot
        >>> command_box(get_robot("daisy"), command_high=[0.3, 0.3, 0.0], command_low=[-0.3, -0.3, 0.0])[1].tolist()
        [0.3, 0.3, 0.0]
    """
    box = []
    for name, given, own in (("command_low", command_low, robot.command_low),
                             ("command_high", command_high, robot.command_high)):
        try:
            bound = np.asarray(own if given is None else given, float)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be 3 numbers (vx m/s, vy m/s, yaw_rate rad/s), got {given!r}") from None
        if bound.shape != (3,) or not np.isfinite(bound).all():
            raise ValueError(f"{name} must be 3 finite numbers (vx m/s, vy m/s, yaw_rate rad/s), got {given!r}")
        box.append(bound)
    low, high = box
    if (low > high).any():
        raise ValueError(f"command_low {low.tolist()} must be at most command_high {high.tolist()} on every axis")
    return low, high


def sample_commands(robot: RobotSpec, num: int, rng: np.random.Generator, command_low=None,
                    command_high=None) -> np.ndarray:
    """``num x 3`` commands uniform in the robot's command box (or the box given, see :func:`command_box`)."""
    low, high = command_box(robot, command_low, command_high)
    return rng.uniform(low, high, size=(num, 3))


def build_expert_library(
    robot: str | RobotSpec,
    num_experts: int = 50,
    *,
    steps_per_action: int = 100,
    seed: int = 0,
    settle_time: float = 3.0,
    disabled_legs: Sequence[str] = (),
    commands: np.ndarray | None = None,
    command_low: Sequence[float] | None = None,
    command_high: Sequence[float] | None = None,
    max_rounds: int = 5,
    max_failed_experts: int | None = None,
    swing_height_m: float | None = None,
    terrain=None,
    progress: bool = False,
) -> ExpertLibrary:
    """Builds a library of ``num_experts`` gaits (see the module docstring).

    Before any simulation, the robot's description (:func:`hierloco.envs.robots.check.description_problems`) and
    the footholds its gait asks for (:func:`hierloco.components.experts.foothold_problems`) are checked, in
    milliseconds; during it, the experts that fall are counted. Either stops the build at once with an
    :class:`ExpertQualityError` saying what is wrong and what to try, instead of walking (or grinding in leg IK)
    to the end.

    Args:
        steps_per_action: N, control steps per latent action; ``N * 0.01 s`` must hold a whole number of gait
            periods.
        settle_time: s of closed-loop walking before recording (rounded up to whole gait periods).
        commands: ``G x 3`` commands to use instead of sampling them (e.g. for tests).
        command_low, command_high: the box the commands are sampled in (default the robot's; see
            :func:`command_box`); the library records it, and its tracking is checked against it.
        max_rounds: rounds of replacing fallen experts by fresh commands.
        max_failed_experts: the build stops as soon as more experts than this have fallen or blown up, over all
            rounds (default: :func:`default_max_failed_experts`).
        swing_height_m: the experts' foot lift, m (default: the robot's ``swing_height``): more clearance for
            uneven ground (``docs/terrain.md``).
        terrain: the ground the experts walk on while they are recorded (a :class:`~hierloco.envs.terrain.Terrain`
            or its spec; default flat): experts whose recorded steps met the ground's bumps and edges.
    """
    robot = own = get_robot(robot)  # own: the robot as described (the metadata's), robot: the experts' foot lift
    if swing_height_m is not None:
        if not (isinstance(swing_height_m, (int, float)) and 0 < float(swing_height_m) < robot.standing_height):
            raise ValueError(f"swing_height_m must be a foot lift in (0, {robot.standing_height:g}) m (below "
                             f"{robot.name}'s standing height), got {swing_height_m!r}")
        robot = robot.replace(swing_height=float(swing_height_m))
    terrain = make_terrain(terrain)
    low, high = command_box(robot, command_low, command_high)
    if int(num_experts) < 1:
        raise ValueError(f"num_experts must be at least 1, got {num_experts}")
    periods = steps_per_action * CONTROL_TIMESTEP / robot.gait_period
    if steps_per_action < 1 or abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
        raise ValueError(f"steps_per_action={steps_per_action} ({steps_per_action * CONTROL_TIMESTEP:.2f} s) must "
                         f"hold a whole number of {robot.name}'s {robot.gait_period} s gait periods")
    rng = np.random.default_rng(seed)
    wanted = sample_commands(robot, num_experts, rng, low, high) if commands is None else np.asarray(commands, float)
    if wanted.shape != (num_experts, 3):
        raise ValueError(f"commands must be {num_experts} x 3, got {wanted.shape}")
    max_failed = default_max_failed_experts(num_experts) if max_failed_experts is None else int(max_failed_experts)
    if not disabled_legs:  # with locked legs the standing statics and footholds of the whole robot do not apply
        problems = expert_setup_problems(robot, command_low=low, command_high=high)
        if problems:
            raise ExpertQualityError(f"{robot.name}: the experts cannot walk, found before any simulation: "
                                     + " | ".join(problems))
    period_steps = int(round(robot.gait_period / CONTROL_TIMESTEP))
    settle_steps = int(np.ceil(settle_time / robot.gait_period)) * period_steps
    records, rejected = [], 0
    pending = wanted
    bar = tqdm(total=num_experts, desc=f"experts ({robot.name})", disable=not progress)
    for _ in range(max_rounds):
        sim = BatchedSimulator(robot, len(pending), disabled_legs=disabled_legs, seed=int(rng.integers(2**31)),
                               terrain=terrain)
        controller = RaibertController(robot, len(pending))
        # settle closed loop, freeze the feedback, let one gait period pass, record one action
        record = settle_steps + period_steps
        falls = _FallCounter(len(pending), max_failed - rejected)
        out = run_closed_loop(sim, controller, pending, record + steps_per_action,
                              ramp_steps=min(settle_steps, 100), freeze_after=settle_steps, stop_when=falls)
        sim.close()
        if falls.exceeded:
            bar.close()
            raise ExpertQualityError(_falls_message(robot, out, pending, rejected, max_failed, len(records),
                                                    steps_per_action))
        ok = ~out.failed[:, -1]
        for g in np.flatnonzero(ok):
            records.append((pending[g], out.joint_targets[g, record:], out.com_state[g, record - 1:],
                            out.foot_contacts[g, record:]))
        bar.update(int(ok.sum()))
        rejected += int((~ok).sum())
        if ok.all():
            break
        pending = sample_commands(robot, int((~ok).sum()), rng, low, high)
    bar.close()
    if len(records) < num_experts:
        raise ExpertQualityError(f"{robot.name}: only {len(records)} of {num_experts} experts walked without falling "
                                 f"in {max_rounds} rounds ({rejected} fell); what to try: "
                                 + "; ".join(_advice(robot, steps_per_action)))
    cmds, targets, states, contacts = (np.stack(x) for x in zip(*records))
    displacement, velocity, yaw_rate = action_motion(states, steps_per_action * CONTROL_TIMESTEP)
    metadata = {
        **robot_metadata(own),
        "steps_per_action": int(steps_per_action), "gait_period": robot.gait_period,
        "seed": int(seed), "settle_time": settle_steps * CONTROL_TIMESTEP, "disabled_legs": list(disabled_legs),
        "joint_names": list(robot.joint_names), "rejected_commands": rejected,
        "command_low": low.tolist(), "command_high": high.tolist(),
        **({"swing_height_m": robot.swing_height} if swing_height_m is not None else {}),
        **({"terrain": terrain.key()} if terrain.key() else {}),
    }
    library = ExpertLibrary(commands=cmds, joint_targets=targets, com_states=states, foot_contacts=contacts,
                            velocity_local=velocity, yaw_rate=yaw_rate, displacement_local=displacement,
                            metadata=metadata)
    report = diagnose_expert_library(library, robot=robot)
    library.metadata["tracking"] = report.summary()
    if not report.ok:
        warnings.warn(str(report), RuntimeWarning, stacklevel=2)
    return library


def robot_metadata(robot: RobotSpec) -> dict:
    """The robot fields of an expert library's metadata: its name, reference, source and fingerprint."""
    return {"robot": robot.name, "robot_reference": robot.reference, "robot_source": robot.source,
            "robot_fingerprint": robot_fingerprint(robot)}


def default_max_failed_experts(num_experts: int) -> int:
    """How many experts may fall before :func:`build_expert_library` gives up: a quarter of them, at least 5
    (the built-in robots lose none to 2 of 50, ``docs/robots.md``)."""
    return max(5, int(num_experts) // 4)


def expert_setup_problems(robot: str | RobotSpec, *, command_low=None, command_high=None) -> list[str]:
    """What keeps ``robot``'s experts from walking, found in milliseconds without simulating: the description's
    problems (:func:`hierloco.envs.robots.check.description_problems`) and footholds out of the legs' reach
    (:func:`hierloco.components.experts.foothold_problems`), one line each; empty when there is none.

    Example:
        >>> expert_setup_problems("a1")
        []
    """
    from hierloco.components.experts import foothold_problems
    from hierloco.envs.robots.check import description_problems

    robot = get_robot(robot)
    problems = description_problems(robot)
    if problems:  # footholds of a pose that cannot stand mean little
        return problems
    return foothold_problems(robot, command_low=command_low, command_high=command_high)


class _FallCounter:
    """``stop_when`` for :func:`run_closed_loop`: true once more than ``allowed`` copies have failed."""

    def __init__(self, num_robots: int, allowed: int):
        self.failed = np.zeros(num_robots, bool)
        self.allowed = allowed
        self.exceeded = False

    def __call__(self, chunk) -> bool:
        self.failed |= chunk.failed[:, -1]
        self.exceeded = int(self.failed.sum()) > self.allowed
        return self.exceeded


def _falls_message(robot: RobotSpec, out, commands: np.ndarray, rejected: int, max_failed: int, walked: int,
                   steps_per_action: int) -> str:
    """Why the experts stage stops on falls: how many, how soon, how (roll, pitch, height, physics), at which
    commands, and what to try."""
    failed = out.failed
    fell = np.flatnonzero(failed[:, -1])
    first = failed[fell].argmax(1)  # the step each fell at
    causes = {"pitch": 0, "roll": 0, "height": 0, "physics": 0}
    for g, step in zip(fell, first):
        roll, pitch = np.abs(out.roll_pitch[g, step])
        if out.unstable[g, step]:
            causes["physics"] += 1
        elif pitch > robot.max_pitch:
            causes["pitch"] += 1
        elif roll > robot.max_roll:
            causes["roll"] += 1
        else:
            causes["height"] += 1
    how = ", ".join(f"{n} by {cause}" for cause, n in causes.items() if n)
    shown = "; ".join("(" + ", ".join(f"{v:+.2f}" for v in commands[g]) + ")" for g in fell[:3])
    return (f"{robot.name}: {len(fell) + rejected} experts fell, more than the {max_failed} allowed "
            f"(max_failed_experts), {walked} walked; the experts stage stopped after "
            f"{failed.shape[1] * CONTROL_TIMESTEP:.1f} s of walking: the median one fell after "
            f"{np.median(first + 1) * CONTROL_TIMESTEP:.2f} s ({how}; roll limit {robot.max_roll:g} rad, pitch "
            f"{robot.max_pitch:g} rad, height {robot.min_height:.3f} m), e.g. at commands (vx, vy, yaw_rate) {shown}; "
            "what to try: " + "; ".join(_advice(robot, steps_per_action)) + " (hierloco-robot-check searches them)")


def replay(sim: BatchedSimulator, joint_targets: np.ndarray, num_actions: int):
    """Replays ``B x N x J`` one-action patterns open loop ``num_actions`` times in a row on ``sim``."""
    return sim.run(np.tile(joint_targets, (1, num_actions, 1)))


# ---------------------------------------------------------------------------------------------------- tracking
TRACKING_AXES = ("vx", "vy", "yaw_rate")
TRACKING_UNITS = ("m/s", "m/s", "rad/s")
_DIRECTIONS = (("forward", "backward"), ("left", "right"), ("counter-clockwise", "clockwise"))
_VERBS = ("walks", "walks", "turns")
MIN_REACH = 0.4  # of the box half-width, towards each edge of each axis
NO_RESPONSE_SLOPE = 0.25  # achieved per commanded below this: the robot ignores the command


class ExpertQualityError(Finding, ValueError):
    """The expert gaits do not walk as commanded: the library cannot represent the command box, the experts
    fall, or the robot's description keeps them from walking at all.

    Attributes:
        report: the :class:`ExpertTrackingReport` that says how far off, in which direction, and what to try
            (``None`` when the build stopped before the experts could be judged: the message says why).
    """

    def __init__(self, report: "ExpertTrackingReport | str"):
        super().__init__(str(report))
        self.report = report if isinstance(report, ExpertTrackingReport) else None


@dataclass(frozen=True)
class AxisTracking:
    """How the experts follow one command axis (``vx``, ``vy`` or ``yaw_rate``) over the command box.

    ``achieved ~ slope * commanded + offset`` is the least-squares line through the experts; ``reach_low`` and
    ``reach_high`` are how far that line gets from the box centre towards each edge of the box, as a fraction of
    the box half-width (1: it reaches the edge; 0: it stays at the centre; negative: it goes the other way); the
    axis is ``ok`` when both reach ``min_reach`` (or when it cannot be assessed: commands that do not vary, a box
    without extent). Errors are achieved minus commanded, in ``unit``.
    """

    axis: str
    unit: str
    command_low: float
    command_high: float
    achieved_low: float
    achieved_high: float
    mean_error: float
    mean_abs_error: float
    worst_abs_error: float
    slope: float
    offset: float
    reach_low: float
    reach_high: float
    min_reach: float
    ok: bool

    def describe(self) -> str:
        """One line: the numbers, and for an axis that fails, what goes wrong in words."""
        u = self.unit
        line = (f"{self.axis}: commanded {self.command_low:+.2f}..{self.command_high:+.2f} {u}, achieved "
                f"{self.achieved_low:+.2f}..{self.achieved_high:+.2f} {u}; error mean {self.mean_error:+.3f}, "
                f"mean |error| {self.mean_abs_error:.3f}, worst |error| {self.worst_abs_error:.3f} {u}")
        if self.ok:
            return line
        index = TRACKING_AXES.index(self.axis)
        positive, negative = _DIRECTIONS[index]
        half = (self.command_high - self.command_low) / 2
        if abs(self.slope) < NO_RESPONSE_SLOPE:
            middle = self.slope * (self.command_low + self.command_high) / 2 + self.offset
            if abs(middle) < 0.1 * half:
                return line + f" -- does not respond to {self.axis} commands"
            return (line + f" -- {_VERBS[index]} {positive if middle > 0 else negative} at {abs(middle):.2f} {u} "
                    "whatever the command")
        problems = []
        for reach, edge, word in ((self.reach_high, self.command_high, positive),
                                  (self.reach_low, self.command_low, negative)):
            if math.isfinite(reach) and reach < self.min_reach:
                fitted = self.slope * edge + self.offset
                problems.append(f"towards {word} it reaches {max(reach, 0.0):.0%} of the box ({fitted:+.2f} {u} "
                                f"when {edge:+.2f} is commanded)")
        if abs(self.mean_error) > 0.25 * half:
            problems.append(f"on average it {_VERBS[index][:-1]}s {abs(self.mean_error):.2f} {u} more "
                            f"{positive if self.mean_error > 0 else negative} than commanded")
        return line + f" -- achieved ~ {self.slope:.2f} x command {self.offset:+.2f} {u}: " + "; ".join(problems)


@dataclass(frozen=True)
class ExpertTrackingReport:
    """Whether an expert library can represent its robot's command box (see :func:`diagnose_expert_library`)."""

    robot: str
    num_experts: int
    min_reach: float
    axes: tuple[AxisTracking, ...]
    advice: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return all(axis.ok for axis in self.axes)

    @property
    def worst_reach(self) -> float:
        """The smallest reach over axes and sides (NaN when no axis could be assessed)."""
        reaches = [r for axis in self.axes for r in (axis.reach_low, axis.reach_high) if math.isfinite(r)]
        return min(reaches) if reaches else math.nan

    def summary(self) -> dict[str, Any]:
        """A JSON-able summary (NaN as ``None``), as stored in the library's metadata under ``"tracking"``."""
        def number(x):
            return float(x) if math.isfinite(x) else None
        keys = ("mean_error", "mean_abs_error", "worst_abs_error", "slope", "offset", "reach_low", "reach_high")
        return {"ok": self.ok, "min_reach": self.min_reach, "worst_reach": number(self.worst_reach),
                "axes": {a.axis: {**{k: number(getattr(a, k)) for k in keys}, "ok": a.ok} for a in self.axes}}

    def __str__(self) -> str:
        verdict = ("walk as commanded" if self.ok else "do not walk as commanded: the library cannot represent the "
                   "command box")
        lines = [f"{self.robot}: the {self.num_experts} experts {verdict} (each axis must reach at least "
                 f"{self.min_reach:.0%} of the box towards both edges; worst {self.worst_reach:.0%})"]
        lines += [f"  {axis.describe()}" for axis in self.axes]
        if not self.ok and self.advice:
            lines.append("  what to try:")
            lines += [f"  - {line}" for line in self.advice]
        return "\n".join(lines)


def _axis_tracking(axis: int, commanded: np.ndarray, achieved: np.ndarray, low: float, high: float,
                   min_reach: float) -> AxisTracking:
    error = achieved - commanded
    half, middle = (high - low) / 2, (high + low) / 2
    slope = offset = reach_low = reach_high = math.nan
    if len(commanded) >= 2 and np.ptp(commanded) > 1e-9:
        slope, offset = (float(v) for v in np.polyfit(commanded, achieved, 1))
        if half > 0:
            reach_low = (slope * low + offset - middle) / (low - middle)
            reach_high = (slope * high + offset - middle) / (high - middle)
    assessed = math.isfinite(reach_low)
    return AxisTracking(
        axis=TRACKING_AXES[axis], unit=TRACKING_UNITS[axis], command_low=float(low), command_high=float(high),
        achieved_low=float(achieved.min()), achieved_high=float(achieved.max()),
        mean_error=float(error.mean()), mean_abs_error=float(np.abs(error).mean()),
        worst_abs_error=float(np.abs(error).max()), slope=slope, offset=offset, reach_low=reach_low,
        reach_high=reach_high, min_reach=float(min_reach),
        ok=bool(not assessed or (reach_low >= min_reach and reach_high >= min_reach)))


def _span(values) -> str:
    if not values:
        return "the model's"
    low, high = min(values), max(values)
    return f"{low:g}" if low == high else f"{low:g}-{high:g}"


def _advice(robot: RobotSpec | None, steps_per_action: int) -> tuple[str, ...]:
    if robot is None:
        return ("another gait_period (hierloco-robot-check searches it)", "stiffer kp and more joint_damping",
                "a standing_height that puts the feet on the floor", "a smaller command box")
    periods = admissible_gait_periods(len(robot.gait_groups), steps_per_action)
    derived = derive_gait_period(robot, steps_per_action) if periods else None
    hint = f"; the size rule gives {derived} s (derive_gait_period)" if derived is not None else ""
    kp, damping = (_span(values) for values in (robot.kp, robot.joint_damping))
    return (
        f"gait_period (now {robot.gait_period} s): a trot balances on short stances, a statically stable gait "
        f"(a tripod) walks well with long ones{hint}; periods that fit {steps_per_action}-step actions: "
        f"{', '.join(f'{p:g}' for p in periods) or 'none'} s",
        f"kp (now {kp} N m/rad) and joint_damping (now {damping} N m s/rad): stiffer, better damped servos sag and "
        "slip less under the body's weight",
        f"standing_height (now {robot.standing_height:.3f} m; the feet touch the floor at "
        f"{derive_standing_height(robot):.3f} m) and standing_pose",
        f"command_low / command_high (now {list(robot.command_low)} / {list(robot.command_high)}): the box must be "
        "within what the robot can walk",
    )


def diagnose_expert_library(library: ExpertLibrary, *, robot: str | RobotSpec | None = None,
                            min_reach: float = MIN_REACH) -> ExpertTrackingReport:
    """How well the experts walk as commanded, axis by axis, over the robot's command box.

    The latent action space can only span what the experts achieve, so what matters is whether their achieved
    velocities cover the box: per axis, the least-squares line ``achieved ~ slope * commanded + offset`` must get
    at least ``min_reach`` of the way from the box centre to each edge. Mean, worst and signed errors are reported
    alongside. At ``min_reach = 0.4`` the built-in robots pass with a wide margin (worst reach 0.9 for A1 and
    1.2 for Daisy with 50 experts, 0.78 and 1.14 with 6 experts settled 1 s), while a robot that walks backward
    whatever it is told, or cannot walk forward, fails (docs/robots.md).

    Args:
        library: the expert library (``G x 3`` commands and what they achieved).
        robot: its robot (default: ``library.robot``); gives the command box when the library does not record
            one, and the values quoted in the advice.
        min_reach: the fraction of the box half-width each axis must reach towards both edges.

    Example:
        >>> lib = build_expert_library("a1", 6, seed=0, progress=False)  # doctest: +SKIP
        >>> report = diagnose_expert_library(lib)  # doctest: +SKIP
        >>> report.ok, round(report.worst_reach, 2)  # doctest: +SKIP
        (True, 0.9...)
    """
    if not (math.isfinite(min_reach) and min_reach > 0):
        raise ValueError(f"min_reach must be a positive fraction, got {min_reach!r}")
    if robot is None:
        try:
            robot = get_robot(library.robot)
        except ValueError:
            robot = None
    else:
        robot = get_robot(robot)
    meta = library.metadata
    if "command_low" in meta:
        low, high = np.asarray(meta["command_low"], float), np.asarray(meta["command_high"], float)
    elif robot is not None:
        low, high = np.asarray(robot.command_low), np.asarray(robot.command_high)
    else:
        raise ValueError(f"expert library of {meta.get('robot')!r} records no command box; pass its robot")
    achieved = library.achieved
    axes = tuple(_axis_tracking(i, library.commands[:, i], achieved[:, i], low[i], high[i], min_reach)
                 for i in range(3))
    report = ExpertTrackingReport(robot=str(meta.get("robot", "?")), num_experts=library.num_experts,
                                  min_reach=float(min_reach), axes=axes)
    if report.ok:
        return report
    return ExpertTrackingReport(robot=report.robot, num_experts=report.num_experts, min_reach=report.min_reach,
                                axes=axes, advice=_advice(robot, library.steps_per_action))


def require_expert_library_quality(library: ExpertLibrary, *, robot: str | RobotSpec | None = None,
                                   min_reach: float = MIN_REACH) -> ExpertTrackingReport:
    """The :func:`diagnose_expert_library` report; raises :class:`ExpertQualityError` (a ``ValueError``) with
    it when the experts cannot represent the command box, so a run stops before learning from them."""
    report = diagnose_expert_library(library, robot=robot, min_reach=min_reach)
    if not report.ok:
        raise ExpertQualityError(report)
    return report


__all__ = ["AxisTracking", "ExpertLibrary", "ExpertQualityError", "ExpertTrackingReport", "MIN_REACH",
           "action_motion", "build_expert_library", "command_box", "default_max_failed_experts",
           "diagnose_expert_library", "expert_setup_problems", "replay", "require_expert_library_quality",
           "sample_commands"]
