"""Export for deployment: from tiny real run directories (a gait policy trained on Daisy experts, CoM models trained
on transitions simulated with the LAT and LIB low levels), the ONNX and TorchScript files agree with PyTorch to 1e-5,
the exported scoring is the planner's score, and a run directory without artifacts is refused."""

import json
import math

import numpy as np
import pytest
import torch

from hierloco.components.com_model import TrainedCoMModel, train_com_model
from hierloco.components.dynamics_data import collect_transitions
from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy import TrainedGaitPolicy, train_gait_policy
from hierloco.components.low_level import ExpertReplayLowLevel, LatentLowLevel
from hierloco.components.planners import RandomShootingPlanner
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot
from hierloco.envs.tasks import GoalReaching, TrajectoryTracking, VelocityTracking
from hierloco.envs.world_model import CoMWorldModelEnv
from hierloco.exporting import TOLERANCE, export_run
from hierloco.io import ArtifactError

onnxruntime = pytest.importorskip("onnxruntime")
ROBOT = "daisy"
MODEL_FUNCTIONS = {"com_model_predict", "planner_model_step", "score_goal_reaching", "score_velocity_tracking"}


def _simulated_model(low_level, run_dir, seed=0):
    """A tiny CoM model on 200 transitions simulated with ``low_level``, saved with its data as the pipeline does."""
    env = LatentActionEnv(low_level, num_robots=20, seed=seed)
    data = collect_transitions(env, 200, episode_length=5, seed=seed, progress=False)
    env.close()
    data.save(run_dir / "dynamics_data_normal.npz")
    trained = train_com_model(data.com_state, low_level.action_features(data.action), data.next_com_state,
                              hidden=32, max_epochs=30, seed=seed, progress=False)
    trained.save(run_dir / "dynamics_model_normal.pt")
    return trained


@pytest.fixture(scope="module")
def library():
    return build_expert_library(ROBOT, 3, seed=0, settle_time=1.0, progress=False)


@pytest.fixture(scope="module")
def lat_run(library, tmp_path_factory):
    """A LAT run directory (gait policy + CoM model over z) and its export (horizon 1, the paper's)."""
    run_dir = tmp_path_factory.mktemp("lat_run")
    periods = int(round(library.steps_per_action * CONTROL_TIMESTEP / get_robot(ROBOT).gait_period))
    policy = train_gait_policy(library.joint_targets, latent_dim=2, periods_per_action=periods, hidden=32,
                               epochs=30, batch_size=300, progress=False)
    policy.save(run_dir / "gait_policy.pt")
    low_level = LatentLowLevel(policy, ROBOT)
    model = _simulated_model(low_level, run_dir)
    out_dir = run_dir / "export"
    manifest = export_run(run_dir, out_dir)
    return {"run_dir": run_dir, "out": out_dir, "manifest": manifest, "policy": policy, "model": model,
            "low_level": low_level}


@pytest.fixture(scope="module")
def lib_run(library, tmp_path_factory):
    """A LIB run directory (no gait policy; a CoM model over one-hot experts) exported with horizon 2."""
    run_dir = tmp_path_factory.mktemp("lib_run")
    low_level = ExpertReplayLowLevel(library)
    model = _simulated_model(low_level, run_dir)
    out_dir = run_dir / "export"
    manifest = export_run(run_dir, out_dir, horizon=2)
    return {"run_dir": run_dir, "out": out_dir, "manifest": manifest, "model": model, "low_level": low_level}


def _session(path):
    return onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def _check_both(out_dir, stem, inputs: dict, expected: torch.Tensor):
    """The ONNX file (onnxruntime) and the TorchScript file give ``expected`` on ``inputs`` within 1e-5."""
    onnx_out = _session(out_dir / f"{stem}.onnx").run(None, {k: v.numpy() for k, v in inputs.items()})[0]
    np.testing.assert_allclose(onnx_out, expected.numpy(), rtol=0, atol=1e-5)
    script_out = torch.jit.load(str(out_dir / f"{stem}.pt"))(*inputs.values())
    torch.testing.assert_close(script_out, expected, rtol=0, atol=1e-5)


def _states(generator, batch):
    low = torch.tensor([-4.0, -4.0, -math.pi, -0.4, -0.4])
    return low + (-2 * low) * torch.rand(batch, 5, generator=generator)


def _latents(box, generator, *shape):
    low, high = torch.as_tensor(box["low"]), torch.as_tensor(box["high"])
    return low + (high - low) * torch.rand(*shape, len(low), generator=generator)


