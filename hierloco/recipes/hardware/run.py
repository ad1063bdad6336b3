"""Transfer to a perturbed "hardware" robot (Li et al., RA-L 2021, Sec. IV-D, in simulation), as jobs on Ray.

    hierloco study hardware                           # Daisy and A1, LAT and IK, 3 seeds, paper scale
    hierloco study hardware robots=[daisy] methods=[lat] '+hardware.servo_latency=0.04'
    hierloco study hardware robots=[daisy] 'hardware_world.terrain={name: rough, difficulty: 0.5}'

Each run learns its low level on the nominal robot (LAT: from 20 experts, as the paper's hardware low level), then
is evaluated in three settings: ``normal`` (the nominal robot), ``hardware_unadapted`` (the perturbed copy of
:func:`hierloco.envs.robots.hardware.perturbed`, planned with the nominal CoM model) and ``hardware`` (the same
copy, with the CoM model learned again on it from 2000 samples). ``hardware_world.terrain`` and
``hardware_world.randomization`` put the perturbed robot (its dynamics data and its evaluations, not the nominal
robot's) on a terrain and give it randomised dynamics: the lab floor the paper's hardware walked on, beside the
robot's own differences (docs/terrain.md, "The hardware gap"). Runs go in
``outputs/hardware/<preset>/<method>/<robot>_seed<seed>``, suffixed with the options that differ from the default
perturbation and with the perturbed robot's world (``daisy_seed0-servo_latency0.04``,
``daisy_seed0-on_rough0.5-randomized-world1a2b3c4d``), so studies of several gaps run side by side. Writes
``hardware.csv``, ``hardware.md`` (the paper's hardware metrics: goals reached and the steps to reach them,
tracking costs; then the full table and the perturbation used) and ``wallclock.md`` in ``out_dir``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from hierloco.io import write_text
from hierloco.results import EPISODE_COLUMNS, csv_text, markdown_table
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists
from hierloco.pipeline.study import end_study, method_problems, missing_markdown, refuse, run_study, study_main

SETTINGS = ("normal", "hardware_unadapted", "hardware")
LABELS = {"normal": "nominal robot", "hardware_unadapted": "perturbed, nominal model",
          "hardware": "perturbed, model re-learned"}
EXPERT_METHODS = ("lat", "lib")  # the recipes whose low level is learned from experts


def check(cfg) -> tuple[list, dict, dict]:
    """The robots, the perturbation options and the perturbed robot's world (``hardware_world``: only the options
    given); raises one ConfigError naming every problem."""
    from hierloco.envs.robots import get_robot, perturbed
    from hierloco.envs.terrain import TerrainError
    from hierloco.pipeline.config import HARDWARE_WORLD_KEYS, make_world

    as_lists(cfg, ("robots", "seeds", "methods", "overrides"))
    problems, robots = [], []
    problems += method_problems(cfg.methods, cfg.variants)
    options = OmegaConf.to_container(cfg.hardware, resolve=True) if cfg.hardware is not None else {}
    for robot in cfg.robots:
        try:
            robots.append(get_robot(robot))
            perturbed(robots[-1], **options)
        except (ValueError, OSError, TypeError) as error:
            problems.append(str(error))
    problems += [f"seed {s!r} is not an integer >= 0" for s in cfg.seeds if not (isinstance(s, int) and s >= 0)]
    for key in ("num_experts", "num_transitions"):
        if not (isinstance(cfg[key], int) and cfg[key] >= 10):
            problems.append(f"{key} must be an integer >= 10, got {cfg[key]!r}")
    given = OmegaConf.to_container(cfg.hardware_world, resolve=True) if cfg.get("hardware_world") else {}
    if not isinstance(given, dict) or set(given) - set(HARDWARE_WORLD_KEYS):
        problems.append(f"hardware_world must map {' and/or '.join(HARDWARE_WORLD_KEYS)} to a world, got {given!r}")
        given = {}
    world = {key: value for key, value in given.items() if value is not None}
    try:
        make_world(world)
    except TerrainError as error:
        problems.append(f"hardware_world: {error}")
    refuse(problems)
    return robots, options, world


def gap_tag(options: dict) -> str:
    """The run-directory suffix naming how ``options`` differ from the default perturbation (``""`` for none), so
    that a study of another gap runs beside the default's instead of being refused by its cached stages.

        >>> gap_tag({"servo_latency": 0.04, "motor_strength": 0.8})   # 0.8 is the default strength
        '-servo_latency0.04'
    """
    from hierloco.envs.robots import hardware_options

    default = hardware_options()
    text = lambda v: "_".join(f"{x:g}" for x in v) if isinstance(v, tuple) else f"{v:g}"  # noqa: E731
    return "".join(f"-{k}{text(v)}" for k, v in hardware_options(**options).items() if v != default[k])


def world_tag(world: dict) -> str:
    """The run-directory suffix naming the perturbed robot's world (``""`` for the simulation's own): the terrain
    and its difficulty, ``-randomized``, and a digest of every option, so that two worlds never share a folder.

        >>> world_tag({})
        ''
        >>> world_tag({"terrain": {"name": "rough", "difficulty": 0.5}})[:17]
        '-on_rough0.5-worl'
    """
    from hierloco.pipeline.config import make_world
    from hierloco.pipeline.rundir import digest

    built = make_world(world)
    if built.is_default:
        return ""
    parts = [f"-on_{built.terrain.registry_name}{built.terrain.difficulty:g}"] if built.terrain.key() else []
    parts += ["-randomized"] if built.randomization.active else []
    return "".join(parts) + f"-world{digest(built.params())[:8]}"


def jobs(cfg, robots, options: dict, world: dict | None = None) -> list:
    from hierloco.pipeline.config import override_value

    planned = []
    world = dict(world or {})
    tag = gap_tag(options) + world_tag(world)
    perturbation = [f"+hardware.{k}={list(v) if isinstance(v, (list, tuple)) else v}" for k, v in options.items()]
    perturbation += [f"+hardware_world.{k}={override_value(v)}" for k, v in world.items()]
    for spec in robots:
        for method in cfg.methods:
            recipe, variant = studies.resolve_method(method, cfg.variants)
            experts = [f"experts.num_experts={cfg.num_experts}"] if recipe in EXPERT_METHODS else []
            for seed in cfg.seeds:
                run_dir = Path("outputs") / "hardware" / cfg.preset_name / method / f"{spec.name}_seed{seed}{tag}"
                overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                             f"settings=[{','.join(SETTINGS)}]", f"dynamics.num_transitions={cfg.num_transitions}",
                             "progress=false", *experts, *perturbation, *variant, *cfg.overrides]
                planned.append(studies.Job(recipe, str(run_dir), overrides, labels={"method": method}))
    return planned


def _mean_std(values, digits: int = 2) -> str:
    values = np.asarray([v for v in values if np.isfinite(v)], dtype=float)
    return f"{values.mean():.{digits}f} +- {values.std():.{digits}f}" if len(values) else "-"


def hardware_table(rows: list[dict]) -> str:
    """The paper's hardware metrics per robot, method and setting: velocity-tracking and trajectory-tracking costs,
    goals reached, and the steps to reach them (mean +- std over the goals reached, over seeds)."""
    lines = ["| robot | method | setting | velocity tracking | goals reached | steps to goal | goal reaching | "
             "trajectory tracking |", "|---|---|---|---|---|---|---|---|"]
    keys = sorted({(r["robot"], r["method"]) for r in rows})
    for robot, method in keys:
        for setting in SETTINGS:
            of = [r for r in rows if (r["robot"], r["method"], r["setting"]) == (robot, method, setting)]
            if not of:
                continue
            task = lambda name: [r for r in of if r["task"] == name]  # noqa: E731
            goals = task("goal_reaching")
            reached = sum(float(r["success"]) == 1.0 for r in goals)
            cost = lambda name: _mean_std([r["normalized_cost"] for r in task(name)])  # noqa: E731
            lines.append(f"| {robot} | {method} | {LABELS[setting]} | {cost('velocity_tracking')} | "
                         f"{reached}/{len(goals)} | {_mean_std([r['steps_to_goal'] for r in goals], 1)} | "
                         f"{cost('goal_reaching')} | {cost('trajectory_tracking')} |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.envs.robots import hardware_options
    from hierloco.pipeline.report import wallclock_markdown

    from hierloco.pipeline.config import make_world

    robots, options, world = check(cfg)
    results = run_study(cfg, jobs(cfg, robots, options, world))
    rows = studies.rows_of(results)
    out = Path(cfg.out_dir)
    if rows:
        summary = hardware_table(rows)
        write_text(out / "hardware.csv", csv_text(rows, EPISODE_COLUMNS))
        used = ", ".join(f"{k} {v}" for k, v in hardware_options(**options).items())
        write_text(out / "hardware.md", f"# Transfer to a perturbed robot ({cfg.preset_name} preset, seeds "
                                        f"{list(cfg.seeds)})\n\nLow level from {cfg.num_experts} experts (LAT) on "
                                        f"the nominal robot; CoM models from {cfg.num_transitions} samples. "
                                        f"Perturbation: {used}. The perturbed robot's world: "
                                        f"{make_world(world).describe()}. Normalised costs, mean +- std over targets and "
                                        f"seeds; steps to goal over the goals reached.\n\n{summary}\n"
                                        f"## Every task\n\n{markdown_table(rows)}" + missing_markdown(results))
        write_text(out / "wallclock.md", wallclock_markdown(results))
        print("\n" + summary)
    print(f"hardware tables in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
