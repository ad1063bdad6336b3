"""The task transforms on a real LatentActionEnv (Daisy replaying 3 experts): task state, -cost reward and its
terms, the StepCounter time limit, partial resets, and falls that do not end an evaluation episode."""

import numpy as np
import pytest
import torch
from torchrl.envs import Compose, StepCounter, TransformedEnv
from torchrl.envs.utils import check_env_specs

from hierloco.components.expert_library import build_expert_library
from hierloco.components.low_level import ExpertReplayLowLevel
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.low_level import LowLevel
from hierloco.envs.robots import START_YAW, get_robot
from hierloco.envs.tasks import GoalReaching, VelocityTracking
from hierloco.envs.transforms import ContinueAfterFalls, TaskEpisode, TaskReward, TaskTransform, task_transforms

THREE_GOALS = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]


@pytest.fixture(scope="module")
def library():
    return build_expert_library("daisy", 3, seed=0, progress=False)


@pytest.fixture
def make_env(library):
    envs = []

    def make(task, num_robots=4, episodes=None):
        env = TransformedEnv(LatentActionEnv(ExpertReplayLowLevel(library), num_robots=num_robots, seed=0),
                             task_transforms(task, episodes))
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()


def fixed_actions(num_robots):
    return torch.arange(num_robots)[:, None] % 3  # expert b % 3 for robot b


def test_check_env_specs(make_env):
    env = make_env(GoalReaching(goals=THREE_GOALS, num_steps=2), num_robots=2)
    check_env_specs(env)
    spec = env.observation_spec
    assert spec["task_episode"].shape == (2, 1) and spec["task_episode"].dtype == torch.int64
    assert spec["task_step"].shape == (2, 1) and spec["task_step"].dtype == torch.int64
    assert spec["cost_tracking"].shape == spec["cost_yaw"].shape == (2, 1)
    kinds = [type(t) for t in env.transform]
    assert kinds == [TaskEpisode, StepCounter, TaskReward]
    assert env.transform[1].max_steps == 2 and env.transform[1].step_count_key == "task_step"


def test_reward_steps_and_time_limit(make_env):
    # a 4-step velocity schedule whose target changes every step, so the reward depends on the step
    task = VelocityTracking(steps_per_target=1, rounds=1)
    assert task.num_steps == 4
    env = make_env(task, num_robots=3)
    td = env.reset()
    assert torch.equal(td["task_step"], torch.zeros(3, 1, dtype=torch.int64))
    assert torch.allclose(td["com_state"][:, 2], torch.full((3,), START_YAW))
    steps = []
    for _ in range(6):  # past the time limit: auto-reset after step 4
        td["action"] = fixed_actions(3)
        step, td = env.step_and_maybe_reset(td)
        steps.append(step)
    for t, step in enumerate(steps):
        expected_step = t % 4  # the task step this transition ends (0-based); reset after the 4th
        assert torch.equal(step["task_step"].squeeze(-1), torch.full((3,), expected_step))
        assert torch.equal(step["next", "task_step"].squeeze(-1), torch.full((3,), expected_step + 1))
        cost = task.cost(step["com_state"], step["next", "com_state"], torch.zeros(3, dtype=torch.int64),
                         torch.full((3,), expected_step))
        reward = step["next", "reward"]
        assert reward.shape == (3, 1) and reward.dtype == torch.float32
        assert torch.allclose(reward.squeeze(-1), -cost, atol=1e-6)
        assert bool((reward < 0).all())  # the experts do not track this schedule exactly
        over = expected_step + 1 == task.num_steps
        assert not step["next", "terminated"].any()  # Daisy's experts do not fall
        assert torch.equal(step["next", "truncated"].squeeze(-1), torch.full((3,), over))
        assert torch.equal(step["next", "done"].squeeze(-1), torch.full((3,), over))
    # after the auto-reset the robots are back at the start
    assert torch.allclose(steps[4]["com_state"][:, :2], torch.zeros(3, 2), atol=1e-6)


