"""The LIB and IK recipes end to end with the tiny preset: they run every stage and write the shared results."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ["method", "robot", "setting", "task", "seed", "normalized_cost", "success_rate", "final_error"]


def run(method, *overrides):
    env = {**os.environ, "WANDB_MODE": "offline"}
    return subprocess.run([sys.executable, str(ROOT / "recipes" / method / "train.py"), "preset=tiny",
                           "progress=false", *overrides], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("method, settings", [("lib", "[normal]"), ("ik", "[normal,legs_disabled]")])
def test_baseline_recipe_runs(method, settings, tmp_path):
    result = run(method, f"run_dir={tmp_path}", f"settings={settings}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    with open(tmp_path / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == COLUMNS
    expected = {(s, t) for s in settings.strip("[]").split(",")
                for t in ("velocity_tracking", "goal_reaching", "trajectory_tracking")}
    assert {(r["setting"], r["task"]) for r in rows} == expected
    assert all(r["method"] == method for r in rows)
    assert (tmp_path / "figures" / "normal_goal_reaching_paths.png").exists()
    data = (tmp_path / "dynamics_data_normal.config.json").read_text()
    assert ("experts" in data) if method == "lib" else ("controller" in data)


def test_lib_refuses_a_continuous_planner(tmp_path):
    result = run("lib", f"run_dir={tmp_path / 'x'}", "planner.name=random_shooting")
    assert result.returncode != 0 and "unknown planner" in result.stderr
