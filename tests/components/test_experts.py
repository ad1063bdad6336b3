"""The Raibert expert controller walks at the commanded velocity on both robots, without falling, per step and with
feedback once per swing phase (the IK low level's fast path)."""

import numpy as np
import pytest

from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.components.low_level import CommandLowLevel
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.frames import world_to_local
from hierloco.envs.robots import get_robot

SETTLE_STEPS, MEASURE_STEPS = 200, 500  # 2 s of settling, then 5 s of measurement at 100 Hz


def _commands(robot):
    """(+-0.2, 0), (0, +-0.2) m/s, turns in place both ways, and two corners of the command box."""
    hi, lo = np.asarray(robot.command_high), np.asarray(robot.command_low)
    yaw = 0.8 * hi[2]
    return np.array([
        [0.2, 0.0, 0.0], [-0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, -0.2, 0.0],
        [0.0, 0.0, yaw], [0.0, 0.0, -yaw],
        [0.9 * hi[0], 0.9 * hi[1], 0.9 * hi[2]], [0.9 * lo[0], 0.9 * hi[1], 0.9 * lo[2]],
    ])


def _achieved(robot, commands, seed, feedback_steps=1, **controller_kwargs):
    """Mean ``(vx, vy, yaw_rate)`` over 5 s after 2 s of settling, closed loop from standing; fails on a fall."""
    sim = BatchedSimulator(robot, len(commands), init_joint_noise=0.05, seed=seed)
    controller = RaibertController(robot, len(commands), **controller_kwargs)
    feedback = controller.swing_chunk_steps() if feedback_steps == "chunk" else feedback_steps
    out = run_closed_loop(sim, controller, commands, SETTLE_STEPS + MEASURE_STEPS, ramp_steps=100,
                          feedback_steps=feedback)
    assert not out.failed.any(), f"fell or blew up: commands {commands[out.failed[:, -1]]}"
    velocity = out.com_velocity_local[:, SETTLE_STEPS:].mean(1)
    yaw_rate = out.yaw_rate[:, SETTLE_STEPS:].mean(1)
    return np.concatenate([velocity, yaw_rate[:, None]], -1)


# (feedback_steps, controller options): the experts' per-step loop, and the IK low level's default fast path
PATHS = {"per_step": (1, {}), "chunked_vectorised": ("chunk", {"ik_solver": "vectorised"})}


