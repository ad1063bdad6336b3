"""The ablation study: LAT trials per value of a varied setting, tabulated and plotted."""

import os
import subprocess
import sys
from pathlib import Path

from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]


def test_ablation_tiny(tmp_path):
    out = tmp_path / "ablations"
    command = [sys.executable, str(ROOT / "recipes" / "ablations" / "run.py"), "preset=tiny", "robot=a1", "trials=1",
               "run=[latent_dim]", "ablations.latent_dim.values=[2,3]", f"out_dir={out}",
               'overrides=["progress=false", "eval.generalization=null", "eval.videos=[]"]']
    result = subprocess.run(command, cwd=ROOT, env={**os.environ, "WANDB_MODE": "offline"}, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(out / "ablations.csv")
    assert {r["method"] for r in rows} == {"latent_dim=2", "latent_dim=3"}
    assert (out / "ablations.png").read_bytes()[:4] == b"\x89PNG"
    # each trial is a LAT run with the value applied
    assert "latent_dim: 3" in (out / "latent_dim_3" / "seed0" / "config.yaml").read_text()


def test_unknown_ablation_is_refused(tmp_path):
    command = [sys.executable, str(ROOT / "recipes" / "ablations" / "run.py"), "run=[magic]", f"out_dir={tmp_path}"]
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "unknown ablation" in result.stderr
