"""Planner oracle tests: with a known analytic model the planners find the exact argmin (Li et al., RA-L 2021,
Sec. III-A.2)."""

import math

import pytest
import torch

from hierloco.components.planners import (
    BoxCEMPlanner,
    BoxMPPIPlanner,
    ExhaustivePlanner,
    RandomShootingPlanner,
)
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.world_model import CoMWorldModelEnv

LOW, HIGH = [-0.3, -0.3], [0.3, 0.3]


class Drift(torch.nn.Module):
    """A test double for the CoM model: the action is the world-frame displacement of one step."""

    def predict(self, com_state, action):
        return torch.cat([com_state[..., :2] + action, com_state[..., 2:]], -1)


def make_env(goals):
    return CoMWorldModelEnv(Drift(), action_low=LOW, action_high=HIGH, task=GoalReaching(goals=goals))


def start(env, positions):
    """States at ``positions`` (``B x 2``) facing +y, each robot in its own episode (its own goal)."""
    positions = torch.as_tensor(positions, dtype=torch.float32)
    state = torch.zeros(len(positions), 5)
    state[:, :2] = positions
    state[:, 2] = math.pi / 2
    return env.initial_state(state, episode=torch.arange(len(positions)), step=0)


GOALS = [[2.0, 0.0], [0.0, 2.0], [-1.0, -1.0]]
POSITIONS = [[1.9, 0.1], [0.0, 0.0], [-0.8, -0.95]]
# exact argmins: goal - position, clipped to the box
EXPECTED = torch.tensor([[0.1, -0.1], [0.0, 0.3], [-0.2, -0.05]])
HALF_WIDTH = 0.3


def cost_to_go(first_action, positions, goals, horizon):
    """Exact best total cost over the horizon after ``first_action``: later actions go straight at the goal,
    clipped to the box (the nearest reachable point of an axis-aligned box), goal reaching cost 2 ||g - p||."""
    position = torch.as_tensor(positions) + first_action
    goals = torch.as_tensor(goals)
    total = 2 * (goals - position).norm(dim=-1)
    for _ in range(horizon - 1):
        position = position + (goals - position).clamp(-HALF_WIDTH, HALF_WIDTH)
        total = total + 2 * (goals - position).norm(dim=-1)
    return total


def resolution(num_candidates, horizon, action_dim=2):
    """Typical spacing of ``num_candidates`` uniform samples in the (H x A)-dimensional box."""
    return 2 * HALF_WIDTH * num_candidates ** (-1.0 / (horizon * action_dim))


PLANNERS = {
    "random_shooting": lambda env, h: RandomShootingPlanner(env, planning_horizon=h, num_candidates=8000, seed=0),
    "cem": lambda env, h: BoxCEMPlanner(env, planning_horizon=h, num_candidates=500, optim_steps=6, top_k=25),
    "mppi": lambda env, h: BoxMPPIPlanner(env, planning_horizon=h, num_candidates=500, optim_steps=6,
                                          temperature=0.01),
}


@pytest.mark.parametrize("name", sorted(PLANNERS))
@pytest.mark.parametrize("horizon", [1, 2])
def test_planner_matches_the_exact_argmin(name, horizon):
    """The chosen first action is within the sampling resolution of optimal: its exact cost-to-go exceeds the
    optimum by at most ``2 w1 x resolution`` (8000 samples: 0.007 m in 2-D, 0.063 m in 4-D)."""
    env = make_env(GOALS)
    planner = PLANNERS[name](env, horizon)
    td = start(env, POSITIONS)
    before = td.clone()
    action = planner(td)["action"]
    assert action.shape == (3, 2) and all(env.action_spec.is_in(a) for a in action)
    optimum = cost_to_go(EXPECTED, POSITIONS, GOALS, horizon)
    gap = cost_to_go(action, POSITIONS, GOALS, horizon) - optimum
    assert torch.all(gap >= -1e-5)
    assert torch.all(gap <= 2 * 2 * resolution(8000, horizon)), gap
    if horizon == 1:  # robots 0 and 2 have optima inside the box: the action itself is pinned down
        torch.testing.assert_close(action[[0, 2]], EXPECTED[[0, 2]], atol=3 * resolution(8000, 1), rtol=0)
    for key in before.keys():
        torch.testing.assert_close(td[key], before[key])  # input keys untouched