@pytest.mark.parametrize("path", sorted(PATHS))
@pytest.mark.parametrize("robot_name", ["a1", "daisy"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_expert_tracks_command(robot_name, seed, path):
    robot = get_robot(robot_name)
    commands = _commands(robot)
    feedback_steps, options = PATHS[path]
    achieved = _achieved(robot, commands, seed, feedback_steps, **options)
    tolerance = np.maximum(0.05, 0.25 * np.abs(commands))
    bad = np.abs(achieved - commands) > tolerance
    assert not bad.any(), "\n".join(f"command {c} achieved {a.round(3)}" for c, a in zip(commands[bad.any(1)],
                                                                                          achieved[bad.any(1)]))


def test_plain_footstep_law_tracks_on_daisy():
    """The paper's law alone (no integral loop) walks the statically stable hexapod at its commands."""
    robot = get_robot("daisy")
    commands = _commands(robot)
    achieved = _achieved(robot, commands, 0, "chunk", footstep_law="plain", ik_solver="vectorised")
    tolerance = np.maximum(0.05, 0.25 * np.abs(commands))
    assert np.all(np.abs(achieved - commands) <= tolerance), achieved.round(3)


def test_integral_loop_removes_most_of_the_plain_laws_error_on_a1():
    """A1's trot drifts under the proportional law alone; the integral outer loop (our default) cuts the worst
    per-command error at least four-fold."""
    robot = get_robot("a1")
    commands = _commands(robot)
    plain = np.abs(_achieved(robot, commands, 0, "chunk", footstep_law="plain", ik_solver="vectorised") - commands)
    integral = np.abs(_achieved(robot, commands, 0, "chunk", ik_solver="vectorised") - commands)
    assert integral.max(1).mean() * 4 <= plain.max(1).mean(), (integral.max(1), plain.max(1))


def test_command_low_level_passes_its_options_on():
    low = CommandLowLevel("daisy", 2, feedback_steps=25, footstep_law="plain", ik_solver="reference")
    assert low.controller.integral_gain == 0.0 and low.controller.kinematics.solver == "reference"
    assert {"feedback_steps": 25, "footstep_law": "plain", "ik_solver": "reference"}.items() <= low.describe().items()
    out = low.run(BatchedSimulator("daisy", 2), np.array([[0.2, 0.0, 0.0], [0.0, 0.2, 0.0]]))
    assert out.joint_targets.shape == (2, 100, 18) and not out.failed.any()


def test_per_step_feedback_is_the_plain_loop_bit_for_bit():
    """``feedback_steps=1`` is exactly one :meth:`act` and one simulator step per control step (the loop the
    expert library is recorded with), through the command ramp and the freeze."""
    robot = get_robot("a1")
    commands = _commands(robot)[:4]
    out = run_closed_loop(BatchedSimulator(robot, 4, init_joint_noise=0.05, seed=3), RaibertController(robot, 4),
                          commands, 60, ramp_steps=30, freeze_after=40, feedback_steps=1)
    sim, controller = BatchedSimulator(robot, 4, init_joint_noise=0.05, seed=3), RaibertController(robot, 4)
    state = sim.com_state
    velocity, yaw_rate = world_to_local(state[:, 3:5], state[:, 2]), np.zeros(4)
    targets, states = [], []
    for n in range(60):
        if n == 40:
            controller.freeze()
        action = controller.act(commands * min(1.0, (n + 1) / 30), velocity, yaw_rate)
        step = sim.run(action[:, None])
        velocity, yaw_rate = step.com_velocity_local[:, 0], step.yaw_rate[:, 0]
        targets.append(action)
        states.append(step.com_state[:, 0])
    np.testing.assert_array_equal(out.joint_targets, np.stack(targets, 1))
    np.testing.assert_array_equal(out.com_state, np.stack(states, 1))


def test_a_chunk_follows_the_per_step_law():
    """With the feedback frozen, planning k steps at once gives the footholds, hence the joint targets, of k
    single steps (up to the IK tolerance: the warm starts differ)."""
    robot = get_robot("daisy")
    commands = np.array([[0.2, -0.1, 0.3], [-0.1, 0.2, -0.2]])
    chunked, stepped = RaibertController(robot, 2, ik_solver="vectorised"), RaibertController(robot, 2)
    velocity, yaw_rate = np.array([[0.15, -0.05], [0.0, 0.1]]), np.array([0.2, -0.1])
    chunked.act(commands, velocity, yaw_rate), stepped.act(commands, velocity, yaw_rate)
    chunked.freeze(), stepped.freeze()
    k = chunked.swing_steps + 7  # across a change of swing group
    planned = chunked.act_chunk(np.repeat(commands[:, None], k, 1), velocity[:, None], yaw_rate[:, None])
    single = np.stack([stepped.act(commands, velocity, yaw_rate) for _ in range(k)], 1)
    np.testing.assert_allclose(chunked.feet, stepped.feet, atol=1e-12)
    np.testing.assert_allclose(planned, single, atol=1e-4)
    assert chunked.step_count == stepped.step_count == k + 1


def test_successive_runs_observe_every_step():
    """Split into runs (one per action), the chunked loop feeds the velocity filter and the integral loop the same
    measurements as one long run: none of the last chunk's are lost at the split."""
    robot = get_robot("daisy")
    commands = np.array([[0.2, 0.1, 0.0], [-0.1, 0.2, 0.0]])
    k = 50
    whole, split = (RaibertController(robot, 2, ik_solver="vectorised") for _ in range(2))
    run_closed_loop(BatchedSimulator(robot, 2, seed=0), whole, commands, 150, feedback_steps=k)
    sim = BatchedSimulator(robot, 2, seed=0)
    first = run_closed_loop(sim, split, commands, 100, feedback_steps=k)
    np.testing.assert_array_equal(split.pending_velocity_local, first.com_velocity_local[:, -k:-1])
    run_closed_loop(sim, split, commands, 50, feedback_steps=k)
    np.testing.assert_array_equal(split.velocity, whole.velocity)  # filtered over steps 0..99 in both
    np.testing.assert_array_equal(split.correction[:, :2], whole.correction[:, :2])


def test_default_feedback_interval_is_a_swing_phase_of_at_most_a_quarter_second():
    assert RaibertController("a1", 1).swing_chunk_steps() == 10  # 0.1 s swing: the whole of it
    assert RaibertController("daisy", 1).swing_chunk_steps() == 25  # 0.5 s swing: halves
    assert RaibertController("daisy", 1).swing_chunk_steps(0.1) == 10
    assert RaibertController("daisy", 1).swing_chunk_steps(1.0) == 50
    assert RaibertController("a1", 1).swing_chunk_steps(0.001) == 1
    with pytest.raises(ValueError, match="max_seconds"):
        RaibertController("a1", 1).swing_chunk_steps(0.0)


def test_default_fast_path_chains_actions_without_falling():
    """The IK low level's default: random commands chained for 4 actions on both robots, nobody falls, and each
    action moves the robots the way they were told (the sign of the commanded forward velocity)."""
    for name in ("a1", "daisy"):
        low = CommandLowLevel(name, 6)
        assert low.feedback_steps == low.controller.swing_chunk_steps()
        assert low.controller.kinematics.solver == "vectorised"
        sim = BatchedSimulator(name, 6, init_joint_noise=0.02, seed=0)
        rng = np.random.default_rng(0)
        for _ in range(4):
            commands = rng.uniform(low.action_low, low.action_high, (6, 3))
            commands[:, 0] = np.where(rng.random(6) < 0.5, -0.25, 0.25)
            out = low.run(sim, commands)
            assert not out.failed.any()
            forward = out.com_velocity_local[:, 50:, 0].mean(1)
            assert np.all(np.sign(forward) == np.sign(commands[:, 0])), (name, forward, commands[:, 0])


def test_gait_groups_alternate():
    """A trot: diagonal pairs are in swing in turn, never together."""
    ctrl = RaibertController("a1", 1)
    legs = list(ctrl.robot.leg_names)
    for step in range(ctrl.steps_per_period):
        swinging = {legs[i] for i in np.flatnonzero(ctrl.swing_progress(step) > 0)}
        assert swinging in ({"FR", "RL"}, {"FL", "RR"})


def test_gait_period_must_fit_control_steps():
    with pytest.raises(ValueError, match="gait_period"):
        RaibertController("a1", 1, gait_period=0.123)


def test_bad_options_and_inputs_are_refused():
    with pytest.raises(ValueError, match="footstep_law"):
        RaibertController("a1", 1, footstep_law="pid")
    with pytest.raises(ValueError, match="integral"):
        RaibertController("a1", 1, footstep_law="plain", integral_gain=1.0)
    with pytest.raises(ValueError, match="solver"):
        RaibertController("a1", 1, ik_solver="analytic")
    controller = RaibertController("a1", 2)
    with pytest.raises(ValueError, match="B x k x 3"):
        controller.act_chunk(np.zeros((2, 3)), np.zeros((2, 1, 2)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="velocity_local"):
        controller.act_chunk(np.zeros((2, 4, 3)), np.zeros((2, 2)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="NaN"):
        controller.act_chunk(np.full((2, 4, 3), np.nan), np.zeros((2, 1, 2)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="feedback_steps"):
        run_closed_loop(BatchedSimulator("a1", 2), controller, np.zeros((2, 3)), 10, feedback_steps=0)
    with pytest.raises(ValueError, match="feedback_steps"):
        CommandLowLevel("a1", 2, feedback_steps=0)
    assert controller.step_count == 0  # nothing ran
