"""Off the lab floor (``docs/terrain.md``): the methods trained on flat ground, evaluated on terrain and under pushes,
training nothing, as jobs on Ray.

    hierloco study terrain                                  # A1 and Daisy, LAT LIB IK SAC SAC-SAC, paper scale
    hierloco study terrain robots=[a1] seeds=[0] methods=[lat] preset=small 'terrains=[rough,stairs]'

Per method, robot and seed one job (``<runs_dir>/<method>/<robot>_seed<seed>``) starts from the trained stages of the
comparison's run directory (``trained_runs``; their keys checked) and evaluates, as extra evaluation tasks of that
run (``eval.generalization``), every task of ``tasks`` on every terrain of ``terrains`` at every difficulty of
``levels`` (``<task>_<terrain><100 x level>``, e.g. ``goal_reaching_rough025``; a seeded terrain is drawn from the
job's seed), and every task of ``pushes.tasks`` on flat ground under pushes of each size of
``pushes.magnitudes_mps`` (``<task>_push<100 x m/s>``). A job whose trained stages are missing from both its own run
directory and ``trained_runs`` is refused before any work (one line, exit 2): this study trains nothing.

Writes in ``out_dir``: ``terrain.csv`` (one row per episode, with its terrain, difficulty, push size, whether the
robot fell and, with pushes, the pushes taken, not survived and recovered from, and the time to recover),
``terrain.md`` (normalised cost, goals reached and falls against difficulty per method and robot, then the
flat-ground evaluations of the comparison for reference), ``pushes.md`` (fall rate and time to recover against push
size; the largest push survived), ``success_<robot>.png`` (goals reached, falls and cost against difficulty, one
panel per terrain, as legged_gym's success against terrain level), ``pushes_<robot>.png``, ``terrains.png`` (every
terrain at every level, rendered) and ``wallclock.md``; with LAT variants among the methods (LAT made for terrain:
``variants`` whose recipe is ``lat``, each trained beforehand into ``trained_runs``), ``variants.md``: each against
plain LAT by the stated tests paired by seed.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

import math
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists, compose_recipe, override_value
from hierloco.pipeline.study import (
    end_study, method_problems, missing_markdown, ray_problems, refuse, run_study, seed_problems, study_main,
    study_robots,
)
from hierloco.recipes.compare.run import name_problems, renamed

LABELS = ("base_task", "terrain", "level", "push_mps")
WORLD_COLUMNS = ("fell", "pushes", "push_falls", "pushes_recovered", "recovery_s")


def physical_size(terrain: str, level: float) -> str:
    """What ``level`` (a difficulty) means on a built-in terrain, in words (``docs/terrain.md``)."""
    from hierloco.envs import terrain as t

    sizes = {"rough": f"{100 * t.ROUGH_MAX_AMPLITUDE_M * level:.0f} cm bumps",
             "slope": f"{math.degrees(t.SLOPE_MAX_ANGLE_RAD * level):.0f} deg slopes",
             "stairs": f"{100 * t.STAIRS_MAX_STEP_HEIGHT_M * level:.0f} cm steps",
             "blocks": f"{100 * t.BLOCKS_MAX_HEIGHT_M * level:.0f} cm blocks",
             "slippery": "friction {:.2f}".format(t.SLIPPERY_FRICTION_RANGE[0] + level * (
                 t.SLIPPERY_FRICTION_RANGE[1] - t.SLIPPERY_FRICTION_RANGE[0]))}
    return sizes.get(terrain, f"difficulty {level:g}")


def terrain_task(task: str, terrain: str, level: float) -> str:
    return f"{task}_{terrain}{int(round(100 * level)):03d}"


def push_task(task: str, magnitude: float) -> str:
    return f"{task}_push{int(round(100 * magnitude)):03d}"


def main_task_specs(recipe: str, preset: str) -> dict:
    """The main evaluation tasks of ``recipe`` at ``preset`` (name -> spec), as its runs evaluated them."""
    tasks = compose_recipe(recipe, [f"preset={preset}"]).eval.tasks
    return {name: dict(spec or {}) for name, spec in OmegaConf.to_container(tasks, resolve=True).items()}


def generalization_overrides(recipe: str, preset: str, tasks: dict) -> list[str]:
    """The overrides that make ``tasks`` a job's extra evaluation tasks in place of the preset's generalisation
    tasks (which the small preset leaves null: set, not deleted and added)."""
    value = override_value(tasks)
    if compose_recipe(recipe, [f"preset={preset}"]).eval.get("generalization") is None:
        return [f"eval.generalization={value}"]
    return ["~eval.generalization", f"+eval.generalization={value}"]


def studied_tasks(cfg) -> list[str]:
    return list(cfg.tasks) if cfg.tasks else list(main_task_specs("lat", cfg.preset_name))


def condition_tasks(cfg, main: dict, seed: int) -> dict:
    """The extra evaluation tasks of one job (name -> spec with its world), each of one main task's type and options:
    on every terrain and level, and under every push size."""
    def of(task: str) -> dict:
        return {"task": main[task].get("task", task), **{k: v for k, v in main[task].items() if k != "task"}}

    tasks = {}
    for task in studied_tasks(cfg):
        for terrain in cfg.terrains:
            for level in cfg.levels:
                tasks[terrain_task(task, terrain, level)] = {
                    **of(task), "terrain": {"name": terrain, "difficulty": float(level), "seed": int(seed)}}
    for task in cfg.pushes.tasks:
        for magnitude in cfg.pushes.magnitudes_mps:
            tasks[push_task(task, magnitude)] = {**of(task), "pushes": {
                "magnitude_mps": float(magnitude), "interval_s": [float(v) for v in cfg.pushes.interval_s]}}
    return tasks


def task_labels(cfg) -> dict:
    """Evaluation task name -> its labels (``base_task``, ``terrain``, ``level``, ``push_mps``); the main tasks are
    the comparison's flat-ground evaluations."""
    labels = {}
    for task in studied_tasks(cfg):
        labels[task] = {"base_task": task, "terrain": "flat", "level": 0.0, "push_mps": 0.0}
        for terrain in cfg.terrains:
            for level in cfg.levels:
                labels[terrain_task(task, terrain, level)] = {"base_task": task, "terrain": terrain,
                                                              "level": float(level), "push_mps": 0.0}
    for task in cfg.pushes.tasks:
        labels.setdefault(task, {"base_task": task, "terrain": "flat", "level": 0.0, "push_mps": 0.0})
        for magnitude in cfg.pushes.magnitudes_mps:
            labels[push_task(task, magnitude)] = {"base_task": task, "terrain": "flat", "level": 0.0,
                                                  "push_mps": float(magnitude)}
    return labels


