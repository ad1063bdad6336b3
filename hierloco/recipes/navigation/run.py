"""Navigation in clutter (Li et al., RA-L 2021, Sec. I, Fig. 2: LAT "can directly be used with waypoint navigation
methods to reach a desired goal"), as jobs on Ray: robots x seeds, each LAT run evaluated on every arena.

    hierloco study navigation records=results/navigation/records out_dir=results/navigation   # paper scale
    hierloco study navigation 'robots=[a1]' 'seeds=[0]' 'arenas=[0]' preset=small

An arena is a :class:`hierloco.envs.navigation.Navigation` task (``navigation_arena<k>``: :func:`cluttered_arena` of
seed ``k``, an A* path inflated by the robot's footprint, LAT's trajectory tracking along it with the boxes in the
world). Per robot and seed one LAT job (``<runs_dir>/<robot>_seed<seed>``) evaluates every arena and nothing else;
it starts from the trained stages of the LAT run in ``lat_runs`` when one is there (their keys checked), so a
machine that ran the comparison trains nothing again. Writes in ``out_dir``: ``navigation.csv`` (one row per robot,
seed and arena: normalised cost, distance to the goal at the end, goal reached, mean distance to the path, closest
approach of the CoM to a box), ``navigation.md`` (per robot and arena over seeds, then per robot), ``wallclock.md``
and, where the run directories are here, ``<robot>_arena<k>.png`` (the arena, the planned path and every seed's CoM
path). The claim's test over seeds: ``hierloco verdicts`` (``docs/statistics.md``).
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists, override_value
from hierloco.pipeline.study import end_study, missing_markdown, refuse, run_study, seed_problems, study_main, study_robots

COLUMNS = ["robot", "seed", "arena", "task", "normalized_cost", "final_error", "success", "path_distance",
           "clearance", "path_length", "inflation"]


def task_name(arena: int) -> str:
    return f"navigation_arena{arena}"


def inflation_of(cfg, spec) -> float:
    """The inflation (m) for robot ``spec``: ``inflation``, or its footprint radius + the margin."""
    from hierloco.envs.navigation import FOOTPRINT_MARGIN, footprint_radius

    value = cfg.inflation if cfg.inflation is not None else footprint_radius(spec) + FOOTPRINT_MARGIN
    return round(float(value), 3)  # a stable number in the evaluation's key


def arena_tasks(cfg, spec) -> dict:
    """The ``eval.tasks`` of robot ``spec``'s jobs: one navigation task per arena."""
    inflation = inflation_of(cfg, spec)
    return {task_name(a): {"task": "navigation", "arena_seed": a, "num_obstacles": cfg.num_obstacles,
                           "goal": list(cfg.goal), "inflation": inflation, "speed": cfg.speed,
                           "extra_steps": cfg.extra_steps} for a in cfg.arenas}


def check(cfg) -> list:
    """The robots; raises one ConfigError naming every problem (an arena without a path among them), before any
    job runs."""
    from hierloco.envs.tasks import make_task

    as_lists(cfg, ("robots", "seeds", "arenas", "videos", "overrides", "goal"))
    problems = []
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    problems += [f"arena {a!r} is not an integer >= 0" for a in cfg.arenas if not (isinstance(a, int) and a >= 0)]
    problems += [] if list(cfg.arenas) else ["arenas is empty"]
    problems += [f"videos: arena {a!r} is not in arenas {list(cfg.arenas)}" for a in cfg.videos or []
                 if a not in cfg.arenas]
    if cfg.inflation is not None and not (isinstance(cfg.inflation, (int, float)) and cfg.inflation >= 0):
        problems.append(f"inflation must be a number >= 0 (m) or null, got {cfg.inflation!r}")
    if not problems:
        for spec in robots:
            for name, options in arena_tasks(cfg, spec).items():
                try:
                    make_task(options["task"], name=name, **{k: v for k, v in options.items() if k != "task"})
                except ValueError as error:
                    problems.append(f"{spec.name} {name}: {error}")
    refuse(problems)
    return robots


def jobs(cfg, robots) -> list:
    planned = []
    for spec in robots:
        tasks = arena_tasks(cfg, spec)
        videos = "[" + ",".join(task_name(a) for a in cfg.videos or []) + "]"
        for seed in cfg.seeds:
            name = f"{spec.name}_seed{seed}"
            overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}", "settings=[normal]",
                         "progress=false", "~eval.tasks", f"+eval.tasks={override_value(tasks)}",
                         "eval.generalization=null", f"eval.videos={videos}", *cfg.overrides]
            planned.append(studies.Job("lat", str(Path(cfg.runs_dir) / name), overrides, labels={"method": "lat"},
                                       reuse_from=str(Path(cfg.lat_runs) / name) if cfg.lat_runs else None))
    return planned


def navigation_rows(rows: list[dict], cfg, robots) -> list[dict]:
    """One row per robot, seed and arena (each arena's task is one episode)."""
    arenas = {task_name(a): int(a) for a in cfg.arenas}
    extra = {spec.name: arena_tasks(cfg, spec) for spec in robots}
    out = []
    for row in rows:
        if row["task"] not in arenas:
            continue
        options = extra[row["robot"]][row["task"]]
        out.append({"robot": row["robot"], "seed": int(row["seed"]), "arena": arenas[row["task"]],
                    "task": row["task"], **{k: row.get(k, float("nan")) for k in COLUMNS[4:9]},
                    "path_length": _path_length(options), "inflation": options["inflation"]})
    return sorted(out, key=lambda r: (r["robot"], r["arena"], r["seed"]))


