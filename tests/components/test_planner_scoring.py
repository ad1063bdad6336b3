"""How planners score candidates (``docs/gpu.md``): the world model's tensor function that ``planner.compile`` captures
gives the TorchRL env steps' returns, lower precision (``planner.precision``) picks actions as good as fp32's on the
paper's tasks, and a compiled planner picks fp32's actions.

The precision check runs the paper's planner (random shooting, 8000 samples, horizon 1) with a paper-size CoM model
(2 x 512) fitted to a robot that walks where its latent points, on the three tasks of Li et al. (RA-L 2021,
Sec. IV-A), from the start and from states along the way. Both precisions score the same candidates; the action a
lower precision picks is scored again in fp32, and its cost may exceed the fp32 pick's by at most
:data:`PRECISION_TOLERANCE` of the step's standing-still cost (the normaliser of the paper's metric): 1 % of the
metric's scale.
"""

from __future__ import annotations

import math

import pytest
import torch

from hierloco.components.com_model import train_com_model
from hierloco.components.planners import make_planner
from hierloco.envs.tasks import make_task
from hierloco.envs.world_model import CoMWorldModelEnv

PRECISION_TOLERANCE = 0.01  # of the standing-still cost of the step (normalised cost units)
LOW, HIGH = [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]
PAPER_TASKS = {"velocity_tracking": {}, "goal_reaching": {}, "trajectory_tracking": {}}


def walking_transitions(count: int = 4000, seed: int = 0):
    """Transitions of a stand-in robot: over one action it walks ``0.3 z[:2]`` m in its own frame and turns
    ``0.2 z[2]`` rad, its velocity becoming the displacement's, with a little noise."""
    generator = torch.Generator().manual_seed(seed)
    state = torch.randn(count, 5, generator=generator, device="cpu")
    state[:, :2] *= 2.0
    action = torch.rand(count, 3, generator=generator, device="cpu") * 2 - 1
    yaw = state[:, 2]
    step = 0.3 * action[:, :2]
    world = torch.stack([step[:, 0] * torch.cos(yaw) - step[:, 1] * torch.sin(yaw),
                         step[:, 0] * torch.sin(yaw) + step[:, 1] * torch.cos(yaw)], -1)
    following = torch.cat([state[:, :2] + world, (yaw + 0.2 * action[:, 2])[:, None], world], -1)
    following = following + 0.005 * torch.randn(count, 5, generator=generator, device="cpu")
    return state, action, following


@pytest.fixture(scope="module")
def paper_model():
    """A 2 x 512 CoM model (the paper's) fitted to :func:`walking_transitions`."""
    state, action, following = walking_transitions()
    return train_com_model(state, action, following, hidden=512, max_epochs=15, patience=15, progress=False).model


def planning_states(task, count: int = 4, seed: int = 1):
    """The start of every episode, and ``count`` states per episode further on (positions, yaws, velocities
    drawn around the path), at steps along the episode."""
    generator = torch.Generator().manual_seed(seed)
    episodes = torch.arange(task.num_episodes, device="cpu").repeat_interleave(count + 1)
    steps = torch.cat([torch.zeros(1, dtype=torch.long, device="cpu"),
                       torch.randint(1, task.num_steps, (count,), generator=generator, device="cpu")])
    steps = steps.repeat(task.num_episodes)
    states = task.start_state().repeat(len(episodes), 1)
    drawn = (torch.arange(len(episodes), device="cpu") % (count + 1)) > 0
    noise = torch.randn(len(episodes), 5, generator=generator, device="cpu") * torch.tensor(
        [0.8, 0.8, 0.3, 0.2, 0.2], device="cpu")
    states[drawn] += noise[drawn]
    return states, episodes, steps