def seeds_of(cfg, method: str) -> list:
    return list(cfg.method_seeds.get(method, cfg.seeds)) if cfg.method_seeds else list(cfg.seeds)


def check(cfg) -> list:
    """The robots; raises one ConfigError naming every problem, before any job runs."""
    from hierloco.envs.terrain import TERRAINS, TerrainError, make_pushes, make_terrain

    as_lists(cfg, ("robots", "seeds", "methods", "terrains", "levels", "tasks", "overrides", "pushes.magnitudes_mps",
                   "pushes.tasks"))
    problems = []
    problems += method_problems(cfg.methods, cfg.variants)
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    for method, seeds in (cfg.method_seeds or {}).items():
        if method not in cfg.methods:
            continue  # seeds of a method not studied now
        if not OmegaConf.is_list(seeds) or not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds):
            problems.append(f"method_seeds.{method} must be a non-empty list of integers >= 0, got {seeds!r}")
    problems += name_problems(cfg.names or {}, cfg.methods)
    main = main_task_specs("lat", cfg.preset_name)
    for task in [*(cfg.tasks or []), *cfg.pushes.tasks]:
        if task not in main:
            problems.append(f"task {task!r} is not a main task of the {cfg.preset_name} preset ({', '.join(main)})")
    for terrain in cfg.terrains:
        if terrain not in TERRAINS or terrain == "flat" or "difficulty" not in TERRAINS.options(terrain):
            problems.append(f"terrains: {terrain!r} is not a terrain with a difficulty (built in: rough, slope, "
                            "stairs, blocks, slippery; a file is a recipe's terrain, not this study's)")
    levels = list(cfg.levels)
    if cfg.terrains and not levels:
        problems.append("levels is empty")
    for level in levels:
        if isinstance(level, bool) or not isinstance(level, (int, float)) or not 0 <= level <= 1:
            problems.append(f"levels: {level!r} is not a difficulty in [0, 1]")
    if len({int(round(100 * v)) for v in levels if isinstance(v, (int, float))}) != len(levels):
        problems.append(f"levels {levels} name a difficulty twice (to 0.01)")
    if not problems:
        for terrain in cfg.terrains:  # each one made now: a bad option is said before any job
            for level in levels:
                try:
                    make_terrain(terrain, difficulty=float(level))
                except TerrainError as error:
                    problems.append(str(error))
    magnitudes = list(cfg.pushes.magnitudes_mps)
    for magnitude in magnitudes:
        try:
            if make_pushes({"magnitude_mps": magnitude, "interval_s": list(cfg.pushes.interval_s)}).magnitude_mps <= 0:
                problems.append(f"pushes.magnitudes_mps: {magnitude!r} is not a push (give sizes > 0 m/s)")
        except (TerrainError, TypeError) as error:
            problems.append(str(error).replace("pushes: ", "pushes."))
    if magnitudes and not cfg.pushes.tasks:
        problems.append("pushes.tasks is empty: name the tasks the pushes are evaluated on")
    rate = cfg.survival_fall_rate
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 <= rate <= 1:
        problems.append(f"survival_fall_rate must be a number in [0, 1], got {rate!r}")
    pattern = str(cfg.trained_runs)
    missing = [part for part in ("{method}", "{robot}", "{seed}") if part not in pattern]
    if missing:
        problems.append(f"trained_runs must name {', '.join(missing)} (e.g. outputs/{{method}}/{cfg.preset_name}/"
                        "{robot}_seed{seed}), got " + repr(pattern))
    problems += ray_problems(cfg)
    refuse(problems)
    return robots


