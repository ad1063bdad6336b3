"""Bad inputs and hostile environments (the reliability issue's cases 11-15, 17, 18): one line (``error: ...``, exit
2) before any work, or a warning after the results are safe; never a traceback, never a wrong table."""

import errno
import json
import os
import time
from pathlib import Path

import pytest

from hierloco.io import load_arrays, save_arrays
from tests.runner import run_in_process, run_subprocess, snapshot


def test_a_tracker_that_cannot_start_costs_a_warning_not_the_run(copy_run, tmp_path):
    """Case 11: wandb with a home it cannot write: the run finishes (exit 0) with the results, and says so."""
    result = run_subprocess("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}",
                            "logger.backends=[csv,wandb]", cwd=tmp_path,
                            env={"HOME": "/dev/null/home", "WANDB_DIR": "/dev/null/wandb",
                                 "WANDB_CONFIG_DIR": "/dev/null/config", "WANDB_CACHE_DIR": "/dev/null/cache"})
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Traceback" not in result.stderr
    assert (copy_run / "results.csv").is_file()


@pytest.mark.parametrize("backend, code, said", [
    ("foo", 2, "MUJOCO_GL='foo' is not a rendering backend"),
    ("glfw", 0, None),
    ("disable", 0, None),
])
def test_the_rendering_backend_is_chosen_safely(copy_run, tmp_path, backend, code, said):
    """Case 12: an invalid ``MUJOCO_GL`` is one line before any work; a backend that cannot render here (glfw with
    no display, or none) turns videos off with one line and the run finishes with its results."""
    (copy_run / "videos" / "normal_goal_reaching.mp4").unlink(missing_ok=True)
    before = snapshot(copy_run)
    result = run_subprocess("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "planner.name=cem",
                            cwd=tmp_path, env={"MUJOCO_GL": backend, "DISPLAY": ""})
    assert result.returncode == code, result.stderr[-3000:]
    assert "Traceback" not in result.stderr
    if said is not None:
        assert result.stderr.strip().splitlines() == [f"error: {said} (choose from egl, osmesa, glfw, disable)"]
        assert snapshot(copy_run) == before
    else:
        warnings = json.loads((copy_run / "report.json").read_text())["warnings"]
        assert any(w.startswith("no video of normal/goal_reaching") for w in warnings)
        assert not (copy_run / "videos" / "normal_goal_reaching.mp4").exists()


def test_bad_thread_variables_are_refused_before_any_work(tmp_path):
    """Case 13: ``OMP_NUM_THREADS=abc`` is one line, and no stage is written."""
    result = run_in_process("lat", "preset=tiny", f"run_dir={tmp_path / 'run'}", env={"OMP_NUM_THREADS": "abc"})
    assert result.returncode == 2 and result.lines == [
        "error: OMP_NUM_THREADS='abc' must be a whole number of threads >= 1 (or unset)"]
    assert not (tmp_path / "run").exists()


def test_a_full_disk_is_one_line_and_the_run_resumes_identically(tiny_lat_run, tmp_path, monkeypatch):
    """Case 14: no space left while a stage is saved: one line (exit 2); the same command then resumes and gives
    the same results as a run that never stopped."""
    from hierloco.components.dynamics_data import TransitionData

    run_dir = tmp_path / "run"
    original = TransitionData.save

    def full(self, path):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(TransitionData, "save", full)
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={run_dir}")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert result.lines[0].startswith("error: no space left on the device writing ")
    assert "run the same command again to resume" in result.lines[0]
    monkeypatch.setattr(TransitionData, "save", original)
    assert run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={run_dir}").returncode == 0
    assert (run_dir / "episodes.csv").read_bytes() == (tiny_lat_run / "episodes.csv").read_bytes()


