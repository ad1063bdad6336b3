"""Tune a baseline on its training targets (Li et al., RA-L 2021, Sec. IV-B: baselines see half of each task's
targets), as jobs on Ray, so that the comparison runs each baseline at its best without looking at its test targets.

    python recipes/tune/run.py                              # IK: integral vs the paper's plain footstep law
    python recipes/tune/run.py target=sac seeds=[1]         # SAC: the paper's lr 1e-3 vs 3e-4
    python recipes/tune/run.py robots=[daisy] seeds=[0] 'candidates={a: {overrides: []}, b: {overrides: [...]}}'

Every candidate runs the method's recipe in the normal setting with every task replaced by its training split
(``eval.tasks.<task>.split=train``), in ``runs_dir/<candidate>/<robot>_seed<seed>``; a candidate with ``reuse``
starts from the finished stages ``reuse_stages`` (the candidate's own, else the study's) of
``outputs/<reuse>/<preset>/<robot>_seed<seed>`` (their keys are checked like any cached stage).
What is tuned is a ``target`` (``target/<name>.yaml``): ``ik`` (default) or ``sac`` (the paper's optimiser against a
lower learning rate). Writes ``tune.csv``, ``tune.md`` (per robot and candidate: the training-split cost
of every task and their mean, the best candidate marked) and ``wallclock.md`` in ``out_dir``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.results import EPISODE_COLUMNS, csv_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists
from hierloco.pipeline.study import end_study, missing_markdown, run_study, seed_problems, study_main, study_robots
from recipes.compare.paper_check import seed_means


def check(cfg) -> list:
    """The robots; raises one ConfigError naming every problem."""
    as_lists(cfg, ("robots", "seeds", "tasks", "overrides", "reuse_stages"))
    problems = []
    if not (Path(__file__).resolve().parents[1] / cfg.method / "train.py").exists():
        problems.append(f"unknown method {cfg.method!r}: no recipes/{cfg.method}/train.py")
    if not cfg.candidates:
        problems.append("candidates is empty")
    for name, candidate in (cfg.candidates or {}).items():
        unknown = set(candidate) - {"overrides", "reuse", "reuse_stages"}
        if unknown:
            problems.append(f"candidate {name!r}: unknown keys {sorted(unknown)} (overrides, reuse, reuse_stages)")
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    if not cfg.tasks:
        problems.append("tasks is empty")
    if problems:
        raise ConfigError("bad config: " + "; ".join(problems))
    return robots


def jobs(cfg, robots) -> list:
    planned = []
    split = [f"+eval.tasks.{task}.split=train" for task in cfg.tasks]
    only = [f"~eval.tasks.{task}" for task in ("velocity_tracking", "goal_reaching", "trajectory_tracking")
            if task not in cfg.tasks]
    for spec in robots:
        for name, candidate in cfg.candidates.items():
            for seed in cfg.seeds:
                run_dir = Path(cfg.runs_dir) / name / f"{spec.name}_seed{seed}"
                reuse = candidate.get("reuse")
                source = str(Path("outputs") / reuse / cfg.preset_name / f"{spec.name}_seed{seed}") if reuse else None
                overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                             "settings=[normal]", "progress=false", *only, *split, *cfg.overrides,
                             *candidate.get("overrides", [])]
                reuse_stages = candidate.get("reuse_stages", cfg.reuse_stages)
                planned.append(studies.Job(cfg.method, str(run_dir), overrides, labels={"candidate": name},
                                           reuse_from=source, reuse_stages=tuple(reuse_stages)))
    return planned


def tune_table(rows: list[dict], tasks) -> tuple[str, dict]:
    """Per robot and candidate, the mean normalised cost on each task's training split (mean over seeds of each
    seed's mean over targets, :func:`recipes.compare.paper_check.seed_means`) and their mean; returns the Markdown table and the best candidate per robot."""
    header = " | ".join(f"{t} (train)" for t in tasks)
    lines = [f"| robot | candidate | {header} | mean | best |", "|---|---|" + "---|" * len(tasks) + "---|---|"]
    best = {}
    for robot in sorted({r["robot"] for r in rows}):
        scores = {}
        for candidate in dict.fromkeys(r["candidate"] for r in rows):
            costs = []
            of = [{**r, "method": r["candidate"]} for r in rows if r["candidate"] == candidate]
            for task in tasks:
                per_seed = seed_means(of, method=candidate, robot=robot, setting="normal", task=f"{task}_train")
                costs.append((float(per_seed.mean()), float(per_seed.std())) if per_seed.size else (np.nan, np.nan))
            scores[candidate] = (float(np.mean([c[0] for c in costs])), costs)
        best[robot] = min(scores, key=lambda c: scores[c][0])
        for candidate, (mean, costs) in scores.items():
            cells = " | ".join(f"{m:.2f} +- {s:.2f}" for m, s in costs)
            lines.append(f"| {robot} | {candidate} | {cells} | {mean:.3f} | {'best' if candidate == best[robot] else ''} |")
    return "\n".join(lines) + "\n", best


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.pipeline.report import wallclock_markdown

    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = studies.rows_of(results)
    out = Path(cfg.out_dir)
    if rows:
        table, best = tune_table(rows, list(cfg.tasks))
        write_text(out / "tune.csv", csv_text(rows, EPISODE_COLUMNS + ["candidate"]))
        chosen = "; ".join(f"{robot}: {name}" for robot, name in best.items())
        write_text(out / "tune.md", f"# Tuning {cfg.method.upper()} on the training targets ({cfg.preset_name} "
                                    f"preset, seeds {list(cfg.seeds)})\n\nNormalised cost on each task's training "
                                    f"split, mean +- std over seeds; the best candidate has the lowest mean.\n\n"
                                    f"{table}\nBest: {chosen}.\n" + missing_markdown(results))
        write_text(out / "wallclock.md", wallclock_markdown(results))
        print("\n" + table + f"\nbest: {chosen}")
    print(f"tuning table in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
