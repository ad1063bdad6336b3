"""Helpers of the study recipes (compare, ablations): run a method's recipe as its own process, in its own cached
run directory, and read back its per-episode results."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Sequence

from hierloco.results import read_csv

RECIPES = Path(__file__).resolve().parents[1]
METHODS = tuple(sorted(p.name for p in RECIPES.iterdir() if (p / "train.py").exists()))


def run_recipe(method: str, run_dir: str | Path, overrides: Sequence[str]) -> list[dict]:
    """Runs ``recipes/<method>/train.py`` with ``overrides`` into ``run_dir`` (finished stages are reused) and
    returns the rows of its ``episodes.csv``; raises if the run fails."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r} (recipes: {', '.join(METHODS)})")
    command = [sys.executable, str(RECIPES / method / "train.py"), f"run_dir={run_dir}", *overrides]
    print(f"\n=== {method}: {' '.join(command[2:])}", flush=True)
    result = subprocess.run(command)
    if result.returncode != 0:
        raise RuntimeError(f"{method} run into {run_dir} failed with exit code {result.returncode}")
    return read_csv(Path(run_dir) / "episodes.csv")