def test_reward_depends_on_the_task_step(make_env):
    """Guard on the test above: with this schedule the step matters for the cost."""
    task = VelocityTracking(steps_per_target=1, rounds=1)
    env = make_env(task, num_robots=2)
    td = env.reset()
    td["action"] = fixed_actions(2)
    td = env.step(td)
    episode = torch.zeros(2, dtype=torch.int64)
    right = -task.cost(td["com_state"], td["next", "com_state"], episode, torch.zeros(2, dtype=torch.int64))
    wrong = -task.cost(td["com_state"], td["next", "com_state"], episode, torch.ones(2, dtype=torch.int64))
    assert torch.allclose(td["next", "reward"].squeeze(-1), right, atol=1e-6)
    assert not torch.allclose(right, wrong, atol=1e-3)


def test_default_episodes_cycle_over_robots(make_env):
    task = GoalReaching(goals=THREE_GOALS, num_steps=3)
    env = make_env(task, num_robots=4)
    td = env.reset()
    assert td["task_episode"].squeeze(-1).tolist() == [0, 1, 2, 0]
    td["action"] = fixed_actions(4)
    td = env.step(td)
    assert td["next", "task_episode"].squeeze(-1).tolist() == [0, 1, 2, 0]
    cost = task.cost(td["com_state"], td["next", "com_state"], torch.tensor([0, 1, 2, 0]), 0)
    assert torch.allclose(td["next", "reward"].squeeze(-1), -cost, atol=1e-6)


def test_given_episodes(make_env):
    task = GoalReaching(goals=THREE_GOALS, num_steps=3)
    env = make_env(task, num_robots=4, episodes=[2, 2, 0, 1])
    td = env.reset()
    assert td["task_episode"].squeeze(-1).tolist() == [2, 2, 0, 1]
    td["action"] = fixed_actions(4)
    td = env.step(td)
    cost = task.cost(td["com_state"], td["next", "com_state"], torch.tensor([2, 2, 0, 1]), 0)
    assert torch.allclose(td["next", "reward"].squeeze(-1), -cost, atol=1e-6)


@pytest.mark.parametrize("episodes", [[0, 1, 2], [0, 1, 2, 3], [-1, 0, 0, 0], [0, 0, 0, 0, 0]])
def test_bad_episodes(make_env, episodes):
    env = make_env(GoalReaching(goals=THREE_GOALS, num_steps=3), num_robots=4, episodes=episodes)
    with pytest.raises(ValueError, match="episodes"):
        env.reset()


def test_partial_reset(make_env):
    task = GoalReaching(goals=THREE_GOALS, num_steps=5)
    env = make_env(task, num_robots=4)
    td = env.reset()
    for _ in range(2):
        td["action"] = fixed_actions(4)
        _, td = env.step_and_maybe_reset(td)
    assert td["task_step"].squeeze(-1).tolist() == [2, 2, 2, 2]
    before = td["com_state"].clone()
    assert (before[:, :2].norm(dim=-1) > 0.05).all()  # every robot has walked away from the start
    mask = torch.tensor([[True], [False], [True], [False]])
    td["_reset"] = mask
    td = env.reset(td)
    assert td["task_step"].squeeze(-1).tolist() == [0, 2, 0, 2]
    assert td["task_episode"].squeeze(-1).tolist() == [0, 1, 2, 0]
    start = torch.tensor([0.0, 0.0, START_YAW, 0.0, 0.0])
    assert torch.allclose(td["com_state"][[0, 2]], start.expand(2, 5), atol=1e-5)
    assert torch.allclose(td["com_state"][[1, 3]], before[[1, 3]])
    # the episodes go on: the kept robots reach the limit 3 steps later, the reset ones 5 steps later
    for t in range(5):
        td.pop("_reset", None)
        td["action"] = fixed_actions(4)
        step, td = env.step_and_maybe_reset(td)
        truncated = step["next", "truncated"].squeeze(-1).tolist()
        assert truncated == [t == 4, t == 2, t == 4, t == 2]