def trained_as(cfg, method: str) -> str:
    """The method whose trained runs a method's jobs start from: a variant's ``trained_as`` (a variant that changes
    only how it is evaluated, say ``lat_replan``, starts from plain LAT's runs), else the method itself."""
    variant = (cfg.variants or {}).get(method) or {}
    return str(variant.get("trained_as") or method)


def jobs(cfg, robots) -> list:
    planned = []
    for spec in robots:
        for method in cfg.methods:
            recipe, variant = studies.resolve_method(method, cfg.variants)
            main = main_task_specs(recipe, cfg.preset_name)
            for seed in seeds_of(cfg, method):
                extra = condition_tasks(cfg, main, seed)
                overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                             "settings=[normal]", "progress=false", *variant, *cfg.overrides,
                             *(cfg.method_overrides or {}).get(method, []), "eval.videos=[]", "eval.figures=false",
                             *generalization_overrides(recipe, cfg.preset_name, extra)]
                trained = str(cfg.trained_runs).format(method=trained_as(cfg, method), robot=spec.name, seed=seed)
                planned.append(studies.Job(recipe, str(Path(cfg.runs_dir) / method / f"{spec.name}_seed{seed}"),
                                           overrides, labels={"method": method}, reuse_from=trained))
    return planned


def check_trained(cfg, planned: list) -> None:
    """Refuses, in one line, the jobs that would train: a training stage neither finished in the job's run directory
    nor reusable from its trained run (``trained_runs``), unless the job is taken from its record."""
    from hierloco.pipeline.rundir import RunDirectory

    missing = []
    for job in planned:
        specs = studies.planned_stages(job)
        training = [spec.name for spec in specs if not spec.name.startswith("evaluation_")]
        if cfg.get("records") and studies.recorded(job, cfg.records, specs) is not None:
            continue
        have = set()
        if Path(job.run_dir).is_dir():
            try:
                have = {name for name, ok in RunDirectory(job.run_dir, readonly=True).verify(specs).items() if ok}
            except Exception:  # noqa: BLE001  (made with another config: the trained run must give the stages)
                have = set()
        try:
            have |= {spec.name for spec in studies.reusable_stages(job, specs)}
        except Exception:  # noqa: BLE001  (no trained run there)
            pass
        lacking = [name for name in training if name not in have]
        if lacking:
            missing.append(f"{job.labels['method']} {Path(job.run_dir).name} (no finished {', '.join(lacking)} in "
                           f"{job.reuse_from})")
    if missing:
        raise ConfigError(f"the terrain study trains nothing; {len(missing)} job(s) have no trained run: "
                          + "; ".join(missing[:3]) + ("; ..." if len(missing) > 3 else "")
                          + ": run the comparison first (hierloco study compare with the same preset, robots, seeds "
                            "and overrides) or point trained_runs at the trained runs")