def _path_length(options: dict) -> float:
    from hierloco.envs.tasks import make_task

    return round(make_task("navigation", **{k: v for k, v in options.items() if k != "task"}).length, 3)


def _mean_std(values, digits: int = 3) -> str:
    values = np.asarray([float(v) for v in values], dtype=float)
    values = values[np.isfinite(values)]
    return f"{values.mean():.{digits}f} +- {values.std():.{digits}f}" if len(values) else "-"


def navigation_markdown(rows: list[dict], *, title: str) -> str:
    """Per robot and arena, then per robot over all arenas: mean +- std over seeds."""
    header = ("| robot | arena | path (m) | inflation (m) | seeds | normalised cost | goal error (m) | reached | "
              "distance to the path (m) | closest CoM to a box (m) |")
    lines = [f"# Navigation ({title})", "", "Each arena's planned path followed by LAT; mean +- std over seeds. Goal "
             "error: the CoM's distance to the goal at the end (reached: within 0.2 m). The claim's test over seeds: "
             "`results/paper_check.md` (`hierloco verdicts`).", "", header, "|---" * 10 + "|"]
    groups = [(robot, arena) for robot in sorted({r["robot"] for r in rows})
              for arena in sorted({r["arena"] for r in rows if r["robot"] == robot})] + \
             [(robot, None) for robot in sorted({r["robot"] for r in rows})]
    for robot, arena in groups:
        of = [r for r in rows if r["robot"] == robot and (arena is None or r["arena"] == arena)]
        reached = sum(float(r["success"]) == 1.0 for r in of)
        path = f"{of[0]['path_length']:.2f}" if arena is not None else "-"
        lines.append(f"| {robot} | {arena if arena is not None else 'all'} | {path} | {of[0]['inflation']:.2f} | "
                     f"{len({r['seed'] for r in of})} | {_mean_std([r['normalized_cost'] for r in of])} | "
                     f"{_mean_std([r['final_error'] for r in of], 2)} | {reached}/{len(of)} | "
                     f"{_mean_std([r['path_distance'] for r in of])} | {_mean_std([r['clearance'] for r in of], 2)} |")
    return "\n".join(lines) + "\n"


def arena_figures(results, cfg, robots, out: Path) -> list[Path]:
    """Per robot and arena: the arena, its planned path and the CoM path of every seed whose run directory is here
    (the evaluation artifacts its plan names, each checked against its key)."""
    from hierloco.envs.tasks import make_task
    from hierloco.io import load_arrays
    from hierloco.pipeline.rundir import RunDirectory
    from hierloco.plots import plot_navigation

    written = []
    for spec in robots:
        mine = [r for r in results if r.ok and Path(r.job.run_dir).name.startswith(f"{spec.name}_seed")
                and Path(r.job.run_dir).is_dir()]
        for name, options in arena_tasks(cfg, spec).items():
            paths, seeds = [], []
            for result in mine:
                plan = {s.name: s for s in studies.planned_stages(result.job)}
                stage = plan[f"evaluation_normal_{name}"]
                directory = RunDirectory(result.job.run_dir, readonly=True)
                if directory.check(stage.name, stage.key, stage.filename):
                    paths.append(load_arrays(directory.path / stage.filename)[0]["com_paths"][0, :, :2])
                    seeds.append(Path(result.job.run_dir).name.rsplit("seed", 1)[1])
            if not paths:
                continue
            task = make_task("navigation", **{k: v for k, v in options.items() if k != "task"})
            written.append(out / f"{spec.name}_arena{options['arena_seed']}.png")
            plot_navigation(task.arena, task.path.numpy(), paths, written[-1], inflation=task.inflation,
                            labels=[f"CoM, seed {s}" for s in seeds],
                            title=f"LAT {spec.name}: arena {options['arena_seed']}, seeds {', '.join(seeds)}")
    return written


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.pipeline.report import wallclock_markdown
    from hierloco.results import csv_text

    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = navigation_rows(studies.rows_of(results), cfg, robots)
    out = Path(cfg.out_dir)
    write_text(out / "wallclock.md", wallclock_markdown(results))
    if rows:
        title = (f"{cfg.preset_name} preset, seeds {list(cfg.seeds)}, arenas {list(cfg.arenas)} of "
                 f"{cfg.num_obstacles} boxes, goal {list(cfg.goal)} m, {cfg.speed} m/s")
        summary = navigation_markdown(rows, title=title)
        write_text(out / "navigation.csv", csv_text(rows, COLUMNS))
        write_text(out / "navigation.md", summary + missing_markdown(results))
        figures = arena_figures(results, cfg, robots, out)
        print("\n" + summary + (f"\nfigures: {', '.join(p.name for p in figures)}" if figures else
                                "\nno arena figures: the run directories are not here (records only)"))
    print(f"navigation tables in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
