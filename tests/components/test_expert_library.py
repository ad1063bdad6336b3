"""The expert library: periodic open-loop gaits that replay to the same CoM motion, saved and loaded safely."""

import numpy as np
import pytest

from hierloco.components.expert_library import ExpertLibrary, action_motion, build_expert_library, replay
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot
from hierloco.io import ArtifactError
from hierloco.plots import plot_gait_diagram

NUM_EXPERTS = 6


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