def test_single_state_without_batch():
    env = make_env(GOALS)
    planner = RandomShootingPlanner(env, num_candidates=8000)
    td = start(env, POSITIONS)[0]
    action = planner(td)["action"]
    assert action.shape == (2,)
    torch.testing.assert_close(action, EXPECTED[0], atol=0.02, rtol=0)


def test_exhaustive_over_a_finite_set():
    env = make_env(GOALS)
    choices = torch.tensor([[0.0, 0.0], [0.1, -0.1], [0.0, 0.3], [-0.2, -0.05], [0.3, 0.3]])
    planner = ExhaustivePlanner(env, choices=choices)
    action = planner(start(env, POSITIONS))["action"]
    torch.testing.assert_close(action, EXPECTED)


def test_exhaustive_over_categorical_indices():
    """A discrete world model (LIB): index g moves by ``moves[g]``; the planner returns the exact best index."""
    moves = torch.tensor([[0.0, 0.0], [0.2, 0.0], [0.0, 0.2], [-0.2, 0.0], [0.0, -0.2]])

    class Library(torch.nn.Module):
        def predict(self, com_state, action):
            return torch.cat([com_state[..., :2] + moves[action[..., 0].long()], com_state[..., 2:]], -1)

    env = CoMWorldModelEnv(Library(), num_choices=len(moves), task=GoalReaching(goals=GOALS))
    planner = ExhaustivePlanner(env, planning_horizon=2)
    action = planner(start(env, POSITIONS))["action"]
    assert action.dtype == torch.int64 and env.action_spec.is_in(action[0])
    assert action.squeeze(-1).tolist() == [1, 2, 3]


def test_warm_start_keeps_a_good_plan():
    env = make_env(GOALS)
    planner = BoxCEMPlanner(env, num_candidates=100, optim_steps=2, top_k=10)
    td = start(env, POSITIONS)
    first = planner(td)["action"]
    second = planner(td)["action"]  # warm started from the first plan
    error = lambda a: (a - EXPECTED).norm(dim=-1)  # noqa: E731
    assert torch.all(error(second) <= error(first) + 0.01)
    planner.reset()
    assert planner.warm_start(3) is None


def test_bad_settings_are_refused():
    env = make_env(GOALS)
    with pytest.raises(ValueError):
        RandomShootingPlanner(env, planning_horizon=0)
    with pytest.raises(ValueError):
        BoxCEMPlanner(env, num_candidates=10, top_k=20)
    with pytest.raises(ValueError, match="Categorical"):
        ExhaustivePlanner(env)


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_begin_task_retargets_the_world_model_and_forgets_the_warm_start(name):
    """Planners are task policies: begin_task(task) scores with the new task's goals from the next call on."""
    from hierloco.components.policies import TaskPolicy

    env = make_env(GOALS)
    planner = PLANNERS[name](env, 1)
    assert isinstance(planner, TaskPolicy)
    planner(start(env, POSITIONS))
    assert planner.warm_start(3) is not None
    mirrored = [[-g[0], -g[1]] for g in GOALS]
    task = GoalReaching(goals=mirrored)
    planner.begin_task(task)
    assert env.task is task and planner.warm_start(3) is None
    action = planner(start(env, [[0.0, 0.0]] * 3))["action"]
    expected = torch.tensor(mirrored).clamp(-HALF_WIDTH, HALF_WIDTH)  # straight at the new goals, clipped
    torch.testing.assert_close(action, expected, atol=0.05, rtol=0)


