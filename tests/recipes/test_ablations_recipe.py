"""The ablation study: LAT trials per value of a varied setting, tabulated and plotted."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # a study through Ray (~50 s)
def test_ablation_tiny(tmp_path):
    out, runs = tmp_path / "ablations", tmp_path / "runs"
    command = [sys.executable, str(ROOT / "recipes" / "ablations" / "run.py"), "preset=tiny", "robot=a1", "trials=1",
               "run=[latent_dim,dynamics_samples]", "ablations.latent_dim.values=[3,2]",
               "ablations.dynamics_samples.values=[100,500]", f"out_dir={out}", f"runs_dir={runs}",
               'overrides=["progress=false", "eval.generalization=null", "eval.videos=[]"]']
    result = subprocess.run(command, cwd=ROOT, env={**os.environ, "WANDB_MODE": "offline"}, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(out / "ablations.csv")
    assert {r["method"] for r in rows} == {"latent_dim=2", "latent_dim=3", "dynamics_samples=100",
                                           "dynamics_samples=500"}
    assert (out / "ablations.png").read_bytes()[:4] == b"\x89PNG"
    # the paper's claims, checked where the study measured them (latent dimension 2 and 3 only here)
    check = (out / "paper_check.md").read_text()
    assert "| latent dimension 2, 3, 4: no significant effect | a1 | normal | goal_reaching | 2: " in check
    assert "| 30 experts better than 10 | a1 | normal | goal_reaching | - |" in check and "| not measured |" in check
    # each trial is a LAT run with the value applied
    assert "latent_dim: 3" in (runs / "latent_dim_3" / "seed0" / "config.yaml").read_text()
    # the tiny preset's own values (latent dimension 2, 500 samples) are one run that both ablations share
    assert "study: 3 jobs" in result.stdout, result.stdout[-2000:]
    costs = lambda method: [r["normalized_cost"] for r in rows if r["method"] == method]  # noqa: E731
    assert costs("latent_dim=2") == costs("dynamics_samples=500") and costs("latent_dim=2")
    # every trial's rows are its own run's episodes, also for a first value that is not the default (its trial's
    # default run is planned while the trial is: the rows must not be the default run's)
    own = lambda run: [r["normalized_cost"] for r in read_csv(runs / run / "seed0" / "episodes.csv")]  # noqa: E731
    assert costs("latent_dim=3") == own("latent_dim_3") != own("default")
    assert costs("dynamics_samples=100") == own("dynamics_samples_100")
    # a dynamics-sample trial waits for its trial's default run and starts from its low level: only the dynamics
    # differ (the copied stage keeps what building it took, for the wall-clock table)
    default, fewer = runs / "default" / "seed0", runs / "dynamics_samples_100" / "seed0"
    assert (fewer / "gait_policy.pt").read_bytes() == (default / "gait_policy.pt").read_bytes()
    builds = json.loads((fewer / "builds.json").read_text())
    assert builds["gait_policy"]["copied_from"] == str(default.resolve()) and "dynamics_data_normal" in builds
    assert "copied_from" not in builds["dynamics_data_normal"]
    assert "| dynamics_samples=100 | a1 | 1 |" in (out / "wallclock.md").read_text()  # compute per value and robot
    # the tables written elsewhere (results/...) reuse every finished trial
    elsewhere = subprocess.run([c for c in command if not c.startswith("out_dir=")] + [
        f"out_dir={tmp_path / 'elsewhere'}"], cwd=ROOT, env={**os.environ, "WANDB_MODE": "offline"},
        capture_output=True, text=True, timeout=600)
    assert elsewhere.returncode == 0 and "study: 3 jobs, 3 reused" in elsewhere.stdout, elsewhere.stdout[-2000:]
    assert (tmp_path / "elsewhere" / "ablations.csv").read_text() == (out / "ablations.csv").read_text()


def test_unknown_ablation_is_refused(tmp_path):
    command = [sys.executable, str(ROOT / "recipes" / "ablations" / "run.py"), "run=[magic]", f"out_dir={tmp_path}"]
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "unknown ablation" in result.stderr


def test_a_missing_causes_file_is_refused_before_any_run(tmp_path):
    command = [sys.executable, str(ROOT / "recipes" / "ablations" / "run.py"), f"causes={tmp_path / 'nope.yaml'}",
               f"out_dir={tmp_path / 'out'}", f"runs_dir={tmp_path / 'runs'}"]
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "causes: no file" in result.stderr
    assert not (tmp_path / "runs").exists() and not (tmp_path / "out").exists()
