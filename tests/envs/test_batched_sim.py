"""The batched simulator: exact agreement with plain MuJoCo stepping, chaining, resets, failure flags, bad input."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hierloco.envs.batched_sim import STATE_SPEC, BatchedSimulator
from hierloco.envs.frames import com_state_from_base, quat_to_roll_pitch_yaw
from hierloco.envs.robots import PHYSICS_STEPS_PER_CONTROL, get_robot, joint_qpos_indices
from hierloco.envs.scripted_gait import sinusoidal_gait
from tests.envs.toy_robot import make_toy_robot

ROBOTS = ("a1", "daisy")
TOLERANCE = 1e-8


def _gait_targets(robot, num_robots, num_steps, amplitude=0.15, frequency=2.0, seed=0):
    return sinusoidal_gait(robot, num_robots, num_steps, amplitude, frequency, seed, min_scale=0.8)


def _step_one_copy(model, state, targets):
    """Plain ``mj_step`` of one copy from a full physics state, holding each target for one control step.

    Returns the full state at the end of every control step (``T x nstate``).
    """
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state, STATE_SPEC)
    out = np.empty((len(targets), len(state)))
    for t, target in enumerate(targets):
        data.ctrl[:] = target
        for _ in range(PHYSICS_STEPS_PER_CONTROL):
            mujoco.mj_step(model, data)
        mujoco.mj_getState(model, data, out[t], STATE_SPEC)
    return out


def _assert_result_matches_states(sim, result, copy, states):
    """Compares one copy's :class:`SimulationResult` with full reference states ``T x nstate``."""
    nq = sim.model.nq
    qpos, qvel = states[:, 1:1 + nq], states[:, 1 + nq:1 + nq + sim.model.nv]
    joints = joint_qpos_indices(sim.model, sim.robot)
    np.testing.assert_allclose(result.joint_positions[copy], qpos[:, joints], rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(result.height[copy], qpos[:, 2], rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(result.com_state[copy], com_state_from_base(qpos[:, :3], qpos[:, 3:7], qvel[:, :3]),
                               rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(result.roll_pitch[copy], quat_to_roll_pitch_yaw(qpos[:, 3:7])[:, :2], rtol=0,
                               atol=TOLERANCE)


# ---------------------------------------------------------------- exactness
@pytest.mark.parametrize("name", ROBOTS)
def test_matches_plain_mj_step_one_copy_at_a_time_over_chained_runs(name):
    robot = get_robot(name)
    sim = BatchedSimulator(name, num_robots=3, init_joint_noise=0.05, seed=1, nthread=2)
    first, second = _gait_targets(robot, 3, 60, seed=0), _gait_targets(robot, 3, 40, seed=1)
    start = sim.state.copy()
    out_first = sim.run(first)
    out_second = sim.run(second)
    for copy in range(3):
        reference = _step_one_copy(sim.model, start[copy], np.concatenate([first[copy], second[copy]]))
        _assert_result_matches_states(sim, out_first, copy, reference[:60])
        _assert_result_matches_states(sim, out_second, copy, reference[60:])
        np.testing.assert_allclose(sim.state[copy], reference[-1], rtol=0, atol=TOLERANCE)
    # the copies did different things and stayed upright
    assert np.ptp(sim.state[:, 1:3], axis=0).max() > 1e-4
    assert not out_first.failed.any() and not out_second.failed.any()
    assert sim.state[0, 0] == pytest.approx(100 * PHYSICS_STEPS_PER_CONTROL * sim.timestep)  # time, s


def test_chained_runs_equal_one_long_run():
    robot = get_robot("a1")
    targets = _gait_targets(robot, 4, 90)
    chained = BatchedSimulator("a1", num_robots=4, init_joint_noise=0.05, seed=7)
    whole = BatchedSimulator("a1", num_robots=4, init_joint_noise=0.05, seed=7)
    np.testing.assert_array_equal(chained.state, whole.state)  # same seed, same initial states
    parts = [chained.run(targets[:, :30]), chained.run(targets[:, 30:45]), chained.run(targets[:, 45:])]
    out = whole.run(targets)
    for field in ("com_state", "com_velocity_local", "yaw_rate", "height", "roll_pitch", "joint_positions",
                  "foot_contacts", "fallen", "unstable"):
        joined = np.concatenate([getattr(part, field) for part in parts], axis=1)
        np.testing.assert_allclose(joined, getattr(out, field), rtol=0, atol=1e-10, err_msg=field)
    np.testing.assert_allclose(chained.state, whole.state, rtol=0, atol=1e-10)


def test_same_seed_same_initial_noise_different_seed_different():
    a, b, c = (BatchedSimulator("daisy", 2, init_joint_noise=0.05, seed=s) for s in (0, 0, 1))
    np.testing.assert_array_equal(a.state, b.state)
    assert np.abs(a.joint_positions - c.joint_positions).max() > 1e-3
    assert np.abs(a.joint_positions - np.asarray(a.robot.standing_pose)).max() <= 0.05


# ---------------------------------------------------------------- resets
def test_reset_mask_resets_only_the_masked_copies():
    robot = get_robot("a1")
    sim = BatchedSimulator("a1", num_robots=4, seed=0)
    fresh = sim.state.copy()
    sim.run(_gait_targets(robot, 4, 50, amplitude=0.3))
    moved = sim.state.copy()
    assert np.abs(moved - fresh).max(axis=1).min() > 1e-3  # every copy moved
    mask = np.array([True, False, True, False])
    com = sim.reset(mask)
    np.testing.assert_array_equal(sim.state[mask], fresh[mask])
    np.testing.assert_array_equal(sim.state[~mask], moved[~mask])
    np.testing.assert_allclose(com[mask], [[0.0, 0.0, np.pi / 2, 0.0, 0.0]] * 2, atol=1e-12)
    np.testing.assert_allclose(sim.joint_positions[mask], np.tile(robot.standing_pose, (2, 1)))


def test_reset_mask_with_joint_noise():
    sim = BatchedSimulator("daisy", num_robots=3, init_joint_noise=0.05, seed=0)
    sim.run(np.tile(np.asarray(sim.robot.standing_pose), (3, 20, 1)))
    before = sim.state.copy()
    mask = np.array([False, True, False])
    sim.reset(mask)
    np.testing.assert_array_equal(sim.state[~mask], before[~mask])
    assert sim.state[1, 0] == 0.0  # time
    offset = sim.joint_positions[1] - np.asarray(sim.robot.standing_pose)
    assert 0 < np.abs(offset).max() <= 0.05


# ---------------------------------------------------------------- failure flags
@pytest.mark.parametrize("name", ROBOTS)
def test_fall_flags_only_the_copy_that_falls(name):
    robot = get_robot(name)
    sim = BatchedSimulator(name, num_robots=3, seed=0)
    targets = np.tile(np.asarray(robot.standing_pose), (3, 200, 1))
    targets[1] = 0.0  # all-zero joint targets: the robot collapses
    out = sim.run(targets)
    assert out.fallen[1, -1] and not out.fallen[[0, 2]].any()
    first = np.argmax(out.fallen[1])
    assert 0 < first and out.fallen[1, first:].all() and not out.fallen[1, :first].any()  # stays fallen
    at_fall = (np.abs(out.roll_pitch[1, first]) > [robot.max_roll, robot.max_pitch]).any()
    assert at_fall or out.height[1, first] < robot.min_height
    assert not out.unstable.any()
    np.testing.assert_array_equal(out.failed, out.fallen)


@pytest.mark.parametrize("name", ROBOTS)
def test_unstable_flags_only_the_copy_that_blows_up(name):
    robot = get_robot(name)
    targets = _gait_targets(robot, 3, 40)
    sims = [BatchedSimulator(name, num_robots=3, init_joint_noise=0.05, seed=2) for _ in range(2)]
    for sim in sims:
        sim.run(targets[:, :10])
    sim, reference = sims
    state = sim.state[1].copy()
    state[1 + sim.model.nq + 8] = 1e11  # a joint velocity beyond MuJoCo's limit (1e10)
    sim.set_state(state[None], mask=np.array([False, True, False]))
    out, expected = sim.run(targets[:, 10:]), reference.run(targets[:, 10:])
    assert out.unstable[1].all()
    assert not out.unstable[[0, 2]].any() and not expected.unstable.any()
    np.testing.assert_array_equal(out.failed[1], True)
    for copy in (0, 2):  # the other copies are unaffected
        np.testing.assert_array_equal(out.joint_positions[copy], expected.joint_positions[copy])
        np.testing.assert_array_equal(out.com_state[copy], expected.com_state[copy])
        np.testing.assert_array_equal(sim.state[copy], reference.state[copy])
    # resetting the blown-up copy makes it usable again
    sim.reset(np.array([False, True, False]))
    after = sim.run(np.tile(np.asarray(robot.standing_pose), (3, 20, 1)))
    assert not after.failed.any() and np.isfinite(sim.state).all()


# ---------------------------------------------------------------- disabled legs
@pytest.mark.parametrize("name", ROBOTS)
def test_disabled_legs_hold_their_standing_angles(name):
    robot = get_robot(name)
    num_robots, num_steps = 3, 150
    disabled = robot.leg_joint_indices(robot.rear_legs)
    working = np.setdiff1d(np.arange(robot.num_joints), disabled)
    sim = BatchedSimulator(name, num_robots, disabled_legs=robot.rear_legs, init_joint_noise=0.05, seed=0)
    targets = _gait_targets(robot, num_robots, num_steps, amplitude=0.35)  # 0.28 to 0.35 rad
    low, high = sim.model.actuator_ctrlrange[:, 0], sim.model.actuator_ctrlrange[:, 1]
    random = np.random.default_rng(0).uniform(low, high, (num_robots, num_steps, robot.num_joints))
    targets[..., disabled] = random[..., disabled]  # the disabled legs are asked to go anywhere
    standing = np.asarray(robot.standing_pose)
    assert np.abs(sim.joint_positions[:, disabled] - standing[disabled]).max() < 1e-12  # they start standing
    out = sim.run(targets)
    assert not out.unstable.any()
    assert np.abs(out.joint_positions[..., disabled] - standing[disabled]).max() < 0.05
    swing = np.ptp(out.joint_positions[..., working], axis=1)  # B x working joints, peak to peak
    assert swing.min() > 0.3


# ---------------------------------------------------------------- a user's MJCF robot
@pytest.mark.parametrize("feet", ["site", "body"])
def test_user_mjcf_robot_in_the_batched_simulator(feet):
    robot = make_toy_robot(feet)
    sim = BatchedSimulator(robot, num_robots=4, init_joint_noise=0.03, seed=0)
    out = sim.run(np.tile(np.asarray(robot.standing_pose), (4, 100, 1)))
    assert out.com_state.shape == (4, 100, 5) and out.foot_contacts.shape == (4, 100, 4)
    assert not out.failed.any() and out.foot_contacts[:, -1].all()
    assert np.abs(out.height[:, 50:] - robot.standing_height).max() < 0.03
    out = sim.run(_gait_targets(robot, 4, 200))  # it walks, without falling
    assert not out.failed.any()
    assert np.linalg.norm(out.com_state[:, -1, :2] - out.com_state[:, 0, :2], axis=-1).min() > 0.1
    start = sim.state.copy()
    targets = _gait_targets(robot, 4, 20, seed=3)
    out = sim.run(targets)
    reference = _step_one_copy(sim.model, start[2], targets[2])
    _assert_result_matches_states(sim, out, 2, reference)


# ---------------------------------------------------------------- bad input
def test_unknown_robot_and_leg_are_errors():
    with pytest.raises(ValueError, match="unknown robot 'anymal'"):
        BatchedSimulator("anymal", num_robots=2)
    with pytest.raises(ValueError, match=r"no legs \['tail'\]"):
        BatchedSimulator("a1", num_robots=2, disabled_legs=("tail",))
    with pytest.raises(ValueError, match="num_robots must be at least 1"):
        BatchedSimulator("a1", num_robots=0)


@pytest.mark.parametrize("shape", [(2, 10, 11), (3, 10, 12), (2, 12), (2, 10, 12, 1)])
def test_wrong_target_shape_is_an_error(shape):
    sim = BatchedSimulator("a1", num_robots=2)
    with pytest.raises(ValueError, match=r"joint_targets must be B x T x J = 2 x T x 12"):
        sim.run(np.zeros(shape))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_targets_are_an_error(bad):
    sim = BatchedSimulator("a1", num_robots=2)
    before = sim.state.copy()
    targets = np.tile(np.asarray(sim.robot.standing_pose), (2, 10, 1))
    targets[1, 4, 3] = bad
    with pytest.raises(ValueError, match="NaN or inf"):
        sim.run(targets)
    np.testing.assert_array_equal(sim.state, before)  # nothing was simulated


@pytest.mark.parametrize("noise", [-0.01, np.nan, "0.05"])
def test_bad_joint_noise_is_an_error(noise):
    with pytest.raises(ValueError, match="init_joint_noise"):
        BatchedSimulator("a1", num_robots=2, init_joint_noise=noise)


# ---------------------------------------------------------------- out-of-range targets, threads
@pytest.mark.parametrize("name", ROBOTS)
def test_targets_beyond_the_joint_range_are_clamped_to_it(name):
    """1e12 rad (and -1e12) act exactly as the joint limits, and the limits are the model's control range."""
    sims = [BatchedSimulator(name, num_robots=2, seed=0) for _ in range(3)]
    low, high = sims[0].model.actuator_ctrlrange.T
    targets = _gait_targets(sims[0].robot, 2, 30)
    huge = targets.copy()
    huge[:, 10:20, 0], huge[:, 10:20, 1] = 1e12, -1e12
    at_limits = targets.copy()
    at_limits[:, 10:20, 0], at_limits[:, 10:20, 1] = high[0], low[1]
    results = [sim.run(t) for sim, t in zip(sims, (huge, at_limits, targets))]
    np.testing.assert_array_equal(results[0].qpos, results[1].qpos)
    np.testing.assert_array_equal(sims[0].state, sims[1].state)
    pushed, plain = results[0].joint_positions[:, 19], results[2].joint_positions[:, 19]
    assert np.all(pushed[:, 0] > plain[:, 0] + 0.05) and np.all(pushed[:, 1] < plain[:, 1] - 0.05)


def test_threads_default_to_the_cores_the_process_may_use(monkeypatch):
    from hierloco.envs import batched_sim

    assert BatchedSimulator("a1", num_robots=2).nthread == batched_sim.available_cores()
    assert batched_sim.available_cores() == len(__import__("os").sched_getaffinity(0))
    monkeypatch.setattr(batched_sim.os, "sched_getaffinity", lambda pid: {0})  # e.g. a one-core Ray worker
    assert BatchedSimulator("a1", num_robots=2).nthread == 1
    assert BatchedSimulator("a1", num_robots=2, nthread=3).nthread == 3  # overridable
    targets = _gait_targets(get_robot("a1"), 4, 20)
    one, three = BatchedSimulator("a1", 4, seed=0, nthread=1), BatchedSimulator("a1", 4, seed=0, nthread=3)
    np.testing.assert_array_equal(one.run(targets).qpos, three.run(targets).qpos)  # threads change no number