@pytest.mark.parametrize("task_name", list(PAPER_TASKS))
@pytest.mark.parametrize("precision", ["bf16", "tf32"])
def test_lower_precision_picks_actions_as_good_as_fp32(paper_model, task_name, precision):
    task = make_task(task_name, **PAPER_TASKS[task_name])
    states, episodes, steps = planning_states(task)
    env = CoMWorldModelEnv(paper_model, action_low=LOW, action_high=HIGH, task=task)
    state = env.initial_state(states, episode=episodes, step=steps)

    def picked(precision: str) -> torch.Tensor:
        planner = make_planner(env, name="random_shooting", num_candidates=8000, seed=0, precision=precision)
        return planner(state.clone())["action"]

    def fp32_cost(action: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            following = paper_model.predict(states, action)
        return task.cost(states, following, episodes, steps)

    reference, lower = picked("fp32"), picked(precision)
    standing = task.cost(states, states, episodes, steps)
    excess = (fp32_cost(lower) - fp32_cost(reference)) / standing
    assert excess.max() <= PRECISION_TOLERANCE, (
        f"{precision} picks cost up to {excess.max():.4f} of the standing cost more than fp32's")
    # not a vacuous bound: an action drawn at random costs far more than the tolerance
    random_action = torch.rand(len(states), 3, generator=torch.Generator().manual_seed(2), device="cpu") * 2 - 1
    assert ((fp32_cost(random_action) - fp32_cost(reference)) / standing).mean() > 10 * PRECISION_TOLERANCE


class Drift(torch.nn.Module):
    """A closed-form CoM model: the action is the world-frame displacement."""

    def predict(self, com_state, action):
        return torch.cat([com_state[..., :2] + action[..., :2], com_state[..., 2:]], -1)


def test_the_tensor_scoring_is_the_env_steps_return(paper_model):
    """``CoMWorldModelEnv.imagined_return`` (what a compiled planner captures) equals the summed rewards of the
    TorchRL env steps the eager planner takes, over a horizon of 3, for a box model, an ensemble with particles
    (trajectory sampling from the env's generator) under a risk, and a finite action set."""
    from hierloco.components.com_ensemble import CoMEnsembleModel
    from hierloco.components.planners.base import BoxPlannerBase

    task = make_task("goal_reaching")
    generator = torch.Generator().manual_seed(0)
    actions = torch.rand(4, 32, 3, 3, generator=generator, device="cpu") * 2 - 1
    states = task.start_state().repeat(4, 1) + 0.1 * torch.randn(4, 5, generator=generator, device="cpu")
    ensemble = CoMEnsembleModel(3, hidden=32, members=3).eval()
    cases = [(paper_model, {}, actions), (ensemble, {"risk": "mean_std", "beta": 0.5}, actions),
             (Drift(), {"num_choices": 5, "action_features": lambda a: torch.stack([0.1 * a[..., 0].float(),
                                                                                    -0.1 * a[..., 0].float()], -1)},
              torch.randint(0, 5, (4, 32, 3, 1), generator=generator, device="cpu"))]
    for model, options, candidates in cases:
        box = {} if "num_choices" in options else {"action_low": LOW, "action_high": HIGH}

        def env():
            return CoMWorldModelEnv(model, task=task, seed=3, **box, **options)

        eager = make_planner(env(), name="exhaustive" if "num_choices" in options else "random_shooting")
        state = eager.env.initial_state(states, episode=torch.arange(4, device="cpu") % 8, step=2)
        through_steps = BoxPlannerBase.score(eager, state, candidates.float())
        fresh = env()
        through_tensors = fresh.imagined_return(state["com_state"], state["task_episode"], state["task_step"],
                                                candidates)
        torch.testing.assert_close(through_tensors, through_steps)


@pytest.mark.slow
@pytest.mark.parametrize("planner", ["random_shooting", "cem"])
def test_a_compiled_planner_picks_the_eager_actions(paper_model, planner):
    """``planner.compile=true`` (``torch.compile``, plain on the CPU) scores as the eager planner does: the same
    candidates give the same picks (or picks of equal cost) on goal reaching, call after call."""
    task = make_task("goal_reaching")
    env = CoMWorldModelEnv(paper_model, action_low=LOW, action_high=HIGH, task=task)
    states, episodes, steps = planning_states(task, count=1)
    state = env.initial_state(states, episode=episodes, step=steps)
    options = {"name": planner, "num_candidates": 2000, "optim_steps": 2, "top_k": 20, "seed": 0}
    eager, compiled = make_planner(env, **options), make_planner(env, compile=True, **options)
    for _ in range(3):
        a, b = eager(state.clone())["action"], compiled(state.clone())["action"]
        with torch.no_grad():
            cost_a = task.cost(states, paper_model.predict(states, a), episodes, steps)
            cost_b = task.cost(states, paper_model.predict(states, b), episodes, steps)
        assert torch.allclose(cost_a, cost_b, atol=1e-4) and math.isfinite(float(cost_b.sum()))
