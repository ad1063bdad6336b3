"""CoMWorldModelEnv: the CoM dynamics model as a TorchRL world model scored by a task."""

import math

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torchrl.collectors import Collector
from torchrl.data import Bounded, Categorical
from torchrl.envs.utils import check_env_specs

from hierloco.components.com_model import CoMDynamicsModel
from hierloco.envs.robots import START_YAW
from hierloco.envs.tasks import GoalReaching, VelocityTracking
from hierloco.envs.world_model import CoMWorldModelEnv

GOALS = [[2.0, 0.0], [0.0, 2.0], [-1.0, -1.0]]


class Shift(torch.nn.Module):
    """Test double with a closed form: the action ``(dx, dy, dyaw)`` moves the robot in the world frame over 1 s."""

    def predict(self, com_state, action):
        position = com_state[..., :2] + action[..., :2]
        yaw = com_state[..., 2:3] + action[..., 2:3]
        return torch.cat([position, yaw, action[..., :2]], -1)


class Table(torch.nn.Module):
    """Test double for a discrete action set: choice ``i`` moves the robot by ``MOVES[i]`` (world frame)."""

    MOVES = torch.tensor([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [-0.5, -0.5]])

    def __init__(self):
        super().__init__()
        self.seen = []

    def predict(self, com_state, action):
        self.seen.append(action)
        move = self.MOVES[action[..., 0].long()]
        return torch.cat([com_state[..., :2] + move, com_state[..., 2:3], move], -1)


def shift_env(task=None):
    task = GoalReaching(goals=GOALS) if task is None else task
    return CoMWorldModelEnv(Shift(), action_low=[-1.0, -1.0, -0.5], action_high=[1.0, 1.0, 0.5], task=task)


def test_reward_closed_form():
    env = shift_env()
    td = env.reset(env.initial_state(episode=torch.tensor([0, 1, 2]), step=7))
    assert torch.allclose(td["com_state"], torch.tensor([0.0, 0.0, START_YAW, 0.0, 0.0]).expand(3, 5))
    td["action"] = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.5, 0.3], [-1.0, 0.0, -0.2]])
    out = env.step(td)
    next_state = out["next", "com_state"]
    assert torch.allclose(next_state[:, :2], torch.tensor([[1.0, 0.0], [0.0, 0.5], [-1.0, 0.0]]))
    # c2 = 2 ||goal - p|| + |yaw error|
    expected = -torch.tensor([2 * 1.0, 2 * 1.5 + 0.3, 2 * 1.0 + 0.2])
    assert torch.allclose(out["next", "reward"].squeeze(-1), expected, atol=1e-6)
    assert out["next", "task_step"].squeeze(-1).tolist() == [8, 8, 8]
    assert out["next", "task_episode"].squeeze(-1).tolist() == [0, 1, 2]
    # the input state is untouched (the env step is functional)
    assert torch.equal(out["task_step"].squeeze(-1), torch.tensor([7, 7, 7]))
    assert torch.allclose(out["com_state"][:, :2], torch.zeros(3, 2))


def test_reward_is_minus_task_cost_with_the_real_model():
    torch.manual_seed(0)
    model = CoMDynamicsModel(action_dim=3, hidden=32)
    task = GoalReaching()
    env = CoMWorldModelEnv(model, action_low=[-1.0] * 3, action_high=[1.0] * 3, task=task)
    state = torch.randn(6, 5)
    episode, step = torch.arange(6) % 8, torch.tensor([0, 3, 9, 12, 29, 1])
    td = env.reset(env.initial_state(state, episode=episode, step=step))
    td["action"] = env.action_spec.rand((6,))
    out = env.step(td)
    with torch.no_grad():
        predicted = model.predict(state, td["action"])
    assert torch.allclose(out["next", "com_state"], predicted, atol=1e-6)
    expected = -task.cost(state, predicted, episode, step)
    assert torch.allclose(out["next", "reward"].squeeze(-1), expected, atol=1e-5)
    assert torch.equal(out["next", "task_step"].squeeze(-1), step + 1)


