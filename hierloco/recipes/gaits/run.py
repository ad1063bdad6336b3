"""Gait transitions (Li et al., RA-L 2021, Sec. V, Fig. 9): LAT learned from experts over several gaits, against LAT
with the robot's own gait; which gait the planner picks for each latent action, and where it switches.

    hierloco study gaits records=results/gaits/records out_dir=results/gaits      # A1, paper scale, 3 seeds
    hierloco study gaits seeds=[0] preset=small

Per seed: the comparison's LAT job (the robot's own gait; its run directory or its record under ``compare_records``,
:func:`recipes.compare.run.comparison_job`) and LAT with ``experts.gaits`` (``docs/gaits.md``: the experts split
between the gaits, one gait policy and latent space over all). Every latent action the planner executed in the
several-gait runs is labelled with its gait from the foot contacts the evaluation recorded
(:func:`hierloco.components.gaits.classify_actions`, the artifacts the plan names, their keys checked): each
several-gait and profile job keeps its *per-action table* (:func:`action_table`: per action of every evaluated
episode its gait, its velocity target's speed and the CoM's speed along it) in its record (``records``,
:mod:`hierloco.pipeline.records`), and the tables below are made from those tables, so a job taken from its record
counts as one run here; a record made before jobs kept the table is not taken: the job runs again. Writes in
``out_dir``: ``gaits.csv`` (one row per action: seed, task, episode, action, gait), ``gaits.md`` (per task: the share
of actions in each gait, switches per episode; the cost of both libraries per task with the test of "several gaits
cost as little as the own gait", ``docs/statistics.md``), ``gait_<task>_episode<k>.png`` (gait diagrams of the
episodes with the most switches, of the first several-gait run whose run directory is here), ``costs.csv`` /
``costs.md`` / ``wallclock.md``.

With ``profile`` (a task that needs a change of speed: forward velocity targets from slow to fast and back), each
library's trained run is also evaluated on it alone, starting from its trained stages (the own gait's from
``own_runs`` when set): ``profile.csv`` (one row per action: its target speed, the CoM's speed along it and, with
several gaits, its gait), ``profile.md`` (per stretch of one target: the gaits' shares and switches, the speeds with
each library; where the switches fall; per seed, the gaits at the fastest target; the cost test) and
``gait_<task>_profile.png`` (the first seed's actions around the fastest target).

With ``gait_boxes`` (a gait's own command box, ``experts.gait_boxes``: e.g. a ripple that walks only slowly) some
targets of the profile need a gait: each several-gait ``profile.csv`` row names the gaits that reach its target
(``needed``; empty in the own gait's rows) and ``profile.md`` tests "the planner picks the gait a target needs"
(:func:`decide_needed_gait`; ``hierloco verdicts`` decides the paper's claim from the same table made from the
profile jobs' records, :func:`profile_from_records`); ``tag`` names the
several-gait run directories (``<robot>_seed<seed>_<tag>``) so that such a library's runs sit beside the others:

    hierloco study gaits robot=daisy own=tripod '~gaits' \
        '+gaits={tripod: [[FL, MR, RL], [FR, ML, RR]], ripple: [[FL, MR], [ML, RR], [RL, FR]]}' \
        'gait_boxes={ripple: {command_low: [-0.1, -0.1, -0.2], command_high: [0.1, 0.1, 0.2]}}' tag=speeds
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists, override_value
from hierloco.pipeline.study import (
    end_study, main_tasks, missing_markdown, refuse, run_study, seed_problems, study_main, study_robots, write_tables,
)
from hierloco.recipes.compare.run import comparison_job


ACTIONS = "hierloco.recipes.gaits.run:action_table"  # the per-action table the study's jobs keep in their records


def gaits_of(cfg) -> dict:
    return OmegaConf.to_container(cfg.gaits, resolve=True) if cfg.gaits is not None else {}


def several_label(gaits) -> str:
    """The several-gait library's name in the tables, e.g. ``"2 gaits"``."""
    return f"{len(gaits)} gaits"


def own_label(own: str | None) -> str:
    """The own gait's library's name in the tables, e.g. ``"own gait (tripod)"``."""
    return f"own gait ({own})" if own else "own gait"