def test_reward_terms_add_up_to_minus_the_reward(make_env):
    task = GoalReaching(goals=THREE_GOALS, num_steps=3)
    env = make_env(task, num_robots=3)
    td = env.reset()
    assert torch.equal(td["cost_tracking"], torch.zeros(3, 1)) and torch.equal(td["cost_yaw"], torch.zeros(3, 1))
    td["action"] = fixed_actions(3)
    td = env.step(td)
    step = torch.zeros(3, dtype=torch.int64)
    terms = task.cost_terms(td["com_state"], td["next", "com_state"], torch.arange(3), step)
    torch.testing.assert_close(td["next", "cost_tracking"].squeeze(-1), terms["tracking"], rtol=0, atol=0)
    torch.testing.assert_close(td["next", "cost_yaw"].squeeze(-1), terms["yaw"], rtol=0, atol=0)
    total = td["next", "cost_tracking"] + td["next", "cost_yaw"]
    torch.testing.assert_close(td["next", "reward"], -total, rtol=0, atol=0)
    assert bool((td["next", "cost_tracking"] > 1.0).all())  # about 2 * 1 m from each goal after one action


def test_deprecated_task_transform_is_the_same_composition(library):
    task = VelocityTracking(steps_per_target=1, rounds=1)
    rewards = []
    for transform in (TaskTransform(task), task_transforms(task)):
        env = TransformedEnv(LatentActionEnv(ExpertReplayLowLevel(library), num_robots=2, seed=0), transform)
        rewards.append(env.rollout(3, policy=lambda td: td.set("action", fixed_actions(2)))["next", "reward"])
        env.close()
    torch.testing.assert_close(rewards[0], rewards[1], rtol=0, atol=0)


class Collapse(LowLevel):
    """Sends every joint of A1 to zero for the first action (the robot falls), then holds the standing pose."""

    kind = "collapse"

    def __init__(self):
        self.robot = get_robot("a1")
        self.steps_per_action = 100
        self.action_low, self.action_high = np.zeros(1), np.ones(1)
        self.calls = 0

    def run(self, sim, actions):
        self.calls += 1
        pose = np.zeros(self.robot.num_joints) if self.calls == 1 else np.asarray(self.robot.standing_pose)
        return sim.run(np.tile(pose, (sim.num_robots, self.steps_per_action, 1)))


@pytest.mark.parametrize("continue_after_falls", [False, True])
def test_a_fall_ends_a_training_episode_but_not_an_evaluation_one(continue_after_falls):
    task = GoalReaching(goals=THREE_GOALS[:2], num_steps=4)
    transforms = [ContinueAfterFalls()] if continue_after_falls else []
    env = TransformedEnv(LatentActionEnv(Collapse(), num_robots=2, seed=0),
                         Compose(*transforms, task_transforms(task)))
    check_env_specs(env)
    env.base_env.low_level.calls = 0  # fall again on the next first action
    rollout = env.rollout(4, policy=lambda td: td.set("action", torch.zeros(2, 1)), break_when_any_done=False)
    env.close()
    start = torch.tensor([0.0, 0.0])
    moved_from_start = (rollout["com_state"][:, 1:, :2] - start).norm(dim=-1) > 1e-3
    if continue_after_falls:
        # the robots fell on the first action and stay where they fell: never reset, scored to the end
        assert rollout["next", "fallen"].squeeze(-1).all()
        assert not rollout["next", "terminated"].any()
        assert rollout["next", "task_step"][0].squeeze(-1).tolist() == [1, 2, 3, 4]
        assert rollout["next", "done"][0].squeeze(-1).tolist() == [False, False, False, True]
        assert moved_from_start.all()
    else:
        # a fall terminates the episode and the rollout resets the robot to the start
        assert rollout["next", "terminated"][:, 0].all()
        assert rollout["task_step"][0, 1].item() == 0
        assert not moved_from_start[:, 0].any()
