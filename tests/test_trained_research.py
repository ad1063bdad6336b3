"""The research API on a trained run: its dynamics data, a planner over another model (the ensemble) and another
cost (no Task subclass), risk-aware closed-loop MPC on the simulated robot, and the ensemble's export (PETS, Chua et
al., NeurIPS 2018; Li et al., RA-L 2021, Sec. III)."""

import json
import shutil

import numpy as np
import pytest
import torch

from hierloco.components.com_ensemble import CoMEnsembleModel
from hierloco.components.com_model import TrainedCoMModel, train_com_model
from hierloco.components.dynamics_data import collect_transitions
from hierloco.components.evaluation import run_task
from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy import train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot
from hierloco.envs.tasks import GoalReaching
from hierloco.exporting import TOLERANCE, export_run
from hierloco.trained import load_run

ROBOT = "daisy"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A tiny LAT run directory as the recipe leaves it: gait policy, dynamics data and MLP, manifest."""
    path = tmp_path_factory.mktemp("lat_run")
    library = build_expert_library(ROBOT, 3, seed=0, settle_time=1.0, progress=False)
    periods = int(round(library.steps_per_action * CONTROL_TIMESTEP / get_robot(ROBOT).gait_period))
    policy = train_gait_policy(library.joint_targets, latent_dim=2, periods_per_action=periods, hidden=64,
                               epochs=100, batch_size=300, lr=3e-3, progress=False)
    policy.save(path / "gait_policy.pt")
    low_level = LatentLowLevel(policy, ROBOT)
    env = LatentActionEnv(low_level, num_robots=20, seed=0)
    data = collect_transitions(env, 300, episode_length=5, seed=0, progress=False)
    env.close()
    data.save(path / "dynamics_data_normal.npz")
    train_com_model(data.com_state, data.action, data.next_com_state, hidden=32, max_epochs=30,
                    progress=False).save(path / "dynamics_model_normal.pt")
    (path / "run.json").write_text(json.dumps({
        "method": "lat", "robot": ROBOT, "seed": 0, "settings": ["normal"], "low_level": {"kind": "latent"},
        "planner": {"name": "random_shooting", "horizon": 1, "num_candidates": 500}}))
    return path


@pytest.fixture(scope="module")
def ensemble(run_dir):
    data = load_run(run_dir).dynamics_data("normal")
    return train_com_model(data.com_state, data.action, data.next_com_state, model="ensemble", members=3,
                           hidden=64, max_epochs=300, lr=3e-3, progress=False)


def test_dynamics_data_of_a_setting(run_dir):
    run = load_run(run_dir)
    data = run.dynamics_data("normal")
    assert data.com_state.shape == (300, 5) and data.action.shape == (300, 2)
    assert data.metadata["low_level"]["kind"] == "latent"
    with pytest.raises(ValueError, match="legs_disabled"):
        run.dynamics_data("legs_disabled")


def test_planner_over_another_model_and_cost(run_dir, ensemble):
    """``run.planner(task, model=, cost=, risk=)`` plans with the given model, cost and risk, keeps the run's
    planner settings, and keeps the cost when it is told a task."""
    run = load_run(run_dir)
    disc = torch.tensor([0.5, 0.0])

    def keep_away(com_state, next_com_state, action, info):
        return -(next_com_state[..., :2] - disc).norm(dim=-1)

    planner = run.planner(GoalReaching(), model=ensemble, cost=keep_away, risk="pessimistic")
    env = planner.env
    assert isinstance(env.model, CoMEnsembleModel) and env.risk == "pessimistic" and env.cost is keep_away
    assert planner.num_candidates == 500
    planner.begin_task(GoalReaching(num_goals=2))
    assert env.cost is keep_away
    state = env.initial_state(torch.zeros(2, 5), episode=torch.arange(2))
    action = planner(state)["action"]
    assert action.shape == (2, 2) and env.action_spec.is_in(action)
    default = run.planner(GoalReaching())
    assert type(default.env.model).__name__ == "CoMDynamicsModel" and default.env.cost is None


@pytest.mark.parametrize("risk", ["none", "mean_std", "pessimistic"])
def test_risk_aware_mpc_runs_closed_loop(run_dir, ensemble, risk):
    """MPC with the ensemble on the simulated robots, every risk: 2 goals 1 m away, where the fastest of the 3
    experts walks (about 0.45 m/s towards -y), 3 actions; both robots close in on their goals."""
    run = load_run(run_dir)
    task = GoalReaching(goals=[[-0.36, -0.93], [0.0, -1.0]], num_steps=3)
    planner = run.planner(task, model=ensemble, risk=risk, beta=1.0)
    env = LatentActionEnv(run.low_level(), num_robots=2, seed=0)
    rollout = run_task(env, planner, task)
    env.close()
    assert rollout.actions.shape == (2, 3, 2) and np.isfinite(rollout.result.normalized_cost).all()
    assert (rollout.result.normalized_cost < 0.85).all(), rollout.result.normalized_cost  # measured 0.60-0.76


def test_ensemble_run_exports_like_the_mlp(run_dir, ensemble, tmp_path):
    """A run whose CoM model is the ensemble exports its mean prediction, the scoring and every member's prediction,
    each agreeing with PyTorch within the exporter's tolerance (1e-5), and the manifest names the model."""
    onnxruntime = pytest.importorskip("onnxruntime")
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    ensemble.save(copy / "dynamics_model_normal.pt")
    manifest = export_run(copy, tmp_path / "out")
    assert manifest["dynamics_model"]["model"] == "ensemble"
    assert manifest["dynamics_model"]["options"]["members"] == 3
    assert {"com_model_predict", "com_model_members", "score_goal_reaching"} <= set(manifest["models"])
    for entry in manifest["models"].values():
        assert max(entry["max_abs_error"].values()) <= TOLERANCE
    model = TrainedCoMModel.load(copy / "dynamics_model_normal.pt").model
    state, action = torch.randn(4, 5), torch.rand(4, 2)
    session = onnxruntime.InferenceSession(str(tmp_path / "out" / "com_model_members.onnx"))
    members = session.run(None, {"com_state": state.numpy(), "action": action.numpy()})[0]
    with torch.no_grad():
        np.testing.assert_allclose(members, model.predict_members(state, action).numpy(), atol=1e-5, rtol=0)