def run_names(robot: str, seed: int, tag: str | None = None) -> dict[str, str]:
    """The names of one seed's run directories (below ``runs_dir``): the several-gait run (``several``:
    ``<robot>_seed<seed>[_<tag>]``) and the profile jobs (``several_profile``: its name with ``_profile``;
    ``own_profile``: ``<robot>_seed<seed>_own_profile``). Their records lie under the same names."""
    several = f"{robot}_seed{seed}{f'_{tag}' if tag else ''}"
    return {"several": several, "several_profile": f"{several}_profile",
            "own_profile": f"{robot}_seed{seed}_own_profile"}


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
    problems += profile_problems(cfg)
    if robots and cfg.get("gait_boxes") is not None:
        from hierloco.components.gaits import check_gait_boxes

        problems += check_gait_boxes(robots[0], gaits, boxes_of(cfg) if OmegaConf.is_dict(cfg.gait_boxes)
                                     else cfg.gait_boxes)
    tag = cfg.get("tag")
    if tag is not None and not (isinstance(tag, str) and tag.replace("_", "").isalnum() and tag.isascii()):
        problems.append(f"tag must be letters, digits and underscores (it names the run directories), got {tag!r}")
    refuse(problems)
    return robots[0]


def boxes_of(cfg) -> dict:
    """The gaits' own command boxes (``gait_boxes``: gait -> ``{command_low, command_high}``), empty when null."""
    return OmegaConf.to_container(cfg.gait_boxes, resolve=True) if cfg.get("gait_boxes") is not None else {}


def gaits_override(gaits: dict) -> str:
    """``experts.gaits={...}`` for the command line, gaits by name (the library does not depend on their order)."""
    return f"experts.gaits={override_value(dict(sorted(gaits.items())))}"


def profile_of(cfg) -> dict:
    """The speed-profile tasks (name -> task options), empty when ``profile`` is null."""
    return OmegaConf.to_container(cfg.profile, resolve=True) if cfg.get("profile") else {}


def profile_problems(cfg) -> list[str]:
    """One line per profile task that is not a velocity task of the registry (its targets are speeds the tables
    group by), or that shares a main task's name; a bad ``own_runs``."""
    from hierloco.pipeline.config import make_task_from_spec

    problems = []
    profile = cfg.get("profile")
    if profile is not None and not OmegaConf.is_dict(profile):
        return [f"profile must map task names to options, got {profile!r}"]
    for name, options in profile_of(cfg).items():
        try:
            task = make_task_from_spec(name, options)
        except (ConfigError, ValueError, KeyError) as error:
            problems.append(f"profile task {name!r}: {' '.join(str(error).split()).removeprefix('bad config: ')}")
            continue
        if not task.target_is_velocity:
            problems.append(f"profile task {name!r} is a {task.kind} task; a speed profile needs velocity targets")
    own_runs = cfg.get("own_runs")
    if own_runs is not None and not (isinstance(own_runs, str) and "{seed}" in own_runs):
        problems.append(f"own_runs must be a path holding {{seed}} (and optionally {{robot}}), got {own_runs!r}")
    return problems


