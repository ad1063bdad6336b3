"""The LAT recipe end to end with the tiny preset: outputs, cached stages, refusals (``docs/index.md``, Runs and
artifacts)."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TRAIN = ROOT / "recipes" / "lat" / "train.py"
COLUMNS = ["method", "robot", "setting", "task", "seed", "normalized_cost", "success_rate", "final_error"]


def run(*overrides, timeout=600):
    env = {**os.environ, "WANDB_MODE": "offline", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run([sys.executable, str(TRAIN), "preset=tiny", "progress=false", *overrides], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("lat") / "run"
    result = run(f"run_dir={run_dir}", "settings=[normal,legs_disabled]")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return run_dir, result


def test_outputs(tiny_run):
    run_dir, result = tiny_run
    with open(run_dir / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == COLUMNS
    tasks = {"velocity_tracking", "goal_reaching", "trajectory_tracking", "goal_reaching_1.5m", "goal_reaching_3m",
             "velocity_tracking_diagonal"}
    assert {(r["setting"], r["task"]) for r in rows} == {(s, t) for s in ("normal", "legs_disabled") for t in tasks}
    assert all(r["method"] == "lat" and r["robot"] == "a1" and float(r["normalized_cost"]) >= 0 for r in rows)
    assert "| lat | a1 | normal | goal_reaching |" in (run_dir / "results.md").read_text()
    assert "normalized cost" in result.stdout  # the table is printed
    figures = {p.name for p in (run_dir / "figures").iterdir()}
    assert {"normal_goal_reaching_paths.png", "normal_gait_during_goal_reaching.png",
            "normal_trajectory_tracking_paths.png", "legs_disabled_velocity_tracking_velocity.png",
            "latent_map.png"} <= figures  # the tiny preset's latent space is 2-D
    assert (run_dir / "videos" / "normal_goal_reaching.mp4").stat().st_size > 1000
    report = json.loads((run_dir / "report.json").read_text())
    assert len(report["dynamics_model_normal"]["heldout_rmse"]) == 5
    assert list((run_dir / "logs").rglob("*.csv")), "the CSV logger wrote metrics"


def test_rerun_reuses_every_stage(tiny_run):
    run_dir, _ = tiny_run
    before = {p.name: p.stat().st_mtime_ns for p in run_dir.glob("*.npz")}
    result = run(f"run_dir={run_dir}", "settings=[normal,legs_disabled]")
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((run_dir / "report.json").read_text())
    assert all(report["reused_stages"].values()), report["reused_stages"]
    assert before == {p.name: p.stat().st_mtime_ns for p in run_dir.glob("*.npz")}


def test_another_config_is_refused_without_overwriting(tiny_run):
    run_dir, _ = tiny_run
    experts = (run_dir / "experts.npz").read_bytes()
    result = run(f"run_dir={run_dir}", "experts.num_experts=5")
    assert result.returncode != 0
    assert "another config" in result.stderr and "num_experts" in result.stderr
    assert (run_dir / "experts.npz").read_bytes() == experts


def test_corrupted_artifact_is_named(tiny_run, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(tiny_run[0], copy)
    policy = copy / "gait_policy.pt"
    policy.write_bytes(policy.read_bytes()[:500])
    result = run(f"run_dir={copy}")
    assert result.returncode != 0 and "corrupted" in result.stderr and "gait_policy.pt" in result.stderr


@pytest.mark.parametrize("override, message", [("robot=spot", "unknown robot"),
                                               ("planner.name=magic", "unknown planner"),
                                               ("dynamics.num_transitions=-5", "num_transitions"),
                                               ("settings=[broken]", "unknown setting")])
def test_bad_config_is_refused_before_any_work(tmp_path, override, message):
    run_dir = tmp_path / "never"
    result = run(f"run_dir={run_dir}", override)
    assert result.returncode != 0 and message in result.stderr
    assert not run_dir.exists()


def test_same_seed_same_numbers(tiny_run, tmp_path):
    """A second run with the same config in a fresh directory reproduces every number."""
    run_dir, _ = tiny_run
    again = tmp_path / "again"
    result = run(f"run_dir={again}", "settings=[normal,legs_disabled]")
    assert result.returncode == 0, result.stderr[-3000:]
    assert (again / "episodes.csv").read_text() == (run_dir / "episodes.csv").read_text()
    assert (again / "experts.npz").read_bytes() == (run_dir / "experts.npz").read_bytes()
