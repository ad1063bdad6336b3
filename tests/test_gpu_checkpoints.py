"""A run trained on a GPU loads and exports on a machine without one (``docs/gpu.md``).

A checkpoint saved from CUDA tensors names its storages' device (``cuda:0``); torch refuses to read it on a machine
without CUDA unless it is mapped (``map_location``). Here the run's checkpoints are written as a GPU machine writes
them (their storages tagged ``cuda:0``), and :func:`hierloco.load_run`, every part it returns, a planner's action,
:func:`hierloco.export` and the SAC agent's loader read them on this CPU machine.
"""

from __future__ import annotations

import json

import pytest
import torch

import hierloco
from hierloco.components.com_model import train_com_model
from hierloco.components.dynamics_data import collect_transitions
from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy import train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.tasks import GoalReaching

ROBOT = "a1"


@pytest.fixture
def as_if_on_a_gpu(monkeypatch):
    """``torch.save`` tags every storage ``cuda:0``, as it does for tensors on a GPU."""
    monkeypatch.setattr(torch.serialization, "location_tag", lambda storage: "cuda:0")


@pytest.fixture(scope="module")
def cpu_run(tmp_path_factory):
    """A tiny LAT run's parts, trained here: expert library, gait policy, dynamics data and CoM MLP."""
    library = build_expert_library(ROBOT, 3, seed=0, settle_time=0.5, progress=False)
    policy = train_gait_policy(library.joint_targets, latent_dim=2, hidden=16, epochs=3, batch_size=100,
                               progress=False)
    env = LatentActionEnv(LatentLowLevel(policy, ROBOT), num_robots=8, seed=0, nthread=1)
    data = collect_transitions(env, 40, episode_length=3, seed=0, progress=False)
    env.close()
    model = train_com_model(data.com_state, data.action, data.next_com_state, hidden=16, max_epochs=3,
                            progress=False)
    return policy, data, model


@pytest.fixture
def gpu_made_run(cpu_run, tmp_path, as_if_on_a_gpu):
    policy, data, model = cpu_run
    path = tmp_path / "run"
    path.mkdir()
    policy.save(path / "gait_policy.pt")
    model.save(path / "dynamics_model_normal.pt")
    data.save(path / "dynamics_data_normal.npz")
    (path / "run.json").write_text(json.dumps({
        "method": "lat", "robot": ROBOT, "seed": 0, "settings": ["normal"], "low_level": {"kind": "latent"},
        "planner": {"name": "random_shooting", "horizon": 1, "num_candidates": 200, "compile": False,
                    "precision": "fp32"}}))
    return path


def test_the_checkpoints_are_as_a_gpu_writes_them(gpu_made_run):
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU: the checkpoints load without mapping")
    with pytest.raises(RuntimeError, match="CUDA"):
        torch.load(gpu_made_run / "gait_policy.pt", weights_only=True)


@pytest.mark.parametrize("device", ["cpu", "auto"])
def test_a_gpu_made_run_loads_and_plans_here(gpu_made_run, cpu_run, device):
    run = hierloco.load_run(gpu_made_run, device=device)
    here = "cuda" if device == "auto" and torch.cuda.is_available() else "cpu"
    low_level = run.low_level()
    assert next(low_level.policy.parameters()).device.type == here
    assert next(run.com_model().model.parameters()).device.type == here
    assert run.world_model().device.type == here
    task = GoalReaching(num_goals=2, num_steps=3)
    planner = run.planner(task)
    state = planner.env.initial_state(episode=torch.arange(2, device=here))
    action = planner(state.cpu())["action"]
    assert action.device.type == "cpu" and action.shape == (2, 2)  # back on the device of the state it was given
    torch.testing.assert_close(run.low_level().patterns(run.low_level().trained.latents.numpy()),
                               LatentLowLevel(cpu_run[0], ROBOT).patterns(cpu_run[0].latents.numpy()))


def test_a_gpu_made_run_exports_here(gpu_made_run, tmp_path):
    manifest = hierloco.export(gpu_made_run, tmp_path / "deploy")
    assert (tmp_path / "deploy" / "manifest.json").is_file() and manifest


def test_a_gpu_made_sac_agent_loads_here(tmp_path, as_if_on_a_gpu):
    from tensordict import TensorDict

    from hierloco.components.sac import SACAgent

    agent = SACAgent.build(7, [-1.0, -1.0], [1.0, 1.0], hidden=16, seed=0)
    agent.update(TensorDict({"goal_observation": torch.zeros(8, 7), "action": torch.zeros(8, 2),
                             "next": {"goal_observation": torch.zeros(8, 7), "reward": torch.ones(8, 1),
                                      "done": torch.zeros(8, 1, dtype=torch.bool),
                                      "terminated": torch.zeros(8, 1, dtype=torch.bool)}}, batch_size=[8]))
    agent.save(tmp_path / "agent.pt")
    loaded = SACAgent.load(tmp_path / "agent.pt")
    assert loaded.device.type == "cpu" and loaded.updates == 1
    observation = torch.randn(4, 7, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(loaded.act(observation), agent.act(observation))
