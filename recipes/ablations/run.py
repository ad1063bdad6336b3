"""LAT ablations: vary one setting at a time (latent dimension, number of experts, dynamics samples) over several
trials, then tabulate and plot (SPEC 8, the paper's ablation figure).

    python recipes/ablations/run.py                    # Daisy, paper scale, 10 trials per value
    python recipes/ablations/run.py trials=3 preset=small robot=a1 run=[latent_dim]

Every trial is a LAT run in ``out_dir/<ablation>_<value>/seed<trial>`` (finished runs are reused). Writes
``ablations.csv``, ``ablations.md`` and ``ablations.png`` in ``out_dir``.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from omegaconf import DictConfig

from recipes.common import studies  # noqa: E402
from hierloco.envs.robots import ROBOTS  # noqa: E402
from hierloco.io import write_text  # noqa: E402
from hierloco.plots import plot_ablations  # noqa: E402
from hierloco.results import EPISODE_COLUMNS, csv_text, markdown_table  # noqa: E402


def validate(cfg: DictConfig) -> None:
    problems = [] if cfg.robot in ROBOTS else [f"unknown robot {cfg.robot!r} (registered: {sorted(ROBOTS)})"]
    if not (isinstance(cfg.trials, int) and cfg.trials >= 1):
        problems.append(f"trials must be a positive integer, got {cfg.trials!r}")
    for name, spec in cfg.ablations.items():
        if "key" not in spec or not spec.get("values"):
            problems.append(f"ablation {name!r} needs a key and a list of values")
    problems += [f"unknown ablation {name!r} in run (ablations: {sorted(cfg.ablations)})" for name in cfg.run
                 if name not in cfg.ablations]
    if problems:
        raise ValueError("bad config:\n  " + "\n  ".join(problems))


@hydra.main(config_path=".", config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    validate(cfg)
    out = Path(cfg.out_dir)
    results, rows = {}, []
    for name in cfg.run:
        spec = cfg.ablations[name]
        results[name] = {}
        for value in spec["values"]:
            trial_rows = []
            for trial in range(cfg.trials):
                run_dir = out / f"{name}_{value}" / f"seed{trial}"
                overrides = [f"preset={cfg.preset}", f"robot={cfg.robot}", f"seed={trial}", f"{spec['key']}={value}",
                             *cfg.overrides]
                for row in studies.run_recipe("lat", run_dir, overrides):
                    trial_rows.append({**row, "method": f"{name}={value}"})
            results[name][value] = trial_rows
            rows += trial_rows
    table = markdown_table(rows)
    write_text(out / "ablations.csv", csv_text(rows, EPISODE_COLUMNS))
    write_text(out / "ablations.md", f"# LAT ablations on {cfg.robot} ({cfg.preset} preset, {cfg.trials} trials per "
                                     "value)\n\nNormalised cost, mean +- std over targets and trials.\n\n" + table)
    plot_ablations(results, out / "ablations.png", title=f"LAT ablations on {cfg.robot} ({cfg.trials} trials)")
    print("\n" + table)
    print(f"ablation table and figure in {out}/")


if __name__ == "__main__":
    main()
