"""The LIB, IK and SAC recipes end to end with the tiny preset: they run every stage and write the shared results."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ["method", "robot", "setting", "task", "seed", "normalized_cost", "success_rate", "final_error"]


def run(method, *overrides):
    env = {**os.environ, "WANDB_MODE": "offline"}
    return subprocess.run([sys.executable, str(ROOT / "recipes" / method / "train.py"), "preset=tiny",
                           "progress=false", *overrides], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("method, settings", [("lib", "[normal]"), ("ik", "[normal,legs_disabled]"),
                                              ("sac", "[normal]"), ("sac_sac", "[normal]")])
def test_baseline_recipe_runs(method, settings, tmp_path):
    result = run(method, f"run_dir={tmp_path}", f"settings={settings}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    with open(tmp_path / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == COLUMNS
    expected = {(s, t) for s in settings.strip("[]").split(",")
                for t in ("velocity_tracking", "goal_reaching", "trajectory_tracking")}
    assert expected <= {(r["setting"], r["task"]) for r in rows}  # (SAC's tiny preset adds generalisation tasks)
    assert all(r["method"] == method for r in rows)
    assert (tmp_path / "figures" / "normal_goal_reaching_paths.png").exists()
    if method == "sac_sac":  # the SAC low level, reported on its own
        import json

        tracking = json.loads((tmp_path / "sac_low_level_tracking.json").read_text())
        assert len(tracking["rows"]) == 27 and "fall_rate" in tracking["summary"]
        assert (tmp_path / "videos" / "sac_low_level_walking.mp4").stat().st_size > 1000
        assert (tmp_path / "sac_low_level.pt").exists() and not (tmp_path / "sac_low_level.training.pt").exists()
        report = (tmp_path / "sac_low_level_report.md").read_text()  # its curve, the budget, tracking per command
        assert "## Learning curve" in report and "frames" in report.split("\n")[2]
        assert sum(line.startswith("| (") for line in report.splitlines()) == 27
        # the table says how the low level acted: the recipe's default, samples of its policy
        assert "the tracking table acts with samples of the policy" in report
        assert "## Tracking per command (stochastic actor)" in report and "deterministic" not in report
        again = subprocess.run([sys.executable, str(ROOT / "recipes" / "sac_sac" / "report.py"), str(tmp_path),
                                str(tmp_path / "report")], capture_output=True, text=True, timeout=120)
        assert again.returncode == 0, again.stderr[-2000:]
        assert (tmp_path / "report" / "report.md").read_text() == report
        assert (tmp_path / "report" / "learning_curve.png").read_bytes()[:4] == b"\x89PNG"
    if method in ("sac", "sac_sac"):  # one SAC agent per task, trained on half the targets
        assert {p.name for p in tmp_path.glob("sac_*.pt") if "low_level" not in p.name} == {f"sac_{t}.pt" for t in
                                                              ("velocity_tracking", "goal_reaching",
                                                               "trajectory_tracking")}
    else:
        data = (tmp_path / "dynamics_data_normal.npz.key.json").read_text()
        assert ('"kind": "expert_replay"' in data) if method == "lib" else ('"kind": "command"' in data)


def test_lib_refuses_a_continuous_planner(tmp_path):
    result = run("lib", f"run_dir={tmp_path / 'x'}", "planner.name=random_shooting")
    assert result.returncode == 2 and "unknown planner" in result.stderr


def test_sac_trains_on_half_the_targets_on_both_axes():
    from hierloco.envs.tasks import GoalReaching, TrajectoryTracking, VelocityTracking

    goals = GoalReaching().training_split()
    assert np.allclose(goals.goals, GoalReaching().goals[::2], atol=1e-6) and goals.num_steps == 30
    velocity = VelocityTracking().training_split()
    assert np.allclose(velocity.velocities.numpy(), [[0.0, 0.2], [0.2, 0.0]]) and velocity.num_steps == 40
    path = TrajectoryTracking().training_split()
    assert abs(path.length - TrajectoryTracking().length / 2) < 0.05 and np.allclose(path.path[-1], [2.0, 0.0])