def jobs(cfg, spec) -> tuple[list, list]:
    """The study's jobs, and its speed-profile jobs (none when ``profile`` is null). Per seed: the own gait's
    comparison job, the several-gait job; then each evaluated on the profile alone, starting from its trained stages
    (the several-gait job's run directory; for the own gait, ``own_runs`` when set, else the comparison's run
    directory), so a profile job trains nothing its source holds. Every job but the comparison's keeps its
    per-action table in its record (:data:`ACTIONS`)."""
    planned, profiled = [], []
    label = several_label(gaits_of(cfg))
    profile = profile_of(cfg)
    boxes = [f"experts.gait_boxes={override_value(dict(sorted(boxes_of(cfg).items())))}"] if boxes_of(cfg) else []
    for seed in cfg.seeds:
        names = run_names(spec.name, seed, cfg.get("tag"))  # e.g. daisy_seed0_speeds: tag names a library's runs
        own = comparison_job("lat", spec, seed, preset=cfg.preset_name, settings=["normal", "legs_disabled"])
        own.labels, own.records_from = {"method": own_label(cfg.own)}, cfg.compare_records
        several = studies.Job("lat", str(Path(cfg.runs_dir) / names["several"]),
                              [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                               "settings=[normal]", "progress=false", *cfg.overrides, gaits_override(gaits_of(cfg)),
                               *boxes],
                              labels={"method": label}, actions=ACTIONS)
        planned += [own, several]
        if not profile:
            continue
        on_profile = ["~eval.tasks", f"+eval.tasks={override_value(profile)}", "eval.generalization=null",
                      "eval.videos=[]"]
        own_source = (cfg.own_runs.format(robot=spec.name, seed=seed) if cfg.get("own_runs") else own.run_dir)
        own_normal = comparison_job("lat", spec, seed, preset=cfg.preset_name, settings=["normal"])
        profiled += [
            studies.Job("lat", str(Path(cfg.runs_dir) / names["own_profile"]),
                        [*own_normal.overrides, *on_profile], labels=dict(own.labels), reuse_from=own_source,
                        actions=ACTIONS),
            studies.Job("lat", str(Path(cfg.runs_dir) / names["several_profile"]),
                        [*several.overrides, *on_profile], labels=dict(several.labels), reuse_from=several.run_dir,
                        actions=ACTIONS)]
    return planned, profiled


def evaluation_arrays(job, task: str, spec=None) -> dict:
    """The arrays of the job's evaluation of ``task`` in the normal setting (or of the evaluation stage ``spec``):
    the artifact its plan names, checked against its key first."""
    from hierloco.io import load_arrays
    from hierloco.pipeline.rundir import RunDirectory

    directory = RunDirectory(job.run_dir, readonly=True)
    if spec is None:
        spec = {spec.name: spec for spec in studies.planned_stages(job)}[f"evaluation_normal_{task}"]
    if not directory.check(spec.name, spec.key, spec.filename):
        raise FileNotFoundError(f"{job.run_dir}: the evaluation {spec.filename} is not there")
    return load_arrays(directory.path / spec.filename)[0]


def action_table(job, specs) -> list[dict]:
    """The job's per-action table (:attr:`hierloco.pipeline.studies.Job.actions`, kept in its record): one row per
    latent action of every episode of each evaluation among ``specs`` (its plan's artifacts, each checked against its
    key first): ``setting``, ``task``, ``episode``, ``action``; ``gait``, the gait its foot contacts walked
    (:func:`hierloco.components.gaits.classify_actions` over the job's ``experts.gaits``; empty for a library of the
    robot's own gait); for a velocity task ``target_speed`` (m/s, the action's target) and ``speed`` (m/s, the CoM's
    mean velocity along it, :func:`action_speeds`), NaN for other tasks; with ``experts.gait_boxes``, ``needed``: the
    gaits whose box reaches the target (:func:`needed_at`, empty for other tasks)."""
    import torch

    from hierloco.components.gaits import classify_actions
    from hierloco.envs.robots import get_robot
    from hierloco.pipeline.config import compose_recipe, make_task_from_spec

    cfg = compose_recipe(job.method, [f"run_dir={job.run_dir}", *job.runtime_overrides(), *job.overrides])
    robot = get_robot(cfg.robot)
    legs, steps = [leg.name for leg in robot.legs], int(cfg.steps_per_action)
    gaits = OmegaConf.to_container(cfg.experts.gaits, resolve=True) if cfg.experts.get("gaits") else {}
    boxes = OmegaConf.to_container(cfg.experts.gait_boxes, resolve=True) if cfg.experts.get("gait_boxes") else {}
    top = gait_top_speeds(robot, gaits, boxes) if boxes else {}
    table = []
    for spec in specs:
        if not spec.name.startswith("evaluation_"):
            continue
        params = spec.key.get("params", {})
        task = make_task_from_spec(params["task_name"], params.get("task") or {})
        arrays = evaluation_arrays(job, task.name, spec)
        for episode, (paths, contacts) in enumerate(zip(arrays["com_paths"], arrays["foot_contacts"])):
            count = len(contacts) // steps
            labels = classify_actions(contacts, steps, gaits, legs) if gaits else [""] * count
            if task.target_is_velocity:
                targets = task.target(torch.full((task.num_steps,), episode), torch.arange(task.num_steps)).numpy()
                targets = np.linalg.norm(targets, axis=-1), action_speeds(paths[None], targets, steps,
                                                                          task.step_duration)[0]
            else:
                targets = np.full(count, np.nan), np.full(count, np.nan)
            table += [{"setting": params["setting"], "task": task.name, "episode": episode, "action": a,
                       "target_speed": round(float(target), 4), "speed": round(float(speed), 4), "gait": gait,
                       **({"needed": needed_at(top, float(target)) if task.target_is_velocity else ""} if top else {})}
                      for a, (target, speed, gait) in enumerate(zip(*targets, labels))]
    return table