def test_check_env_specs():
    torch.manual_seed(0)
    real = CoMWorldModelEnv(CoMDynamicsModel(action_dim=3, hidden=32), action_low=[-1.0] * 3,
                            action_high=[1.0] * 3, task=GoalReaching())
    for env in (real, shift_env(), CoMWorldModelEnv(Table(), num_choices=4, task=GoalReaching(goals=GOALS))):
        check_env_specs(env)


@pytest.mark.parametrize("batch", [(5,), (4, 500), (2, 3, 7)])
def test_any_batch_shape(batch):
    assert not shift_env().batch_locked
    torch.manual_seed(0)
    model = CoMDynamicsModel(action_dim=3, hidden=32)
    task = GoalReaching()
    env = CoMWorldModelEnv(model, action_low=[-1.0] * 3, action_high=[1.0] * 3, task=task)
    state = torch.randn(*batch, 5)
    episode = torch.randint(0, 8, batch)
    td = env.reset(env.initial_state(state, episode=episode, step=4))
    td["action"] = env.action_spec.rand(batch)
    assert td["action"].shape == (*batch, 3)
    out = env.step(td)
    assert out["next", "reward"].shape == (*batch, 1)
    assert out["next", "com_state"].shape == (*batch, 5)
    with torch.no_grad():
        flat_next = model.predict(state.reshape(-1, 5), td["action"].reshape(-1, 3))
    flat_cost = task.cost(state.reshape(-1, 5), flat_next, episode.reshape(-1), 4)
    assert torch.allclose(out["next", "reward"].reshape(-1), -flat_cost, atol=1e-5)
    assert bool((out["next", "task_step"] == 5).all())


def test_rollout_advances_the_task_step():
    task = VelocityTracking(steps_per_target=1, rounds=1)  # the target changes every step
    env = shift_env(task)
    td = env.reset(env.initial_state(episode=torch.zeros(2, 3, dtype=torch.int64)))
    # move at (0, 0.2) m/s forever: zero cost on step 0, then the targets (0.2, 0), (0, -0.2), (-0.2, 0)
    policy = lambda td: td.set("action", torch.tensor([0.0, 0.2, 0.0]).expand(*td.batch_size, 3))  # noqa: E731
    rollout = env.rollout(4, policy, auto_reset=False, tensordict=td)
    assert rollout.batch_size == (2, 3, 4)
    assert rollout["next", "task_step"][0, 0].squeeze(-1).tolist() == [1, 2, 3, 4]
    expected = -2 * torch.tensor([0.0, math.hypot(0.2, 0.2), 0.4, math.hypot(0.2, 0.2)])
    assert torch.allclose(rollout["next", "reward"].squeeze(-1), expected.expand(2, 3, 4), atol=1e-6)


def test_set_task_changes_the_reward():
    env = shift_env(GoalReaching(goals=GOALS))
    td = env.reset(env.initial_state(episode=torch.tensor([0]), step=0))
    td["action"] = torch.tensor([[0.0, 0.2, 0.0]])
    assert env.step(td.clone())["next", "reward"].item() == pytest.approx(-2 * math.hypot(2.0, 0.2))
    env.set_task(VelocityTracking())
    assert env.task is not None and env.step(td.clone())["next", "reward"].item() == pytest.approx(0.0, abs=1e-6)
    env.set_task(VelocityTracking(velocities=[[0.2, 0.0]]))
    assert env.step(td.clone())["next", "reward"].item() == pytest.approx(-2 * math.hypot(0.2, 0.2))
    env.set_task(None)
    out = env.step(td.clone())
    assert out["next", "reward"].item() == 0.0
    assert out["next", "task_step"].item() == 1


