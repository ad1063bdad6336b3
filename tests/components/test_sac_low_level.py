"""SAC-SAC's low level: training wiring (learning curve, checkpoint and resume, artifact round trip), the low level
executing commands closed loop (the actor's own targets, the clock across actions, inside the latent-action env),
and the tracking evaluation on the IK expert as an oracle."""

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from hierloco.components.low_level import CommandLowLevel
from hierloco.components.sac import torch_threads
from hierloco.components.sac_low_level import (
    SACLowLevel,
    TrainedSACLowLevel,
    command_grid,
    evaluate_velocity_tracking,
    train_sac_low_level,
)
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP

TINY = dict(num_robots=16, hidden=32, batch_size=64, init_random_frames=512, updates_per_frame=1 / 16,
            log_every=512, progress=False)


@pytest.fixture(autouse=True)
def _one_torch_thread():
    with torch_threads(1):
        yield


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    path = tmp_path_factory.mktemp("sac_low") / "training.pt"
    return train_sac_low_level("a1", total_frames=1536, checkpoint_path=path, checkpoint_every=1024, **TINY), path


def test_training_reports_a_learning_curve(trained):
    result, _ = trained
    curve = result.metadata["learning_curve"]
    assert [p["frames"] for p in curve] == [512, 1024, 1536]
    assert result.metadata["frames"] == 1536 and result.agent.updates == (1536 - 512) // 16 + 1
    for point in curve:
        assert 0 <= point["tracking_error"] < 2 and np.isfinite(point["reward"])
        total = sum(point[f"reward/{t}"] for t in ("tracking_linear", "tracking_yaw", "alive", "torque",
                                                   "action_rate", "orientation"))
        assert total == pytest.approx(point["reward"], abs=1e-4)


def test_training_resumes_from_its_checkpoint_and_refuses_other_settings(trained, tmp_path):
    result, path = trained
    longer = train_sac_low_level("a1", total_frames=2048, checkpoint_path=path, **TINY)
    assert [p["frames"] for p in longer.metadata["learning_curve"]] == [512, 1024, 1536, 2048]
    assert longer.metadata["learning_curve"][:3] == result.metadata["learning_curve"]
    assert longer.agent.updates == result.agent.updates + 512 // 16
    with pytest.raises(ValueError, match="other settings.*hidden"):
        train_sac_low_level("a1", total_frames=4096, checkpoint_path=path, **{**TINY, "hidden": 64})


def test_artifact_round_trip(trained, tmp_path):
    result, _ = trained
    result.save(tmp_path / "low.pt")
    loaded = TrainedSACLowLevel.load(tmp_path / "low.pt")
    obs = torch.randn(5, result.interface.observation_size)
    torch.testing.assert_close(loaded.agent.act(obs), result.agent.act(obs))
    assert loaded.metadata == result.metadata and loaded.interface.describe() == result.interface.describe()


def test_low_level_runs_the_actor_closed_loop(trained):
    """Each control step's targets are the deterministic actor's action on that step's observation; the clock
    and previous action carry over to the next command and restart on reset."""
    result, _ = trained
    low = SACLowLevel(result, steps_per_action=5)
    sim, replay = BatchedSimulator("a1", 3, seed=0), BatchedSimulator("a1", 3, seed=0)
    commands = np.array([[0.2, 0.0, 0.0], [0.0, -0.1, 0.3], [0.0, 0.0, 0.0]])
    out = low.run(sim, commands)
    assert out.com_state.shape == (3, 5, 5) and out.joint_velocities.shape == (3, 5, 12)
    interface, last = result.interface, np.zeros((3, 12))
    for n in range(5):
        obs = interface.observe(replay.qpos, replay.qvel, commands, np.full(3, n * CONTROL_TIMESTEP), last)
        last = result.agent.act(torch.from_numpy(obs)).double().numpy()
        replay.run(interface.joint_targets(last)[:, None])
    np.testing.assert_array_equal(replay.state, sim.state)
    np.testing.assert_allclose(low._time, 5 * CONTROL_TIMESTEP)
    low.run(sim, commands)
    np.testing.assert_allclose(low._time, 10 * CONTROL_TIMESTEP)
    low.reset(np.array([True, False, False]))
    np.testing.assert_allclose(low._time, [0.0, 10 * CONTROL_TIMESTEP, 10 * CONTROL_TIMESTEP])
    assert np.all(low._last_action[0] == 0) and np.any(low._last_action[1] != 0)
    assert low.describe()["kind"] == "sac_command" and low.describe()["policy_frames"] == 1536


