"""Warm starts are per robot: a robot whose episode (re)starts plans cold, under ``env.rollout`` with auto-reset and
under a TorchRL collector with partial resets; the other robots keep theirs (Li et al., RA-L 2021, Sec. III-A.2: MPC
re-plans from the measured state after every action)."""

import pytest
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from torchrl.envs import Compose, InitTracker, TransformedEnv
from torchrl.envs.transforms import Transform

from hierloco.components.com_model import CoMDynamicsModel
from hierloco.components.low_level import CommandLowLevel
from hierloco.components.planners import BoxCEMPlanner, BoxMPPIPlanner, RandomShootingPlanner
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.transforms import task_transforms
from hierloco.envs.world_model import CoMWorldModelEnv

PLANNERS = {
    "cem": lambda env: BoxCEMPlanner(env, planning_horizon=2, num_candidates=40, optim_steps=1, top_k=5),
    "mppi": lambda env: BoxMPPIPlanner(env, planning_horizon=2, num_candidates=40, optim_steps=1),
}


class RecordWarmStart(TensorDictModuleBase):
    """The planner, also writing ``warm_start`` (``B x 1``): whether each robot's plan started from its previous one."""

    def __init__(self, planner):
        super().__init__()
        self.planner = planner
        self.in_keys = list(planner.in_keys) + ["is_init"]
        self.out_keys = ["action", "warm_start"]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        out = self.planner(tensordict)
        return out.set("warm_start", self.planner.warm_rows.reshape(*out.batch_size, 1).clone())


class EndAfter(Transform):
    """Ends robot ``b``'s episode (truncated) once its task step reaches ``lengths[b]``: partial resets."""

    def __init__(self, lengths):
        super().__init__(in_keys=["task_step"], out_keys=[])
        self.register_buffer("lengths", torch.as_tensor(lengths)[:, None])

    def _step(self, tensordict, next_tensordict):
        end = next_tensordict.get("task_step") >= self.lengths
        next_tensordict.set("truncated", next_tensordict.get("truncated") | end)
        next_tensordict.set("done", next_tensordict.get("done") | end)
        return next_tensordict


def world_model(low_level, task):
    torch.manual_seed(0)
    model = CoMDynamicsModel(action_dim=low_level.action_dim, hidden=16)
    return CoMWorldModelEnv(model, action_low=low_level.action_low, action_high=low_level.action_high, task=task)


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_rollout_with_auto_reset_plans_each_new_episode_cold(name):
    """Episodes of 2 steps in a 5-step rollout: task steps 0, 1, 0, 1, 0; only the second step of each episode may
    use a warm start (before the fix, steps 3 and 5 inherited the previous episode's plan)."""
    task = GoalReaching(num_goals=2, num_steps=2)
    low_level = CommandLowLevel("a1", 2)
    env = TransformedEnv(LatentActionEnv(low_level, num_robots=2, seed=0), task_transforms(task))
    planner = RecordWarmStart(PLANNERS[name](world_model(low_level, task)))
    rollout = env.rollout(5, planner, auto_reset=True, break_when_any_done=False)
    assert rollout["task_step"].squeeze(-1).tolist() == [[0, 1, 0, 1, 0]] * 2
    assert rollout["warm_start"].squeeze(-1).tolist() == [[False, True, False, True, False]] * 2


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_collector_with_partial_resets_keeps_each_robots_own_warm_start(name):
    """Three robots whose episodes last 2, 3 and 4 actions, collected 6 actions each: a robot plans warm exactly when
    it is past the first step of its episode, whatever the others do (``is_init`` and the step counter agree)."""
    lengths = [2, 3, 4]
    task = GoalReaching(num_goals=3, num_steps=10)
    low_level = CommandLowLevel("a1", 3)
    env = TransformedEnv(LatentActionEnv(low_level, num_robots=3, seed=0),
                         Compose(InitTracker(), task_transforms(task), EndAfter(lengths)))
    planner = PLANNERS[name](world_model(low_level, task))
    collector = Collector(env, RecordWarmStart(planner), frames_per_batch=18, total_frames=18,
                          auto_register_policy_transforms=False)
    try:
        batch = next(iter(collector))
    finally:
        collector.shutdown()
    steps = batch["task_step"].squeeze(-1)
    assert steps.tolist() == [[t % n for t in range(6)] for n in lengths]
    torch.testing.assert_close(batch["is_init"].squeeze(-1), steps == 0)
    torch.testing.assert_close(batch["warm_start"].squeeze(-1), steps > 0)


def test_is_init_alone_restarts_a_row():
    """Without a step counter advancing backwards, ``is_init`` alone makes a row plan cold; a new episode index
    does too."""
    task = GoalReaching(goals=[[1.0, 0.0], [0.0, 1.0]], num_steps=5)
    low_level = CommandLowLevel("a1", 1)
    env = world_model(low_level, task)
    planner = PLANNERS["cem"](env)
    state = env.initial_state(episode=torch.tensor([0, 1]), step=torch.tensor([1, 1]))
    planner(state)
    state["task_step"] += 1
    planner(state.set("is_init", torch.tensor([[True], [False]])))
    assert planner.warm_rows.tolist() == [False, True]
    state["task_step"] += 1
    state["task_episode"][1] = 0
    planner(state.exclude("is_init"))
    assert planner.warm_rows.tolist() == [True, False]
    random_shooting = RandomShootingPlanner(env, num_candidates=10)
    random_shooting(state)
    assert random_shooting.warm_rows.tolist() == [False, False]


def test_a_row_re_planning_within_its_task_step_starts_from_its_plan_unshifted():
    """Re-planning within an action (``eval.replan_steps``): while a row's task step stays, its previous plan's
    first action is still under way, so the warm start is that plan as it was; once the step moves on, it is shifted
    by one action."""
    task = GoalReaching(goals=[[1.0, 0.0], [0.0, 1.0]], num_steps=5)
    low_level = CommandLowLevel("a1", 1)
    planner = PLANNERS["cem"](world_model(low_level, task))
    state = planner.env.initial_state(episode=torch.tensor([0, 1]), step=torch.tensor([1, 1]))
    planner(state)
    plan = planner._previous.clone()
    state["task_step"][1] += 1  # row 0 re-plans within task step 1, row 1 has moved on to task step 2
    planner._moved_on = planner.moved_on_rows(state)
    warm = planner.warm_start(2)
    assert planner._moved_on.tolist() == [False, True]
    assert torch.equal(warm[0], plan[0]) and torch.equal(warm[1], torch.cat([plan[1, 1:], plan[1, -1:]]))
