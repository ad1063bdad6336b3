"""Hydra launchers and sweepers for single recipes are installed (pinned) and compose with every recipe's config."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("override, target", [
    ("hydra/launcher=joblib", "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher"),
    pytest.param("hydra/launcher=submitit_slurm",
                 "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher", marks=pytest.mark.slow),
    pytest.param("hydra/sweeper=optuna", "hydra_plugins.hydra_optuna_sweeper.optuna_sweeper.OptunaSweeper",
                 marks=pytest.mark.slow),
])
def test_a_launcher_composes_with_the_recipe(override, target):
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "lat" / "train.py"), override, "--cfg", "hydra"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert target in result.stdout