def test_a_stochastic_low_level_samples_its_policy_from_its_own_seeded_stream(trained):
    """Samples of the policy (what it was trained with) instead of its mean: the same seed gives the same motion,
    another seed or the mean another, and the global torch RNG is left where it was."""
    result, _ = trained
    commands = np.array([[0.2, 0.0, 0.0], [0.0, -0.1, 0.3]])

    def motion(**options):
        sim = BatchedSimulator("a1", 2, seed=0)
        low = SACLowLevel(result, steps_per_action=5, **options)
        states = [low.run(sim, commands).com_state for _ in range(2)]
        return np.concatenate(states, 1), low

    torch.manual_seed(123)
    before = torch.get_rng_state()
    first, low = motion(stochastic=True, seed=7)
    assert torch.equal(torch.get_rng_state(), before)  # the global stream is untouched
    again, _ = motion(stochastic=True, seed=7)
    np.testing.assert_array_equal(first, again)
    other, _ = motion(stochastic=True, seed=8)
    mean, _ = motion()
    assert not np.array_equal(first, other) and not np.array_equal(first, mean)
    assert low.describe()["stochastic"] is True


def test_low_level_serves_the_latent_action_env(trained):
    result, _ = trained
    low = SACLowLevel(result, steps_per_action=4)
    env = LatentActionEnv(low, num_robots=2, seed=0)
    check_env_specs(env)
    torch.testing.assert_close(env.action_spec.space.low[0], torch.tensor(env.robot.command_low, dtype=torch.float32))
    td = env.rollout(2)
    assert td["next", "com_state"].shape == (2, 2, 5)
    with pytest.raises(ValueError, match="actions must be"):
        low.run(BatchedSimulator("a1", 2), np.zeros((2, 2)))


def test_tracking_evaluation_on_the_ik_expert():
    """The IK expert tracks the box's corners within 0.1 m/s; standing still would be 0.42 m/s off."""
    commands = command_grid("a1", 2)
    assert commands.shape == (8, 3) and np.allclose(np.abs(commands[:, :2]), 0.3)
    report = evaluate_velocity_tracking(CommandLowLevel("a1", len(commands)), commands, num_actions=3)
    summary = report["summary"]
    assert summary["fall_rate"] == 0 and summary["linear_error_mean"] < 0.1
    assert summary["linear_error_standing"] == pytest.approx(np.hypot(0.3, 0.3))
    assert summary["yaw_rate_error_mean"] < 0.1 and len(report["rows"]) == 8
    row = report["rows"][0]
    assert row["linear_error"] == pytest.approx(np.linalg.norm(np.subtract(row["command"][:2], row["achieved"][:2])))
    with pytest.raises(ValueError, match="C x 3"):
        evaluate_velocity_tracking(CommandLowLevel("a1", 2), np.zeros((2, 2)))


@pytest.mark.slow
def test_training_learns_to_track():
    """100,000 frames (about 3,000 updates, several minutes here): the tracking error falls to at most 60 % of
    its value under the initial random actions (measured: 0.58 -> 0.18 m/s)."""
    result = train_sac_low_level("a1", total_frames=100_000, num_robots=32, hidden=256, batch_size=256,
                                 log_every=20_000, progress=False)
    curve = result.metadata["learning_curve"]
    assert curve[-1]["tracking_error"] < 0.6 * curve[0]["tracking_error"], [p["tracking_error"] for p in curve]