def labelled_rows(rows: list[dict], cfg) -> list[dict]:
    """The rows of the studied evaluations, each with its labels (:func:`task_labels`)."""
    labels = task_labels(cfg)
    return [{**row, **labels[row["task"]]} for row in rows if row["task"] in labels]


def _mean_std(values, digits: int = 2) -> str:
    values = np.asarray([float(v) for v in values], dtype=float)
    values = values[np.isfinite(values)]
    return f"{values.mean():.{digits}f} +- {values.std():.{digits}f}" if len(values) else "-"


def _count(rows, key: str) -> str:
    values = [float(r[key]) for r in rows if _finite(r.get(key))]
    return f"{int(round(sum(values)))}/{len(values)}" if values else "-"


def _finite(value) -> bool:
    try:
        return value is not None and value != "" and math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def goals(rows) -> list[dict]:
    """The rows of goal reaching (the tasks whose success is a goal reached)."""
    return [r for r in rows if r["base_task"].startswith("goal_reaching") and _finite(r.get("success"))]


def terrain_markdown(rows: list[dict], cfg, *, title: str) -> str:
    """Normalised cost, goals reached and falls against difficulty, per robot, method and terrain."""
    lines = [f"# Off the lab floor ({title})", "",
             "The comparison's runs, trained on flat ground, evaluated on each terrain (training nothing). Cost: "
             "normalised cost over the tasks' episodes and seeds, mean +- std (1 = no better than standing still); "
             "goals reached: goal-reaching episodes ending within 0.2 m of the goal; falls: episodes in which the "
             "robot fell. Difficulty 0 is flat ground for stairs and blocks and nearly so for the others "
             "(docs/terrain.md).",
             "", "| robot | method | terrain | difficulty | ground | cost | goals reached | falls |",
             "|---|---|---|---|---|---|---|---|"]
    on_terrain = [r for r in rows if r["terrain"] != "flat"]
    for robot in sorted({r["robot"] for r in on_terrain}):
        for method in sorted({r["method"] for r in on_terrain if r["robot"] == robot}, key=_method_order):
            for terrain in cfg.terrains:
                for level in cfg.levels:
                    of = [r for r in on_terrain if (r["robot"], r["method"], r["terrain"]) == (robot, method, terrain)
                          and r["level"] == float(level)]
                    if of:
                        cost = _mean_std([r["normalized_cost"] for r in of])
                        lines.append(f"| {robot} | {method} | {terrain} | {float(level):g} | "
                                     f"{physical_size(terrain, float(level))} | {cost} | "
                                     f"{_count(goals(of), 'success')} | {_count(of, 'fell')} |")
    flat = [r for r in rows if r["terrain"] == "flat" and r["push_mps"] == 0]
    if flat:
        lines += ["", "## Flat ground (the comparison's evaluations, for reference)", "",
                  "| robot | method | cost | goals reached |", "|---|---|---|---|"]
        for robot in sorted({r["robot"] for r in flat}):
            for method in sorted({r["method"] for r in flat if r["robot"] == robot}, key=_method_order):
                of = [r for r in flat if (r["robot"], r["method"]) == (robot, method)]
                lines.append(f"| {robot} | {method} | {_mean_std([r['normalized_cost'] for r in of])} | "
                             f"{_count(goals(of), 'success')} |")
    return "\n".join(lines) + "\n"