def gait_sequences(actions: list[dict], tasks) -> dict[str, list[list[str]]]:
    """Per task of ``tasks``, the gait of each action of each episode of a job's per-action table
    (:func:`action_table`) in the normal setting, in order."""
    episodes: dict[str, dict[int, list[str]]] = {task: {} for task in tasks}
    for row in actions:
        if row["setting"] == "normal" and row["task"] in episodes:
            episodes[row["task"]].setdefault(int(row["episode"]), []).append(row["gait"])
    return {task: [found[e] for e in sorted(found)] for task, found in episodes.items()}


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
    from hierloco.claims import seed_means

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
    from hierloco.pipeline.report import wallclock_markdown
    from hierloco.results import csv_text

    spec = check(cfg)
    planned, profiled = jobs(cfg, spec)
    results = run_study(cfg, planned + profiled)
    results, profile_results = results[:len(planned)], results[len(planned):]
    tasks = main_tasks(cfg)
    gaits = gaits_of(cfg)
    rows = [{**row, **r.job.labels} for r in results if r.ok for row in r.rows if row["setting"] == "normal"]
    out = Path(cfg.out_dir)
    own, several = own_label(cfg.own), several_label(gaits)
    write_tables(rows, results, out, name="costs", title=f"Normalised cost, {spec.name} ({cfg.preset_name} preset, "
                 f"seeds {list(cfg.seeds)})", tasks=tasks)
    labels, first = [], None
    for result in results:
        if not (result.ok and result.job.labels["method"] == several and result.actions is not None):
            continue
        per_task = gait_sequences(result.actions, tasks)
        if first is None and here(result):
            first = (result.job, per_task)
        labels += [{"robot": spec.name, "seed": seed_of(result.job), "task": task, "episode": e, "action": a,
                    "gait": gait}
                   for task, episodes in per_task.items() for e, sequence in enumerate(episodes)
                   for a, gait in enumerate(sequence)]
    if labels:
        write_text(out / "gaits.csv", csv_text(labels, list(labels[0])))
        write_text(out / "gaits.md", gaits_markdown(labels, rows, gaits, tasks, own=own, several=several,
                                                    title=f"{spec.name}, {cfg.preset_name} preset, seeds "
                                                          f"{list(cfg.seeds)}"))
        if first is not None:
            plot_diagrams(first, tasks, out, cfg.diagrams)
        else:
            print("gait diagrams: no several-gait run directory here (every such job was taken from its record)")
        print((out / "gaits.md").read_text())
    if profiled:
        write_profile(cfg, spec, profile_results, out, own=own, several=several)
        write_text(out / "wallclock.md", wallclock_markdown([*results, *profile_results]))
    print(f"gait tables and diagrams in {out}/")
    end_study(results + profile_results)


def seed_of(job) -> int:
    return int(next(o.split("=", 1)[1] for o in job.overrides if o.startswith("seed=")))


def here(result) -> bool:
    """Whether a job's result came from its run directory (its evaluations are here), not from its record."""
    return result.source == result.job.run_dir


