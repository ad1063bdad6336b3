"""The navigation study end to end on tiny settings: a LAT job per robot and seed evaluating every arena (the boxes
in its world), its record, the tables and the arena figure; a bad config refused in one line before any work."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "recipes" / "navigation" / "run.py"


def run(*arguments, timeout=900):
    return subprocess.run([sys.executable, str(SCRIPT), *arguments], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "WANDB_MODE": "offline"}, timeout=timeout)


@pytest.mark.slow  # a tiny LAT run through Ray (~40 s)
def test_navigation_study_tiny(tmp_path):
    out, records = tmp_path / "out", tmp_path / "records"
    arguments = ["preset=tiny", "robots=[a1]", "seeds=[0]", "arenas=[0,1]", "num_obstacles=4", "speed=1.0",
                 "extra_steps=1", "overrides=['planner.num_candidates=200']", f"runs_dir={tmp_path / 'runs'}",
                 f"records={records}", "lat_runs=null", f"out_dir={out}", "videos=[]"]
    result = run(*arguments)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = list(csv.DictReader((out / "navigation.csv").open()))
    assert [(r["robot"], r["arena"]) for r in rows] == [("a1", "0"), ("a1", "1")]
    for row in rows:
        assert float(row["path_length"]) >= 5.0 - 1e-6  # at least the straight line from (0, 0) to (3, 4)
        assert float(row["inflation"]) > 0.3 and 0 <= float(row["normalized_cost"]) <= 1.5
        assert float(row["clearance"]) > -0.5  # the boxes are solid: the CoM never goes deep into one
    assert "| a1 | all |" in (out / "navigation.md").read_text()
    assert (out / "a1_arena0.png").read_bytes()[:4] == b"\x89PNG"
    assert len(list(records.rglob("record.json"))) == 1
    again = run(*arguments)  # the job comes back from its run directory: nothing trained or evaluated again
    assert again.returncode == 0 and "1 reused from their run directories" in again.stdout


def test_a_bad_navigation_config_is_one_line_before_any_work(tmp_path):
    result = run("robots=[a1]", "arenas=[0,-1]", "inflation=5.0", f"runs_dir={tmp_path / 'runs'}", timeout=120)
    assert result.returncode == 2 and result.stdout.count("error:") + result.stderr.count("error:") == 1
    assert "arena -1 is not an integer >= 0" in result.stdout + result.stderr
    assert not (tmp_path / "runs").exists()