def lat_variants(cfg) -> list[str]:
    """The studied methods that are LAT made otherwise (a variant of the ``lat`` recipe: experts with more foot
    clearance on rough ground, a CoM model that reads the body state, dynamics data under randomised dynamics;
    ``variants`` of the config), when plain ``lat`` is studied too."""
    if "lat" not in cfg.methods:
        return []
    return [m for m in cfg.methods if m != "lat" and studies.resolve_method(m, cfg.variants)[0] == "lat"]


def variants_markdown(rows: list[dict], cfg, *, title: str) -> str:
    """Each LAT variant against plain LAT on every terrain and level (and the flat main tasks), by the stated tests
    over seeds paired by seed (:func:`hierloco.claims.variant_verdicts`, ``docs/statistics.md``)."""
    from hierloco.claims import variant_verdicts

    variants = lat_variants(cfg)
    tasks = sorted({r["task"] for r in rows if r["push_mps"] == 0 and r["method"] in ["lat", *variants]})
    described = "; ".join(f"`{m}`: " + " ".join(studies.resolve_method(m, cfg.variants)[1]) for m in variants)
    return "\n".join([
        f"# LAT made for terrain, against plain LAT ({title})", "",
        f"Variants ({described}), each trained as plain LAT is but for its overrides, then evaluated as the others on "
        "every terrain and level. Per place (robot, setting, task on a terrain at a difficulty), the variant's mean "
        "normalised cost per seed against plain LAT's of the same seed: \"better\" holds when the paired difference "
        "is significantly above 0 and at least the minimum effect; \"close\" when it is within the equivalence "
        "margin (docs/statistics.md). No correction over the places: read the tally as a screen.", "",
        variant_verdicts(rows, "lat", variants, tasks, reference_name="plain LAT")])


def _method_order(method: str):
    return (method != "lat", method)


def push_summary(rows: list[dict], survival_fall_rate: float) -> dict:
    """Per (robot, method): per push size its pushes, fall rate, recovered fraction and mean recovery time, and the
    largest size survived (at and below it every size's fall rate is at most ``survival_fall_rate``)."""
    summary = {}
    pushed = [r for r in rows if r["push_mps"] > 0]
    for robot, method in sorted({(r["robot"], r["method"]) for r in pushed}):
        sizes = {}
        for magnitude in sorted({r["push_mps"] for r in pushed}):
            of = [r for r in pushed if (r["robot"], r["method"], r["push_mps"]) == (robot, method, magnitude)]
            taken = sum(float(r.get("pushes", 0) or 0) for r in of)
            felled = sum(float(r.get("push_falls", 0) or 0) for r in of)
            recovered = sum(float(r.get("pushes_recovered", 0) or 0) for r in of)
            times = [(float(r["recovery_s"]), float(r["pushes_recovered"])) for r in of
                     if _finite(r.get("recovery_s")) and float(r.get("pushes_recovered", 0) or 0) > 0]
            weight = sum(n for _, n in times)
            sizes[magnitude] = {"pushes": taken, "fall_rate": felled / taken if taken else float("nan"),
                                "recovered": recovered / (taken - felled) if taken > felled else float("nan"),
                                "recovery_s": sum(t * n for t, n in times) / weight if weight else float("nan")}
        survived = None
        for magnitude, numbers in sizes.items():
            if not (numbers["pushes"] and numbers["fall_rate"] <= survival_fall_rate):
                break
            survived = magnitude
        summary[(robot, method)] = {"sizes": sizes, "largest_survived": survived}
    return summary


