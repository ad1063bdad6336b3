"""The expert library: periodic open-loop gaits that replay to the same CoM motion, saved and loaded safely, and
checked to walk as commanded (experts that cannot represent the command box stop the run)."""

import numpy as np
import pytest

from hierloco.components.expert_library import (
    MIN_REACH,
    ExpertLibrary,
    ExpertQualityError,
    action_motion,
    build_expert_library,
    diagnose_expert_library,
    replay,
    require_expert_library_quality,
)
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot, robot_fingerprint
from hierloco.io import ArtifactError
from hierloco.plots import plot_gait_diagram
from tests.envs.test_user_robots import FIXTURE_YAML

NUM_EXPERTS = 6
TINY_SETTLE_TIME = 1.0  # s, the CI preset's
WIDE_MARGIN = 1.5  # the built-in robots' worst reach is at least this many times the threshold


@pytest.fixture(scope="module", params=["a1", "daisy"])
def library(request):
    return build_expert_library(request.param, NUM_EXPERTS, seed=0, progress=False)


def test_library_contents(library):
    n, joints = library.steps_per_action, len(library.metadata["joint_names"])
    assert library.joint_targets.shape == (NUM_EXPERTS, n, joints)
    assert library.com_states.shape == (NUM_EXPERTS, n + 1, 5)
    assert np.all(np.isfinite(library.joint_targets))
    low, high = library.commands.min(0), library.commands.max(0)
    assert np.all(high - low > 0.05), "commands should spread over the command box"


def test_pattern_is_periodic(library):
    """The jump from the last step back to the first is no bigger than the jumps inside the pattern."""
    targets = library.joint_targets
    wrap = np.abs(targets[:, 0] - targets[:, -1]).max(-1)
    inside = np.abs(np.diff(targets, axis=1)).max((1, 2))
    assert np.all(wrap <= inside + 1e-9)


def test_open_loop_replay_reproduces_the_expert(library):
    """Replayed 5 times from standing, actions 2-5 move the CoM as recorded: within 0.02 m/s and 0.05 rad/s."""
    sim = BatchedSimulator(library.robot, NUM_EXPERTS)
    out = replay(sim, library.joint_targets, 5)
    assert not out.failed.any()
    n = library.steps_per_action
    per_action = [action_motion(out.com_state[:, a * n - 1:(a + 1) * n], n * CONTROL_TIMESTEP) for a in range(2, 5)]
    velocity = np.mean([v for _, v, _ in per_action], 0)
    yaw_rate = np.mean([w for _, _, w in per_action], 0)
    np.testing.assert_allclose(velocity, library.velocity_local, atol=0.02)
    np.testing.assert_allclose(yaw_rate, library.yaw_rate, atol=0.05)


def test_same_seed_same_library(library):
    again = build_expert_library(library.robot, NUM_EXPERTS, seed=0, progress=False)
    np.testing.assert_array_equal(again.joint_targets, library.joint_targets)
    other = build_expert_library(library.robot, 2, seed=1, progress=False)
    assert not np.allclose(other.commands, library.commands[:2])


def test_save_load_round_trip(library, tmp_path):
    path = tmp_path / "experts.npz"
    library.save(path)
    loaded = ExpertLibrary.load(path)
    np.testing.assert_array_equal(loaded.joint_targets, library.joint_targets)
    np.testing.assert_array_equal(loaded.commands, library.commands)
    assert loaded.metadata == library.metadata
    assert [p.name for p in tmp_path.iterdir()] == ["experts.npz"], "no temporary files left behind"


def test_corrupted_library_is_refused(library, tmp_path):
    path = tmp_path / "experts.npz"
    library.save(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ArtifactError, match="corrupted"):
        ExpertLibrary.load(path)
    with pytest.raises(ArtifactError, match="no such"):
        ExpertLibrary.load(tmp_path / "missing.npz")


def test_experts_in_a_box_of_ones_own_walk_as_commanded():
    """Experts that do not turn: the yaw-rate axis held at 0; the library records the box and is checked on it."""
    lib = build_expert_library("daisy", NUM_EXPERTS, seed=0, settle_time=TINY_SETTLE_TIME, progress=False,
                               command_low=[-0.3, -0.3, 0.0], command_high=[0.3, 0.3, 0.0])
    assert np.all(lib.commands[:, 2] == 0.0) and np.ptp(lib.commands[:, 0]) > 0.1
    assert lib.metadata["command_low"] == [-0.3, -0.3, 0.0] and lib.metadata["command_high"] == [0.3, 0.3, 0.0]
    assert np.abs(lib.yaw_rate).max() < 0.1  # rad/s: they walk without turning
    require_expert_library_quality(lib)  # vx and vy reach the box's edges; yaw does not vary, so is not assessed
    for low, high, problem in (([0.3, 0.0, 0.0], [-0.3, 0.0, 0.0], "at most command_high"),
                               ([0.1, 0.1], None, "3 finite numbers"), (["x", 0, 0], None, "3 numbers")):
        with pytest.raises(ValueError, match=problem):
            build_expert_library("daisy", 2, command_low=low, command_high=high, progress=False)