# ---------------------------------------------------------------------------------------------------- LAT run
def test_manifest_describes_the_exported_files(lat_run):
    out, manifest, policy = lat_run["out"], lat_run["manifest"], lat_run["policy"]
    assert json.loads((out / "manifest.json").read_text()) == json.loads(json.dumps(manifest))
    assert set(manifest["models"]) == {"gait_policy_pattern", "gait_policy_step"} | MODEL_FUNCTIONS
    for stem, entry in manifest["models"].items():
        assert (out / entry["onnx"]).is_file() and (out / entry["torchscript"]).is_file()
        assert max(entry["max_abs_error"].values()) <= TOLERANCE, (stem, entry["max_abs_error"])
    joints = len(get_robot(ROBOT).joint_names)
    pattern = manifest["models"]["gait_policy_pattern"]
    assert pattern["inputs"][0]["shape"] == ["B", 2]
    assert pattern["outputs"][0]["shape"] == ["B", policy.policy.steps_per_action, joints]
    assert manifest["models"]["score_goal_reaching"]["inputs"][1]["shape"] == ["B", "S", 1, 2]
    assert manifest["joint_names"] == list(get_robot(ROBOT).joint_names)
    np.testing.assert_allclose(manifest["latent_box"]["low"], policy.latent_low.numpy(), rtol=0, atol=0)
    np.testing.assert_allclose(manifest["latent_box"]["high"], policy.latent_high.numpy(), rtol=0, atol=0)
    np.testing.assert_allclose(manifest["expert_latents"], policy.latents.numpy(), rtol=0, atol=0)
    assert manifest["action"]["kind"] == "latent" and manifest["action"]["dim"] == 2
    assert manifest["robot"] == ROBOT and manifest["cost"]["horizon"] == 1
    assert not list(out.glob("*.tmp*")), "atomic writes leave no temporary files"


def test_gait_policy_agrees_with_pytorch(lat_run):
    policy, box, out = lat_run["policy"].policy, lat_run["manifest"]["latent_box"], lat_run["out"]
    generator = torch.Generator().manual_seed(11)
    for batch in (1, 4, 33):
        latent = _latents(box, generator, batch)
        with torch.no_grad():
            _check_both(out, "gait_policy_pattern", {"latent": latent}, policy.pattern(latent))
        n = torch.randint(1, policy.steps_per_action + 1, (batch, 1), generator=generator)
        phase = n.float() / policy.steps_per_action
        with torch.no_grad():
            _check_both(out, "gait_policy_step", {"phase": phase, "latent": latent}, policy(phase, latent))
    # the per-step function at the N phases of an action is the whole pattern
    latent = _latents(box, generator, 2)
    steps = policy.steps_per_action
    phases = (torch.arange(1, steps + 1).float() / steps)[None, :, None].expand(2, steps, 1).reshape(-1, 1)
    session = _session(out / "gait_policy_step.onnx")
    per_step = session.run(None, {"phase": phases.numpy(),
                                  "latent": latent.repeat_interleave(steps, 0).numpy()})[0]
    whole = _session(out / "gait_policy_pattern.onnx").run(None, {"latent": latent.numpy()})[0]
    np.testing.assert_allclose(per_step.reshape(whole.shape), whole, rtol=0, atol=1e-5)


def test_com_model_agrees_with_pytorch(lat_run):
    model, box, out = lat_run["model"].model, lat_run["manifest"]["latent_box"], lat_run["out"]
    generator = torch.Generator().manual_seed(12)
    for batch, samples in ((1, 1), (5, 64), (2, 8000)):
        state, latent = _states(generator, batch), _latents(box, generator, batch)
        with torch.no_grad():
            _check_both(out, "com_model_predict", {"com_state": state, "action": latent},
                        model.predict(state, latent))
        candidates = _latents(box, generator, batch, samples)
        with torch.no_grad():
            _check_both(out, "planner_model_step", {"com_state": state, "candidates": candidates},
                        model.predict(state[:, None], candidates))


def _planner_costs(model, low_level, task, state, episode, step, candidates, **box):
    """``B x S`` costs of ``B x S x H x A`` candidates as the pipeline's planner scores them (``-reward``)."""
    env = CoMWorldModelEnv(model.model, task=task, action_features=low_level.action_features, **box)
    planner = RandomShootingPlanner(env, planning_horizon=candidates.shape[2], num_candidates=candidates.shape[1])
    td = env.initial_state(com_state=state, episode=episode, step=step)
    return -planner.score(td, candidates)


def test_exported_scoring_is_the_planners_score(lat_run):
    """The same candidates, scored by the exported function of the target and by the planner on the world model."""
    run, box = lat_run, lat_run["manifest"]["latent_box"]
    generator = torch.Generator().manual_seed(13)
    state = _states(generator, 3)
    candidates = _latents(box, generator, 3, 500, 1)
    env_box = {"action_low": box["low"], "action_high": box["high"]}

    goals = GoalReaching(radius=1.5, angle_offset=0.3927)  # the generalisation goals, never seen in training
    episode = torch.tensor([0, 3, 6])
    expected = _planner_costs(run["model"], run["low_level"], goals, state, episode, 0, candidates, **env_box)
    target = goals.goals[episode][:, None, :]  # B x H x 2
    _check_both(run["out"], "score_goal_reaching", {"com_state": state, "candidates": candidates, "target": target},
                expected)

    velocities = VelocityTracking()
    step = torch.tensor([0, 7, 12])  # targets (0, 0.2), (0.2, 0), (0, -0.2) m/s
    expected = _planner_costs(run["model"], run["low_level"], velocities, state, 0, step, candidates, **env_box)
    target = velocities.target(torch.zeros(3, dtype=torch.long), step)[:, None, :]
    _check_both(run["out"], "score_velocity_tracking",
                {"com_state": state, "candidates": candidates, "target": target}, expected)
    # and the best candidate is the planner's choice
    onnx_costs = _session(run["out"] / "score_velocity_tracking.onnx").run(None, {
        "com_state": state.numpy(), "candidates": candidates.numpy(), "target": target.numpy()})[0]
    assert (onnx_costs.argmin(1) == expected.argmin(1).numpy()).all()


