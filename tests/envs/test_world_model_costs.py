"""Pluggable costs and risk-aware scoring in the CoM world model: a cost of one's own needs no Task subclass, a Task
stays the default cost, an ensemble's particles are scored per particle and aggregated by the risk (PETS, Chua et
al., NeurIPS 2018; planning as in Li et al., RA-L 2021, Sec. III-A.2)."""

import math

import pytest
import torch
from torchrl.envs.utils import check_env_specs

from hierloco.components.com_ensemble import CoMEnsembleModel
from hierloco.components.com_model import CoMDynamicsModel
from hierloco.components.planners import BoxCEMPlanner, RandomShootingPlanner
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.world_model import CoMWorldModelEnv, risk_of

BOX = dict(action_low=[-0.3, -0.3], action_high=[0.3, 0.3])


class Drift(torch.nn.Module):
    """Closed form: the action is the world-frame displacement of one step."""

    def predict(self, com_state, action):
        return torch.cat([com_state[..., :2] + action, com_state[..., 2:]], -1)


class Spread(Drift):
    """Closed form with particles: particle p moves by ``(1 + GAINS[p]) * action``: the members disagree about the
    step length, more so for long steps."""

    GAINS = torch.tensor([-0.5, 0.0, 0.5])
    num_particles = 3

    def predict_particles(self, particles, action, generator=None):
        move = (1 + self.GAINS[:, None]) * action
        return torch.cat([particles[..., :2] + move, particles[..., 2:]], -1)


GOAL, DISC, RADIUS = torch.tensor([0.6, 0.0]), torch.tensor([0.3, 0.0]), 0.15


def reach_avoiding_disc(com_state, next_com_state, action, info):
    """Distance to GOAL after the step plus 10 per metre inside the disc (a plain function: no Task, no hook)."""
    position = next_com_state[..., :2]
    inside = (RADIUS - (position - DISC).norm(dim=-1)).clamp_min(0)
    return (GOAL - position).norm(dim=-1) + 10 * inside


def test_a_plain_cost_function_steers_the_planner_around_a_disc():
    """Straight at the goal (0.3, 0) then (0.3, 0) goes through the disc's centre; the best 2-step plan goes around,
    its first step ending outside the disc, and it scores better than the straight plan."""
    env = CoMWorldModelEnv(Drift(), cost=reach_avoiding_disc, **BOX)
    planner = RandomShootingPlanner(env, planning_horizon=2, num_candidates=20000, seed=0)
    state = env.initial_state(torch.zeros(1, 5))
    action = planner(state)["action"][0]
    assert (action - DISC).norm() > RADIUS - 1e-3, action
    straight = torch.tensor([[[[0.3, 0.0], [0.3, 0.0]]]])
    plan = planner._previous[None]
    assert planner.score(state, plan) > planner.score(state, straight) + 1.0


def test_the_task_is_the_default_cost_and_a_given_cost_survives_begin_task():
    task = GoalReaching(goals=[[1.0, 0.0]])
    env = CoMWorldModelEnv(Drift(), task=task, **BOX)
    td = env.initial_state(torch.zeros(2, 5), episode=torch.zeros(2, dtype=torch.int64), step=0)
    td["action"] = torch.tensor([[0.3, 0.0], [0.0, 0.3]])
    out = env.step(td.clone())
    expected = -task.cost(td["com_state"], out["next", "com_state"], torch.zeros(2, dtype=torch.int64), 0)
    torch.testing.assert_close(out["next", "reward"].squeeze(-1), expected)
    env.set_cost(reach_avoiding_disc)
    planner = RandomShootingPlanner(env, num_candidates=10)
    planner.begin_task(GoalReaching(goals=[[5.0, 5.0]]))  # a new task: the given cost still scores
    out = env.step(td.clone())
    torch.testing.assert_close(out["next", "reward"].squeeze(-1),
                               -reach_avoiding_disc(td["com_state"], out["next", "com_state"], None, None))
    env.set_cost(None)
    assert env.step(td.clone())["next", "reward"].squeeze(-1)[0] == pytest.approx(-2 * math.hypot(5 - 0.3, 5) - math.pi / 2)  # + the yaw term: facing +x, not +y


