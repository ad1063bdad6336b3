"""Gait transitions (Li et al., RA-L 2021, Sec. VI, Fig. 9): LAT learned from experts over several gaits, against LAT
with the robot's own gait; which gait the planner picks for each latent action, and where it switches.

    python recipes/gaits/run.py records=results/gaits/records out_dir=results/gaits      # A1, paper scale, 3 seeds
    python recipes/gaits/run.py seeds=[0] preset=small

Per seed: the comparison's LAT job (the robot's own gait; its run directory or its record under ``compare_records``,
:func:`recipes.compare.run.comparison_job`) and LAT with ``experts.gaits`` (``docs/gaits.md``: the experts split
between the gaits, one gait policy and latent space over all). Every latent action the planner executed in the
several-gait runs is labelled with its gait from the foot contacts the evaluation recorded
(:func:`hierloco.components.gaits.classify_actions`, the artifacts the plan names, their keys checked). Writes in
``out_dir``: ``gaits.csv`` (one row per action: seed, task, episode, action, gait), ``gaits.md`` (per task: the share
of actions in each gait, switches per episode; the cost of both libraries per task with the test of "several gaits
cost as little as the own gait", ``docs/statistics.md``), ``gait_<task>_episode<k>.png`` (gait diagrams of the
episodes with the most switches, first seed), ``costs.csv`` / ``costs.md`` / ``wallclock.md``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists
from hierloco.pipeline.study import (
    end_study, main_tasks, run_study, seed_problems, study_main, study_robots, write_tables,
)
from recipes.compare.run import comparison_job


def gaits_of(cfg) -> dict:
    return OmegaConf.to_container(cfg.gaits, resolve=True) if cfg.gaits is not None else {}


def check(cfg):
    from hierloco.components.gaits import check_gaits

    as_lists(cfg, ("seeds", "overrides"))
    problems = []
    robots = study_robots([cfg.robot], problems)
    problems += seed_problems(cfg.seeds)
    gaits = gaits_of(cfg)
    if robots:
        problems += check_gaits(robots[0], gaits)
        own = {frozenset(group) for group in robots[0].gait_groups}
        if cfg.own not in gaits:
            problems.append(f"own: {cfg.own!r} is not one of the gaits ({', '.join(gaits)})")
        elif {frozenset(group) for group in gaits[cfg.own]} != own:
            problems.append(f"own: gait {cfg.own!r} {gaits[cfg.own]} is not {robots[0].name}'s own gait groups "
                            f"{[list(g) for g in robots[0].gait_groups]}")
    if not (isinstance(cfg.diagrams, int) and cfg.diagrams >= 0):
        problems.append(f"diagrams must be an integer >= 0, got {cfg.diagrams!r}")
    if problems:
        raise ConfigError("bad config: " + "; ".join(problems))
    return robots[0]


def gaits_override(gaits: dict) -> str:
    """``experts.gaits={...}`` for the command line, gaits by name (the library does not depend on their order)."""
    body = ", ".join(f"{name}: [{', '.join('[' + ', '.join(group) + ']' for group in groups)}]"
                     for name, groups in sorted(gaits.items()))
    return f"experts.gaits={{{body}}}"


def jobs(cfg, spec) -> list:
    planned = []
    label = f"{len(gaits_of(cfg))} gaits"
    for seed in cfg.seeds:
        own = comparison_job("lat", spec, seed, preset=cfg.preset_name, settings=["normal", "legs_disabled"])
        own.labels, own.records_from = {"method": f"own gait ({cfg.own})"}, cfg.compare_records
        several = studies.Job("lat", str(Path(cfg.runs_dir) / f"{spec.name}_seed{seed}"),
                              [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                               "settings=[normal]", "progress=false", *cfg.overrides, gaits_override(gaits_of(cfg))],
                              labels={"method": label})
        planned += [own, several]
    return planned


def action_gaits(job, tasks, gaits: dict) -> dict[str, list[list[str]]]:
    """Per task, the gait of each action of each episode the job's evaluation recorded (its plan's artifacts, each
    checked against its key first)."""
    from hierloco.components.gaits import classify_actions
    from hierloco.io import load_arrays
    from hierloco.pipeline.rundir import RunDirectory

    directory = RunDirectory(job.run_dir, readonly=True)
    specs = {spec.name: spec for spec in studies.planned_stages(job)}
    legs, steps = gait_context(job)
    found = {}
    for task in tasks:
        spec = specs[f"evaluation_normal_{task}"]
        if not directory.check(spec.name, spec.key, spec.filename):
            raise FileNotFoundError(f"{job.run_dir}: the evaluation {spec.filename} is not there")
        arrays, _ = load_arrays(directory.path / spec.filename)
        found[task] = [classify_actions(contacts, steps, gaits, legs) for contacts in arrays["foot_contacts"]]
    return found


def gait_context(job) -> tuple[list[str], int]:
    """The leg names and the steps per latent action of a job's robot and config."""
    from hierloco.envs.robots import get_robot
    from hierloco.pipeline.config import compose_recipe

    cfg = compose_recipe("lat", [f"run_dir={job.run_dir}", *job.overrides])
    return [leg.name for leg in get_robot(cfg.robot).legs], int(cfg.steps_per_action)


def switches(sequence: list[str]) -> int:
    return sum(a != b for a, b in zip(sequence, sequence[1:]))