def action_speeds(com_paths: np.ndarray, targets: np.ndarray, steps: int, step_duration: float) -> np.ndarray:
    """``E x T`` the CoM's mean velocity over each latent action projected on that action's velocity target (m/s,
    world frame), from ``E x (T * steps) x >=2`` CoM paths that start at the origin (the tasks' start) and ``T x 2``
    targets."""
    paths = np.asarray(com_paths)[..., :2]
    ends = paths[:, steps - 1::steps]                                  # E x T: where each action ended
    starts = np.concatenate([np.zeros_like(ends[:, :1]), ends[:, :-1]], axis=1)
    velocity = (ends - starts) / step_duration
    direction = targets / np.maximum(np.linalg.norm(targets, axis=-1, keepdims=True), 1e-9)
    return (velocity * direction[None]).sum(-1)


def profile_rows(tables) -> list[dict]:
    """The profile table (``profile.csv``): one row per latent action of every profile episode, from the profile
    jobs' per-action tables (:func:`action_table`; ``tables``: ``(seed, library, table)`` per job, in order): seed,
    library (``method``), task, episode, action, the action's target speed (m/s), the CoM's speed along it (m/s), its
    gait (empty for the own gait) and, where a table has it, ``needed`` (the gaits that reach the target; empty in
    the rows of a table without it)."""
    tables = list(tables)
    with_needed = any("needed" in row for _, _, table in tables for row in table)
    return [{"seed": int(seed), "method": method, "task": row["task"], "episode": row["episode"],
             "action": row["action"], "target_speed": row["target_speed"], "speed": row["speed"], "gait": row["gait"],
             **({"needed": row.get("needed", "")} if with_needed else {})}
            for seed, method, table in tables for row in table if row["setting"] == "normal"]


def experts_gaits(record: dict) -> dict:
    """The gaits (name -> groups) a job record's expert library was built over (its ``experts`` stage key), empty
    for the robot's own gait alone."""
    key = (record["stages"].get("experts.npz") or {}).get("key") or {}
    return dict((key.get("params") or {}).get("gaits") or {})


def profile_from_records(root, *, robot: str, tag: str | None = None,
                         preset: str = "paper") -> tuple[list[dict], list[str]]:
    """The profile table of a gait study (:func:`profile_rows`) made from its profile jobs' records under ``root``
    (a records directory: the records named ``<robot>_seed<seed>[_<tag>]_profile`` and
    ``<robot>_seed<seed>_own_profile`` of ``preset``, :func:`run_names`; each verified as it is read), with the
    labels the study gives (:func:`several_label`; :func:`own_label`, the own gait named as the several-gait
    library names the robot's own gait groups); and the records among them without a per-action table (made
    before the study kept it), which add no rows."""
    import re

    from hierloco.envs.robots import get_robot
    from hierloco.pipeline import records

    chosen = []
    for path in sorted(Path(root).rglob(records.RECORD)):
        match = re.fullmatch(rf"{re.escape(robot)}_seed(\d+)_\w+", path.parent.name)
        if match is None:
            continue
        names = run_names(robot, int(match[1]), tag)
        kind = {names["own_profile"]: 0, names["several_profile"]: 1}.get(path.parent.name)
        if kind is None:
            continue
        record = records.read(path.parent)
        if record["rows"] is not None and f"preset={preset}" in record["signature"].get("overrides", []):
            chosen.append((int(match[1]), kind, path.parent, record))
    chosen.sort(key=lambda item: item[:2])  # per seed, the own gait's then the several gaits', as the study runs them
    own_groups = {frozenset(group) for group in get_robot(robot).gait_groups}
    gaits = next((found for *_, record in chosen if (found := experts_gaits(record))), {})
    own = next((name for name, groups in gaits.items() if {frozenset(g) for g in groups} == own_groups), None)
    tables, lacking = [], []
    for seed, kind, directory, record in chosen:
        if record.get("actions") is None:
            lacking.append(directory.as_posix())
            continue
        tables.append((seed, several_label(experts_gaits(record)) if kind else own_label(own), record["actions"]))
    return profile_rows(tables), lacking


NEEDED_GAIT_EFFECT = 0.2  # the least rise in the share of the gaits a target needs that counts (docs/gaits.md)


def top_speeds(cfg) -> dict[str, float]:
    """Each gait's fastest planar command (m/s) in the study's config (:func:`gait_top_speeds`)."""
    from hierloco.envs.robots import get_robot

    return gait_top_speeds(get_robot(cfg.robot), gaits_of(cfg), boxes_of(cfg))