def push_markdown(summary: dict, *, title: str, survival_fall_rate: float) -> str:
    lines = [f"# Push recovery ({title})", "",
             "Flat ground; the trunk's velocity changes by the push size in a random direction every few seconds. "
             "Fall rate: pushes after which the robot fell before the next push or the episode's end (to one action) / "
             "pushes taken standing; recovered: of the pushes survived, those after which the CoM velocity (0.5 s "
             "mean) came back within 0.05 m/s of the error to the commanded velocity it had before the push; time to "
             f"recover: mean over those. Largest push survived: the largest size at and below which every size's fall "
             f"rate is at most {survival_fall_rate:g}.", "",
             "| robot | method | largest push survived (m/s) |", "|---|---|---|"]
    for (robot, method), item in summary.items():
        survived = item["largest_survived"]
        lines.append(f"| {robot} | {method} | {'none' if survived is None else f'{survived:g}'} |")
    lines += ["", "| robot | method | push (m/s) | pushes | fall rate | recovered | time to recover (s) |",
              "|---|---|---|---|---|---|---|"]
    for (robot, method), item in summary.items():
        for magnitude, n in item["sizes"].items():
            text = lambda v, f: "-" if not math.isfinite(v) else f.format(v)  # noqa: E731
            lines.append(f"| {robot} | {method} | {magnitude:g} | {int(n['pushes'])} | "
                         f"{text(n['fall_rate'], '{:.0%}')} | {text(n['recovered'], '{:.0%}')} | "
                         f"{text(n['recovery_s'], '{:.2f}')} |")
    return "\n".join(lines) + "\n"


def success_figure(rows: list[dict], cfg, robot: str, path: Path) -> None:
    """legged_gym's success against terrain level: per terrain (a column) goals reached, falls and normalised cost
    against difficulty, a line per method (mean over episodes and seeds)."""
    from hierloco.plots import plt, save_figure

    on = [r for r in rows if r["robot"] == robot and r["terrain"] != "flat"]
    methods = sorted({r["method"] for r in on}, key=_method_order)
    terrains = [t for t in cfg.terrains if any(r["terrain"] == t for r in on)]
    panels = [("goals reached", lambda of: np.mean([float(r["success"]) for r in goals(of)]) if goals(of) else np.nan),
              ("falls (fraction of episodes)", lambda of: np.mean([float(r["fell"]) for r in of])),
              ("normalised cost", lambda of: np.mean([float(r["normalized_cost"]) for r in of]))]
    fig, axes = plt.subplots(len(panels), len(terrains), figsize=(3.2 * len(terrains), 2.6 * len(panels)),
                             squeeze=False, sharey="row")
    colors = plt.cm.tab10(np.arange(max(1, len(methods))))
    for column, terrain in enumerate(terrains):
        for row_index, (label, measure) in enumerate(panels):
            ax = axes[row_index][column]
            for m, method in enumerate(methods):
                levels = sorted({r["level"] for r in on if (r["terrain"], r["method"]) == (terrain, method)})
                values = [measure([r for r in on if (r["terrain"], r["method"], r["level"]) == (terrain, method, lv)])
                          for lv in levels]
                ax.plot(levels, values, "o-", color=colors[m], label=method.upper())
            if row_index == 0:
                ax.set_title(f"{terrain} (1 = {physical_size(terrain, 1.0)})", fontsize=9)
            if row_index == len(panels) - 1:
                ax.set_xlabel("difficulty")
            if column == 0:
                ax.set_ylabel(label)
            if row_index < 2:  # fractions
                ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"{robot}: trained on flat ground, evaluated on terrain")
    save_figure(fig, path)


