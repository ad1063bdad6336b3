"""The navigation study end to end on tiny settings: a LAT run, an arena, a planned path, tracking, outputs."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # a study through Ray (~40 s)
def test_navigation_tiny(tmp_path):
    out = tmp_path / "nav"
    command = [sys.executable, str(ROOT / "recipes" / "navigation" / "run.py"), "lat_preset=tiny", "progress=false",
               f"lat_run_dir={tmp_path / 'lat'}", f"out_dir={out}", "arena.num_obstacles=4", "speed=1.0",
               "extra_steps=1", "planner.num_candidates=200"]
    result = subprocess.run(command, cwd=ROOT, env={**os.environ, "WANDB_MODE": "offline"}, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    report = json.loads((out / "navigation.json").read_text())
    assert report["num_obstacles"] == 4 and report["min_planned_clearance"] >= 0.3
    assert report["path_length"] >= 5.0 - 1e-6  # at least the straight line from (0, 0) to (3, 4)
    assert (out / "navigation.png").read_bytes()[:4] == b"\x89PNG" and (out / "navigation.mp4").stat().st_size > 0