def gait_top_speeds(robot, gaits: dict, boxes: dict) -> dict[str, float]:
    """Each gait's fastest planar command (m/s): the corner of its command box (its own in ``boxes``, else
    ``robot``'s) farthest from standing in ``(vx, vy)``; a target faster than that needs another gait."""
    from hierloco.components.expert_library import command_box

    out = {}
    for name in gaits:
        low, high = command_box(robot, boxes.get(name, {}).get("command_low"), boxes.get(name, {}).get("command_high"))
        out[name] = float(max(np.hypot(x, y) for x in (low[0], high[0]) for y in (low[1], high[1])))
    return out


def needed_at(top: dict[str, float], speed: float) -> str:
    """The gaits whose commands reach ``speed`` (m/s; ``top``: :func:`top_speeds`), sorted and joined by ``|``."""
    return "|".join(sorted(name for name, fastest in top.items() if fastest >= speed - 1e-9))


def split_needed(found: list[dict], several: str) -> tuple[list[dict], list[dict]]:
    """The several-gait runs' profile rows with a ``needed`` column (:func:`profile_rows` with ``gait_boxes``), split
    into those at targets only some gaits reach and those at targets every gait reaches."""
    mine = [r for r in found if r["method"] == several and r.get("needed")]
    every = max((set(r["needed"].split("|")) for r in mine), key=len, default=set())
    needing = [r for r in mine if set(r["needed"].split("|")) < every]
    return needing, [r for r in mine if set(r["needed"].split("|")) == every]


def targets_needing(found: list[dict], several: str) -> list[tuple[float, str]]:
    """``(target speed, the gaits that reach it)`` of each target only some gaits reach, by speed."""
    return sorted({(r["target_speed"], r["needed"]) for r in split_needed(found, several)[0]})


def needed_gait_shares(found: list[dict], several: str) -> dict[int, tuple[float, float]]:
    """Per seed (:func:`split_needed`): the share of the several-gait runs' actions at the targets only some gaits
    reach that walk one of those gaits, and the share of the actions in the same gaits at the targets every gait
    reaches. Empty when no target needs a gait."""
    needing, anywhere = split_needed(found, several)
    wanted = set().union(*(set(r["needed"].split("|")) for r in needing))
    shares = {}
    for seed in sorted({int(r["seed"]) for r in needing}):
        fast = [r["gait"] in r["needed"].split("|") for r in needing if int(r["seed"]) == seed]
        slow = [r["gait"] in wanted for r in anywhere if int(r["seed"]) == seed]
        shares[seed] = (float(np.mean(fast)), float(np.mean(slow)) if slow else float("nan"))
    return shares


def decide_needed_gait(shares: dict[int, tuple[float, float]]):
    """"The planner picks the gait a target needs": over seeds, the share of the actions in the needed gaits at the
    targets that need them is higher than those gaits' share where any gait will do, by at least
    :data:`NEEDED_GAIT_EFFECT` (one-sided paired Welch, ``docs/statistics.md``; as costs, one minus the shares)."""
    from hierloco.stats import decide_better

    fast = [1.0 - shares[seed][0] for seed in sorted(shares)]
    slow = [1.0 - shares[seed][1] for seed in sorted(shares)]
    return decide_better(fast, slow, paired=True, min_effect_rel=0.0, min_effect_abs=NEEDED_GAIT_EFFECT,
                         not_testable=float("inf"))


