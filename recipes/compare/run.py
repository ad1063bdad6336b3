"""Compare methods: run every method's recipe on every robot and seed, then tabulate and plot (SPEC 8).

    python recipes/compare/run.py                           # LAT, LIB, IK on A1 and Daisy, paper scale
    python recipes/compare/run.py robots=[a1] seeds=[0,1,2] preset=small

Each method runs as its own recipe in its own run directory (``outputs/<method>/<preset>/<robot>_seed<seed>``), so
finished runs are reused. Writes ``comparison.csv``, ``comparison.md`` and ``comparison_<setting>.png`` in
``out_dir``.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from omegaconf import DictConfig

from recipes.common import studies  # noqa: E402
from hierloco.envs.robots import ROBOTS  # noqa: E402
from hierloco.io import write_text  # noqa: E402
from hierloco.plots import plot_comparison  # noqa: E402
from hierloco.results import EPISODE_COLUMNS, csv_text, markdown_table  # noqa: E402


def validate(cfg: DictConfig) -> None:
    problems = [f"unknown method {m!r} (recipes: {', '.join(studies.METHODS)})" for m in cfg.methods
                if m not in studies.METHODS]
    problems += [f"unknown robot {r!r} (registered: {sorted(ROBOTS)})" for r in cfg.robots if r not in ROBOTS]
    problems += [f"unknown setting {s!r}" for s in cfg.settings if s not in ("normal", "legs_disabled")]
    if not cfg.seeds:
        problems.append("seeds is empty")
    if problems:
        raise ValueError("bad config:\n  " + "\n  ".join(problems))


def run_method(cfg, method: str, robot: str, seed: int) -> list[dict]:
    settings = [s for s in cfg.settings if s == "normal" or method in cfg.adverse_methods]
    run_dir = Path("outputs") / method / cfg.preset / f"{robot}_seed{seed}"
    return studies.run_recipe(method, run_dir, [f"preset={cfg.preset}", f"robot={robot}", f"seed={seed}",
                                                f"settings=[{','.join(settings)}]", *cfg.overrides])


@hydra.main(config_path=".", config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    validate(cfg)
    rows = []
    for robot in cfg.robots:
        for method in cfg.methods:
            for seed in cfg.seeds:
                rows += run_method(cfg, method, robot, seed)
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