class CommandDrift(torch.nn.Module):
    """A test double for the CoM model over velocity commands ``(vx, vy, yaw_rate)``: the robot moves by ``(vx, vy)``
    in the world frame over the 1 s action and ends with that velocity."""

    def predict(self, com_state, action):
        return torch.cat([com_state[..., :2] + action[..., :2], com_state[..., 2:3], action[..., :2]], -1)


def bare_env_planner(task, num_robots):
    """A bare latent-action env (A1 under the Raibert controller, no transform at all) and a random-shooting planner
    over :class:`CommandDrift` for ``task``."""
    from hierloco.components.low_level import CommandLowLevel
    from hierloco.envs.latent_env import LatentActionEnv

    low_level = CommandLowLevel("a1", num_robots)
    world_model = CoMWorldModelEnv(CommandDrift(), action_low=low_level.action_low, action_high=low_level.action_high,
                                   task=task)
    env = LatentActionEnv(low_level, num_robots=num_robots, seed=0)
    return env, RandomShootingPlanner(world_model, num_candidates=4000, seed=0)


def collect(env, planner, frames, **options):
    import warnings

    from torchrl.collectors import Collector

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        collector = Collector(env, planner, frames_per_batch=frames, total_frames=frames, **options)
        try:
            batch = next(iter(collector))
        finally:
            collector.shutdown()
    assert not [w for w in caught if "missing transforms" in str(w.message)], "the env lacks nothing the planner reads"
    return batch


def test_a_planner_runs_in_a_collector_over_the_bare_latent_env():
    """No task transform, no InitTracker: robot b pursues episode b of the planner's task (goal b), as
    ``task_transforms`` would have it; the env's tensordicts are left without task keys. Under the test model the
    best command from a measured position p is the nearest point of the command box to ``goal - p``."""
    goals = torch.tensor([[2.0, 0.0], [-2.0, 0.0]])
    env, planner = bare_env_planner(GoalReaching(goals=goals.tolist()), num_robots=2)
    batch = collect(env, planner, frames=6)
    assert batch.batch_size == (2, 3) and "task_episode" not in batch.keys()
    action = batch["action"]
    assert all(env.action_spec.is_in(action[:, t]) for t in range(3))
    to_goal = goals[:, None] - batch["com_state"][..., :2]
    best = to_goal.clamp(-HALF_WIDTH, HALF_WIDTH)
    gap = 2 * (to_goal - action[..., :2]).norm(dim=-1) - 2 * (to_goal - best).norm(dim=-1)  # goal reaching cost
    assert torch.all(gap <= 2 * 2 * resolution(4000, 1, action_dim=3)), gap
    assert (action[0, :, 0] > 0.25).all() and (action[1, :, 0] < -0.25).all()  # each robot towards its own goal


def test_a_planner_counts_the_task_steps_of_a_bare_env_across_resets():
    """Velocity tracking with a new target at every step: the planner's own step count follows each robot's episode,
    back to 0 when the collector resets the robot (episodes of 2 actions), so it commands the target of that step."""
    from hierloco.envs.tasks import VelocityTracking

    targets = torch.tensor([[0.2, 0.0], [0.0, 0.2], [-0.2, -0.1]])
    env, planner = bare_env_planner(VelocityTracking(velocities=targets.tolist(), steps_per_target=1, rounds=1),
                                    num_robots=2)
    batch = collect(env, planner, frames=10, max_frames_per_traj=2)
    assert batch["step_count"].squeeze(-1).tolist() == [[0, 1, 0, 1, 0]] * 2
    torch.testing.assert_close(batch["is_init"].squeeze(-1), batch["step_count"].squeeze(-1) == 0)
    expected = targets[batch["step_count"].squeeze(-1)]  # without the resets, the third action would chase target 2
    torch.testing.assert_close(batch["action"][..., :2], expected, atol=0.03, rtol=0)
