"""Compare methods (Li et al., RA-L 2021, Sec. IV-B and IV-C): every method's recipe on every robot and seed, as
jobs on Ray, then the comparison table and bar charts.

    hierloco study compare                           # LAT, LIB, IK, IK-plain, SAC, SAC-SAC on A1 and Daisy
    hierloco study compare robots=[a1] seeds=[0,1,2] preset=small ray.cores_per_job=2
    hierloco study compare seeds=[0,1,2] +method_seeds.sac=[0] +method_seeds.sac_sac=[0]   # fewer seeds for some
    RAY_ADDRESS=ray://head:10001 hierloco study compare seeds=[0,1,2]

Each method runs as its own recipe in its own run directory (``outputs/<method>/<preset>/<robot>_seed<seed>``), so
finished runs are reused. Writes ``comparison.csv``, ``comparison.md``, ``wallclock.md``,
``comparison_<setting>.png`` and ``paper_check.md`` (the paper's claims beside our numbers, ``paper_check.py``; each
claim that does not hold with the cause we checked, from the YAML file ``causes``) in ``out_dir``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from collections.abc import Mapping
from pathlib import Path

from omegaconf import OmegaConf

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import ConfigError, as_lists
from hierloco.pipeline.study import (
    chosen_targets, end_study, main_tasks, method_problems, ray_problems, refuse, rows_of, run_study, seed_problems,
    study_main, study_robots, write_tables,
)
from hierloco.recipes.compare import paper_check


def check(cfg) -> list:
    """The robots (resolved: names or YAML paths); raises one ConfigError naming every problem."""
    as_lists(cfg, ("methods", "robots", "seeds", "settings", "adverse_methods", "overrides"))
    problems = []
    problems += method_problems(cfg.methods, cfg.variants)
    robots = study_robots(cfg.robots, problems)
    problems += [f"unknown setting {s!r} (normal, legs_disabled)" for s in cfg.settings
                 if s not in ("normal", "legs_disabled")]
    problems += seed_problems(cfg.seeds)
    for method, seeds in cfg.method_seeds.items():
        if method not in cfg.methods:
            problems.append(f"method_seeds names {method!r}, which is not in methods {list(cfg.methods)}")
        elif not OmegaConf.is_list(seeds) or not seeds:
            problems.append(f"method_seeds.{method} must be a non-empty list of seeds, got {seeds!r}")
        else:
            problems += [f"method_seeds.{method}: seed {s!r} is not an integer >= 0" for s in seeds
                         if not (isinstance(s, int) and s >= 0)]
    problems += ray_problems(cfg)
    if cfg.causes is not None:
        try:
            paper_check.load_causes(cfg.causes)
        except ValueError as error:
            problems.append(str(error))
    problems += name_problems(cfg.names, cfg.methods)
    if not isinstance(cfg.generalization, bool):
        problems.append(f"generalization must be true or false, got {cfg.generalization!r}")
    refuse(problems)
    return robots


def name_problems(names, methods) -> list[str]:
    """What is wrong with a ``names`` mapping (method -> its name in the tables and claims): two of the methods
    (``methods`` and the ones it names) under one name would be pooled as one.

        >>> name_problems({"sac_sac_2x512": "sac_sac", "sac_sac": "sac_sac_2x256"}, ["lat", "sac_sac"])
        []
        >>> name_problems({"sac_sac_2x512": "sac_sac"}, ["sac_sac"])
        ["names: two methods would be shown as 'sac_sac'"]
    """
    if not isinstance(names, Mapping):
        return [f"names must be a mapping of method to name, got {names!r}"]
    problems = [f"names.{m}: {n!r} is not a name" for m, n in names.items() if not (isinstance(n, str) and n)]
    shown = [names.get(m, m) for m in dict.fromkeys([*methods, *names])]
    problems += [f"names: two methods would be shown as {n!r}" for n in sorted({n for n in shown
                                                                                  if shown.count(n) > 1})]
    return problems


def renamed(rows: list[dict], names) -> list[dict]:
    """``rows`` with each method under its name in the tables and claims (``names``: method -> name)."""
    return [{**row, "method": names.get(row["method"], row["method"])} for row in rows] if names else rows


def seeds_of(cfg, method: str) -> list[int]:
    """The seeds ``method`` runs with: ``method_seeds.<method>`` if given, else ``seeds``."""
    return list(cfg.method_seeds.get(method, cfg.seeds))


def seeds_text(cfg) -> str:
    """The seeds of the study, in words: ``seeds [0, 1, 2]`` or ``seeds [0, 1, 2] (sac: [0])``, each method under
    its name in the tables (``names``)."""
    names = dict(cfg.get("names") or {})
    others = ", ".join(f"{names.get(m, m)}: {seeds_of(cfg, m)}" for m in cfg.methods if m in cfg.method_seeds)
    return f"seeds {list(cfg.seeds)}" + (f" ({others})" if others else "")


def jobs(cfg, robots) -> list:
    planned = []
    generalization = [] if cfg.generalization else ["eval.generalization=null"]
    for robot, spec in zip(cfg.robots, robots):
        for method in cfg.methods:
            settings = [s for s in cfg.settings if s == "normal" or method in cfg.adverse_methods]
            if not settings:
                continue
            recipe, variant = studies.resolve_method(method, cfg.variants)
            for seed in seeds_of(cfg, method):
                planned.append(comparison_job(method, spec, seed, preset=cfg.preset_name, settings=settings,
                                              recipe=recipe, targets=chosen_targets(),
                                              overrides=[*generalization, *variant, *cfg.overrides,
                                                         *cfg.method_overrides.get(method, [])]))
    return planned


def comparison_job(method: str, spec, seed: int, *, preset: str, settings, recipe: str | None = None,
                   targets: str = "paper", overrides=("eval.generalization=null",)) -> studies.Job:
    """The comparison's job of ``method`` on the robot ``spec`` (a :class:`hierloco.envs.robots.spec.RobotSpec`) with
    ``seed``: its run directory ``outputs/<method>/<preset>/<robot>_seed<seed>`` and its overrides, so other studies
    (the sample-efficiency study's full budgets) name the same job and take its run or record. ``targets`` other
    than the paper's (``fair``, ``docs/tasks.md``) is the recipes' ``targets=`` and a run directory of its own,
    ``outputs/<method>/<preset>_<targets>/...``, beside the paper targets' run."""
    folder = preset if targets == "paper" else f"{preset}_{targets}"
    run_dir = Path("outputs") / method / folder / f"{spec.name}_seed{seed}"
    chosen = [] if targets == "paper" else [f"targets={targets}"]
    return studies.Job(recipe or method, str(run_dir),
                       [f"preset={preset}", f"robot={spec.reference}", f"seed={seed}",
                        f"settings=[{','.join(settings)}]", "progress=false", *chosen, *overrides],
                       labels={"method": method})


@study_main(__file__)
def main(cfg) -> None:
    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = renamed(rows_of(results), OmegaConf.to_container(cfg.names))
    title = f"Normalised cost ({cfg.preset_name} preset, {seeds_text(cfg)})"
    out = Path(cfg.out_dir)
    table = write_tables(rows, results, out, name="comparison", title=title, settings=cfg.settings,
                         tasks=main_tasks(cfg))
    if rows:
        checks = paper_check.check_claims(rows, tuned_ik=OmegaConf.to_container(cfg.tuned_ik) if cfg.tuned_ik else None)
        causes = paper_check.load_causes(cfg.causes) if cfg.causes is not None else []
        write_text(out / "paper_check.md", paper_check.paper_check_markdown(
            checks, title=f"{cfg.preset_name} preset, {seeds_text(cfg)}", causes=causes))
        print("\n" + table)
        print(f"comparison table, figures and the paper's claims checked (paper_check.md) in {cfg.out_dir}/")
    end_study(results)


if __name__ == "__main__":
    main()