# ---------------------------------------------------------------------------------------------------- LIB run
def test_lib_run_exports_only_the_model(lib_run):
    manifest, low_level = lib_run["manifest"], lib_run["low_level"]
    assert set(manifest["models"]) == MODEL_FUNCTIONS
    assert not (lib_run["out"] / "gait_policy_pattern.onnx").exists() and "latent_box" not in manifest
    num_experts = low_level.num_choices
    assert manifest["action"] == {"kind": "expert_replay", "dim": num_experts, "action_low": [0.0],
                                  "action_high": [num_experts - 1.0], "num_choices": num_experts,
                                  "features": "one_hot"}
    assert manifest["models"]["score_goal_reaching"]["inputs"][1]["shape"] == ["B", "S", 2, num_experts]
    for entry in manifest["models"].values():
        assert max(entry["max_abs_error"].values()) <= TOLERANCE


def test_lib_scoring_over_a_horizon_follows_a_moving_reference(lib_run):
    """Horizon 2 on trajectory tracking: the target moves between the two imagined steps."""
    low_level, model = lib_run["low_level"], lib_run["model"]
    generator = torch.Generator().manual_seed(14)
    state = _states(generator, 2)
    index = torch.randint(0, low_level.num_choices, (2, 40, 2, 1), generator=generator).float()  # B x S x H x 1
    task = TrajectoryTracking()
    step = torch.tensor([3, 40])
    expected = _planner_costs(model, low_level, task, state, 0, step, index, num_choices=low_level.num_choices)
    target = torch.stack([task.target(torch.zeros(2, dtype=torch.long), step + h) for h in range(2)], 1)
    one_hot = low_level.action_features(index)  # B x S x H x G
    _check_both(lib_run["out"], "score_goal_reaching", {"com_state": state, "candidates": one_hot, "target": target},
                expected)
    with torch.no_grad():
        _check_both(lib_run["out"], "com_model_predict", {"com_state": state, "action": one_hot[:, 0, 0]},
                    model.model.predict(state, one_hot[:, 0, 0]))


# ---------------------------------------------------------------------------------------------------- refusals
def test_refuses_a_run_directory_without_artifacts(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="no such run directory"):
        export_run(tmp_path / "missing", out)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.csv").write_text("method\nlat\n")
    with pytest.raises(ValueError, match="nothing to export: neither gait_policy.pt nor dynamics_model_normal.pt"):
        export_run(tmp_path / "run", out)
    assert not out.exists(), "nothing written"


def test_names_the_setting_that_exists(lib_run, tmp_path):
    run_dir = tmp_path / "adverse"
    run_dir.mkdir()
    TrainedCoMModel.load(lib_run["run_dir"] / "dynamics_model_normal.pt").save(
        run_dir / "dynamics_model_legs_disabled.pt")
    with pytest.raises(ValueError, match="dynamics_model_legs_disabled.pt: pass that setting"):
        export_run(run_dir, tmp_path / "out")
    for bad, message in [({"horizon": 0}, "horizon"), ({"opset": 7}, "opset"), ({"setting": ""}, "setting")]:
        with pytest.raises(ValueError, match=message):
            export_run(run_dir, tmp_path / "out", **({"setting": "legs_disabled"} | bad))
    assert not (tmp_path / "out").exists()


def test_refuses_corrupted_and_mismatched_artifacts(lat_run, tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "gait_policy.pt").write_bytes((lat_run["run_dir"] / "gait_policy.pt").read_bytes()[:500])
    with pytest.raises(ArtifactError, match="corrupted gait policy checkpoint"):
        export_run(run_dir, tmp_path / "out")
    # a 2-D latent policy beside a model over 3-D actions: not one run
    TrainedGaitPolicy.load(lat_run["run_dir"] / "gait_policy.pt").save(run_dir / "gait_policy.pt")
    rng = np.random.default_rng(0)
    state = rng.normal(size=(50, 5))
    train_com_model(state, rng.uniform(-1, 1, (50, 3)), state + 0.1, hidden=8, max_epochs=1,
                    progress=False).save(run_dir / "dynamics_model_normal.pt")
    with pytest.raises(ArtifactError, match="3-D actions .* 2-D latents"):
        export_run(run_dir, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_command_line_refuses_with_one_line_and_exit_code(tmp_path):
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "hierloco.exporting", str(tmp_path), str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    assert done.stderr.strip() == f"hierloco.exporting: {tmp_path} holds nothing to export: neither gait_policy.pt " \
                                  "nor dynamics_model_normal.pt"
    assert not (tmp_path / "out").exists()