def push_figure(summary: dict, robot: str, path: Path) -> None:
    """Fall rate and time to recover against push size, a line per method."""
    from hierloco.plots import plt, save_figure

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for (of_robot, method), item in summary.items():
        if of_robot != robot:
            continue
        sizes = list(item["sizes"])
        axes[0].plot(sizes, [item["sizes"][s]["fall_rate"] for s in sizes], "o-", label=method.upper())
        axes[1].plot(sizes, [item["sizes"][s]["recovery_s"] for s in sizes], "o-", label=method.upper())
    for ax, label in zip(axes, ("fall rate (pushes not survived)", "time to recover (s)")):
        ax.set_xlabel("push (m/s)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{robot}: push recovery on flat ground")
    save_figure(fig, path)


def terrains_figure(cfg, robot, path: Path) -> str | None:
    """Every terrain of the study at every level, rendered with ``robot`` at the start; the reason when it cannot
    be rendered here, else ``None``."""
    from hierloco import render_backend
    from hierloco.plots import plt, save_figure
    from hierloco.render import render_terrain

    why = render_backend.unavailable()
    if why is not None:
        return why
    levels = list(cfg.levels)
    fig, axes = plt.subplots(len(cfg.terrains), len(levels), figsize=(2.6 * len(levels), 2.0 * len(cfg.terrains)),
                             squeeze=False)
    for i, terrain in enumerate(cfg.terrains):
        for j, level in enumerate(levels):
            ax = axes[i][j]
            ax.imshow(render_terrain({"name": terrain, "difficulty": float(level)}, robot, width=320, height=240))
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{terrain} {float(level):g}: {physical_size(terrain, float(level))}", fontsize=8)
    fig.suptitle(f"the terrains ({robot.name} for scale)")
    save_figure(fig, path)
    return None


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.pipeline.report import wallclock_markdown
    from hierloco.results import EPISODE_COLUMNS, csv_text

    robots = check(cfg)
    planned = jobs(cfg, robots)
    check_trained(cfg, planned)
    results = run_study(cfg, planned)
    rows = labelled_rows(renamed(studies.rows_of(results), OmegaConf.to_container(cfg.names or {})), cfg)
    out = Path(cfg.out_dir)
    write_text(out / "wallclock.md", wallclock_markdown(results))
    title = f"{cfg.preset_name} preset, seeds {list(cfg.seeds)}"
    if rows:
        write_text(out / "terrain.csv", csv_text(rows, [*EPISODE_COLUMNS, *LABELS, *WORLD_COLUMNS]))
        table = terrain_markdown(rows, cfg, title=title)
        write_text(out / "terrain.md", table + missing_markdown(results))
        if lat_variants(cfg):
            write_text(out / "variants.md", variants_markdown(rows, cfg, title=title))
        summary = push_summary(rows, float(cfg.survival_fall_rate))
        if summary:
            write_text(out / "pushes.md", push_markdown(summary, title=title,
                                                        survival_fall_rate=float(cfg.survival_fall_rate)))
        for spec in robots:
            if any(r["robot"] == spec.name and r["terrain"] != "flat" for r in rows):
                success_figure(rows, cfg, spec.name, out / f"success_{spec.name}.png")
            if any(robot == spec.name for robot, _ in summary):
                push_figure(summary, spec.name, out / f"pushes_{spec.name}.png")
        print("\n" + table)
    if cfg.render and cfg.terrains and robots:
        why = terrains_figure(cfg, robots[0], out / "terrains.png")
        if why is not None:
            print(f"no terrains.png: {why}")
    print(f"terrain tables in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
