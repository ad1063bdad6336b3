"""The latent-action environment: TorchRL contracts, seeding, falls, collectors, with every kind of low level."""

import warnings

import numpy as np
import pytest
import torch
from torchrl.collectors import Collector
from torchrl.envs import StepCounter, TransformedEnv
from torchrl.envs.utils import check_env_specs

from hierloco.components.dynamics_data import UniformActionPolicy
from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy import train_gait_policy
from hierloco.components.low_level import CommandLowLevel, ExpertReplayLowLevel, LatentLowLevel, LowLevel
from hierloco.envs.latent_env import LatentActionEnv


@pytest.fixture(scope="module")
def library():
    return build_expert_library("a1", 4, seed=0, progress=False)


@pytest.fixture(scope="module")
def latent_low_level(library):
    trained = train_gait_policy(library.joint_targets, latent_dim=2, periods_per_action=5, hidden=64, epochs=20,
                                progress=False)
    return LatentLowLevel(trained, "a1")


class Collapse(LowLevel):
    """A low level that sends every joint to zero: the robot falls."""

    kind = "collapse"

    def __init__(self, robot="a1"):
        from hierloco.envs.robots import get_robot

        self.robot = get_robot(robot)
        self.steps_per_action = 100
        self.action_low, self.action_high = np.zeros(1), np.ones(1)

    def run(self, sim, actions):
        return sim.run(np.zeros((sim.num_robots, self.steps_per_action, self.robot.num_joints)))


def test_check_env_specs_latent(latent_low_level):
    env = LatentActionEnv(latent_low_level, num_robots=3, seed=0)
    check_env_specs(env)
    assert env.action_spec.shape == (3, 2)
    torch.testing.assert_close(env.action_spec.space.low[0], torch.as_tensor(latent_low_level.action_low).float())


def test_check_env_specs_expert_replay_and_command(library):
    check_env_specs(LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2, record=True))
    check_env_specs(LatentActionEnv(CommandLowLevel("a1", 2), num_robots=2, disabled_legs=("RR", "RL")))


def test_a_step_is_one_whole_action(library):
    env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2, record=True)
    td = env.reset()
    td["action"] = torch.tensor([[0], [1]])
    out = env.step(td)["next"]
    assert out["com_path"].shape == (2, 100, 5) and out["foot_contacts"].shape == (2, 100, 4)
    torch.testing.assert_close(out["com_path"][:, -1], out["com_state"])
    moved = (out["com_state"][:, :2] - td["com_state"][:, :2]).norm(dim=-1)
    assert torch.all(moved > 0.02), "the experts walk"


def test_same_seed_same_rollout_different_seed_different(latent_low_level):
    def rollout(seed):
        env = LatentActionEnv(latent_low_level, num_robots=2, init_joint_noise=0.05, seed=seed)
        policy = UniformActionPolicy(env.action_spec, seed=1)
        return env.rollout(3, policy=policy)["next", "com_state"]

    torch.testing.assert_close(rollout(0), rollout(0), atol=0, rtol=0)
    assert not torch.allclose(rollout(0), rollout(1))


def test_fall_terminates_and_reset_restores(library):
    env = LatentActionEnv(Collapse(), num_robots=2)
    td = env.reset()
    td["action"] = torch.zeros(2, 1)
    out = env.step(td)["next"]
    assert out["terminated"].all() and out["done"].all() and not out["truncated"].any()
    assert env.failures == 2
    reset = env.reset()
    torch.testing.assert_close(reset["com_state"][:, :3], torch.tensor([[0.0, 0.0, np.pi / 2]] * 2))


def test_works_with_a_collector_and_transforms(latent_low_level):
    env = TransformedEnv(LatentActionEnv(latent_low_level, num_robots=4), StepCounter(max_steps=2))
    collector = Collector(env, UniformActionPolicy(env.action_spec, seed=0), frames_per_batch=8, total_frames=16,
                          auto_register_policy_transforms=False)
    batches = list(collector)
    collector.shutdown()
    assert len(batches) == 2 and batches[0].numel() == 8
    assert batches[0]["next", "truncated"].any(), "StepCounter truncates after 2 actions"
    action = torch.cat([b["action"].reshape(-1, 2) for b in batches])
    low = torch.as_tensor(latent_low_level.action_low, dtype=torch.float32)
    high = torch.as_tensor(latent_low_level.action_high, dtype=torch.float32)
    assert torch.all(action >= low) and torch.all(action <= high)


def test_bad_actions_are_refused(library):
    env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2)
    td = env.reset()
    td["action"] = torch.tensor([[0], [99]])
    with pytest.raises(ValueError, match="expert indices"):
        env.step(td)


def test_is_init_marks_each_robots_episode_start_in_a_collector(library):
    """The env writes TorchRL's ``is_init`` itself: true at a robot's reset (only the robots reset), false after a
    step; a collector over the bare env sees it at every episode start and finds no transform missing."""
    env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2, seed=0)
    td = env.reset()
    assert td["is_init"].squeeze(-1).tolist() == [True, True]
    td = env.step(td.set("action", torch.tensor([[0], [1]])))["next"]
    assert td["is_init"].squeeze(-1).tolist() == [False, False]
    td = env.reset(td.set("_reset", torch.tensor([[False], [True]])))
    assert td["is_init"].squeeze(-1).tolist() == [False, True]

    limited = TransformedEnv(env, StepCounter(max_steps=2))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        collector = Collector(limited, UniformActionPolicy(limited.action_spec, seed=0), frames_per_batch=10,
                              total_frames=10)
        batch = next(iter(collector))
        collector.shutdown()
    assert not [w for w in caught if "missing transforms" in str(w.message)]
    assert batch["step_count"].squeeze(-1).tolist() == [[0, 1, 0, 1, 0]] * 2
    torch.testing.assert_close(batch["is_init"], batch["step_count"] == 0)


def test_one_robot_keeps_its_batch_dimension(library):
    """The batch is ``[B]`` for every B, 1 included (the conventions of ``hierloco.envs``); recorded foot contacts
    are bool."""
    env = LatentActionEnv(ExpertReplayLowLevel(library), num_robots=1, record=True, seed=0)
    check_env_specs(env)
    td = env.rollout(2, policy=UniformActionPolicy(env.action_spec, seed=0))
    assert env.batch_size == (1,) and td.batch_size == (1, 2)
    assert td["next", "com_state"].shape == (1, 2, 5) and td["next", "done"].shape == (1, 2, 1)
    assert td["action"].shape == (1, 2, 1) and td["next", "foot_contacts"].shape == (1, 2, 100, 4)
    assert td["next", "foot_contacts"].dtype == torch.bool and env.observation_spec["foot_contacts"].dtype == torch.bool


@pytest.mark.parametrize("num_robots", [0, -2, 1.5, True, "2", float("nan")])
def test_a_bad_number_of_robots_is_refused(library, num_robots):
    with pytest.raises(ValueError, match="num_robots must be a whole number >= 1"):
        LatentActionEnv(ExpertReplayLowLevel(library), num_robots=num_robots)
