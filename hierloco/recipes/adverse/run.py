"""Damage and transfer (Li et al., RA-L 2021, Sec. IV-C): LAT against IK under fault models and actuator profiles,
and few-sample re-learning of the dynamics after damage, as jobs on Ray.

    hierloco study adverse                          # both robots, 3 seeds, paper scale
    hierloco study adverse robots=[a1] seeds=[0] preset=small samples=[500,2000]

Writes ``adverse.csv``, ``adverse.md`` (the table, with the speeds each fault leaves the robot: from the random-action
dynamics data), ``samples.csv``, ``samples.png`` (cost against re-learning samples), ``wallclock.md``, and copies
LAT's goal-reaching video under every fault to ``videos/``, in ``out_dir``; the few-sample runs go to
``runs_dir/samples/<method>/<robot>_seed<seed>_n<count>`` (the fault runs to ``outputs/<method>/<preset>/``).
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

import shutil
from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.plots import plot_samples
from hierloco.results import EPISODE_COLUMNS, csv_text, markdown_table
from hierloco.pipeline import studies
from hierloco.pipeline.config import SETTINGS, as_lists
from hierloco.pipeline.study import (
    end_study, main_tasks, method_problems, refuse, run_study, seed_problems, study_main, study_robots,
)

def check(cfg) -> list:
    from hierloco.envs.robots.profiles import PROFILES

    as_lists(cfg, ("robots", "seeds", "methods", "samples", "sample_methods", "overrides", "profiles"))
    problems = []
    robots = study_robots(cfg.robots, problems)
    problems += method_problems([*cfg.methods, *cfg.sample_methods], cfg.variants)
    for profile in cfg.profiles:
        if profile not in cfg.faults:
            problems.append(f"profile {profile!r} has no settings in faults")
    for profile, settings in cfg.faults.items():
        if profile not in PROFILES:
            problems.append(f"unknown robot profile {profile!r} in faults (profiles: {', '.join(PROFILES)})")
        problems += [f"unknown setting {s!r} in faults.{profile} (settings: {', '.join(SETTINGS)})" for s in settings
                     if s not in SETTINGS]
    problems += [f"method_overrides names {m!r}, which is in neither methods nor sample_methods"
                 for m in cfg.method_overrides if m not in (*cfg.methods, *cfg.sample_methods)]
    for profile, per_method in cfg.profile_overrides.items():
        if profile not in PROFILES:
            problems.append(f"unknown robot profile {profile!r} in profile_overrides (profiles: {', '.join(PROFILES)})")
            continue
        problems += [f"profile_overrides.{profile} names {m!r}, which is not in methods" for m in per_method
                     if m not in cfg.methods]
    problems += seed_problems(cfg.seeds)
    problems += [f"samples must be integers >= 10, got {n!r}" for n in cfg.samples if not (isinstance(n, int) and
                                                                                           n >= 10)]
    refuse(problems)
    return robots


def run_dir(method: str, preset: str, robot, profile: str, seed: int) -> Path:
    name = robot.name if profile == "own" else f"{robot.name}-{profile}"
    return Path("outputs") / method / preset / f"{name}_seed{seed}"


PAPER_SETTINGS = ("normal", "legs_disabled")  # run together, in the run directory the comparison study shares


def fault_jobs(cfg, robots) -> tuple[list, list]:
    """The runs of the paper's settings (one run directory per method, robot, profile and seed), and one job per
    other fault, starting from the first's finished stages that it shares (its trained low level), so a fault
    nothing can be learned in fails alone."""
    main, extra = [], []
    for robot, spec in zip(cfg.robots, robots):
        for method in cfg.methods:
            recipe, variant = studies.resolve_method(method, cfg.variants)
            for profile in cfg.profiles:
                settings = list(cfg.faults[profile])
                for seed in cfg.seeds:
                    common = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                              f"robot_profile={profile}", "progress=false", *variant, *cfg.overrides,
                              *cfg.method_overrides.get(method, []),
                              *cfg.profile_overrides.get(profile, {}).get(method, [])]
                    home = run_dir(method, cfg.preset_name, spec, profile, seed)
                    labels = {"method": method, "profile": profile, "robot": spec.name}
                    paper = [s for s in settings if s in PAPER_SETTINGS] or ["normal"]
                    main.append(studies.Job(recipe, str(home), [*common, f"settings=[{','.join(paper)}]"],
                                            labels={**labels, "faults": paper}))
                    for fault in (s for s in settings if s not in paper):
                        extra.append(studies.Job(recipe, f"{home}_{fault}", [*common, f"settings=[{fault}]"],
                                                 labels={**labels, "faults": [fault]}, reuse_from=str(home)))
    return main, extra


def sample_jobs(cfg, robots) -> list:
    """One job per method, robot, seed and sample count: the dynamics re-learned with the rear legs locked from that
    many transitions, starting from the stages it shares with the method's run of the paper's settings (the trained
    low level; at that run's own count, its dynamics and evaluations too). Where that run is not finished in its
    run directory (it is still to run, or the study takes it from its record, which keeps no artifacts), only the
    first count starts from it and the other counts start from the first, so the low level is built once, not once
    per count."""
    jobs = []
    for robot, spec in zip(cfg.robots, robots):
        for method in cfg.sample_methods:
            recipe, variant = studies.resolve_method(method, cfg.variants)
            for seed in cfg.seeds:
                paper_run = run_dir(method, cfg.preset_name, spec, "own", seed)
                on_disk, source = (paper_run / studies.DONE).is_file(), paper_run
                for count in cfg.samples:
                    target = Path(cfg.runs_dir) / "samples" / method / f"{spec.name}_seed{seed}_n{count}"
                    overrides = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                                 "settings=[legs_disabled]", f"dynamics.num_transitions={count}", "progress=false",
                                 "eval.videos=[]", *variant, *cfg.overrides, *cfg.method_overrides.get(method, [])]
                    jobs.append(studies.Job(recipe, str(target), overrides, labels={"method": method,
                                                                                    "samples": count},
                                            reuse_from=str(source)))
                    if not on_disk and source == paper_run:
                        source = target  # the first count's run directory, for every later count
    return jobs


def fault_summary(results, methods, seeds: int, tasks) -> str:
    """One row per robot, profile and fault, one column per method: the normalised cost at velocity tracking (mean
    +- std over targets and seeds) / goal reaching / trajectory tracking (the study's ``tasks``), and the goals reached; "not evaluable" where
    every seed's run failed with a finding (the reason is listed below the tables), and the number of seeds where
    fewer than ``seeds`` were evaluated."""
    costs: dict[tuple, list] = {}
    order: list[tuple] = []
    for result in results:
        labels = result.job.labels
        for fault in labels["faults"]:
            place = (labels["robot"], labels["profile"], fault)
            if place not in order:
                order.append(place)
            cell = costs.setdefault((*place, labels["method"]), [])
            cell += [row for row in result.rows if row["setting"] == fault] if result.ok else []
    seen = [list(dict.fromkeys(place[k] for place in order)) for k in range(3)]  # robots, profiles, faults in order
    order.sort(key=lambda place: tuple(seen[k].index(place[k]) for k in range(3)))
    lines = ["| robot | profile | fault | " + " | ".join(methods) + " |", "|---|---|---|" + "---|" * len(methods)]
    for place in order:
        cells = []
        for method in methods:
            rows = costs.get((*place, method))
            if rows is None:
                cells.append("-")
                continue
            if not rows:
                cells.append("not evaluable")
                continue
            per_task = {task: np.array([r["normalized_cost"] for r in rows if r["task"] == task], dtype=float)
                        for task in tasks}
            text = " / ".join(f"{c.mean():.2f}" + (f" +- {c.std():.2f}" if i == 0 else "") if len(c) else "-"
                              for i, c in enumerate(per_task.values()))
            goals = [float(r["success"]) for r in rows if r["task"] == "goal_reaching"]
            text += f" ({100 * np.mean(goals):.0f} %)" if goals else ""
            evaluated = len({r["seed"] for r in rows})
            cells.append(text + (f", {evaluated} of {seeds} seeds" if evaluated < seeds else ""))
        lines.append(f"| {' | '.join(place)} | {' | '.join(cells)} |")
    return "\n".join(lines) + "\n"


def achievable_speeds(results) -> str:
    """Per robot, profile and fault, what the robot can still do: the 95th percentile of its speed in each
    direction over the random-action dynamics data (m/s, in the local frame at the start of each action;
    :meth:`TransitionData.achievable_speeds`), as each job's ``report.json`` keeps it, so a job taken from its
    record has it too (for runs made before reports kept it, from the data in the run directory)."""
    lines = ["| method | robot | profile | setting | forward | backward | left | right | turn (rad/s) | transitions "
             "dropped for falls | seed |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for result in results:
        if not result.ok or result.job.labels.get("method") not in ("lat", "ik"):
            continue
        robot = result.rows[0]["robot"] if result.rows else "?"
        seed = result.rows[0]["seed"] if result.rows else "?"
        for name, entry in sorted(result.report.items()):
            if not name.startswith("dynamics_data_"):
                continue
            speeds = entry.get("achievable_speeds")
            data = Path(result.job.run_dir) / f"{name}.npz"
            if speeds is None and data.is_file():
                from hierloco.components.dynamics_data import TransitionData  # torch: only for a rebuilt row

                speeds = TransitionData.load(data).achievable_speeds()
            cells = " | ".join(f"{speeds[k]:.2f}" if speeds else "-"
                               for k in ("forward", "backward", "left", "right", "turn"))
            lines.append(f"| {result.job.labels['method']} | {robot} | {result.job.labels['profile']} | "
                         f"{name.removeprefix('dynamics_data_')} | {cells} | {entry.get('dropped_failures', 0)} | "
                         f"{seed} |")
    return "\n".join(lines) + "\n"


def low_level_checks(results) -> str:
    """Per LAT run, how well its gait policy reproduces its experts in simulation (its ``gait_policy_check``, from
    ``report.json``): a profile can leave it below the run's own bar if ``checks.min_reproduced_fraction`` was
    lowered for the study."""
    lines = ["| robot | profile | run directory | experts reproduced within 0.05 m/s | median error m/s | fell |",
             "|---|---|---|---|---|---|"]
    for result in results:
        check = result.report.get("gait_policy_check")
        if result.job.labels.get("method") != "lat" or not check or result.job.reuse_from:
            continue
        errors = np.asarray(check["reproduction_error"], dtype=float)
        robot = result.rows[0]["robot"] if result.rows else "?"
        lines.append(f"| {robot} | {result.job.labels['profile']} | {result.source} | "
                     f"{100 * check['reproduced_fraction']:.0f}% | {np.median(errors):.3f} | "
                     f"{int(np.isinf(errors).sum())} |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.pipeline.report import wallclock_markdown

    robots = check(cfg)
    main_jobs, extra_jobs = fault_jobs(cfg, robots)
    samples = sample_jobs(cfg, robots)
    out = Path(cfg.out_dir)
    results = run_study(cfg, main_jobs + extra_jobs + samples)  # a job starting from another's stages waits for it
    faults = len(main_jobs) + len(extra_jobs)
    fault_results, sample_results = results[:faults], results[faults:]
    write_text(out / "wallclock.md", wallclock_markdown(results))
    rows = [{**row, "setting": row["setting"] + ("" if row["profile"] == "own" else f"_{row['profile']}")}
            for row in studies.rows_of(fault_results)]
    unusable = [r for r in fault_results if not r.ok]
    if rows:
        table = markdown_table(rows)
        write_text(out / "adverse.csv", csv_text(rows, EPISODE_COLUMNS + ["profile"]))
        notes = "".join(f"- {r.job.labels['method']} in {r.job.run_dir}: {r.error}\n" for r in unusable)
        write_text(out / "adverse.md", f"# Damage: LAT against IK under fault models ({cfg.preset_name} preset, "
                                       f"{len(cfg.seeds)} seed(s))\n\nNormalised cost, mean +- std over targets and "
                                       "seeds; cells: velocity tracking / goal reaching / trajectory tracking "
                                       "(goals reached).\n\n"
                                       + fault_summary(fault_results, list(cfg.methods), len(cfg.seeds),
                                                       main_tasks(cfg))
                                       + "\n## Every task\n\nA setting `<fault>_<profile>` ran under that "
                                       "actuator profile (`stiff`, `stiff_servos`).\n\n"
                                       + table
                                       + "\n## Speeds each fault leaves (random-action dynamics data)\n\n"
                                       + achievable_speeds(fault_results)
                                       + "\n## LAT's low level: its experts reproduced in simulation\n\n"
                                       + low_level_checks(fault_results)
                                       + ("\n## Runs that could not be evaluated\n\n" + notes if notes else ""))
        for result in fault_results:  # LAT under every fault
            if result.ok and result.job.labels["method"] == "lat":
                for video in Path(result.job.run_dir).glob("videos/*_goal_reaching.mp4"):
                    home = Path(result.job.run_dir).name
                    for fault in SETTINGS:  # the extra faults' run directories are <home>_<fault>
                        home = home.removesuffix(f"_{fault}")
                    name = f"{home}_{video.name}"
                    (out / "videos").mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(video, out / "videos" / name)
        print("\n" + table)
    sample_rows = studies.rows_of(sample_results)
    if sample_rows:
        write_text(out / "samples.csv", csv_text(sample_rows, EPISODE_COLUMNS + ["samples"]))
        plot_samples(sample_rows, out / "samples.png",
                     title=f"Cost after damage (rear legs locked) against re-learning samples ({cfg.preset_name})")
    print(f"adverse tables and figures in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
