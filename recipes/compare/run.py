"""Compare methods: run every method's recipe on every robot and seed, then tabulate and plot (SPEC 8).

    python recipes/compare/run.py                           # LAT, LIB, IK on A1 and Daisy, paper scale
    python recipes/compare/run.py robots=[a1] seeds=[0,1,2] preset=small

Each method runs as its own recipe in its own run directory (``outputs/<method>/<preset>/<robot>_seed<seed>``), so
finished runs are reused. Writes ``comparison.csv``, ``comparison.md`` and ``comparison_<setting>.png`` in
``out_dir``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

from hierloco.envs.robots import ROBOTS
from hierloco.io import write_text
from hierloco.plots import plot_comparison
from hierloco.results import EPISODE_COLUMNS, csv_text, markdown_table, read_csv

RECIPES = Path(__file__).resolve().parents[1]


def validate(cfg: DictConfig) -> None:
    problems = [f"unknown method {m!r} (recipes: lat, lib, ik)" for m in cfg.methods
                if not (RECIPES / m / "train.py").exists() or m in ("compare", "common")]
    problems += [f"unknown robot {r!r} (registered: {sorted(ROBOTS)})" for r in cfg.robots if r not in ROBOTS]
    problems += [f"unknown setting {s!r}" for s in cfg.settings if s not in ("normal", "legs_disabled")]
    if not cfg.seeds:
        problems.append("seeds is empty")
    if problems:
        raise ValueError("bad config:\n  " + "\n  ".join(problems))


def run_method(cfg, method: str, robot: str, seed: int) -> Path:
    settings = [s for s in cfg.settings if s == "normal" or method in cfg.adverse_methods]
    run_dir = Path("outputs") / method / cfg.preset / f"{robot}_seed{seed}"
    command = [sys.executable, str(RECIPES / method / "train.py"), f"preset={cfg.preset}", f"robot={robot}",
               f"seed={seed}", f"settings=[{','.join(settings)}]", f"run_dir={run_dir}", *cfg.overrides]
    print(f"\n=== {method} on {robot}, seed {seed}: {' '.join(command[1:])}", flush=True)
    result = subprocess.run(command)
    if result.returncode != 0:
        raise RuntimeError(f"{method} on {robot} (seed {seed}) failed with exit code {result.returncode}")
    return run_dir


@hydra.main(config_path=".", config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    validate(cfg)
    rows = []
    for robot in cfg.robots:
        for method in cfg.methods:
            for seed in cfg.seeds:
                rows += read_csv(run_method(cfg, method, robot, seed) / "episodes.csv")
    out = Path(cfg.out_dir)
    table = markdown_table(rows)
    write_text(out / "comparison.csv", csv_text(rows, EPISODE_COLUMNS))
    write_text(out / "comparison.md", "# Comparison\n\nNormalised cost, mean +- std over targets and seeds.\n\n" + table)
    for setting in cfg.settings:
        if any(r["setting"] == setting for r in rows):
            plot_comparison(rows, out / f"comparison_{setting}.png", setting=setting,
                            title=f"Normalised cost ({cfg.preset} preset, {len(cfg.seeds)} seed(s))")
    print("\n" + table)
    print(f"comparison table and figures in {out}/")


if __name__ == "__main__":
    main()
