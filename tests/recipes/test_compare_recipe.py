"""The comparison study: runs the method recipes, then writes the comparison table and bar charts."""

import os
import subprocess
import sys
from pathlib import Path

from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]


def test_compare_tiny(tmp_path):
    out = tmp_path / "compare"
    env = {**os.environ, "WANDB_MODE": "offline"}
    command = [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny", "robots=[a1]",
               "methods=[lat,lib]", "settings=[normal]", f"out_dir={out}", 'overrides=["progress=false"]']
    result = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(out / "comparison.csv")
    assert {r["method"] for r in rows} == {"lat", "lib"}
    table = (out / "comparison.md").read_text()
    assert "| lat | a1 | normal | goal_reaching |" in table and "| lib | a1 | normal | goal_reaching |" in table
    assert (out / "comparison_normal.png").read_bytes()[:4] == b"\x89PNG"
    # each method ran in its own run directory, which a re-run reuses
    assert (tmp_path / "outputs" / "lib" / "tiny" / "a1_seed0" / "results.csv").exists()


def test_compare_refuses_unknown_method(tmp_path):
    command = [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "methods=[magic]",
               f"out_dir={tmp_path}"]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "unknown method" in result.stderr
