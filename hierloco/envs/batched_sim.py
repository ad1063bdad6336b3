"""The batched simulator: B copies of a robot stepped in lockstep through open-loop joint-target sequences.

This is hierloco's hot loop. A whole sequence of T control steps (a latent action is T = N = 100 steps at 100 Hz)
for all B copies runs natively in one threaded ``mujoco.rollout`` call, with no Python per step. Each copy keeps its
own state; copies can be reset one by one; disabled legs are locked at their standing angles.

Example:
    >>> import numpy as np
    >>> from hierloco.envs.batched_sim import BatchedSimulator
    >>> sim = BatchedSimulator("a1", num_robots=4, seed=0)
    >>> targets = np.tile(np.asarray(sim.robot.standing_pose), (4, 100, 1))  # B x T x J joint targets, rad
    >>> out = sim.run(targets)
    >>> out.com_state.shape, bool(out.fallen.any())
    ((4, 100, 5), False)
"""

from __future__ import annotations

import os
from copy import deepcopy
from dataclasses import dataclass
from typing import Sequence

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from hierloco.envs.frames import com_state_from_base, quat_to_roll_pitch_yaw, world_to_local, yaw_rate_from_base
from hierloco.envs.locomotion import (
    FOOT_CONTACT_FORCE,
    check_joint_noise,
    clamp_joint_targets,
    joint_target_limits,
    reset_joint_noise,
    robot_has_fallen,
)
from hierloco.envs.robots import (
    PHYSICS_STEPS_PER_CONTROL,
    RobotSpec,
    compile_model,
    get_robot,
    joint_qpos_indices,
    joint_qvel_indices,
)
from hierloco.envs.robots.spec import foot_geoms
from hierloco.envs.terrain import (
    PushEvent,
    make_pushes,
    make_randomization,
    make_terrain,
    random_stream,
    standing_qpos_on,
)

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


