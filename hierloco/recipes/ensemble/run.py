"""A probabilistic ensemble CoM model and risk-aware planning against LAT's single MLP (the research API's study),
as jobs on Ray.

    hierloco study ensemble                              # A1 and Daisy, 3 seeds, paper scale
    hierloco study ensemble robots=[a1] seeds=[0] preset=small records=results/ensemble/records

Per robot and seed: LAT with its MLP (``mlp``), then the same run's low level and dynamics data with an ensemble
(``ensemble``: ``dynamics.model=ensemble``, PETS's Gaussian members) planned risk-neutral, then with each risk of
``risks`` (``planner.risk=mean_std`` / ``pessimistic``: the evaluations alone). Every job is evaluated in the
normal setting, with the rear legs locked (model re-learned) and on the perturbed "hardware" robot planned with the
nominal model, where the model is most wrong. Writes ``ensemble.csv``, ``ensemble.md`` (the costs side by side, the
paired differences per seed) and ``wallclock.md`` in ``out_dir``.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)

from pathlib import Path

import numpy as np

from hierloco.io import write_text
from hierloco.pipeline import studies
from hierloco.pipeline.config import as_lists
from hierloco.pipeline.study import (
    end_study, main_tasks, refuse, rows_of, run_study, seed_problems, study_main, study_robots, write_tables,
)


def check(cfg) -> list:
    from hierloco.envs.faults import SETTINGS
    from hierloco.envs.world_model import RISKS

    as_lists(cfg, ("robots", "seeds", "settings", "risks", "overrides"))
    problems = []
    robots = study_robots(cfg.robots, problems)
    problems += seed_problems(cfg.seeds)
    problems += [f"unknown setting {s!r}" for s in cfg.settings if s not in SETTINGS]
    problems += [f"unknown risk {r!r} (risks: {', '.join(RISKS)})" for r in cfg.risks if r not in RISKS]
    if not (isinstance(cfg.members, int) and cfg.members >= 2):
        problems.append(f"members must be an integer >= 2, got {cfg.members!r}")
    transitions = cfg.get("calibration_transitions")
    if isinstance(transitions, bool) or not (isinstance(transitions, int) and transitions >= 0):
        problems.append(f"calibration_transitions must be an integer >= 0, got {transitions!r}")
    refuse(problems)
    return robots


def jobs(cfg, robots) -> list:
    """Per robot and seed: the MLP run, the ensemble run starting from its low level and data, and one run per
    risk starting from the ensemble run (evaluations only)."""
    planned = []
    for spec in robots:
        for seed in cfg.seeds:
            base = [f"preset={cfg.preset_name}", f"robot={spec.reference}", f"seed={seed}",
                    f"settings=[{','.join(cfg.settings)}]", "progress=false", *cfg.overrides]
            root = Path(cfg.runs_dir) / f"{spec.name}_seed{seed}"
            mlp = studies.Job("lat", str(root / "mlp"), base, labels={"method": "mlp"})
            ensemble = [*base, "dynamics.model=ensemble", f"+dynamics.members={cfg.members}",
                        f"+dynamics.propagation={cfg.propagation}"]
            planned.append(mlp)
            previous = mlp.run_dir
            for risk in cfg.risks:
                name = "ensemble" if risk == "none" else f"ensemble_{risk}"
                overrides = [*ensemble, *([f"planner.risk={risk}", f"planner.beta={cfg.beta}"] if risk != "none"
                                          else [])]
                planned.append(studies.Job("lat", str(root / name), overrides, labels={"method": name},
                                           reuse_from=previous))
                previous = str(root / "ensemble") if risk == "none" else previous
    return planned


def paired_table(rows: list[dict], methods: list[str], tasks) -> str:
    """Per robot, setting and task: each method's mean normalised cost over seeds, and each ensemble variant's
    paired difference from the MLP (per seed; mean and its standard error)."""
    cost: dict[tuple, dict[int, float]] = {}
    for row in rows:
        key = (row["method"], row["robot"], row["setting"], row["task"])
        cost.setdefault(key, {}).setdefault(int(row["seed"]), []).append(float(row["normalized_cost"]))
    header = "| robot | setting | task | " + " | ".join(methods) + " |"
    lines = [header, "|---|---|---|" + "---|" * len(methods)]
    places = sorted({(r["robot"], r["setting"], r["task"]) for r in rows if r["task"] in tasks})
    for robot, setting, task in places:
        base = {s: np.mean(v) for s, v in cost.get(("mlp", robot, setting, task), {}).items()}
        cells = []
        for method in methods:
            seeds = {s: np.mean(v) for s, v in cost.get((method, robot, setting, task), {}).items()}
            if not seeds:
                cells.append("-")
                continue
            text = f"{np.mean(list(seeds.values())):.3f}"
            shared = sorted(set(seeds) & set(base))
            if method != "mlp" and shared:
                diff = np.array([seeds[s] - base[s] for s in shared])
                error = diff.std(ddof=1) / np.sqrt(len(diff)) if len(diff) > 1 else float("nan")
                text += f" ({diff.mean():+.3f} +- {error:.3f})"
            cells.append(text)
        lines.append(f"| {robot} | {setting} | {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def verdict_table(rows: list[dict], methods: list[str], tasks) -> str:
    """Per robot, setting and task, each ensemble variant against the MLP (``methods[0]``) by the stated tests over
    seeds, paired by seed (:func:`hierloco.claims.variant_verdicts`)."""
    from hierloco.claims import variant_verdicts

    return variant_verdicts(rows, methods[0], methods[1:], tasks, reference_name="the MLP")


def calibration_rows(cfg, results) -> list[dict]:
    """Per risk-neutral ensemble run and setting: :func:`~hierloco.components.com_ensemble.transition_calibration`
    of the model its planner used there (the normal model on the unadapted robot) on ``calibration_transitions``
    fresh transitions collected in that setting with the run's low level (seed ``1000 + seed``: never its training
    data). The run's model artifacts are checked against the keys its plan names first."""
    from hierloco.components.com_ensemble import CALIBRATION_OUTPUTS, transition_calibration
    from hierloco.components.dynamics_data import collect_transitions
    from hierloco.envs.faults import fault_legs, is_unadapted, setting_robot
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.pipeline.config import compose_recipe
    from hierloco.pipeline.rundir import RunDirectory
    from hierloco.pipeline.stages import hardware_params
    from hierloco.trained import load_run

    found = []
    for result in results:
        if not (result.ok and result.job.labels["method"] == "ensemble"):
            continue
        job = result.job
        run_cfg = compose_recipe("lat", [f"run_dir={job.run_dir}", *job.overrides])
        directory = RunDirectory(job.run_dir, readonly=True)
        specs = {spec.name: spec for spec in studies.planned_stages(job)}
        run = load_run(job.run_dir)
        num_robots = int(run_cfg.dynamics.num_robots)
        low_level = run.low_level(num_robots=num_robots)  # one per run: an env's close leaves it usable
        for setting in cfg.settings:
            model_setting = "normal" if is_unadapted(setting) else setting
            spec = specs[f"dynamics_model_{model_setting}"]
            if not directory.check(spec.name, spec.key, spec.filename):
                raise FileNotFoundError(f"{job.run_dir}: {spec.filename} is not the one its plan names")
            locked, limp = fault_legs(run.robot, setting)
            robot = setting_robot(run.robot, setting, hardware_params(run_cfg, setting).get("hardware"))
            env = LatentActionEnv(low_level, num_robots=num_robots, disabled_legs=locked, limp_legs=limp,
                                  seed=1000 + int(run_cfg.seed), nthread=1, robot=robot)
            try:
                data = collect_transitions(env, cfg.calibration_transitions, seed=1000 + int(run_cfg.seed),
                                           progress=False)
            finally:
                env.close()
            report = transition_calibration(run.com_model(model_setting).model, data.com_state,
                                            low_level.action_features(data.action), data.next_com_state)
            for i, output in enumerate(CALIBRATION_OUTPUTS):
                found.append({"robot": run.robot.name, "seed": int(run_cfg.seed), "setting": setting,
                              "model": model_setting, "output": output,
                              **{k: round(v[i], 5) for k, v in report.items()}})
    return found


