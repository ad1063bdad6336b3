"""The latent action space's continuity (Li et al., RA-L 2021, Sec. III-B, Fig. 4), as jobs on Ray: robots x seeds.

    hierloco study latent_map records=results/latent_map/records out_dir=results/latent_map   # paper scale
    hierloco study latent_map 'robots=[daisy]' 'seeds=[0]' preset=tiny

Per robot and seed one LAT job (``<runs_dir>/<robot>_seed<seed>``) with a ``latent_dim``-D latent and the stage
``latent_continuity`` (:func:`hierloco.components.evaluation.latent_continuity`): every latent of a ``grid``-point
lattice over the learned box held ``num_actions`` actions from standing, its mean CoM velocity measured, and the mean
velocity difference of lattice neighbours against that of all pairs. Writes in ``out_dir``: ``latent_map.csv`` (one
row per robot and seed), ``latent_map.md`` (per robot over seeds) and ``wallclock.md``; each run draws its own map
(``<run>/figures/latent_map.png``). The claim's test over seeds: ``hierloco verdicts``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists, override_value
from hierloco.pipeline.study import end_study, missing_markdown, refuse, run_study, seed_problems, study_main, study_robots

STAGE = "latent_continuity"  # the stage (hierloco.pipeline.stages.latent_continuity_stage) whose report is read
COLUMNS = ["robot", "seed", "latent_dim", "grid", "neighbour_difference", "pair_difference", "ratio",
           "fell_fraction"]


def check(cfg) -> list:
    """The robots; raises one ConfigError naming every problem, before any job runs."""
    as_lists(cfg, ("robots", "seeds", "overrides"))
    problems = []
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    for name, least in (("latent_dim", 1), ("grid", 2), ("num_actions", 2)):
        value = cfg.get(name)
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= least):
            problems.append(f"{name} must be an integer >= {least}, got {value!r}")
    extra = cfg.get("robot_overrides") or {}
    if not hasattr(extra, "items"):
        problems.append(f"robot_overrides must map robot names to lists of overrides, got {extra!r}")
    else:
        problems += [f"robot_overrides.{name} must be a list of overrides, got {value!r}" for name, value
                     in extra.items() if isinstance(value, str) or not hasattr(value, "__iter__")]
    refuse(problems)
    return robots


def jobs(cfg, robots) -> list:
    measure = override_value({"grid": cfg.grid, "num_actions": cfg.num_actions})
    extra = cfg.get("robot_overrides") or {}
    planned = []
    for spec in robots:
        for seed in cfg.seeds:
            overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}", "settings=[normal]",
                         "progress=false", f"policy.latent_dim={cfg.latent_dim}", f"eval.latent_continuity={measure}",
                         *extra.get(spec.name, []), *cfg.overrides]
            planned.append(studies.Job("lat", str(Path(cfg.runs_dir) / f"{spec.name}_seed{seed}"), overrides,
                                       labels={"method": "lat"}))
    return planned


def continuity_rows(results) -> list[dict]:
    """One row per finished job: its ``latent_continuity`` stage's numbers (from its run's report, or its
    verified record's), with the robot and seed its rows name."""
    out = []
    for result in results:
        measured = (result.report or {}).get(STAGE)
        if not result.ok or not measured or not result.rows:
            continue
        first = result.rows[0]
        out.append({"robot": first["robot"], "seed": int(first["seed"]),
                    **{k: measured[k] for k in COLUMNS[2:]}})
    return sorted(out, key=lambda r: (r["robot"], r["seed"]))


def _mean_std(values, digits: int = 3) -> str:
    values = np.asarray(values, dtype=float)
    return f"{values.mean():.{digits}f} +- {values.std():.{digits}f}"


def continuity_markdown(rows: list[dict], *, title: str) -> str:
    """Per robot over seeds: the velocity difference of lattice neighbours and of all pairs, and their ratio."""
    lines = [f"# The latent space's continuity ({title})", "",
             "Each latent of a lattice over the learned box held from standing; its mean CoM velocity (m/s) over the "
             "actions after the first. Neighbours: lattice points one step apart along one axis; all pairs: every two "
             "lattice points (pairs with a fallen robot left out). Mean +- std over seeds. The claim's test over "
             "seeds: `results/paper_check.md` (`hierloco verdicts`).", "",
             "| robot | latent | lattice | seeds | neighbours (m/s) | all pairs (m/s) | ratio | fell |",
             "|---|---|---|---|---|---|---|---|"]
    for robot in sorted({r["robot"] for r in rows}):
        of = [r for r in rows if r["robot"] == robot]
        lines.append(f"| {robot} | {of[0]['latent_dim']}-D | {of[0]['grid']} per axis | {len(of)} | "
                     f"{_mean_std([r['neighbour_difference'] for r in of])} | "
                     f"{_mean_std([r['pair_difference'] for r in of])} | {_mean_std([r['ratio'] for r in of], 2)} | "
                     f"{_mean_std([100 * r['fell_fraction'] for r in of], 0)} % |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.pipeline.report import wallclock_markdown
    from hierloco.results import csv_text

    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = continuity_rows(results)
    out = Path(cfg.out_dir)
    write_text(out / "wallclock.md", wallclock_markdown(results))
    if rows:
        summary = continuity_markdown(rows, title=f"{cfg.preset_name} preset, seeds {list(cfg.seeds)}")
        write_text(out / "latent_map.csv", csv_text(rows, COLUMNS))
        write_text(out / "latent_map.md", summary + missing_markdown(results))
        print("\n" + summary)
    print(f"latent map tables in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