def test_broken_artifacts_and_configs_are_one_line(copy_run, tmp_path):
    """Case 15: an extra array in the experts, a gait policy with weights of another shape, an evaluation without
    its summary cost, an unparsable ``config.yaml`` for evaluate.py: one line each naming the file."""
    import torch

    def one_line(script, *args):
        result = run_in_process(script, *args)
        assert result.returncode == 2 and len(result.lines) == 1, result.stderr
        return result.lines[0]

    experts = copy_run / "experts.npz"
    arrays, meta = load_arrays(experts)
    kept = experts.read_bytes()
    save_arrays(experts, {**arrays, "extra": arrays["commands"]}, meta)
    assert "unexpected arrays ['extra']" in one_line("lat", "preset=tiny", f"run_dir={copy_run}")
    experts.write_bytes(kept)

    policy = copy_run / "gait_policy.pt"
    kept = policy.read_bytes()
    payload = torch.load(policy, weights_only=True)
    key = next(k for k in payload["state_dict"] if k.endswith("weight"))
    payload["state_dict"][key] = payload["state_dict"][key][:, :-1]
    torch.save(payload, policy)
    line = one_line("lat", "preset=tiny", f"run_dir={copy_run}")
    assert f"corrupted gait policy checkpoint {policy}" in line
    policy.write_bytes(kept)

    evaluation = next((copy_run / "evaluation" / "normal").glob("velocity_tracking-*.npz"))
    arrays, meta = load_arrays(evaluation)
    kept = evaluation.read_bytes()
    del meta["metrics"]["normalized_cost"]
    save_arrays(evaluation, arrays, meta)
    assert "summary normalised cost is None" in one_line("lat", "preset=tiny", f"run_dir={copy_run}")
    evaluation.write_bytes(kept)

    (copy_run / "config.yaml").write_text("eval: [unclosed\n")
    assert "config.yaml" in one_line("evaluate.py", f"run_dir={copy_run}", "planner.name=cem")


def test_a_budget_that_cannot_end_is_refused_before_any_work(tmp_path):
    """Case 17: a billion dynamics transitions is refused, with the estimate and the way to confirm it."""
    result = run_in_process("lat", "preset=tiny", f"run_dir={tmp_path / 'run'}", "dynamics.num_transitions=1000000000")
    assert result.returncode == 2 and len(result.lines) == 1
    assert "add +confirm_long=true to run it anyway" in result.lines[0]
    assert not (tmp_path / "run").exists()


def test_a_ray_address_that_does_not_answer_is_one_line_within_seconds(tmp_path):
    """Case 18: ``RAY_ADDRESS=127.0.0.1:1``: one line, exit 2, well within 30 s; nothing runs."""
    start = time.perf_counter()
    result = run_subprocess("compare", "preset=tiny", "methods=[lib]", "robots=[a1]", "seeds=[0]",
                            f"out_dir={tmp_path / 'out'}", cwd=tmp_path, env={"RAY_ADDRESS": "127.0.0.1:1"},
                            timeout=120)
    assert time.perf_counter() - start < 30
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        "error: cannot reach a Ray cluster at 127.0.0.1:1 (Connection refused): start it, or leave ray.address and "
        "RAY_ADDRESS unset for a local instance"], result.stderr
    assert not (tmp_path / "outputs").exists()


@pytest.mark.parametrize("recipe", ["lat", "ik"])
@pytest.mark.parametrize("change, said", [
    ({"standing_pose": [0.0, 2.4, -2.7]}, "the feet are only 0.054 m below their hips"),  # a folded 'home' pose
    ({"torque_limit": 15.0}, "121% of its 15.0 N m limit"),                            # motors too weak for it
])
def test_a_robot_that_cannot_walk_is_a_finding_in_seconds(tmp_path, recipe, change, said):
    """Case 16: a robot whose description cannot stand is refused at the first stage that would simulate it, in
    seconds, as a finding (``failed.json``: a study reports it and does not run it again); not minutes of leg IK
    or a traceback after the experts."""
    from tests.envs.test_robot_check import _yaml_copy

    robot = _yaml_copy(tmp_path, **change)
    start = time.perf_counter()
    result = run_in_process(recipe, "preset=tiny", f"robot={robot}", f"run_dir={tmp_path / 'run'}")
    assert time.perf_counter() - start < 30  # most of it: the recipe's import and the config check
    assert result.returncode == 2 and len(result.lines) == 1 and said in result.lines[0], result.stderr
    failure = json.loads((tmp_path / "run" / "failed.json").read_text())
    assert failure["stage"] == ("experts" if recipe == "lat" else "dynamics_data_normal") and said in failure["error"]
