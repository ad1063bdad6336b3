"""CoM dynamics data: the right count, seeded, falls dropped and counted, stored safely."""

import numpy as np
import pytest

from hierloco.components.dynamics_data import TransitionData, collect_transitions
from hierloco.components.expert_library import build_expert_library
from hierloco.components.low_level import ExpertReplayLowLevel, LowLevel
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import get_robot
from hierloco.io import ArtifactError


@pytest.fixture(scope="module")
def library():
    return build_expert_library("daisy", 4, seed=0, progress=False)


def _collect(library, seed, count=30):
    env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=8, init_joint_noise=0.02, seed=seed)
    return collect_transitions(env, count, episode_length=3, seed=seed, progress=False)


def test_count_shapes_and_chaining(library):
    data = _collect(library, 0)
    assert len(data) == 30 and data.com_state.shape == (30, 5) and data.action.shape == (30, 1)
    assert set(np.unique(data.action)) <= {0.0, 1.0, 2.0, 3.0}
    assert data.metadata["dropped_failures"] == 0 and data.metadata["low_level"]["kind"] == "expert_replay"
    # actions are chained: some transitions start away from the origin (not every one from a reset)
    assert np.any(np.linalg.norm(data.com_state[:, :2], axis=1) > 0.05)
    # the next state is where the robot went: replayed experts move it by roughly their recorded displacement
    moved = np.linalg.norm(data.next_com_state[:, :2] - data.com_state[:, :2], axis=1)
    expected = np.linalg.norm(library.displacement_local[data.action[:, 0].astype(int), :2], axis=1)
    assert np.median(np.abs(moved - expected)) < 0.05


def test_same_seed_same_data_different_seed_different(library):
    a, b, c = _collect(library, 0), _collect(library, 0), _collect(library, 1)
    np.testing.assert_array_equal(a.next_com_state, b.next_com_state)
    np.testing.assert_array_equal(a.action, b.action)
    assert not np.array_equal(a.action, c.action)


class FallsOnHighActions(LowLevel):
    """Replays expert 0, except that actions above 0.5 send every joint to zero: those robots fall."""

    kind = "falls_on_high_actions"

    def __init__(self, library):
        self.library, self.robot = library, get_robot(library.robot)
        self.steps_per_action = library.steps_per_action
        self.action_low, self.action_high = np.zeros(1), np.ones(1)

    def run(self, sim, actions):
        targets = np.repeat(self.library.joint_targets[:1], sim.num_robots, 0)
        targets[actions[:, 0] > 0.5] = 0.0
        return sim.run(targets)


def test_falls_are_dropped_and_counted(library):
    env = LatentActionEnv(FallsOnHighActions(library), num_robots=8)
    data = collect_transitions(env, 20, episode_length=5, seed=0, progress=False)
    assert len(data) == 20
    assert np.all(data.action <= 0.5), "no transition that fell reaches the data"
    assert data.metadata["dropped_failures"] > 0
    assert data.metadata["actions_executed"] == 20 + data.metadata["dropped_failures"]


def test_save_load_and_corruption(library, tmp_path):
    data = _collect(library, 0, count=10)
    path = tmp_path / "data.npz"
    data.save(path)
    loaded = TransitionData.load(path)
    np.testing.assert_array_equal(loaded.next_com_state, data.next_com_state)
    assert loaded.metadata == data.metadata
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(ArtifactError, match="corrupted"):
        TransitionData.load(path)


def test_bad_requests_are_refused(library):
    env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2)
    with pytest.raises(ValueError, match="num_transitions"):
        collect_transitions(env, 0, progress=False)
