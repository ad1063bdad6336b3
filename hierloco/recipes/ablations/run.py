"""LAT ablations (Li et al., RA-L 2021, Sec. IV-E): vary one setting at a time (latent dimension, number of experts,
dynamics samples) over several trials, as jobs on Ray, then tabulate and plot.

    hierloco study ablations                    # Daisy, paper scale, 10 trials per value
    hierloco study ablations trials=3 preset=small robot=a1 run=[latent_dim]

Every trial is a LAT run in ``runs_dir/<ablation>_<value>/seed<trial>``, or, at the preset's own value, the trial's
default run ``runs_dir/default/seed<trial>`` that every ablation shares (finished runs are reused). Writes
``ablations.csv``, ``ablations.md``, ``wallclock.md``, ``ablations.png`` and ``paper_check.md`` (the paper's ablation
claims beside our numbers, ``paper_check.py``; each claim that does not hold with the cause we checked, from the YAML
file ``causes``) in ``out_dir``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import as_lists
from hierloco.pipeline.study import end_study, refuse, run_study, study_main, write_tables
from hierloco.recipes.ablations import paper_check


def check(cfg) -> None:
    from hierloco.envs.robots import get_robot

    as_lists(cfg, ("run", "overrides"))
    problems = []
    try:
        get_robot(cfg.robot)
    except (ValueError, OSError) as error:
        problems.append(str(error))
    if not (isinstance(cfg.trials, int) and cfg.trials >= 1):
        problems.append(f"trials must be an integer >= 1, got {cfg.trials!r}")
    for name, spec in cfg.ablations.items():
        if "key" not in spec or not spec.get("values"):
            problems.append(f"ablation {name!r} needs a key and a list of values")
    if cfg.causes is not None:
        try:
            paper_check.load_causes(cfg.causes)
        except ValueError as error:
            problems.append(str(error))
    problems += [f"unknown ablation {name!r} in run (ablations: {', '.join(cfg.ablations)})" for name in cfg.run
                 if name not in cfg.ablations]
    refuse(problems)


def jobs(cfg) -> tuple[list, list]:
    """The study's jobs, and each trial as ``(labels, job index)``. A value that is the preset's own (at paper scale
    latent dimension 3, 50 experts) gives the same run whichever ablation varies it: one default run per trial, in
    ``runs_dir/default/seed<trial>``, serves them all. Every other trial starts from the stages it shares with the
    default run of its trial (a dynamics-sample trial: the whole low level, so only the dynamics differ)."""
    from omegaconf import OmegaConf

    from hierloco.envs.robots import robot_reference
    from hierloco.pipeline.config import compose_recipe

    robot = robot_reference(cfg.robot)  # a YAML robot as an absolute path: every worker finds it
    common = [f"preset={cfg.preset_name}", f"robot={robot}", "progress=false", *cfg.overrides]
    defaults = compose_recipe("lat", common)
    planned, trials, default_jobs = [], [], {}

    def default_job(trial: int) -> int:
        if trial not in default_jobs:
            default_jobs[trial] = len(planned)
            planned.append(studies.Job("lat", str(Path(cfg.runs_dir) / "default" / f"seed{trial}"),
                                       [*common, f"seed={trial}"], labels={"method": "default"}))
        return default_jobs[trial]

    for name in cfg.run:
        spec = cfg.ablations[name]
        for value in spec["values"]:
            for trial in range(cfg.trials):
                labels = {"method": f"{name}={value}", "ablation": name, "value": value}
                if value == OmegaConf.select(defaults, spec["key"]):
                    trials.append((labels, default_job(trial)))
                    continue
                source = planned[default_job(trial)].run_dir  # first: it may add the trial's default job
                trials.append((labels, len(planned)))
                planned.append(studies.Job("lat", str(Path(cfg.runs_dir) / f"{name}_{value}" / f"seed{trial}"),
                                           [*common, f"seed={trial}", f"{spec['key']}={value}"], labels=labels,
                                           reuse_from=source))
    return planned, trials


@study_main(__file__)
def main(cfg) -> None:
    check(cfg)
    planned, trials = jobs(cfg)
    results = run_study(cfg, planned)
    rows = [{**row, **labels} for labels, index in trials if results[index].ok for row in results[index].rows]
    out = Path(cfg.out_dir)
    table = write_tables(rows, results, out, name="ablations",
                         title=f"LAT ablations on {cfg.robot} ({cfg.preset_name} preset, {cfg.trials} trials per "
                               "value; the seeds column counts trials)")
    if rows:
        from hierloco.plots import plot_ablations

        per_value: dict = {}
        for row in rows:
            per_value.setdefault(row["ablation"], {}).setdefault(row["value"], []).append(row)
        plot_ablations(per_value, out / "ablations.png", title=f"LAT ablations on {cfg.robot} ({cfg.trials} trials)")
        causes = paper_check.load_causes(cfg.causes) if cfg.causes is not None else []
        write_text(out / "paper_check.md", paper_check.paper_check_markdown(
            paper_check.check_claims(rows), title=f"LAT ablations, {cfg.preset_name} preset, {cfg.trials} trials per "
                                                  "value (a trial's seed is its index)", causes=causes))
        print("\n" + table)
        print(f"ablation table, figure and the paper's claims checked (paper_check.md) in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
