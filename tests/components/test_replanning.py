"""Re-planning within an action (``docs/terrain.md``, "Re-planning within an action"): a latent action cut after
whole gait periods runs exactly the first steps of the whole action, the env runs that many steps per step, a
planner chooses ``N / replan_steps`` times per task step while the task is scored on its own steps, and the recipe
keys only the evaluations and refuses what cannot be cut, in one line."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hierloco.components.com_model import CoMDynamicsModel
from hierloco.components.evaluation import replans_per_action, run_task
from hierloco.components.low_level import ExpertReplayLowLevel
from hierloco.components.planners import RandomShootingPlanner
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.world_model import CoMWorldModelEnv
from tests.recipes.stage_plans import plan


def test_a_cut_action_runs_exactly_the_first_gait_periods(latent):
    assert latent.period_steps == 20  # A1: a 0.2 s trot, 5 periods in the 1 s action
    z = np.tile((latent.action_low + latent.action_high) / 2, (2, 1))
    whole, cut = (BatchedSimulator("a1", 2, seed=3) for _ in range(2))
    full = latent.run(whole, z)
    first = latent.run_steps(cut, z, 40)
    assert first.com_state.shape == (2, 40, 5)
    np.testing.assert_allclose(first.com_state, full.com_state[:, :40], atol=1e-9)  # the same steps, no other
    # the pattern repeats every period: the targets of the next action begin where a period would
    pattern = latent.patterns(z)
    np.testing.assert_allclose(pattern[:, :20], pattern[:, 20:40], atol=1e-5)
    with pytest.raises(ValueError, match="whole gait periods of 20 control steps"):
        latent.run_steps(cut, z, 30)
    assert latent.replan_problem(40) is not None  # runs, but 40 steps do not divide a task step of 100


def test_what_cannot_be_cut_is_refused(latent, library):
    assert latent.replan_problem(20) is None and latent.replan_problem(100) is None
    assert "one of [20, 100], got 40" in latent.replan_problem(40)  # 40 does not divide the action's 100 steps
    replay = ExpertReplayLowLevel(library)
    assert "replan_steps must be null or 100" in replay.replan_problem(20)
    with pytest.raises(ValueError, match="runs only whole actions"):
        LatentActionEnv(replay, num_robots=1, replan_steps=20)
    with pytest.raises(ValueError, match="cut only after whole gait periods"):
        replay.run_steps(BatchedSimulator("a1", 1), np.zeros((1, 1)), 20)


def test_a_planner_chooses_five_times_per_task_step_and_the_task_is_scored_on_its_own_steps(latent):
    with torch.random.fork_rng():
        torch.manual_seed(0)
        model = CoMDynamicsModel(action_dim=2, hidden=32).eval()
    world_model = CoMWorldModelEnv(model, action_low=latent.action_low, action_high=latent.action_high)
    planner = RandomShootingPlanner(world_model, num_candidates=50, seed=0)
    calls = []

    def counted(tensordict):
        calls.append(tensordict.get("task_step").squeeze(-1).tolist())
        return planner(tensordict)

    task = GoalReaching(goals=[[1.0, 0.0], [0.0, 1.0]], num_steps=3)
    env = LatentActionEnv(latent, num_robots=2, record=True, seed=0, replan_steps=20)
    try:
        assert replans_per_action(env) == 5
        rollout = run_task(env, counted, task)
    finally:
        env.close()
    assert len(calls) == 15 and [step[0] for step in calls] == [t for t in range(3) for _ in range(5)]
    assert rollout.actions.shape == (2, 15, 2)
    assert rollout.com_paths.shape == (2, 300, 5)  # the 100 Hz path covers the task's 3 s
    # the cost is the task's, on the state at every whole second: the 100 Hz path at steps 99, 199, 299
    states = torch.cat([torch.tensor([[0.0, 0.0, task.start_yaw, 0.0, 0.0]]).expand(2, 1, 5),
                        torch.as_tensor(rollout.com_paths[:, 99::100])], 1)
    states[:, 0, :2] = torch.as_tensor(rollout.com_paths[:, 0, :2])  # where it stood at the start (reset noise)
    expected = np.asarray(task.evaluate(states, torch.arange(2)).costs)
    np.testing.assert_allclose(np.asarray(rollout.result.costs)[:, 1:], expected[:, 1:], atol=1e-4)


def test_the_recipe_keys_only_the_evaluations_and_refuses_what_cannot_be_cut():
    from hierloco.pipeline.config import ConfigError

    before, after = plan("lat"), plan("lat", "eval.replan_steps=20")
    changed = {name for name in before if before[name].digest != after[name].digest}
    assert changed == {name for name in before if name.startswith("evaluation_")}
    assert after["evaluation_normal_goal_reaching"].params["replan_steps"] == 20
    assert plan("lat", "eval.replan_steps=100")["evaluation_normal_goal_reaching"].digest == \
        before["evaluation_normal_goal_reaching"].digest  # a whole action is the default
    for recipe, value, said in (("lat", 40, "one of [20, 100], got 40"), ("ik", 20, "runs only whole actions"),
                                ("sac", 20, "runs only whole actions")):
        with pytest.raises(ConfigError, match="eval.replan_steps") as error:
            plan(recipe, f"eval.replan_steps={value}")
        assert said in str(error.value) and "\n" not in str(error.value)
