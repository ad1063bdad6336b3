"""Closed-loop evaluation (run_task) on real simulated robots: the same numbers as the step loop it is built on,
falls kept in their episode, the task-policy protocol, metrics."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import step_mdp

from hierloco.components.com_model import CoMDynamicsModel
from hierloco.components.evaluation import run_task
from hierloco.components.low_level import ExpertReplayLowLevel
from hierloco.components.planners import ExhaustivePlanner, RandomShootingPlanner
from hierloco.components.policies import ActorPolicy, TaskPolicy
from hierloco.components.sac import SACAgent
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.low_level import LowLevel
from hierloco.envs.robots import get_robot
from hierloco.envs.tasks import GoalReaching, TrajectoryTracking, VelocityTracking
from hierloco.envs.transforms import GoalObservation, task_transforms
from hierloco.envs.world_model import CoMWorldModelEnv

TWO_GOALS = [[1.0, 0.0], [0.0, 1.0]]


def make_planner(low_level, seed=0):
    with torch.random.fork_rng():
        torch.manual_seed(0)
        model = CoMDynamicsModel(action_dim=2, hidden=32).eval()
    world_model = CoMWorldModelEnv(model, action_low=low_level.action_low, action_high=low_level.action_high)
    return RandomShootingPlanner(world_model, num_candidates=300, seed=seed)


def step_loop(env, planner, task):
    """The loop run_task replaces: reset, then plan, step and step_mdp for every task step."""
    planner.env.set_task(task)
    planner.reset()
    task_env = TransformedEnv(env, task_transforms(task))
    td = task_env.reset()
    steps = []
    for _ in range(task.num_steps):
        td = task_env.step(planner(td))
        steps.append(td.clone())
        td = step_mdp(td)
    return torch.stack(steps, 1)


def test_same_numbers_as_the_step_loop(latent):
    task = GoalReaching(goals=TWO_GOALS, num_steps=3)
    rollouts = []
    for run in (run_task, step_loop):
        env = LatentActionEnv(latent, num_robots=2, record=True, seed=0)
        rollouts.append(run(env, make_planner(latent), task))
        env.close()
    rollout, loop = rollouts
    states = torch.cat([loop["com_state"], loop["next", "com_state"][:, -1:]], 1).double().numpy()
    np.testing.assert_array_equal(rollout.result.com_states, states)
    np.testing.assert_array_equal(rollout.actions, loop["action"].numpy())
    np.testing.assert_array_equal(rollout.com_paths, loop["next", "com_path"].flatten(1, 2).numpy())
    assert rollout.actions.shape == (2, 3, 2) and not rollout.fell.any()
    assert len(np.unique(rollout.actions.reshape(-1, 2), axis=0)) == 6  # a fresh sampled plan at every step
    np.testing.assert_allclose(rollout.result.normalized_cost, task.evaluate(states).normalized_cost, rtol=0)


class Collapse(LowLevel):
    """A1 with every joint sent to zero: it falls on the first action."""

    kind = "collapse"

    def __init__(self):
        self.robot = get_robot("a1")
        self.steps_per_action = 100
        self.action_low, self.action_high = np.zeros(1), np.ones(1)

    def run(self, sim, actions):
        return sim.run(np.zeros((sim.num_robots, self.steps_per_action, self.robot.num_joints)))


def test_a_fallen_robot_stays_in_its_episode_and_is_counted():
    task = GoalReaching(goals=TWO_GOALS, num_steps=4)
    env = LatentActionEnv(Collapse(), num_robots=2, record=True, seed=0)
    rollout = run_task(env, lambda td: td.set("action", torch.zeros(2, 1)), task)  # a plain callable policy
    env.close()
    assert rollout.fell.all()
    assert rollout.actions.shape == (2, 4, 1) and rollout.result.costs.shape == (2, 4)
    positions = rollout.result.com_states[:, 1:, :2]
    assert np.all(np.linalg.norm(positions, axis=-1) > 1e-3)  # never put back at the start
    np.testing.assert_allclose(positions[:, -1], rollout.com_paths[:, -1, :2], atol=1e-6)  # one continuous path


class Recorder(TaskPolicy):
    """A task policy that records the tasks it is told about and sends expert 1."""

    def __init__(self):
        self.tasks = []

    def begin_task(self, task):
        self.tasks.append(task)

    def __call__(self, tensordict):
        return tensordict.set("action", torch.ones(*tensordict.batch_size, 1, dtype=torch.int64))


def test_task_policies_are_told_the_task_first(library):
    low = ExpertReplayLowLevel(library)
    recorder = Recorder()
    task = VelocityTracking(steps_per_target=1, rounds=1)
    env = LatentActionEnv(low, num_robots=1, seed=0)
    rollout = run_task(env, recorder, task)
    assert recorder.tasks == [task] and (rollout.actions == 1).all()
    # a planner: its world model is re-targeted to each task in turn, its warm start forgotten
    planner = ExhaustivePlanner(CoMWorldModelEnv(CoMDynamicsModel(action_dim=4, hidden=16), num_choices=4,
                                                 action_features=low.action_features, task=GoalReaching()))
    for task in (GoalReaching(goals=TWO_GOALS, num_steps=2), VelocityTracking(steps_per_target=1, rounds=1)):
        planner._previous = torch.zeros(7, 1, 1)  # a stale plan
        run_task(LatentActionEnv(low, num_robots=task.num_episodes, seed=0), planner, task)
        assert planner.env.task is task and planner.world_model.module.task is task
        assert planner._previous.shape == (task.num_episodes, 1, 1)  # planned afresh for these robots


def test_actor_policy_acts_with_the_mode_of_its_distribution(latent):
    task = GoalReaching(goals=TWO_GOALS, num_steps=2)
    agent = SACAgent.build(GoalObservation.SIZE, latent.action_low, latent.action_high, hidden=32, seed=0)

    def actions(deterministic, seed):
        torch.manual_seed(seed)
        env = LatentActionEnv(latent, num_robots=2, seed=0)
        out = run_task(env, ActorPolicy(agent.actor, deterministic=deterministic), task,
                       transforms=[GoalObservation(task)]).actions
        env.close()
        return out

    np.testing.assert_array_equal(actions(True, 0), actions(True, 1))  # no sampling
    assert not np.array_equal(actions(False, 0), actions(False, 1))  # exploration samples
    assert isinstance(ActorPolicy(agent.actor), TaskPolicy)


def test_metrics_plan_time_and_bad_episodes(library):
    low = ExpertReplayLowLevel(library)
    task = TrajectoryTracking(speed=1.0, extra_steps=0)  # 8 steps along the S path
    policy = lambda td: td.set("action", torch.zeros(1, 1, dtype=torch.int64))  # noqa: E731
    rollout = run_task(LatentActionEnv(low, num_robots=1, record=True, seed=0), policy, task)
    assert set(rollout.metrics) == {"path_distance"}
    np.testing.assert_array_equal(rollout.metrics["path_distance"],
                                  task.extra_metrics(rollout.com_paths)["path_distance"])
    assert rollout.metrics["path_distance"][0] > 0.05  # expert 0 does not follow the S path
    assert rollout.plan_seconds > 0
    unrecorded = run_task(LatentActionEnv(low, num_robots=1, seed=0), policy, task)
    assert unrecorded.metrics == {} and unrecorded.com_paths is None
    np.testing.assert_array_equal(unrecorded.result.com_states, rollout.result.com_states)
    with pytest.raises(ValueError, match="2 robots for 3 episodes"):
        run_task(LatentActionEnv(low, num_robots=2), policy, GoalReaching(), episodes=[0, 1, 2])


def test_latent_grid_spans_the_box_with_the_last_axis_fastest():
    from hierloco.components.evaluation import latent_grid

    index, latents = latent_grid([-0.5, 0.0, 1.0], [0.5, 2.0, 3.0], 5)
    assert index.shape == latents.shape == (125, 3)
    assert np.allclose(latents.min(0), [-0.5, 0.0, 1.0]) and np.allclose(latents.max(0), [0.5, 2.0, 3.0])
    assert np.allclose(latents[1] - latents[0], [0.0, 0.0, 0.5])


def test_continuity_statistics_tell_a_smooth_map_from_a_jumping_one():
    """A velocity that varies linearly over a 7 x 7 lattice gives neighbours about a third of the average pair's
    difference; the same velocities shuffled over the lattice give about the same as any pair; pairs with a fallen
    robot are left out."""
    from hierloco.components.evaluation import continuity_statistics, latent_grid

    index, latents = latent_grid([-1.0, -1.0], [1.0, 1.0], 7)
    smooth = 0.3 * latents
    shuffled = smooth[np.random.default_rng(0).permutation(len(smooth))]
    walking = np.zeros(len(index), bool)
    linear = continuity_statistics(index, smooth, walking)
    jumping = continuity_statistics(index, shuffled, walking)
    assert 0.25 < linear["ratio"] < 0.4 and jumping["ratio"] > 0.8
    assert np.isclose(linear["neighbour_difference"], 0.3 * 2 / 6)  # one lattice step along one axis
    assert linear["neighbour_pairs"] == 2 * 7 * 6 and linear["pairs"] == 49 * 48 // 2
    fell = walking.copy()
    fell[0] = True
    smooth_fallen = smooth.copy()
    smooth_fallen[0] = [5.0, 5.0]  # a fallen robot's velocity is not the latent's: never counted
    dropped = continuity_statistics(index, smooth_fallen, fell)
    assert dropped["pairs"] == 48 * 47 // 2 and dropped["neighbour_pairs"] == 2 * 7 * 6 - 2
    assert np.isclose(dropped["neighbour_difference"], linear["neighbour_difference"])
    assert np.isclose(dropped["fell_fraction"], 1 / 49)
