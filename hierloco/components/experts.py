"""The expert controller: a Raibert-style footstep law with leg inverse kinematics (Li et al., RA-L 2021, Sec. III).

A desired CoM velocity ``(vx, vy, yaw_rate)`` in the robot's local (yaw) frame becomes footsteps and then joint
targets, closed loop on the measured CoM velocity, batched over B robots that share one gait clock:

- gait: the robot's gait groups take turns in swing (trot pairs for A1, tripods for Daisy, one leg at a time for a
  wave gait); with K groups each swings for ``floor(P / K)`` of the period's P control steps and stands for the
  rest (``stance_duration``); when K does not divide P the period ends with ``P mod K`` steps on all feet;
- stance: a stance foot moves in the body's yaw frame opposite to the commanded motion,
  ``p <- R(-yaw_rate dt) p - v_des dt``;
- swing: the foot travels from lift-off to the touchdown point chosen by the feedback law
  ``p_td = R(yaw_rate T_st / 2 + k_yaw (yaw_rate_meas - yaw_rate)) p_nominal + T_st / 2 v_des + k (v - v_des)``
  with height ``h sin(pi * phase)``;
- the feet are placed in the base frame (so stance legs push the body back to level) and turned into joint
  targets by :class:`LegKinematics`.

Two footstep laws (``footstep_law=``): ``"integral"`` (default) follows the command corrected by an outer loop that
integrates the velocity and yaw-rate errors (it removes the steady-state error of the proportional law), and
``"plain"`` is the law above alone, with ``v_des`` the command itself. The paper names only "an expert-designed
feedback law" that converts desired CoM velocities to footsteps (Li et al., RA-L 2021, Sec. IV-A and IV-C, after
Truong et al. 2020); it does not say whether that law has an integral loop.

The feedback can be applied every control step (``feedback_steps=1`` in :func:`run_closed_loop`, how the experts
are recorded) or every k steps: the controller then plans k steps of footholds from the state measured so far, turns
all ``B x k x L`` of them into joint targets in one vectorised IK call and the simulator runs the k steps in one
``mujoco.rollout`` call. With ``k`` = one swing phase this is the classic Raibert controller, which chooses the
touchdown point at lift-off (the IK low level's default splits swing phases longer than 0.25 s,
:meth:`RaibertController.swing_chunk_steps`); the measurements of every step still reach the velocity filter and
the integral loop.

Example:
    >>> import numpy as np
    >>> from hierloco.envs.batched_sim import BatchedSimulator
    >>> sim = BatchedSimulator("daisy", num_robots=2)
    >>> ctrl = RaibertController("daisy", num_robots=2)
    >>> commands = np.array([[0.2, 0.0, 0.0], [0.0, -0.1, 0.0]])  # B x 3: m/s, m/s, rad/s
    >>> out = run_closed_loop(sim, ctrl, commands, num_steps=200)
    >>> out.com_state.shape
    (2, 200, 5)
    >>> fast = RaibertController("daisy", num_robots=2, ik_solver="vectorised")
    >>> out = run_closed_loop(BatchedSimulator("daisy", 2), fast, commands, 200, feedback_steps=fast.swing_steps)
    >>> out.joint_targets.shape
    (2, 200, 18)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hierloco.components.kinematics import LegKinematics
from hierloco.envs.batched_sim import BatchedSimulator, SimulationResult
from hierloco.envs.frames import rotate_xy, world_to_local
from hierloco.envs.robots import CONTROL_TIMESTEP, RobotSpec, get_robot


FOOTSTEP_LAWS = ("integral", "plain")


class RaibertController:
    """Velocity command -> joint targets for B robots, one control step (:meth:`act`) or k (:meth:`act_chunk`) per
    call.

    Args:
        robot: a registered name or a :class:`RobotSpec`.
        num_robots: B.
        gait_period: s (default: the robot's).
        swing_height: foot lift h in m (default: the robot's).
        feedback_gain: k of the footstep law, in s.
        yaw_gain: k_yaw of the footstep rotation, in s.
        footstep_law: ``"integral"`` (the law with the integral outer loop) or ``"plain"`` (the law alone).
        integral_gain: gain in 1/s of the outer loop that integrates the velocity and yaw-rate errors into the
            command the footstep law follows (default 1; the ``"plain"`` law has none).
        integral_limit: bound on that correction, ``(vx, vy, yaw_rate)`` in m/s, m/s, rad/s (anti-windup, for a
            robot that cannot follow its command, e.g. with disabled legs); default: half the command box.
        velocity_filter: time constant in s of the low-pass filter on the measured velocities.
        ik_solver: ``"reference"`` (the experts' solver) or ``"vectorised"`` (:class:`LegKinematics`).
    """

    def __init__(self, robot: str | RobotSpec, num_robots: int, *, gait_period: float | None = None,
                 swing_height: float | None = None, feedback_gain: float = 0.05, yaw_gain: float = 0.05,
                 footstep_law: str = "integral", integral_gain: float | None = None,
                 integral_limit: tuple[float, float, float] | None = None, velocity_filter: float | None = None,
                 ik_solver: str = "reference"):
        if footstep_law not in FOOTSTEP_LAWS:
            raise ValueError(f"unknown footstep_law {footstep_law!r}; choose one of {FOOTSTEP_LAWS}")
        if footstep_law == "plain" and integral_gain not in (None, 0, 0.0):
            raise ValueError(f"the plain footstep law has no integral loop; got integral_gain={integral_gain}")
        if int(num_robots) < 1:
            raise ValueError(f"num_robots must be at least 1, got {num_robots}")
        self.robot = get_robot(robot)
        self.num_robots = int(num_robots)
        self.kinematics = LegKinematics(self.robot, solver=ik_solver)
        self.gait_period = float(gait_period or self.robot.gait_period)
        self.swing_height = float(swing_height if swing_height is not None else self.robot.swing_height)
        self.feedback_gain = float(feedback_gain)
        self.yaw_gain = float(yaw_gain)
        self.footstep_law = footstep_law
        self.integral_gain = 0.0 if footstep_law == "plain" else float(1.0 if integral_gain is None else integral_gain)
        span = np.asarray(self.robot.command_high) - np.asarray(self.robot.command_low)
        self.integral_limit = np.asarray(integral_limit if integral_limit is not None else span / 2, dtype=float)
        self.velocity_filter = float(velocity_filter or self.gait_period)
        self.dt = CONTROL_TIMESTEP
        steps = self.gait_period / self.dt
        if abs(steps - round(steps)) > 1e-6 or round(steps) < 2:
            raise ValueError(f"gait_period {self.gait_period} s must be a whole number (>= 2) of control steps")
        self.steps_per_period = int(round(steps))
        groups = self.robot.gait_groups
        self.num_groups = len(groups)
        # each group swings for swing_steps in turn; when the period does not split evenly (a wave gait of 3 or 6
        # groups in a 100-step action), its last steps_per_period % num_groups steps have every foot on the ground
        self.swing_steps = self.steps_per_period // self.num_groups
        if self.swing_steps < 1:
            raise ValueError(f"{self.steps_per_period} steps per gait period are too few for {self.num_groups} "
                             "swing phases of at least one step")
        self.stance_duration = self.gait_period - self.swing_steps * self.dt
        self.leg_group = np.array([next(g for g, grp in enumerate(groups) if leg in grp)
                                   for leg in self.robot.leg_names])
        # nominal footholds: the standing feet, centred under the centre of mass
        self.nominal_feet = self.kinematics.forward(self.kinematics.standing_pose)  # L x 3, base frame
        self.nominal_feet[:, :2] += self.kinematics.com_offset[:2] - self.nominal_feet[:, :2].mean(0)
        self.reset()

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Restarts the gait clock (all robots) or puts the robots in ``mask`` back to standing feet."""
        b, legs = self.num_robots, self.kinematics.num_legs
        if mask is None:
            self.step_count = 0
            self.feet = np.broadcast_to(self.nominal_feet, (b, legs, 3)).copy()
            self.liftoff = self.feet.copy()
            self.joint_targets = np.broadcast_to(self.kinematics.standing_pose, (b, self.robot.num_joints)).copy()
            self.recent_targets = np.broadcast_to(self.kinematics.standing_pose,
                                                  (b, self.steps_per_period, self.robot.num_joints)).copy()
            self.velocity = np.zeros((b, 2))
            self.yaw_rate = np.zeros(b)
            self.correction = np.zeros((b, 3))
            self.previous_commands = np.zeros((b, 1, 3))  # the last chunk's commands, B x k x 3
            # measurements a run left for the next one (B x m x 2 and B x m): see run_closed_loop
            self.pending_velocity_local, self.pending_yaw_rate = np.zeros((b, 0, 2)), np.zeros((b, 0))
            self.frozen = False
            return
        index = np.flatnonzero(np.asarray(mask, dtype=bool))
        self.feet[index] = self.nominal_feet
        self.liftoff[index] = self.nominal_feet
        self.joint_targets[index] = self.kinematics.standing_pose
        self.recent_targets[index] = self.kinematics.standing_pose
        self.velocity[index] = 0.0
        self.yaw_rate[index] = 0.0
        self.correction[index] = 0.0
        self.pending_velocity_local[index] = 0.0  # standing still, as after a reset: no error to integrate
        self.pending_yaw_rate[index] = 0.0
        self.previous_commands[index] = 0.0

    def freeze(self, frozen: bool = True) -> None:
        """Stops (or resumes) the feedback: the filtered velocities and the integral correction are held.

        A frozen controller at steady state produces an exactly periodic joint-target pattern, the open-loop gait
        an expert is recorded as.
        """
        self.frozen = frozen

    def swing_chunk_steps(self, max_seconds: float = 0.25) -> int:
        """Control steps in the longest equal split of a swing phase that lasts at most ``max_seconds`` (the whole
        swing phase when it is short enough): the IK low level's default feedback interval."""
        if max_seconds <= 0:
            raise ValueError(f"max_seconds must be positive, got {max_seconds}")
        for parts in range(1, self.swing_steps + 1):
            if self.swing_steps % parts == 0 and self.swing_steps // parts * self.dt <= max_seconds + 1e-9:
                return self.swing_steps // parts
        return 1

    def swing_progress(self, step: int | None = None) -> np.ndarray:
        """``L`` swing progress in (0, 1] of each leg at control step ``step`` (0 for a leg in stance)."""
        step = self.step_count if step is None else step
        in_period = step % self.steps_per_period
        group, offset = divmod(in_period, self.swing_steps)
        progress = np.zeros(self.kinematics.num_legs)
        progress[self.leg_group == group] = (offset + 1) / self.swing_steps
        return progress

    def act(self, command: np.ndarray, velocity_local: np.ndarray, yaw_rate: np.ndarray) -> np.ndarray:
        """Joint targets ``B x J`` (rad) for the next control step.

        Args:
            command: ``B x 3`` desired ``(vx, vy, yaw_rate)`` in the local frame (m/s, m/s, rad/s).
            velocity_local: ``B x 2`` measured CoM velocity in the local frame, m/s.
            yaw_rate: ``B`` measured yaw rate, rad/s.
        """
        command, velocity_local, yaw_rate = (np.asarray(x, dtype=np.float64) for x in (command, velocity_local,
                                                                                       yaw_rate))
        return self.act_chunk(command[:, None], velocity_local[:, None], yaw_rate[:, None])[:, 0]

    def act_chunk(self, commands: np.ndarray, velocity_local: np.ndarray, yaw_rate: np.ndarray) -> np.ndarray:
        """Joint targets ``B x k x J`` (rad) for the next k control steps, from the m measurements since the last
        call.

        The measurements update the velocity filter and the integral loop one by one, each against the command of
        the step after the one it was measured in (the last one against the first new command); the footholds of
        the k steps follow from that state, and all of them go through one IK call, each step warm started from the
        previous step's solution when k = 1, else from the solution one gait period earlier (the same phase of the
        gait).

        Args:
            commands: ``B x k x 3`` desired ``(vx, vy, yaw_rate)`` per step, local frame (m/s, m/s, rad/s).
            velocity_local: ``B x m x 2`` measured CoM velocities in the local frame, m/s, oldest first.
            yaw_rate: ``B x m`` measured yaw rates, rad/s.
        """
        commands = np.asarray(commands, dtype=np.float64)
        velocity_local, yaw_rate = np.asarray(velocity_local, np.float64), np.asarray(yaw_rate, np.float64)
        b = self.num_robots
        if commands.ndim != 3 or commands.shape[0] != b or commands.shape[2] != 3 or commands.shape[1] < 1:
            raise ValueError(f"commands must be B x k x 3 with B = {b} and k >= 1, got {commands.shape}")
        if velocity_local.ndim != 3 or velocity_local.shape[0] != b or velocity_local.shape[2] != 2 \
                or yaw_rate.shape != velocity_local.shape[:2]:
            raise ValueError(f"velocity_local must be B x m x 2 and yaw_rate B x m with B = {b}, got "
                             f"{velocity_local.shape} and {yaw_rate.shape}")
        if not (np.all(np.isfinite(commands)) and np.all(np.isfinite(velocity_local))
                and np.all(np.isfinite(yaw_rate))):
            raise ValueError("commands or measurements contain NaN or inf")
        if not self.frozen:
            # measurement i was taken at the end of the step before paired[i]'s
            paired = np.concatenate([self.previous_commands[:, 1:], commands[:, :1]], 1)
            m = velocity_local.shape[1]
            for i in range(m):
                self._observe(paired[:, max(0, paired.shape[1] - m + i)], velocity_local[:, i], yaw_rate[:, i])
        self.previous_commands = commands.copy()
        k, legs = commands.shape[1], self.kinematics.num_legs
        feet = np.empty((b, k, legs, 3))
        for j in range(k):
            self._advance_feet(commands[:, j])
            feet[:, j] = self.feet
        slots = (self.step_count - k + np.arange(k)) % self.steps_per_period  # the k steps' phases in the period
        if k == 1:
            initial = self.joint_targets
        else:
            initial = self.recent_targets[:, slots].reshape(b * k, -1)
        targets = self.kinematics.inverse(feet.reshape(b * k, legs, 3), initial).reshape(b, k, -1)
        self.joint_targets = targets[:, -1].copy()
        last = slice(max(0, k - self.steps_per_period), k)
        self.recent_targets[:, slots[last]] = targets[:, last]
        return targets

    def _observe(self, command: np.ndarray, velocity_local: np.ndarray, yaw_rate: np.ndarray) -> None:
        """One measurement into the velocity filter and the integral correction (``B x 3`` command)."""
        alpha = self.dt / self.velocity_filter
        self.velocity += alpha * (velocity_local - self.velocity)
        self.yaw_rate += alpha * (yaw_rate - self.yaw_rate)
        measured = np.concatenate([self.velocity, self.yaw_rate[:, None]], -1)
        self.correction += self.integral_gain * self.dt * (command - measured)
        np.clip(self.correction, -self.integral_limit, self.integral_limit, out=self.correction)

    def _advance_feet(self, command: np.ndarray) -> None:
        """Moves ``self.feet`` (``B x L x 3``, base frame) one control step for the ``B x 3`` command."""
        v_des, w_des = command[:, :2] + self.correction[:, :2], command[:, 2] + self.correction[:, 2]
        progress = self.swing_progress()
        swing = progress > 0
        starting = progress == 1.0 / self.swing_steps
        # stance feet: move against the commanded body motion
        stance_xy = rotate_xy(self.feet[..., :2], -w_des[:, None] * self.dt) - v_des[:, None, :] * self.dt
        # swing feet: lift-off -> Raibert touchdown point
        self.liftoff[:, starting] = self.feet[:, starting]
        half = 0.5 * self.stance_duration
        turn = w_des * half + self.yaw_gain * (self.yaw_rate - command[:, 2])
        touchdown = rotate_xy(self.nominal_feet[None, :, :2], turn[:, None])
        touchdown = touchdown + (half * v_des + self.feedback_gain * (self.velocity - command[:, :2]))[:, None, :]
        blend = 0.5 * (1.0 - np.cos(np.pi * progress))[None, :, None]
        swing_xy = self.liftoff[..., :2] + blend * (touchdown - self.liftoff[..., :2])
        self.feet[..., :2] = np.where(swing[None, :, None], swing_xy, stance_xy)
        self.feet[..., 2] = self.nominal_feet[:, 2] + self.swing_height * np.sin(np.pi * progress)
        self.step_count += 1


@dataclass(frozen=True)
class FootholdReach:
    """How far each leg is from the footholds the expert gait asks of it (:func:`foothold_reach`).

    Attributes:
        shortfall: ``L`` m, per leg the largest distance between a foothold and the nearest foot position the leg
            reaches (0: every foothold reached).
        worst_target: ``L x 3`` m, per leg that foothold, in the base frame.
        stride: m, the largest stance sweep asked, ``stance_duration * |v|`` at the box's corners.
        stance_duration: s. swing_height: m.
    """

    shortfall: np.ndarray
    worst_target: np.ndarray
    stride: float
    stance_duration: float
    swing_height: float


def foothold_reach(robot: str | RobotSpec, *, command_low=None, command_high=None, gait_period: float | None = None,
                   swing_height: float | None = None) -> FootholdReach:
    """Whether the legs reach what the expert gait asks at the corners of the command box: in stance each foot
    sweeps ``stance_duration * v`` through its standing position (turned by ``yaw_rate * stance_duration``), in
    swing it rises ``swing_height`` above it. Leg IK on those footholds, in milliseconds, before any simulation:
    a foothold out of reach costs the experts' IK many restarts per control step.

    Example:
        >>> reach = foothold_reach("a1")
        >>> float(reach.shortfall.max()) < 0.01
        True
    """
    robot = get_robot(robot)
    controller = RaibertController(robot, 1, gait_period=gait_period, swing_height=swing_height,
                                   ik_solver="vectorised")
    low = np.asarray(robot.command_low if command_low is None else command_low, float)
    high = np.asarray(robot.command_high if command_high is None else command_high, float)
    half = controller.stance_duration / 2
    corners = np.array(np.meshgrid(*[(lo, 0.0, hi) for lo, hi in zip(low, high)], indexing="ij")).reshape(3, -1).T
    nominal = controller.nominal_feet  # L x 3
    targets = []
    for sign in (-1.0, 1.0):  # touchdown (+) and lift-off (-) ends of the stance sweep
        xy = rotate_xy(nominal[None, :, :2], sign * corners[:, None, 2] * half) + sign * half * corners[:, None, :2]
        targets.append(np.concatenate([xy, np.broadcast_to(nominal[None, :, 2:], xy.shape[:-1] + (1,))], -1))
    apex = nominal.copy()
    apex[:, 2] += controller.swing_height
    targets = np.concatenate(targets + [apex[None]])  # M x L x 3
    kinematics = controller.kinematics
    q = kinematics.inverse(targets, np.broadcast_to(kinematics.standing_pose, targets.shape[:1] + (robot.num_joints,)))
    error = np.linalg.norm(kinematics.forward(q) - targets, axis=-1)  # M x L
    worst = error.argmax(0)
    legs = np.arange(len(robot.legs))
    return FootholdReach(shortfall=error[worst, legs], worst_target=targets[worst, legs],
                         stride=float(2 * half * np.linalg.norm(corners[:, :2], axis=-1).max()),
                         stance_duration=float(controller.stance_duration), swing_height=controller.swing_height)


MAX_FOOTHOLD_SHORTFALL = 0.01  # m: footholds further out of reach than this are refused before any simulation


def foothold_problems(robot: str | RobotSpec, *, command_low=None, command_high=None) -> list[str]:
    """:func:`foothold_reach` as problem lines (at most one), for a shortfall over ``MAX_FOOTHOLD_SHORTFALL``.

    Example:
        >>> foothold_problems("a1")
        []
    """
    robot = get_robot(robot)
    reach = foothold_reach(robot, command_low=command_low, command_high=command_high)
    short = np.flatnonzero(reach.shortfall > MAX_FOOTHOLD_SHORTFALL)
    if not len(short):
        return []
    worst = int(short[np.argmax(reach.shortfall[short])])
    target = ", ".join(f"{v:+.3f}" for v in reach.worst_target[worst])
    names = ", ".join(robot.leg_names[i] for i in short)
    return [f"footholds: leg {robot.leg_names[worst]} cannot reach the footholds its gait asks for, "
            f"{reach.shortfall[worst]:.3f} m short of ({target}) m in the base frame (legs {names}; a "
            f"{reach.stance_duration:.2f} s stance sweeps up to {reach.stride:.2f} m at the command box's corners, "
            f"swing height {reach.swing_height:g} m): give a shorter gait_period, a smaller command box or swing_height, "
            "or a standing pose with more room (hierloco-robot-check searches them)"]


def run_closed_loop(sim: BatchedSimulator, controller: RaibertController, commands: np.ndarray,
                    num_steps: int, ramp_steps: int = 0, freeze_after: int | None = None,
                    feedback_steps: int = 1, stop_when=None) -> SimulationResult:
    """Runs ``controller`` on ``sim`` for ``num_steps`` control steps at fixed ``commands`` (``B x 3``).

    The command ramps up linearly over the first ``ramp_steps``; the feedback is frozen after ``freeze_after``
    steps (see :meth:`RaibertController.freeze`). The controller plans ``feedback_steps`` control steps at a time
    from what it has measured so far (:meth:`RaibertController.act_chunk`), and each chunk is simulated in one call;
    chunks are aligned to the gait clock (they start on multiples of ``feedback_steps`` steps), so with one swing
    phase each touchdown point is chosen at lift-off. ``feedback_steps=1`` is the per-step loop the experts are
    recorded with. The first chunk observes the current state (its yaw rate unknown: 0) after the measurements
    the previous run's last chunk left (all but its last step's, which the state repeats), so successive runs (one
    per action) lose none. ``stop_when(chunk)``, called with each chunk's :class:`SimulationResult`, ends the run
    early when it returns true (the result then has fewer than ``num_steps`` steps). Returns the per-step
    :class:`SimulationResult` with an extra attribute ``joint_targets`` (``B x T x J``).
    """
    commands = np.asarray(commands, dtype=np.float64)
    b = sim.num_robots
    if commands.shape != (b, 3):
        raise ValueError(f"commands must be B x 3 = {b} x 3, got {commands.shape}")
    if controller.num_robots != b:
        raise ValueError(f"controller built for {controller.num_robots} robots, simulator has {b}")
    if int(feedback_steps) < 1:
        raise ValueError(f"feedback_steps must be a positive number of control steps, got {feedback_steps}")
    feedback_steps = int(feedback_steps)
    state = sim.com_state
    # B x m x 2 and B x m: the measurements not yet observed
    measured = world_to_local(state[:, 3:5], state[:, 2])[:, None]
    velocity = np.concatenate([controller.pending_velocity_local, measured], 1)
    yaw_rate = np.concatenate([controller.pending_yaw_rate, np.zeros((b, 1))], 1)
    results, targets = [], []
    n = 0
    while n < num_steps:
        if n == freeze_after:
            controller.freeze()
        k = min(feedback_steps - controller.step_count % feedback_steps, num_steps - n)
        if freeze_after is not None and n < freeze_after:
            k = min(k, freeze_after - n)
        steps = n + 1 + np.arange(k)
        scale = np.minimum(1.0, steps / ramp_steps) if ramp_steps else np.ones(k)
        action = controller.act_chunk(commands[:, None, :] * scale[None, :, None], velocity, yaw_rate)
        out = sim.run(action)
        velocity, yaw_rate = out.com_velocity_local, out.yaw_rate
        results.append(out)
        targets.append(action)
        n += k
        if stop_when is not None and stop_when(out):
            break
    controller.pending_velocity_local, controller.pending_yaw_rate = velocity[:, :-1].copy(), yaw_rate[:, :-1].copy()
    merged = SimulationResult(**{
        name: np.concatenate([getattr(r, name) for r in results], axis=1)
        for name in SimulationResult.__dataclass_fields__
    })
    merged.fallen = np.logical_or.accumulate(merged.fallen, axis=1)
    merged.unstable = np.logical_or.accumulate(merged.unstable, axis=1)
    merged.joint_targets = np.concatenate(targets, axis=1)
    return merged