@pytest.mark.parametrize("risk,beta", [("none", 0.0), ("mean_std", 2.0), ("pessimistic", 0.0)])
def test_risk_scores_a_plan_by_the_risk_of_its_particles_summed_costs(risk, beta):
    """Over a horizon of 3 the rewards add up to ``-risk`` of each particle's cost summed over the plan (computed
    here by hand from the closed-form particles), whatever the risk."""
    env = CoMWorldModelEnv(Spread(), cost=reach_avoiding_disc, risk=risk, beta=beta, **BOX)
    td = env.reset(env.initial_state(torch.zeros(4, 5)))
    actions = torch.tensor([[0.3, 0.0], [0.1, 0.2], [0.2, -0.1], [-0.3, 0.3]])
    total, position, summed = torch.zeros(4), torch.zeros(3, 2), torch.zeros(4, 3)
    for _ in range(3):
        out = env.step(td.set("action", actions))
        total += out["next", "reward"].squeeze(-1)
        moved = position + (1 + Spread.GAINS[:, None]) * actions[:, None]  # 4 x 3 x 2
        summed += reach_avoiding_disc(None, torch.cat([moved, torch.zeros(4, 3, 3)], -1), None, None)
        position = moved
        td = out["next"]
    torch.testing.assert_close(total, -risk_of(summed, risk, beta))
    torch.testing.assert_close(td["com_state"][:, :2], position.mean(1))


def test_risk_changes_the_plan_where_the_members_disagree():
    """Spread's members disagree about the step length (x 0.5, 1, 1.5). For the squared distance to a goal 0.25 m
    ahead, the risk-neutral plan minimises the mean, 0.25 x 3 / 3.5 = 0.214 m (the members' mean step, shortened by
    their disagreement); the pessimistic one minimises the worst member, the step of 0.25 m at which the shortest and
    the longest member miss by the same amount."""

    def squared_distance(com_state, next_com_state, action, info):
        return ((next_com_state[..., :2] - torch.tensor([0.25, 0.0])) ** 2).sum(-1)

    plans = {}
    for risk in ("none", "pessimistic"):
        env = CoMWorldModelEnv(Spread(), cost=squared_distance, risk=risk, **BOX)
        planner = RandomShootingPlanner(env, num_candidates=20000, seed=0)
        plans[risk] = planner(env.initial_state(torch.zeros(1, 5)))["action"][0]
    torch.testing.assert_close(plans["none"], torch.tensor([0.25 * 3 / 3.5, 0.0]), atol=0.01, rtol=0)
    torch.testing.assert_close(plans["pessimistic"], torch.tensor([0.25, 0.0]), atol=0.01, rtol=0)


def test_cost_info_holds_the_task_state_and_the_particles_spread():
    seen = {}

    def record(com_state, next_com_state, action, info):
        seen.update({k: v.shape for k, v in info.items()}, state=com_state.shape, action=action.shape)
        return torch.zeros(next_com_state.shape[:-1])

    torch.manual_seed(0)
    env = CoMWorldModelEnv(CoMEnsembleModel(action_dim=2, hidden=8, members=4), cost=record, **BOX)
    td = env.initial_state(torch.zeros(2, 7, 5))
    env.step(td.set("action", torch.zeros(2, 7, 2)))
    assert seen == {"task_episode": (2, 7, 1), "task_step": (2, 7, 1), "next_com_state_mean": (2, 7, 1, 5),
                    "next_com_state_std": (2, 7, 1, 5), "state": (2, 7, 4, 5), "action": (2, 7, 1, 2)}
    env = CoMWorldModelEnv(CoMDynamicsModel(action_dim=2, hidden=8), cost=record, **BOX)
    seen.clear()
    env.step(env.initial_state(torch.zeros(3, 5)).set("action", torch.zeros(3, 2)))
    assert seen["task_step"] == (3,) and seen["state"] == (3, 5) and "next_com_state_std" not in seen


def test_ensemble_world_model_specs_and_planners():
    torch.manual_seed(0)
    for propagation in ("ts", "mm", "expectation"):
        model = CoMEnsembleModel(action_dim=2, hidden=8, members=3, propagation=propagation)
        env = CoMWorldModelEnv(model, task=GoalReaching(), risk="mean_std", **BOX)
        check_env_specs(env)
        planner = BoxCEMPlanner(env, planning_horizon=2, num_candidates=50, optim_steps=2, top_k=5)
        assert planner.in_keys == ["com_state", "task_episode", "task_step"]  # what a measured state holds
        action = planner(env.initial_state(torch.zeros(3, 5), episode=torch.arange(3)))["action"]
        assert action.shape == (3, 2) and env.action_spec.is_in(action)


def test_risk_needs_a_model_with_members():
    with pytest.raises(ValueError, match="needs a model with members"):
        CoMWorldModelEnv(Drift(), risk="pessimistic", **BOX)
    with pytest.raises(ValueError, match="risk must be one of"):
        CoMWorldModelEnv(Spread(), risk="cvar", **BOX)
    with pytest.raises(ValueError, match="cost must be a callable"):
        CoMWorldModelEnv(Drift(), cost="goal", **BOX)