def needed_gait_markdown(found: list[dict], several: str, top: dict[str, float]) -> list[str]:
    """The section of ``profile.md`` on the gait a target needs (with ``gait_boxes``): each gait's fastest command,
    the targets that need a gait, per seed the shares, and :func:`decide_needed_gait`."""
    shares = needed_gait_shares(found, several)
    if not shares:
        return []
    needing = targets_needing(found, several)
    lines = ["## The gait the task needs", "",
             "Each gait's fastest command (its box's corner farthest from standing): "
             + ", ".join(f"{name} {speed:.2f} m/s" for name, speed in sorted(top.items())) + ". Targets only some "
             "gaits reach: " + ", ".join(f"{speed:.2f} m/s ({needed.replace('|', ', ')})" for speed, needed in needing)
             + ".", "", "| seed | the needed gaits' share where they are needed | their share where any gait will do |",
             "|---|---|---|"]
    lines += [f"| {seed} | {100 * fast:.0f} % | {100 * slow:.0f} % |" for seed, (fast, slow) in shares.items()]
    lines += ["", f"The test \"the planner picks the gait a target needs\" (the share higher by at least "
              f"{NEEDED_GAIT_EFFECT:.0%}, paired over seeds): {decide_needed_gait(shares).text()}.", ""]
    return lines


def segments(targets: list[float]) -> list[tuple[int, int]]:
    """``(first, end)`` action indices of each stretch of one target speed, in order."""
    bounds = [0] + [a for a in range(1, len(targets)) if targets[a] != targets[a - 1]] + [len(targets)]
    return list(zip(bounds, bounds[1:]))


def profile_markdown(found: list[dict], costs: list[dict], gaits: dict, *, own: str, several: str, title: str,
                     top: dict[str, float] | None = None) -> str:
    """Per profile task: per stretch of one target speed, each gait's share of the several-gait runs' actions, their
    switches, and the CoM's speed along the target with each library; where the switches fall (at a change of
    target or inside a stretch); the normalised cost of both libraries with the test "several gaits cost as little
    as the own gait" (``docs/statistics.md``); with ``top`` (each gait's fastest command, ``gait_boxes``), which
    targets need a gait and whether the planner picks it (:func:`needed_gait_markdown`)."""
    from hierloco.stats import decide_close
    from hierloco.claims import seed_means

    names = sorted(gaits)
    lines = [f"# Gait transitions on a speed profile ({title})", ""]
    for task in dict.fromkeys(r["task"] for r in found):
        of = [r for r in found if r["task"] == task]
        episodes: dict = {}
        for r in of:
            episodes.setdefault((r["method"], r["seed"], r["episode"]), []).append(r)
        mixed = [sequence for (method, _, _), sequence in episodes.items() if method == several]
        reference = next(iter(episodes.values()))
        stretches = segments([r["target_speed"] for r in reference])
        lines += [f"## {task.replace('_', ' ')}", "",
                  f"Each latent action's gait in the {several} runs ({len(mixed)} episodes), and the CoM's speed "
                  "along the target (m/s, mean over seeds and episodes) with each library.", "",
                  f"| actions | target (m/s) | {' | '.join(names)} | switches inside | speed, {several} | "
                  f"speed, {own} |", "|---|---|" + "---|" * len(names) + "---|---|---|"]
        for first, end in stretches:
            chosen = [r["gait"] for sequence in mixed for r in sequence[first:end]]
            inside = [switches([r["gait"] for r in sequence[first:end]]) for sequence in mixed]
            speed = {method: [r["speed"] for (m, _, _), sequence in episodes.items() if m == method
                              for r in sequence[first:end]] for method in (several, own)}
            shares = " | ".join(f"{100 * chosen.count(name) / max(1, len(chosen)):.0f} %" for name in names)
            lines.append(f"| {first}-{end - 1} | {reference[first]['target_speed']:.2f} | {shares} | "
                         f"{np.mean(inside) if inside else float('nan'):.1f} | "
                         f"{f'{np.mean(speed[several]):.3f}' if speed[several] else '-'} | "
                         f"{f'{np.mean(speed[own]):.3f}' if speed[own] else '-'} |")
        changes = {first for first, _ in stretches[1:]}
        at_change = sum(sequence[a]["gait"] != sequence[a - 1]["gait"] for sequence in mixed for a in changes)
        total = sum(switches([r["gait"] for r in sequence]) for sequence in mixed)
        chance = len(changes) / max(1, len(reference) - 1)
        lines += ["", f"Switches: {total} in all, {at_change} at the first action after a change of target "
                  f"({100 * at_change / max(1, total):.0f} %; {100 * chance:.0f} % of the action boundaries are "
                  "changes of target).", ""]
        fastest = max(r["target_speed"] for r in reference)
        lines += [f"Per seed, each gait's share of the actions at the fastest target ({fastest:.2f} m/s) and at the "
                  "others (a gait picked for speed is picked more at the fastest target in every seed):", "",
                  f"| seed | {' | '.join(names)} |", "|---|" + "---|" * len(names)]
        for seed in sorted({s for (m, s, _) in episodes if m == several}):
            mine = [r for (m, s, _), sequence in episodes.items() if m == several and s == seed for r in sequence]
            fast = [r["gait"] for r in mine if r["target_speed"] == fastest]
            slow = [r["gait"] for r in mine if r["target_speed"] != fastest]
            cells = [f"{100 * fast.count(n) / max(1, len(fast)):.0f} % / "
                     f"{100 * slow.count(n) / max(1, len(slow)):.0f} %" for n in names]
            lines.append(f"| {seed} | {' | '.join(cells)} |")
        lines.append("")
        a, b = (seed_means(costs, method=method, robot=costs[0]["robot"] if costs else "", setting="normal",
                           task=task) for method in (several, own))
        verdict = decide_close(a, b).text() if a.size and b.size else "not measured"
        lines += [f"| normalised cost | {own} | {several} | verdict |", "|---|---|---|---|",
                  f"| {task.replace('_', ' ')} | {b.mean() if b.size else float('nan'):.3f} | "
                  f"{a.mean() if a.size else float('nan'):.3f} | {verdict} |", ""]
    if top:
        lines += needed_gait_markdown(found, several, top)
    return "\n".join(lines)


