"""Tune a baseline on its training targets (Li et al., RA-L 2021, Sec. IV-B: baselines see half of each task's
targets), as jobs on Ray, so that the comparison runs each baseline at its best without looking at its test targets.

    hierloco study tune                              # IK: integral vs the plain footstep law
    hierloco study tune target=sac seeds=[1]         # SAC: the paper's lr 1e-3 vs 3e-4
    hierloco study tune robots=[daisy] seeds=[0] 'candidates={a: {overrides: []}, b: {overrides: [...]}}'

Every candidate runs the method's recipe in the normal setting with every task replaced by its training split
(``eval.tasks.<task>.split=train``), in ``runs_dir/<candidate>/<robot>_seed<seed>``; a candidate with ``reuse``
starts from the finished stages ``reuse_stages`` (the candidate's own, else the study's) of
``outputs/<reuse>/<preset>/<robot>_seed<seed>`` (their keys are checked like any cached stage).
What is tuned is a ``target`` (``target/<name>.yaml``): ``ik`` (default) or ``sac`` (the paper's optimiser against a
lower learning rate). Writes ``tune.csv``, ``tune.md`` (per robot and candidate: the training-split cost
of every task and their mean, the candidate chosen) and ``wallclock.md`` in ``out_dir``.

**The rule** (:func:`choose`): the target's ``incumbent`` (the setting the comparison runs: the paper's optimiser for
SAC, our integral footstep law for IK) is kept unless another candidate is *better* on the training targets by the
test over seeds of ``docs/statistics.md`` (each seed's mean training cost over the tasks; Welch's interval, alpha
0.05, at least 10 % and 0.01 lower); of several that are, the lowest mean. A lower mean that the test does not
establish (one seed, or a difference within the seeds' spread) changes nothing.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.results import EPISODE_COLUMNS, csv_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists
from hierloco.pipeline.study import end_study, missing_markdown, refuse, run_study, seed_problems, study_main, study_robots
from hierloco.claims import seed_means


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
    if cfg.candidates and cfg.get("incumbent") not in cfg.candidates:
        problems.append(f"incumbent {cfg.get('incumbent')!r} is not a candidate ({', '.join(cfg.candidates)}): the "
                        "setting kept unless another is better")
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    if not cfg.tasks:
        problems.append("tasks is empty")
    refuse(problems)
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


def training_costs(rows: list[dict], tasks, robot: str, candidate: str) -> tuple[np.ndarray, list]:
    """A candidate's per-seed training cost (``S``: each seed's mean over ``tasks`` of its mean over the task's
    training targets, :func:`recipes.compare.paper_check.seed_means`) and each task's ``(mean, std)`` over seeds."""
    of = [{**r, "method": r["candidate"]} for r in rows if r["candidate"] == candidate]
    per_task = [seed_means(of, method=candidate, robot=robot, setting="normal", task=f"{task}_train") for task in tasks]
    if any(costs.size == 0 for costs in per_task) or len({costs.size for costs in per_task}) > 1:
        return np.array([]), [(float(c.mean()), float(c.std())) if c.size else (np.nan, np.nan) for c in per_task]
    return np.mean(per_task, axis=0), [(float(c.mean()), float(c.std())) for c in per_task]


def choose(per_seed: dict[str, np.ndarray], incumbent: str) -> tuple[str, dict]:
    """The rule (module docstring): the candidate chosen, and each other candidate's decision against the
    incumbent (:func:`hierloco.stats.decide_better`)."""
    from hierloco.stats import decide_better

    decisions = {name: decide_better(costs, per_seed[incumbent]) for name, costs in per_seed.items()
                 if name != incumbent and costs.size and per_seed.get(incumbent, np.array([])).size}
    better = [name for name, decision in decisions.items() if decision.verdict == "holds"]
    return (min(better, key=lambda name: per_seed[name].mean()) if better else incumbent), decisions


def tune_table(rows: list[dict], tasks, incumbent: str) -> tuple[str, dict]:
    """Per robot and candidate, the mean normalised cost on each task's training split (mean +- std over seeds) and
    their mean, with each candidate's test against the incumbent; returns the Markdown table and the candidate the
    rule chooses per robot (:func:`choose`)."""
    header = " | ".join(f"{t} (train)" for t in tasks)
    lines = [f"| robot | candidate | {header} | mean | better than {incumbent}? | chosen |",
             "|---|---|" + "---|" * len(tasks) + "---|---|---|"]
    chosen = {}
    for robot in sorted({r["robot"] for r in rows}):
        candidates = list(dict.fromkeys(r["candidate"] for r in rows if r["robot"] == robot))
        costs = {name: training_costs(rows, tasks, robot, name) for name in candidates}
        chosen[robot], decisions = choose({name: per_seed for name, (per_seed, _) in costs.items()}, incumbent)
        for name, (per_seed, per_task) in costs.items():
            cells = " | ".join(f"{m:.2f} +- {s:.2f}" for m, s in per_task)
            mean = f"{per_seed.mean():.3f}" if per_seed.size else "-"
            test = "(incumbent)" if name == incumbent else (decisions[name].text() if name in decisions else "-")
            lines.append(f"| {robot} | {name} | {cells} | {mean} | {test} | {'chosen' if name == chosen[robot] else ''} |")
    return "\n".join(lines) + "\n", chosen


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.pipeline.report import wallclock_markdown

    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = studies.rows_of(results)
    out = Path(cfg.out_dir)
    if rows:
        table, picked = tune_table(rows, list(cfg.tasks), cfg.incumbent)
        write_text(out / "tune.csv", csv_text(rows, EPISODE_COLUMNS + ["candidate"]))
        chosen = "; ".join(f"{robot}: {name}" for robot, name in picked.items())
        write_text(out / "tune.md", f"# Tuning {cfg.method.upper()} on the training targets ({cfg.preset_name} "
                                    f"preset, seeds {list(cfg.seeds)})\n\nNormalised cost on each task's training "
                                    f"split, mean +- std over seeds. The rule: `{cfg.incumbent}` is kept unless "
                                    "another candidate is better by the test over seeds (each seed's mean over the "
                                    "tasks; Welch's interval, alpha 0.05, at least 10 % and 0.01 lower; "
                                    f"docs/statistics.md); of several, the lowest mean.\n\n"
                                    f"{table}\nChosen: {chosen}.\n" + missing_markdown(results))
        write_text(out / "wallclock.md", wallclock_markdown(results))
        print("\n" + table + f"\nchosen: {chosen}")
    print(f"tuning table in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