def test_action_must_hold_whole_gait_periods():
    with pytest.raises(ValueError, match="whole number"):
        build_expert_library("daisy", 2, steps_per_action=150, progress=False)
    with pytest.raises(ValueError, match="num_experts"):
        build_expert_library("daisy", 0, progress=False)


def test_gait_diagram(library, tmp_path):
    path = tmp_path / "gait.png"
    legs = get_robot(library.robot).leg_names
    duty = plot_gait_diagram(library.foot_contacts[0], legs, path, action_steps=library.steps_per_action)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # trot and tripod: every leg is in stance roughly half the time, and in swing for a while
    assert np.all((duty > 0.3) & (duty < 0.85)), duty


# ---------------------------------------------------------------------------------------------------- tracking
def test_tracking_is_recorded(library, tmp_path):
    robot = get_robot(library.robot)
    achieved = np.c_[library.velocity_local, library.yaw_rate]
    np.testing.assert_array_equal(library.tracking_error, achieved - library.commands)
    tracking = library.metadata["tracking"]
    assert tracking["ok"] and set(tracking["axes"]) == {"vx", "vy", "yaw_rate"}
    vx = tracking["axes"]["vx"]
    assert vx["mean_abs_error"] == pytest.approx(np.abs(library.tracking_error[:, 0]).mean())
    assert vx["worst_abs_error"] == pytest.approx(np.abs(library.tracking_error[:, 0]).max())
    assert library.metadata["robot_fingerprint"] == robot_fingerprint(robot)
    assert library.metadata["command_low"] == list(robot.command_low)
    library.save(tmp_path / "experts.npz")
    np.testing.assert_array_equal(ExpertLibrary.load(tmp_path / "experts.npz").tracking_error, library.tracking_error)


@pytest.mark.parametrize("name", ["a1", "daisy"])
def test_builtin_experts_walk_as_commanded_at_the_tiny_preset(name):
    """6 experts settled 1 s (the CI preset): worst reach 0.96 (A1) and 1.14 (Daisy) against the 0.4 threshold."""
    lib = build_expert_library(name, NUM_EXPERTS, seed=0, settle_time=TINY_SETTLE_TIME, progress=False)
    report = require_expert_library_quality(lib)
    assert report.ok and report.worst_reach >= WIDE_MARGIN * MIN_REACH, str(report)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["a1", "daisy"])
def test_builtin_experts_walk_as_commanded_at_paper_scale(name):
    """50 experts settled 3 s: worst reach 0.90-0.93 (A1) and 1.21-1.26 (Daisy) over seeds 0-2."""
    lib = build_expert_library(name, 50, seed=0, progress=False)
    report = require_expert_library_quality(lib)
    assert report.worst_reach >= 2 * MIN_REACH, str(report)


@pytest.fixture(scope="module")
def quadruped20():
    """The 20 kg fixture robot with its derived 0.5 s gait period and with a 0.2 s one."""
    robot = get_robot(str(FIXTURE_YAML))
    with pytest.warns(RuntimeWarning, match="do not walk as commanded"):
        short = build_expert_library(robot.replace(gait_period=0.2), NUM_EXPERTS, seed=0, progress=False)
    return robot, build_expert_library(robot, NUM_EXPERTS, seed=0, progress=False), short


def test_user_robot_with_a_suitable_gait_period_walks_as_commanded(quadruped20):
    robot, library, _ = quadruped20
    assert robot.gait_period == 0.5  # derived from its size
    report = require_expert_library_quality(library)
    assert report.worst_reach >= WIDE_MARGIN * MIN_REACH, str(report)


def test_user_robot_with_a_too_short_gait_period_stops_the_run(quadruped20):
    """0.2 s trot: about 0.75 x command - 0.14 m/s forward, so it cannot walk forward faster than 0.08 m/s."""
    robot, _, library = quadruped20
    with pytest.raises(ExpertQualityError) as caught:
        require_expert_library_quality(library, robot=robot.replace(gait_period=0.2))
    report = caught.value.report
    assert isinstance(caught.value, ValueError) and not report.ok
    vx, vy, yaw = report.axes
    assert not vx.ok and vy.ok and yaw.ok
    assert vx.reach_high < MIN_REACH and vx.mean_error < -0.1
    message = str(caught.value)
    for part in ("do not walk as commanded", "vx: commanded -0.30..+0.30 m/s", "towards forward it reaches",
                 "more backward than commanded", "gait_period (now 0.2 s)", "the size rule gives 0.5 s",
                 "kp (now 150 N m/rad)", "standing_height (now 0.375 m"):
        assert part in message, message


