"""A machine without OpenGL (``MUJOCO_GL=disable``, as on a bare GPU server with no EGL): ``hierloco``, MuJoCo and
dm_control import, and a LAT run trains from nothing and finishes with its results, videos off with one warning
(``hierloco.render_backend``, ``docs/gpu.md``)."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.runner import ROOT, run_subprocess


def test_hierloco_and_mujoco_import_without_rendering():
    code = ("import hierloco, os, mujoco, dm_control.mujoco; from hierloco import render_backend; "
            "print(os.environ['MUJOCO_GL'], render_backend.unavailable())")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT), "MUJOCO_GL": "disable"})
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["disable", "MUJOCO_GL=disable"]


def test_a_lat_run_trains_and_finishes_without_rendering(tmp_path):
    run_dir = tmp_path / "run"
    result = run_subprocess(
        "lat", "preset=tiny", f"run_dir={run_dir}", "progress=false", "device=auto", "experts.num_experts=4",
        "policy.epochs=20", "dynamics.num_transitions=60", "dynamics.num_robots=20", "dynamics.max_epochs=5",
        "eval.generalization=null", "~eval.tasks.velocity_tracking", "~eval.tasks.trajectory_tracking",
        "+eval.tasks.goal_reaching.num_goals=2", "eval.tasks.goal_reaching.num_steps=2",
        "planner.num_candidates=100", "eval.videos=[goal_reaching]", "logger.backends=[csv]",
        cwd=tmp_path, env={"MUJOCO_GL": "disable"})
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Traceback" not in result.stderr
    assert (run_dir / "results.csv").is_file() and not (run_dir / "videos" / "normal_goal_reaching.mp4").exists()
    warnings = json.loads((run_dir / "report.json").read_text())["warnings"]
    assert any(w.startswith("no video of normal/goal_reaching") for w in warnings)
    keys = json.loads((run_dir / "gait_policy.pt.key.json").read_text())
    assert keys["params"]["device"] in ("cpu", "cuda")  # auto, resolved