def test_categorical_actions():
    table = Table()
    env = CoMWorldModelEnv(table, num_choices=4, task=GoalReaching(goals=GOALS))
    assert isinstance(env.action_spec, Categorical) and env.action_spec.space.n == 4
    assert env.action_spec.shape == (1,) and env.action_spec.dtype == torch.int64
    td = env.reset(env.initial_state(episode=torch.tensor([0, 1, 2, 0]), step=0))
    td["action"] = torch.tensor([[0], [1], [2], [3]])
    out = env.step(td)
    assert table.seen[-1].is_floating_point()  # the index reaches the model as a float
    assert torch.allclose(out["next", "com_state"][:, :2], Table.MOVES)
    goals = torch.tensor(GOALS)[[0, 1, 2, 0]]
    expected = -2 * (goals - Table.MOVES).norm(dim=-1)
    assert torch.allclose(out["next", "reward"].squeeze(-1), expected, atol=1e-6)
    sample = env.action_spec.rand((100,))
    assert env.action_spec.is_in(sample) and set(sample.unique().tolist()) <= {0, 1, 2, 3}


def test_action_box_spec():
    env = shift_env()
    assert isinstance(env.action_spec, Bounded)
    assert torch.equal(env.action_spec.space.low, torch.tensor([-1.0, -1.0, -0.5]))
    assert torch.equal(env.action_spec.space.high, torch.tensor([1.0, 1.0, 0.5]))


def test_reset_defaults():
    env = shift_env()
    td = env.reset()
    assert td.batch_size == ()
    assert torch.allclose(td["com_state"], torch.tensor([0.0, 0.0, START_YAW, 0.0, 0.0]))
    assert td["task_episode"].item() == 0 and td["task_step"].item() == 0
    # a state without task keys gets episode 0, step 0
    td = env.reset(TensorDict({"com_state": torch.ones(3, 5)}, batch_size=[3]))
    assert td["task_step"].shape == (3, 1) and bool((td["task_step"] == 0).all())


@pytest.mark.parametrize("kwargs", [
    dict(action_low=[1.0, 0.0], action_high=[0.0, 1.0]),  # low > high
    dict(action_low=[0.0, 0.0], action_high=[1.0]),  # shapes differ
    dict(action_low=[[0.0, 0.0]], action_high=[[1.0, 1.0]]),  # not a vector
    dict(action_low=[math.nan], action_high=[1.0]),
    dict(action_low=None, action_high=[1.0]),
    dict(),  # no box, no choices
    dict(num_choices=0),
])
def test_bad_action_space(kwargs):
    with pytest.raises(ValueError):
        CoMWorldModelEnv(Shift(), task=GoalReaching(), **kwargs)


def test_the_task_end_sets_done_and_terminated_and_the_rewards_stay():
    """A step that ends the task's last step (task_step reaching num_steps) is terminal; a TorchRL collector cuts the
    imagined episodes there and starts over; every reward is the one the same steps give without an end in sight."""
    task, endless = GoalReaching(goals=GOALS, num_steps=3), GoalReaching(goals=GOALS, num_steps=1000)
    env = shift_env(task)
    check_env_specs(env)
    policy = TensorDictModule(lambda state: torch.tensor([0.3, 0.2, 0.1]).expand(*state.shape[:-1], 3),
                              in_keys=["com_state"], out_keys=["action"])
    collector = Collector(env, policy, frames_per_batch=7, total_frames=7, auto_register_policy_transforms=False)
    batch = next(iter(collector))
    collector.shutdown()
    assert batch["next", "task_step"].squeeze(-1).tolist() == [1, 2, 3, 1, 2, 3, 1]
    ended = [False, False, True] * 2 + [False]
    assert batch["next", "terminated"].squeeze(-1).tolist() == ended
    assert batch["next", "done"].squeeze(-1).tolist() == ended and not batch["next", "truncated"].any()
    state = batch.select("com_state", "task_episode", "task_step", "action")
    torch.testing.assert_close(shift_env(endless).step(state)["next", "reward"], batch["next", "reward"])
    past_the_end = env.step(env.initial_state(episode=torch.tensor([0]), step=5).set("action", torch.zeros(1, 3)))
    assert past_the_end["next", "done"].item()
    assert past_the_end["next", "reward"].item() == pytest.approx(-2 * 2.0)  # still the task's cost


def test_without_a_task_the_world_model_never_ends():
    env = CoMWorldModelEnv(Shift(), action_low=[-1.0] * 3, action_high=[1.0] * 3)
    td = env.step(env.initial_state(step=10**6).set("action", torch.zeros(3)))
    assert not td["next", "done"].item() and not td["next", "terminated"].item()