def test_user_robot_trot_alternates_diagonal_stance(quadruped20, tmp_path):
    """The fixture's feet (foot sites exactly the size of the foot spheres) show a trot in the gait diagram."""
    robot, library, _ = quadruped20
    contacts = library.foot_contacts[0]  # N x L, legs FR, FL, RR, RL
    fr, fl, rr, rl = contacts.T
    assert np.mean(fr == rl) > 0.9 and np.mean(fl == rr) > 0.9  # diagonal pairs together
    assert np.mean(fr != fl) > 0.5  # the two pairs take turns
    periods = round(library.steps_per_action * CONTROL_TIMESTEP / robot.gait_period)
    for leg in contacts.T:  # each foot touches down once per gait cycle
        assert np.sum(leg & ~np.roll(leg, 1)) == periods
    duty = plot_gait_diagram(contacts, robot.leg_names, tmp_path / "gait.png", action_steps=library.steps_per_action)
    assert np.all((duty > 0.3) & (duty < 0.85)), duty


def _synthetic_library(achieved: np.ndarray, commands: np.ndarray) -> ExpertLibrary:
    """An expert library holding only commands and achieved motion, for oracle tests of the diagnosis."""
    g = len(commands)
    return ExpertLibrary(commands=commands, joint_targets=np.zeros((g, 100, 12)), com_states=np.zeros((g, 101, 5)),
                         foot_contacts=np.zeros((g, 100, 4), bool), velocity_local=achieved[:, :2],
                         yaw_rate=achieved[:, 2], displacement_local=np.zeros((g, 3)),
                         metadata={"robot": "a1", "command_low": [-0.3, -0.3, -0.5], "command_high": [0.3, 0.3, 0.5]})


def test_diagnosis_says_how_far_off_and_in_which_direction():
    commands = np.stack(np.meshgrid([-0.3, 0.0, 0.3], [-0.3, 0.3], [-0.5, 0.5]), -1).reshape(-1, 3)
    achieved = commands.copy()
    achieved[:, 0] = -0.3  # walks backward at 0.3 m/s whatever the command
    achieved[:, 2] = 0.01 * commands[:, 2]  # does not turn
    with pytest.raises(ExpertQualityError) as caught:
        require_expert_library_quality(_synthetic_library(achieved, commands))
    vx, vy, yaw = caught.value.report.axes
    assert (vx.ok, vy.ok, yaw.ok) == (False, True, False)
    assert vx.mean_error == pytest.approx(-0.3) and vx.worst_abs_error == pytest.approx(0.6)
    assert vx.reach_low == pytest.approx(1.0) and vx.reach_high == pytest.approx(-1.0)
    message = str(caught.value)
    assert "vx: commanded -0.30..+0.30 m/s, achieved -0.30..-0.30 m/s" in message
    assert "walks backward at 0.30 m/s whatever the command" in message
    assert "does not respond to yaw_rate commands" in message
    assert "what to try" in message and "gait_period (now 0.2 s)" in message  # A1's values, from the registry
    perfect = diagnose_expert_library(_synthetic_library(commands.copy(), commands))
    assert perfect.ok and perfect.worst_reach == pytest.approx(1.0)
    with pytest.raises(ValueError, match="min_reach must be a positive fraction"):
        diagnose_expert_library(_synthetic_library(commands.copy(), commands), min_reach=float("nan"))


# ---------------------------------------------------------------------------------------------------- off flat ground
def _foot_lift_m(library) -> float:
    """The experts' median foot lift: per expert and leg, the range of the foot's height in the base frame over the
    recorded action, from the joint targets (forward kinematics)."""
    from hierloco.components.kinematics import LegKinematics

    feet = LegKinematics("a1").forward(library.joint_targets)  # G x N x L x 3
    return float(np.median(np.ptp(feet[..., 2], axis=1)))


def test_experts_lift_their_feet_as_asked_and_record_the_ground_they_walked_on():
    """``swing_height_m`` raises the experts' foot lift (A1's own is 0.06 m) and ``terrain`` is the ground they are
    recorded on; both are in the library's metadata, the robot's fingerprint stays the robot's (docs/terrain.md)."""
    commands = np.array([[0.2, 0.0, 0.0], [0.0, 0.1, 0.0], [-0.1, 0.0, 0.2]])
    own = build_expert_library("a1", 3, commands=commands, settle_time=1.0, progress=False)
    high = build_expert_library("a1", 3, commands=commands, settle_time=1.0, progress=False, swing_height_m=0.10,
                                terrain={"name": "rough", "difficulty": 0.3})
    assert _foot_lift_m(high) > _foot_lift_m(own) + 0.025, (_foot_lift_m(high), _foot_lift_m(own))
    assert high.metadata["swing_height_m"] == 0.10
    assert high.metadata["terrain"] == {"name": "rough", "difficulty": 0.3, "seed": 0}
    assert "swing_height_m" not in own.metadata and "terrain" not in own.metadata
    assert high.metadata["robot_fingerprint"] == own.metadata["robot_fingerprint"]
    # on rough ground the recorded CoM paths are not the flat ones: the experts met the bumps
    assert not np.allclose(high.com_states, own.com_states)
    with pytest.raises(ValueError, match="swing_height_m must be a foot lift in"):
        build_expert_library("a1", 3, commands=commands, progress=False, swing_height_m=0.5)