def write_profile(cfg, spec, results, out: Path, *, own: str, several: str) -> None:
    """``profile.csv`` (one row per action, :func:`profile_rows` of the profile jobs' per-action tables),
    ``profile.md`` and ``gait_<task>_profile.png`` (the first several-gait episode whose run directory is here, from
    two actions before the fastest target) in ``out``."""
    from hierloco.plots import plot_gait_diagram
    from hierloco.results import csv_text

    gaits = gaits_of(cfg)
    found = profile_rows((seed_of(r.job), r.job.labels["method"], r.actions) for r in results
                         if r.ok and r.actions is not None)
    costs = [{**row, **r.job.labels} for r in results if r.ok for row in r.rows if row["setting"] == "normal"]
    title = f"{spec.name}, {cfg.preset_name} preset, seeds {list(cfg.seeds)}"
    if not found:
        write_text(out / "profile.md", f"# Gait transitions on a speed profile ({title})\n\nNo job finished.\n"
                   + missing_markdown(results))
        return
    write_text(out / "profile.csv", csv_text(found, list(found[0])))
    write_text(out / "profile_costs.csv", csv_text(costs, list(costs[0])))
    write_text(out / "profile.md", profile_markdown(found, costs, gaits, own=own, several=several, title=title,
                                                    top=top_speeds(cfg) if boxes_of(cfg) else None)
               + missing_markdown(results))
    print((out / "profile.md").read_text())
    first = next((r for r in results if r.ok and r.job.labels["method"] == several and here(r)), None)
    if first is None:  # the contacts a diagram draws are in the run directories, not in the records
        return
    legs, steps = gait_context(first.job)
    for task in profile_of(cfg):
        sequence = [r for r in found if r["task"] == task and r["method"] == several and r["seed"] == seed_of(first.job)
                    and r["episode"] == 0]
        fastest = max(range(len(sequence)), key=lambda a: (sequence[a]["target_speed"], -a))
        start = max(0, min(fastest - 2, len(sequence) - DIAGRAM_ACTIONS))
        window = sequence[start:start + DIAGRAM_ACTIONS]
        contacts = evaluation_arrays(first.job, task)["foot_contacts"][0][start * steps:(start + len(window)) * steps]
        speeds = " ".join(f"{r['target_speed']:g}" for r in window)
        plot_gait_diagram(contacts, legs, out / f"gait_{task}_profile.png", action_steps=steps,
                          title=f"{task.replace('_', ' ')}, actions {start}-{start + len(window) - 1}: "
                                + " ".join(r["gait"] for r in window) + f" (targets {speeds} m/s)")


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