def available_cores() -> int:
    """The number of cores this process may run on (its CPU affinity, e.g. a Ray worker's share), else all cores."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on Linux
        return os.cpu_count() or 1


@dataclass
class SimulationResult:
    """What happened to each copy at the end of each control step (``B x T`` leading dimensions).

    Attributes:
        com_state: ``B x T x 5`` ``(x, y, yaw, vx, vy)`` of the base in the world frame (m, rad, m/s).
        com_velocity_local: ``B x T x 2`` base velocity in the local yaw frame (forward, left), m/s.
        yaw_rate: ``B x T`` in rad/s.
        height: ``B x T`` base height (world z), m; on a terrain falls are judged from the ground's height.
        roll_pitch: ``B x T x 2`` in rad.
        joint_positions: ``B x T x J`` in rad, ``robot.joint_names`` order.
        foot_contacts: ``B x T x L`` bool, leg order.
        fallen: ``B x T`` bool, true from the first step the robot fell (roll, pitch or height out of limits).
        unstable: ``B x T`` bool, true from the first step the physics blew up (NaN or MuJoCo auto-reset).
        qpos: ``B x T x nq`` the full generalised positions (for rendering).
        joint_velocities: ``B x T x J`` in rad/s, ``robot.joint_names`` order.
        angular_velocity_local: ``B x T x 3`` base angular velocity in the base (body) frame, rad/s.
    """

    com_state: np.ndarray
    com_velocity_local: np.ndarray
    yaw_rate: np.ndarray
    height: np.ndarray
    roll_pitch: np.ndarray
    joint_positions: np.ndarray
    foot_contacts: np.ndarray
    fallen: np.ndarray
    unstable: np.ndarray
    qpos: np.ndarray
    joint_velocities: np.ndarray
    angular_velocity_local: np.ndarray

    @property
    def failed(self) -> np.ndarray:
        """``B x T`` bool: fallen or unstable."""
        return self.fallen | self.unstable

    @classmethod
    def concatenate(cls, results: Sequence["SimulationResult"]) -> "SimulationResult":
        """Successive results of the same copies (``B x T_i`` each) as one ``B x sum(T_i)`` result; ``fallen`` and
        ``unstable`` stay true from their first step on."""
        merged = cls(**{name: np.concatenate([getattr(r, name) for r in results], axis=1)
                        for name in cls.__dataclass_fields__})
        merged.fallen = np.logical_or.accumulate(merged.fallen, axis=1)
        merged.unstable = np.logical_or.accumulate(merged.unstable, axis=1)
        return merged


class BatchedSimulator:
    """B copies of ``robot`` driven by open-loop joint targets at 100 Hz, simulated natively with threads.

    Args:
        robot: a registered robot name or a :class:`RobotSpec`.
        num_robots: B, the number of copies.
        disabled_legs: legs locked at their standing angles (their targets are ignored).
        limp_legs: legs whose servos are off (unpowered: their joints swing freely, with their damping).
        obstacles: static boxes in the world (:class:`hierloco.envs.robots.Obstacle`), e.g. a navigation arena.
        init_joint_noise: uniform noise in rad on the standing joint angles at reset
            (:func:`hierloco.envs.locomotion.reset_joint_noise`).
        seed: seeds the reset noise.
        nthread: simulation threads (default: the cores this process may use, :func:`available_cores`).
        copy_robots: B variants of ``robot``, one per copy (the same joints and bodies; other gains, damping,
            torque limits, masses, standing pose and height): copy ``i`` is simulated with the model of
            ``copy_robots[i]``, stands in its pose at reset and falls by its thresholds. All copies still run in one
            ``mujoco.rollout`` call, so a search over a robot's parameters is one batched simulation
            (:mod:`hierloco.components.expert_tuning`). Not with disabled or limp legs, nor servo latency.
        terrain: the ground (:func:`hierloco.envs.terrain.make_terrain`: a name, a mapping with a name, a file or a
            :class:`~hierloco.envs.terrain.Terrain`; default flat). Copies start standing on it at the origin, and
            have fallen when their base is lower than ``min_height`` above the lowest ground near it.
        pushes: velocity impulses on the trunk at random times (:class:`hierloco.envs.terrain.Pushes` or a mapping
            of its options), drawn per copy from ``seed``; each is logged in :attr:`push_log`.
        randomization: randomised dynamics (:class:`hierloco.envs.terrain.DynamicsRandomization`, a mapping of its
            options or ``"standard"``): each copy gets a model of its own, redrawn from ``seed`` at each of its
            resets; :attr:`dynamics` holds the current draws. Not with ``copy_robots``.

    Joint targets outside the joint range are clamped to it (:func:`hierloco.envs.locomotion.clamp_joint_targets`,
    as MuJoCo's control range would); NaN or infinite targets are refused. With ``robot.servo_latency`` the servos
    act on each target that many s late (whole physics steps): the first physics steps of a call run the last
    targets of the call before (the standing pose after a reset).

    A push acts at the start of a control step: the copy's trunk velocity changes by the impulse, and the sequence
    goes on from there (the rollout is split at the steps where some copy is pushed).
    """

    def __init__(self, robot: str | RobotSpec, num_robots: int, *, disabled_legs: Sequence[str] = (),
                 init_joint_noise: float = 0.0, seed: int | None = None, nthread: int | None = None,
                 obstacles: Sequence = (), limp_legs: Sequence[str] = (),
                 copy_robots: Sequence[RobotSpec] | None = None, terrain=None, pushes=None, randomization=None):
        if int(num_robots) < 1:
            raise ValueError(f"num_robots must be at least 1, got {num_robots}")
        self.robot = get_robot(robot)
        self.num_robots = int(num_robots)
        self.disabled_legs = tuple(disabled_legs)
        self.limp_legs = tuple(limp_legs)
        self.init_joint_noise = check_joint_noise(init_joint_noise)
        self.obstacles = tuple(obstacles)
        self.terrain = make_terrain(terrain)
        self.pushes = make_pushes(pushes)
        self.randomization = make_randomization(randomization)
        if self.randomization.active and copy_robots is not None:
            raise ValueError("randomization cannot be combined with copy_robots (both give each copy a model)")
        self.model = compile_model(self.robot, self.disabled_legs, self.obstacles, limp_legs=self.limp_legs,
                                   terrain=self.terrain)
        self.nthread = int(nthread) if nthread is not None else available_cores()
        self._datas = [mujoco.MjData(self.model) for _ in range(max(1, self.nthread))]
        self._pool = mj_rollout.Rollout(nthread=self.nthread if self.nthread > 1 else 0)
        self._rng = np.random.default_rng(seed)

        nq, nv = self.model.nq, self.model.nv
        self.nstate = mujoco.mj_stateSize(self.model, STATE_SPEC)
        self._qpos = slice(1, 1 + nq)
        self._qvel = slice(1 + nq, 1 + nq + nv)
        self._joint_qpos = joint_qpos_indices(self.model, self.robot)
        self._joint_qvel = joint_qvel_indices(self.model, self.robot)
        self._locked = self.robot.leg_joint_indices(self.disabled_legs)
        self._standing = np.asarray(self.robot.standing_pose, dtype=np.float64)
        self._target_low, self._target_high = joint_target_limits(self.model)
        self.timestep = self.model.opt.timestep
        self.latency_steps = int(round(self.robot.servo_latency / self.timestep))
        self._in_flight = np.tile(self._standing, (self.num_robots, self.latency_steps, 1))  # sent, not yet acting
        self._ground_reach = 0.0
        if not self.terrain.is_flat:
            from hierloco.envs.navigation import footprint_radius

            self._ground_reach = footprint_radius(self.robot) / 2

        data = self._datas[0]
        data.qpos[:] = standing_qpos_on(self.terrain, self.model, self.robot)
        self._standing_state = np.empty(self.nstate)
        mujoco.mj_getState(self.model, data, self._standing_state, STATE_SPEC)
        self.state = np.tile(self._standing_state, (self.num_robots, 1))
        self._copy_models = self._copy_standing = self._copy_fall = None
        if copy_robots is not None:
            self._set_copy_robots(copy_robots)
        self._push_rng, self._dynamics_rng = random_stream(seed, 1), random_stream(seed, 2)
        self.push_log: list[PushEvent] = []  # every push since the simulator was made
        self.last_pushes: list[PushEvent] = []  # the pushes of the last run
        self._episode_steps = np.zeros(self.num_robots, dtype=np.int64)  # control steps since each copy's reset
        self._next_push = np.zeros(self.num_robots, dtype=np.int64)
        self._copy_latency = None  # per-copy physics steps of servo delay, with randomised latency
        self.dynamics: dict[str, np.ndarray] = {}
        if self.randomization.active:
            self._set_randomization()
        self.reset()

    def _set_randomization(self) -> None:
        self._copy_models = [deepcopy(self.model) for _ in range(self.num_robots)]
        self._feet = foot_geoms(self.model, self.robot)
        self.dynamics = {name: np.zeros((self.num_robots, *np.shape(value)[1:]), dtype=np.asarray(value).dtype)
                         for name, value in self.randomization.sample(np.random.default_rng(0), 1).items()}
        if self.randomization.latency_steps[1] > 0:
            self._copy_latency = np.full(self.num_robots, self.latency_steps, dtype=np.int64)
            longest = self.latency_steps + self.randomization.latency_steps[1]
            self._in_flight = np.tile(self._standing, (self.num_robots, longest, 1))

    def _set_copy_robots(self, copy_robots: Sequence[RobotSpec]) -> None:
        copies = [get_robot(r) for r in copy_robots]
        if len(copies) != self.num_robots:
            raise ValueError(f"copy_robots must give one robot per copy: {self.num_robots}, got {len(copies)}")
        if self.disabled_legs or self.limp_legs or self.obstacles or self.latency_steps:
            raise ValueError("copy_robots cannot be combined with disabled or limp legs, obstacles or servo latency")
        compiled: dict[int, tuple] = {}
        models, standing, falls = [], np.empty((self.num_robots, self.nstate)), np.empty((self.num_robots, 3))
        for i, copy in enumerate(copies):
            if id(copy) not in compiled:
                if copy.joint_names != self.robot.joint_names or copy.servo_latency != self.robot.servo_latency:
                    raise ValueError(f"copy_robots[{i}] ({copy.name!r}) must have the joints and servo latency of "
                                     f"{self.robot.name!r}")
                model = compile_model(copy, terrain=self.terrain)
                if (model.nq, model.nv, model.nu, model.nsensordata) != (self.model.nq, self.model.nv, self.model.nu,
                                                                         self.model.nsensordata):
                    raise ValueError(f"copy_robots[{i}] ({copy.name!r}) compiles to a model of another size than "
                                     f"{self.robot.name!r}'s")
                data = mujoco.MjData(model)
                data.qpos[:] = standing_qpos_on(self.terrain, model, copy)
                state = np.empty(self.nstate)
                mujoco.mj_getState(model, data, state, STATE_SPEC)
                compiled[id(copy)] = (model, state, (copy.max_roll, copy.max_pitch, copy.min_height))
            model, state, fall = compiled[id(copy)]
            models.append(model)
            standing[i], falls[i] = state, fall
        self._copy_models, self._copy_standing, self._copy_fall = models, standing, falls

    # ------------------------------------------------------------------ state
    def reset(self, mask: np.ndarray | None = None) -> np.ndarray:
        """Puts the copies in ``mask`` (``B`` bool, default all) back standing at the origin facing +y.

        Returns the ``B x 5`` CoM state of every copy.
        """
        index = np.arange(self.num_robots) if mask is None else np.flatnonzero(np.asarray(mask, dtype=bool))
        self.state[index] = self._standing_state if self._copy_standing is None else self._copy_standing[index]
        if self._in_flight.shape[1]:
            self._in_flight[index] = self._standing
        if self.init_joint_noise > 0 and len(index):
            noise = reset_joint_noise(self._rng, self.init_joint_noise, len(index), len(self._joint_qpos), self._locked)
            self.state[np.ix_(index, 1 + self._joint_qpos)] += noise
        self._episode_steps[index] = 0
        if self.pushes.active and len(index):
            self._next_push[index] = self.pushes.interval_steps(self._push_rng, len(index))
        if self.randomization.active and len(index):
            self._draw_dynamics(index)
        return self.com_state

    def _draw_dynamics(self, index: np.ndarray) -> None:
        """New dynamics for the copies ``index`` (their models, their servo latency)."""
        draws = self.randomization.sample(self._dynamics_rng, len(index))
        for j, i in enumerate(index):
            draw = {name: values[j] for name, values in draws.items()}
            self.randomization.apply(self._copy_models[i], self.model, self.robot, draw, self._feet)
            for name, value in draw.items():
                self.dynamics[name][i] = value
        if self._copy_latency is not None:
            self._copy_latency[index] = self.latency_steps + draws["latency_steps"]

    def seed(self, seed: int | None) -> None:
        """Re-seeds the reset noise, the pushes and the randomised dynamics (drawn at the next resets)."""
        self._rng = np.random.default_rng(seed)
        self._push_rng, self._dynamics_rng = random_stream(seed, 1), random_stream(seed, 2)

    def set_state(self, state: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Sets full physics states (``B x nstate``, or ``M x nstate`` for the ``M`` copies in ``mask``)."""
        index = slice(None) if mask is None else np.flatnonzero(np.asarray(mask, dtype=bool))
        self.state[index] = state

    def push(self, velocity_change_mps: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Adds ``velocity_change_mps`` (``2``, or ``B x 2`` / ``M x 2`` for the ``M`` copies in ``mask``; world
        frame, m/s) to the trunk's horizontal velocity of the copies in ``mask`` (default all), now; logged in
        :attr:`push_log` with ``run_step = -1``."""
        index = np.arange(self.num_robots) if mask is None else np.flatnonzero(np.asarray(mask, dtype=bool))
        change = np.broadcast_to(np.asarray(velocity_change_mps, dtype=np.float64), (len(index), 2))
        if not np.all(np.isfinite(change)):
            raise ValueError("velocity_change_mps contains NaN or inf")
        yaw = self.com_state[index, 2]
        for i, dv, heading in zip(index, change, yaw):
            self.push_log.append(self._apply_push(self.state, int(i), dv, float(np.arctan2(dv[1], dv[0]) - heading),
                                                  -1, int(self._episode_steps[i])))

    def _apply_push(self, state: np.ndarray, i: int, change: np.ndarray, direction: float, run_step: int,
                    episode_step: int) -> PushEvent:
        state[i, self._qvel.start:self._qvel.start + 2] += change  # the free joint's linear velocity, world frame
        return PushEvent(copy=i, episode_step=episode_step, run_step=run_step, time_s=float(state[i, 0]),
                         velocity_change_mps=(float(change[0]), float(change[1])),
                         direction_rad=float(np.mod(direction, 2 * np.pi)))

    def _due_pushes(self, num_steps: int) -> dict[int, list[int]]:
        """The copies pushed at each control step of the next ``num_steps`` (their next push times move on)."""
        due: dict[int, list[int]] = {}
        if not self.pushes.active:
            return due
        end = self._episode_steps + num_steps
        for i in np.flatnonzero(self._next_push < end):
            while self._next_push[i] < end[i]:
                due.setdefault(int(self._next_push[i] - self._episode_steps[i]), []).append(int(i))
                self._next_push[i] += self.pushes.interval_steps(self._push_rng, 1)[0]
        return due

    @property
    def com_state(self) -> np.ndarray:
        """``B x 5`` current ``(x, y, yaw, vx, vy)`` of each copy in the world frame."""
        qpos, qvel = self.state[:, self._qpos], self.state[:, self._qvel]
        return com_state_from_base(qpos[:, 0:3], qpos[:, 3:7], qvel[:, 0:3])

    @property
    def qpos(self) -> np.ndarray:
        """``B x nq`` current generalised positions."""
        return self.state[:, self._qpos]

    @property
    def joint_positions(self) -> np.ndarray:
        """``B x J`` current joint angles in rad."""
        return self.state[:, self._qpos][:, self._joint_qpos]

    @property
    def body_state(self) -> np.ndarray:
        """``B x 3`` what each copy's trunk feels of the ground now: roll and pitch (rad) and the base's height above
        the lowest ground near it (m; above the floor on flat ground), as falls are judged (``docs/terrain.md``)."""
        qpos = self.qpos
        roll_pitch = quat_to_roll_pitch_yaw(qpos[:, 3:7])[:, :2]
        return np.concatenate([roll_pitch, self._height_above_ground(qpos)[:, None]], axis=1)

    def _height_above_ground(self, qpos: np.ndarray) -> np.ndarray:
        """``...`` the base's height above the lowest ground within half the footprint radius of it (m; its world z
        on flat ground), from ``... x nq`` generalised positions: what falls are judged by."""
        if self.terrain.is_flat:
            return qpos[..., 2]
        return qpos[..., 2] - self.terrain.ground_below(qpos[..., 0], qpos[..., 1], self._ground_reach)

    @property
    def qvel(self) -> np.ndarray:
        """``B x nv`` current generalised velocities (the free joint's ``0:3`` in the world frame in m/s, ``3:6``
        in the base frame in rad/s)."""
        return self.state[:, self._qvel]

    # ------------------------------------------------------------------ simulation
    def run(self, joint_targets: np.ndarray) -> SimulationResult:
        """Runs ``B x T x J`` joint targets (rad, one per control step) on every copy, from its current state.

        Each target is held for the 5 physics steps of its control step. The copies' states advance to the end of
        the sequence (fallen or unstable copies too: reset them with :meth:`reset`).
        """
        targets = np.asarray(joint_targets, dtype=np.float64)
        if targets.ndim != 3 or targets.shape[0] != self.num_robots or targets.shape[2] != self.robot.num_joints:
            raise ValueError(f"joint_targets must be B x T x J = {self.num_robots} x T x {self.robot.num_joints}, "
                             f"got shape {targets.shape}")
        if not np.all(np.isfinite(targets)):
            raise ValueError("joint_targets contain NaN or inf")
        targets = clamp_joint_targets(targets, self._target_low, self._target_high)
        if len(self._locked):
            targets[..., self._locked] = self._standing[self._locked]
        num_steps = targets.shape[1]
        control = np.repeat(targets, PHYSICS_STEPS_PER_CONTROL, axis=1)
        if self._copy_latency is not None:  # copy i acts on the targets sent _copy_latency[i] physics steps ago
            sent = np.concatenate([self._in_flight, control], axis=1)
            first = self._in_flight.shape[1] - self._copy_latency
            steps = first[:, None] + np.arange(control.shape[1])
            control, self._in_flight = sent[np.arange(self.num_robots)[:, None], steps], sent[:, control.shape[1]:]
        elif self.latency_steps:
            delayed = np.concatenate([self._in_flight, control], axis=1)
            control, self._in_flight = delayed[:, :control.shape[1]], delayed[:, control.shape[1]:]
        model = self.model if self._copy_models is None else self._copy_models
        t0 = self.state[:, 0]
        due = self._due_pushes(num_steps)
        if not due:
            states, sensors = self._pool.rollout(model, self._datas, self.state, control)
            self.last_pushes = []
        else:
            states, sensors = self._rollout_with_pushes(model, control, due)
        self.state = states[:, -1].copy()
        self._episode_steps += num_steps
        return self._summarise(states, sensors, t0, num_steps)

    def _rollout_with_pushes(self, model, control: np.ndarray, due: dict[int, list[int]]):
        """One rollout split at the control steps where some copy is pushed (``due``: step -> copies)."""
        k = PHYSICS_STEPS_PER_CONTROL
        num_steps = control.shape[1] // k
        state, parts, start, events = self.state.copy(), [], 0, []
        for step in sorted(due) + [num_steps]:
            if step > start:
                part = self._pool.rollout(model, self._datas, state, control[:, start * k:step * k])
                parts.append(part)
                state = part[0][:, -1].copy()
            if step < num_steps:
                yaw = com_state_from_base(state[:, self._qpos][:, 0:3], state[:, self._qpos][:, 3:7],
                                          state[:, self._qvel][:, 0:3])[:, 2]
                for i in due[step]:
                    direction = self.pushes.direction(self._push_rng)
                    angle = yaw[i] + direction
                    change = self.pushes.magnitude_mps * np.array([np.cos(angle), np.sin(angle)])
                    events.append(self._apply_push(state, i, change, direction, step,
                                                   int(self._episode_steps[i]) + step))
            start = step
        self.last_pushes = events
        self.push_log.extend(events)
        return np.concatenate([p[0] for p in parts], axis=1), np.concatenate([p[1] for p in parts], axis=1)

    def _summarise(self, states, sensors, t0, num_steps) -> SimulationResult:
        k = PHYSICS_STEPS_PER_CONTROL
        # a blow-up shows as non-finite numbers or as MuJoCo's auto-reset sending the clock back
        expected_time = t0[:, None] + self.timestep * np.arange(1, states.shape[1] + 1)
        broken = ~np.isfinite(states).all(-1) | (np.abs(states[..., 0] - expected_time) > 0.5 * self.timestep)
        unstable = np.logical_or.accumulate(broken.reshape(self.num_robots, num_steps, k).any(-1), axis=1)

        ends = states[:, k - 1::k]  # B x T x nstate at the end of each control step
        qpos, qvel = ends[..., self._qpos], ends[..., self._qvel]
        quat = qpos[..., 3:7]
        rpy = quat_to_roll_pitch_yaw(quat)
        robot = self.robot
        height = self._height_above_ground(qpos)
        if self._copy_fall is None:
            down = robot_has_fallen(robot, rpy[..., 0], rpy[..., 1], height)
        else:
            roll_limit, pitch_limit, min_height = (self._copy_fall[:, i:i + 1] for i in range(3))
            down = (np.abs(rpy[..., 0]) > roll_limit) | (np.abs(rpy[..., 1]) > pitch_limit) | (height < min_height)
        fallen = np.logical_or.accumulate(down, axis=1)
        com_state = com_state_from_base(qpos[..., 0:3], quat, qvel[..., 0:3])
        return SimulationResult(
            com_state=com_state,
            com_velocity_local=world_to_local(qvel[..., 0:2], rpy[..., 2]),
            yaw_rate=yaw_rate_from_base(quat, qvel[..., 3:6]),
            height=qpos[..., 2],
            roll_pitch=rpy[..., :2],
            joint_positions=qpos[..., self._joint_qpos],
            foot_contacts=sensors[:, k - 1::k, : len(robot.legs)] > FOOT_CONTACT_FORCE,
            fallen=fallen,
            unstable=unstable,
            qpos=qpos,
            joint_velocities=qvel[..., self._joint_qvel],
            angular_velocity_local=qvel[..., 3:6],
        )

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown
            pass
