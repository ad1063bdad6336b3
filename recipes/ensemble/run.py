"""A probabilistic ensemble CoM model and risk-aware planning against LAT's single MLP (the research API's study),
as jobs on Ray.

    python recipes/ensemble/run.py                              # A1 and Daisy, 3 seeds, paper scale
    python recipes/ensemble/run.py robots=[a1] seeds=[0] preset=small records=results/ensemble/records

Per robot and seed: LAT with its MLP (``mlp``), then the same run's low level and dynamics data with an ensemble
(``ensemble``: ``dynamics.model=ensemble``, PETS's Gaussian members) planned risk-neutral, then with each risk of
``risks`` (``planner.risk=mean_std`` / ``pessimistic``: the evaluations alone). Every job is evaluated in the
normal setting, with the rear legs locked (model re-learned) and on the perturbed "hardware" robot planned with the
nominal model, where the model is most wrong. Writes ``ensemble.csv``, ``ensemble.md`` (the costs side by side, the
paired differences per seed) and ``wallclock.md`` in ``out_dir``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists
from hierloco.pipeline.study import (
    end_study, main_tasks, rows_of, run_study, seed_problems, study_main, study_robots, write_tables,
)


def check(cfg) -> list:
    from hierloco.envs.faults import SETTINGS
    from hierloco.envs.world_model import RISKS

    as_lists(cfg, ("robots", "seeds", "settings", "risks", "overrides"))
    problems = []
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    problems += [f"unknown setting {s!r}" for s in cfg.settings if s not in SETTINGS]
    problems += [f"unknown risk {r!r} (risks: {', '.join(RISKS)})" for r in cfg.risks if r not in RISKS]
    if not (isinstance(cfg.members, int) and cfg.members >= 2):
        problems.append(f"members must be an integer >= 2, got {cfg.members!r}")
    if problems:
        raise ConfigError("bad config: " + "; ".join(problems))
    return robots


def jobs(cfg, robots) -> list:
    """Per robot and seed: the MLP run, the ensemble run starting from its low level and data, and one run per
    risk starting from the ensemble run (evaluations only)."""
    planned = []
    for spec in robots:
        for seed in cfg.seeds:
            base = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                    f"settings=[{','.join(cfg.settings)}]", "progress=false", *cfg.overrides]
            root = Path(cfg.runs_dir) / f"{spec.name}_seed{seed}"
            mlp = studies.Job("lat", str(root / "mlp"), base, labels={"method": "mlp"})
            ensemble = [*base, "dynamics.model=ensemble", f"+dynamics.members={cfg.members}",
                        f"+dynamics.propagation={cfg.propagation}"]
            planned.append(mlp)
            previous = mlp.run_dir
            for risk in cfg.risks:
                name = "ensemble" if risk == "none" else f"ensemble_{risk}"
                overrides = [*ensemble, *([f"planner.risk={risk}", f"planner.beta={cfg.beta}"] if risk != "none"
                                          else [])]
                planned.append(studies.Job("lat", str(root / name), overrides, labels={"method": name},
                                           reuse_from=previous))
                previous = str(root / "ensemble") if risk == "none" else previous
    return planned


def paired_table(rows: list[dict], methods: list[str], tasks) -> str:
    """Per robot, setting and task: each method's mean normalised cost over seeds, and each ensemble variant's
    paired difference from the MLP (per seed; mean and its standard error)."""
    cost: dict[tuple, dict[int, float]] = {}
    for row in rows:
        key = (row["method"], row["robot"], row["setting"], row["task"])
        cost.setdefault(key, {}).setdefault(int(row["seed"]), []).append(float(row["normalized_cost"]))
    header = "| robot | setting | task | " + " | ".join(methods) + " |"
    lines = [header, "|---|---|---|" + "---|" * len(methods)]
    places = sorted({(r["robot"], r["setting"], r["task"]) for r in rows if r["task"] in tasks})
    for robot, setting, task in places:
        base = {s: np.mean(v) for s, v in cost.get(("mlp", robot, setting, task), {}).items()}
        cells = []
        for method in methods:
            seeds = {s: np.mean(v) for s, v in cost.get((method, robot, setting, task), {}).items()}
            if not seeds:
                cells.append("-")
                continue
            text = f"{np.mean(list(seeds.values())):.3f}"
            shared = sorted(set(seeds) & set(base))
            if method != "mlp" and shared:
                diff = np.array([seeds[s] - base[s] for s in shared])
                error = diff.std(ddof=1) / np.sqrt(len(diff)) if len(diff) > 1 else float("nan")
                text += f" ({diff.mean():+.3f} +- {error:.3f})"
            cells.append(text)
        lines.append(f"| {robot} | {setting} | {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = [{**row, "method": result.job.labels["method"]} for result in results if result.ok for row in result.rows]
    out = Path(cfg.out_dir)
    title = (f"LAT's CoM model: an MLP against a {cfg.members}-member ensemble ({cfg.propagation} propagation) and "
             f"risk-aware planning ({cfg.preset_name} preset, seeds {list(cfg.seeds)})")
    table = write_tables(rows, results, out, name="ensemble", title=title)
    if rows:
        methods = ["mlp", *["ensemble" if r == "none" else f"ensemble_{r}" for r in cfg.risks]]
        paired = paired_table(rows, methods, main_tasks(cfg))
        text = (out / "ensemble.md").read_text()
        write_text(out / "ensemble.md", text.replace("\n\n| method", "\n\n## Side by side\n\nMean normalised cost "
                                                     "over seeds; in brackets the paired difference from the MLP "
                                                     "(per seed) with its standard error.\n\n" + paired
                                                     + "\n## Every task\n\n| method", 1))
        print("\n" + paired)
    print(f"ensemble tables in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
