"""Sample efficiency (Li et al., RA-L 2021, Sec. I and IV-B): normalised cost against the environment samples each
method learns its task layer from, as jobs on Ray.

    hierloco study sample_efficiency records=results/sample_efficiency/records out_dir=results/sample_efficiency
    hierloco study sample_efficiency robots=[a1] seeds=[0] preset=small lat_samples=[100,200] sac_samples=[100]

LAT learns one CoM model from ``dynamics.num_transitions`` transitions and plans every task with it; SAC trains one
agent per task from ``sac.total_frames`` high-level steps, so its samples in all are the number of tasks times that
("SAC and SAC-SAC are re-trained for new tasks, hence using 3 times as much data", Sec. IV-B). Both share the same
low level (the experts and the gait policy), whose budget is stated apart. Per robot and seed: the comparison's
LAT and SAC runs at the preset's budgets (:func:`recipes.compare.run.comparison_job`: their run directories, or their
records under ``compare_records``), then LAT at each of ``lat_samples`` and SAC at each of ``sac_samples``, each
starting from the low level of the run before it. Writes in ``out_dir``: ``sample_efficiency.csv`` / ``.md`` (every
episode; the table of means per budget), ``curves.csv`` (per seed), ``sample_efficiency.png`` (cost against samples
in all, log scale) and ``paper_check.md``: the claims, each decided by a test over seeds (``docs/statistics.md``):

- at equal samples per task, LAT (with that many samples in all) is better than SAC (with one task's worth per task);
- LAT at each smaller budget is close to LAT at the preset's budget (its cost saturates).
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import as_lists
from hierloco.pipeline.study import (
    end_study, main_tasks, refuse, run_study, seed_problems, study_main, study_robots, write_tables,
)
from hierloco.recipes.compare.run import comparison_job


# each method's budget as a factor of its records' runs (hierloco.evidence.read_records): LAT's CoM transitions, SAC's
# high-level steps per task
BUDGET = {"lat": "num_transitions", "sac": "high_level_frames"}


def budgets(cfg) -> tuple[int, int, int]:
    """The preset's own budgets: LAT's dynamics transitions, SAC's high-level steps per task, SAC's random start."""
    from hierloco.pipeline.config import compose_recipe

    lat = compose_recipe("lat", [f"preset={cfg.preset_name}"])
    sac = compose_recipe("sac", [f"preset={cfg.preset_name}"])
    return int(lat.dynamics.num_transitions), int(sac.sac.total_frames), int(sac.sac.init_random_frames)


def check(cfg) -> list:
    as_lists(cfg, ("robots", "seeds", "lat_samples", "sac_samples", "overrides"))
    problems = []
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    lat_full, sac_full, sac_random = budgets(cfg)
    for name, values, low, full in (("lat_samples", cfg.lat_samples, 1, lat_full),
                                    ("sac_samples", cfg.sac_samples, sac_random + 1, sac_full)):
        for value in values:
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value < full:
                why = f" (SAC acts at random for its first {sac_random} steps)" if name == "sac_samples" else ""
                problems.append(f"{name}: {value!r} is not an integer in [{low}, {full}), below the {cfg.preset_name} "
                                f"preset's own {full}{why}")
    if cfg.compare_records is not None and not isinstance(cfg.compare_records, str):
        problems.append(f"compare_records must be a directory path or null, got {cfg.compare_records!r}")
    refuse(problems)
    return robots


def jobs(cfg, robots) -> list:
    """Per robot and seed, for LAT then SAC: the comparison's job at the preset's budget, then one job per smaller
    budget (largest first), each starting from the low level of the job before it."""
    lat_full, sac_full, _ = budgets(cfg)
    planned = []
    for spec in robots:
        for seed in cfg.seeds:
            for method, key, full, smaller, settings in (
                    ("lat", "dynamics.num_transitions", lat_full, cfg.lat_samples, ["normal", "legs_disabled"]),
                    ("sac", "sac.total_frames", sac_full, cfg.sac_samples, ["normal"])):
                job = comparison_job(method, spec, seed, preset=cfg.preset_name, settings=settings)
                job.labels = {"method": method, "samples": full}
                job.records_from = cfg.compare_records
                planned.append(job)
                previous = job.run_dir
                for samples in sorted(set(smaller), reverse=True):
                    run_dir = Path(cfg.runs_dir) / f"{spec.name}_seed{seed}" / f"{method}_{samples}"
                    overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                                 "settings=[normal]", "progress=false", *cfg.overrides, f"{key}={samples}"]
                    planned.append(studies.Job(method, str(run_dir), overrides, reuse_from=previous,
                                               labels={"method": method, "samples": samples}))
                    previous = str(run_dir)
    return planned


def samples_in_all(method: str, samples: int, num_tasks: int) -> int:
    """The environment samples a method's task layer used for ``num_tasks`` tasks: LAT's one model serves them all,
    SAC trains an agent per task."""
    return samples * (num_tasks if method == "sac" else 1)


def seed_curves(rows: list[dict], tasks) -> list[dict]:
    """One row per robot, method, task, budget and seed: the seed's mean normalised cost over its episodes
    (:func:`recipes.compare.paper_check.seed_means`: a fallen robot's episode counts as 1)."""
    from hierloco.claims import seed_means

    groups: dict = {}
    for row in rows:
        if row["setting"] == "normal" and row["task"] in tasks:
            groups.setdefault((row["robot"], row["method"], row["task"], int(row["samples"])), []).append(row)
    curves = []
    for (robot, method, task, samples), group in sorted(groups.items()):
        seeds = sorted({row["seed"] for row in group})
        costs = seed_means(group, method=method, robot=robot, setting="normal", task=task)
        curves += [{"robot": robot, "method": method, "task": task, "samples_per_task": samples,
                    "samples_in_all": samples_in_all(method, samples, len(tasks)), "seed": int(seed),
                    "cost": float(cost)} for seed, cost in zip(seeds, costs)]
    return curves


def check_claims(curves: list[dict], full: int) -> list:
    """The two claims per robot, task and budget (:class:`recipes.compare.paper_check.Check`, keys
    ``sample_efficient`` and ``saturates``), each decided by its test over seeds (:mod:`hierloco.stats`)."""
    from hierloco.claims import decided, part

    def values(robot, method, task, samples):
        return [c["cost"] for c in curves if (c["robot"], c["method"], c["task"], c["samples_per_task"]) ==
                (robot, method, task, samples)]

    def check(key, claim, robot, task, a, b, kind, names):
        ours = f"{names[0]} {np.mean(a):.3f} (n={len(a)}), {names[1]} {np.mean(b):.3f} (n={len(b)})"
        return decided(key, claim, robot, "normal", task, ours, "-", [part(claim, a, b, kind, names=names)],
                       "Sec. I, III-C, IV-B")

    claims = []
    for robot, task in sorted({(c["robot"], c["task"]) for c in curves}):
        budgets = {m: sorted({c["samples_per_task"] for c in curves if (c["robot"], c["method"], c["task"]) ==
                              (robot, m, task)}) for m in ("lat", "sac")}
        for samples in sorted(set(budgets["lat"]) & set(budgets["sac"])):
            claims.append(check("sample_efficient", f"LAT with {samples} samples in all is better than SAC with "
                                f"{samples} per task", robot, task, values(robot, "lat", task, samples),
                                values(robot, "sac", task, samples), "better", (f"lat:{samples}", f"sac:{samples}")))
        if full in budgets["lat"]:
            for samples in (s for s in budgets["lat"] if s < full):
                claims.append(check("saturates", f"LAT with {samples} samples is close to LAT with {full}", robot,
                                    task, values(robot, "lat", task, samples), values(robot, "lat", task, full),
                                    "close", (f"lat:{samples}", f"lat:{full}")))
    return claims


def curves_of(runs, tasks) -> list[dict]:
    """:func:`seed_curves`'s rows from job records' runs (:func:`hierloco.evidence.read_records`): each LAT run's
    budget is its CoM transitions, each SAC run's its high level's steps per task (both from the stage keys)."""
    from hierloco.evidence import rows_of

    chosen = [r for r in runs if r.method in BUDGET and r.factor(BUDGET[r.method]) is not None]
    rows = [{**row, "samples": run.factor(BUDGET[run.method])} for run in chosen for row in rows_of([run])]
    return seed_curves(rows, tasks)


def claims_markdown(claims: list, *, title: str) -> str:
    lines = [f"# Sample efficiency: the claims ({title})", "",
             "Each claim decided over seeds (each seed's mean normalised cost over its episodes; Welch's t interval, "
             "alpha 0.05; \"better\": at least 10 % and 0.01 lower; \"close\": within 20 % or 0.01; "
             "`docs/statistics.md`). Paper: \"our approach outperforms baselines in all evaluation tasks, while being "
             "more sample-efficient\" (Sec. I); SAC is \"re-trained for new tasks, hence using 3 times as much data\" "
             "(Sec. IV-B).", "",
             "| robot | task | claim | first (mean over seeds) | second | verdict and test |",
             "|---|---|---|---|---|---|"]
    for c in claims:
        a, b = c.parts[0].a, c.parts[0].b
        lines.append(f"| {c.robot} | {c.task.replace('_', ' ')} | {c.claim} | {np.mean(a):.3f} (n={len(a)}) | "
                     f"{np.mean(b):.3f} (n={len(b)}) | {c.parts[0].decision.text()} |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = [{**row, **result.job.labels} for result in results if result.ok for row in result.rows
            if row["setting"] == "normal"]
    out = Path(cfg.out_dir)
    tasks = main_tasks(cfg)
    lat_full, sac_full, _ = budgets(cfg)
    title = (f"{cfg.preset_name} preset, seeds {list(cfg.seeds)}; LAT's budgets in dynamics transitions, SAC's in "
             f"high-level steps per task")
    table_rows = [{**row, "method": f"{row['method']} {row['samples']}"} for row in rows]
    table = write_tables(table_rows, results, out, name="sample_efficiency", title=f"Normalised cost ({title})",
                         tasks=tasks)
    if rows:
        from hierloco.plots import plot_samples
        from hierloco.results import csv_text

        curves = seed_curves(rows, tasks)
        write_text(out / "curves.csv", csv_text(curves, list(curves[0])))
        plot_rows = [{**row, "samples": samples_in_all(row["method"], int(row["samples"]), len(tasks))}
                     for row in rows if row["task"] in tasks]
        plot_samples(plot_rows, out / "sample_efficiency.png", tasks=tasks, title="Normalised cost against samples",
                     xlabel="environment samples in all (LAT: dynamics transitions; SAC: high-level steps, all tasks)")
        if lat_full != sac_full:
            print(f"note: LAT's preset budget ({lat_full}) and SAC's ({sac_full}) differ; claims compare equal budgets")
        write_text(out / "paper_check.md", claims_markdown(check_claims(curves, lat_full), title=title))
        print("\n" + table)
        print(f"sample-efficiency table, curves, figure and claims (paper_check.md) in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