def gaits_markdown(labels: list[dict], rows: list[dict], gaits: dict, tasks, *, own: str, several: str,
                   title: str) -> str:
    from hierloco.stats import decide_close
    from recipes.compare.paper_check import seed_means

    names = sorted(gaits)
    lines = [f"# Gait transitions ({title})", "",
             "Each latent action the planner executed in the several-gait runs, labelled with its gait from the foot "
             "contacts (`docs/gaits.md`).", "",
             f"| task | actions | {' | '.join(names)} | switches per episode | episodes with a switch |",
             "|---|---|" + "---|" * len(names) + "---|---|"]
    for task in tasks:
        of = [r for r in labels if r["task"] == task]
        episodes: dict = {}
        for r in of:
            episodes.setdefault((r["seed"], r["episode"]), []).append(r["gait"])
        counts = [sum(r["gait"] == name for r in of) for name in names]
        per_episode = [switches(sequence) for sequence in episodes.values()]
        shares = " | ".join(f"{100 * c / max(1, len(of)):.0f} %" for c in counts)
        lines.append(f"| {task.replace('_', ' ')} | {len(of)} | {shares} | "
                     f"{np.mean(per_episode) if per_episode else float('nan'):.2f} | "
                     f"{sum(s > 0 for s in per_episode)} of {len(per_episode)} |")
    lines += ["", "## Cost", "",
              f"Mean normalised cost over seeds (each seed's mean over its episodes, a fall counting 1); the test: \"{several} cost as "
              f"little as {own}\" (close: within 20 % or 0.01, `docs/statistics.md`).", "",
              f"| task | {own} | {several} | verdict |", "|---|---|---|---|"]
    robot = rows[0]["robot"] if rows else ""
    for task in tasks:
        a, b = (seed_means(rows, method=method, robot=robot, setting="normal", task=task) for method in (several, own))
        verdict = decide_close(a, b).text() if a.size and b.size else "not measured"
        lines.append(f"| {task.replace('_', ' ')} | {b.mean() if b.size else float('nan'):.3f} | "
                     f"{a.mean() if a.size else float('nan'):.3f} | {verdict} |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.results import csv_text

    spec = check(cfg)
    planned = jobs(cfg, spec)
    results = run_study(cfg, planned)
    tasks = main_tasks(cfg)
    gaits = gaits_of(cfg)
    rows = [{**row, **r.job.labels} for r in results if r.ok for row in r.rows if row["setting"] == "normal"]
    out = Path(cfg.out_dir)
    own, several = f"own gait ({cfg.own})", f"{len(gaits)} gaits"
    write_tables(rows, results, out, name="costs", title=f"Normalised cost, {spec.name} ({cfg.preset_name} preset, "
                 f"seeds {list(cfg.seeds)})", tasks=tasks)
    labels, first = [], None
    for result in results:
        if not (result.ok and result.job.labels["method"] == several):
            continue
        seed = int(next(o.split("=", 1)[1] for o in result.job.overrides if o.startswith("seed=")))
        per_task = action_gaits(result.job, tasks, gaits)
        first = first or (result.job, per_task)
        labels += [{"robot": spec.name, "seed": seed, "task": task, "episode": e, "action": a, "gait": gait}
                   for task, episodes in per_task.items() for e, sequence in enumerate(episodes)
                   for a, gait in enumerate(sequence)]
    if labels:
        write_text(out / "gaits.csv", csv_text(labels, list(labels[0])))
        write_text(out / "gaits.md", gaits_markdown(labels, rows, gaits, tasks, own=own, several=several,
                                                    title=f"{spec.name}, {cfg.preset_name} preset, seeds "
                                                          f"{list(cfg.seeds)}"))
        plot_diagrams(first, tasks, out, cfg.diagrams)
        print((out / "gaits.md").read_text())
    print(f"gait tables and diagrams in {out}/")
    end_study(results)


DIAGRAM_ACTIONS = 8  # latent actions a gait diagram shows


def plot_diagrams(first, tasks, out: Path, count: int) -> None:
    """Gait diagrams of the ``count`` episodes of the first seed with the most switches (ties: the first): the
    :data:`DIAGRAM_ACTIONS` actions from two before its first switch."""
    from hierloco.io import load_arrays
    from hierloco.plots import plot_gait_diagram

    job, per_task = first
    legs, steps = gait_context(job)
    specs = {spec.name: spec for spec in studies.planned_stages(job)}
    ranked = sorted(((switches(sequence), task, e) for task in tasks for e, sequence in enumerate(per_task[task])),
                    key=lambda item: -item[0])[:count]
    for _, task, episode in ranked:
        arrays, _ = load_arrays(Path(job.run_dir) / specs[f"evaluation_normal_{task}"].filename)
        sequence = per_task[task][episode]
        first = next((a for a in range(1, len(sequence)) if sequence[a] != sequence[a - 1]), 0)
        start = max(0, min(first - 2, len(sequence) - DIAGRAM_ACTIONS))  # a readable window around the first switch
        window = sequence[start:start + DIAGRAM_ACTIONS]
        contacts = arrays["foot_contacts"][episode][start * steps:(start + len(window)) * steps]
        plot_gait_diagram(contacts, legs, out / f"gait_{task}_episode{episode}.png", action_steps=steps,
                          title=f"{task.replace('_', ' ')}, episode {episode}, actions {start}-"
                                f"{start + len(window) - 1}: " + " ".join(window))


if __name__ == "__main__":
    main()