def calibration_markdown(found: list[dict]) -> str:
    """Per robot and setting, each output's error of the members' mean against their spread (mean over seeds), and
    the coverage of two predictive standard deviations."""
    from hierloco.components.com_ensemble import CALIBRATION_OUTPUTS

    lines = ["| robot | setting (model) | " + " | ".join(f"{o}: error / spread / noise" for o in CALIBRATION_OUTPUTS)
             + " | within 2 std | seeds |", "|---|---|" + "---|" * len(CALIBRATION_OUTPUTS) + "---|---|"]
    for robot, setting, model in dict.fromkeys((r["robot"], r["setting"], r["model"]) for r in found):
        of = [r for r in found if (r["robot"], r["setting"]) == (robot, setting)]
        cells = []
        for output in CALIBRATION_OUTPUTS:
            mine = [r for r in of if r["output"] == output]
            cells.append(" / ".join(f"{np.mean([r[k] for r in mine]):.3f}" for k in ("error", "spread", "noise")))
        lines.append(f"| {robot} | {setting} ({model}) | " + " | ".join(cells)
                     + f" | {100 * np.mean([r['coverage'] for r in of]):.0f} % | {len({r['seed'] for r in of})} |")
    return "\n".join(lines) + "\n"


@study_main(__file__)
def main(cfg) -> None:
    from hierloco.results import csv_text

    robots = check(cfg)
    results = run_study(cfg, jobs(cfg, robots))
    rows = [{**row, "method": result.job.labels["method"]} for result in results if result.ok for row in result.rows]
    out = Path(cfg.out_dir)
    title = (f"LAT's CoM model: an MLP against a {cfg.members}-member ensemble ({cfg.propagation} propagation) and "
             f"risk-aware planning ({cfg.preset_name} preset, seeds {list(cfg.seeds)})")
    table = write_tables(rows, results, out, name="ensemble", title=title)
    if rows:
        methods = ["mlp", *["ensemble" if r == "none" else f"ensemble_{r}" for r in cfg.risks]]
        paired = paired_table(rows, methods, main_tasks(cfg))
        text = (out / "ensemble.md").read_text()
        write_text(out / "ensemble.md", text.replace("\n\n| method", "\n\n## Side by side\n\nMean normalised cost "
                                                     "over seeds; in brackets the paired difference from the MLP "
                                                     "(per seed) with its standard error.\n\n" + paired
                                                     + "\n## Every task\n\n| method", 1))
        verdicts = verdict_table(rows, methods, main_tasks(cfg))
        write_text(out / "verdicts.md", f"# Ensemble variants against the MLP, by the stated tests\n\n{title}. "
                   "Paired by seed; alpha 0.05; better: at least 10 % (and 0.01) lower; close: within 20 % (or "
                   "0.01); not testable: both at or above 0.9 (`docs/statistics.md`).\n\n" + verdicts)
        print("\n" + paired + "\n" + verdicts)
    if rows and cfg.calibration_transitions:
        found = calibration_rows(cfg, results)
        if found:
            write_text(out / "calibration.csv", csv_text(found, list(found[0])))
            write_text(out / "calibration.md", "# Does the members' disagreement see the model's error?\n\n"
                       f"Per risk-neutral ensemble run: {cfg.calibration_transitions} fresh transitions per setting "
                       "with the run's low level, scored by the model its planner used there (the normal model on "
                       "the unadapted robot). Per output of the local-frame delta (m, m, rad, m/s, m/s): the RMS "
                       "error of the members' mean / the RMS spread of the members (what `planner.risk` weighs) / "
                       "the RMS noise of their Gaussian heads, mean over seeds; the share of errors within two "
                       "predictive standard deviations (95 % when calibrated).\n\n" + calibration_markdown(found))
            print((out / "calibration.md").read_text())
    print(f"ensemble tables in {out}/")
    end_study(results)


if __name__ == "__main__":
    main()
