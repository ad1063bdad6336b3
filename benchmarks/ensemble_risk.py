"""The probabilistic ensemble and risk-aware planning on a trained run (PETS, Chua et al., NeurIPS 2018, on the CoM
model of Li et al., RA-L 2021, Sec. III-C/D).

On a finished LAT (or LIB, IK) run directory: trains the ensemble on the run's own dynamics data with the MLP's
split, seed and training settings, reports both models' held-out errors (and the ensemble's held-out NLL and 2-std
coverage), then runs closed-loop MPC on the simulated robot with the run's MLP and with the ensemble under each risk
(``none``, ``mean_std`` with ``beta``, ``pessimistic``), with the run's planner, and prints the normalised cost per
task (1 = no better than standing still).

    python benchmarks/ensemble_risk.py outputs/lat/paper/a1_seed0
    python benchmarks/ensemble_risk.py RUN_DIR --setting legs_disabled --members 5 --tasks velocity_tracking
    python benchmarks/ensemble_risk.py RUN_DIR --num-transitions 300 --num-candidates 1000   # data-poor, cheaper

The paper-scale study is this script over the comparison's LAT and IK run directories (both robots, normal and
legs disabled, seeds 0-2): one row per run, setting, task and model.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from hierloco.components.com_model import train_com_model
from hierloco.components.evaluation import run_task
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.tasks import make_task
from hierloco.trained import load_run

RISKS = (("none", 0.0), ("mean_std", 1.0), ("pessimistic", 0.0))
TRAINING_KEYS = ("hidden", "lr", "batch_size", "holdout", "patience", "max_epochs", "seed", "duration")


def ensemble_study(run_dir, *, setting: str = "normal", members: int = 5, head: str = "gaussian",
                   propagation: str = "ts", risks=RISKS, tasks=("velocity_tracking", "goal_reaching"),
                   num_transitions: int | None = None, nthread: int | None = None, progress: bool = False,
                   **planner_overrides) -> dict:
    """Trains the ensemble on ``run_dir``'s dynamics data of ``setting`` and plans with it; returns a report with
    ``models`` (held-out figures of the run's MLP and of the ensemble) and ``planning`` (one row per task and model:
    mean and std of the normalised cost over the task's episodes, the success rate, seconds per planner call).

    ``num_transitions`` keeps only the first transitions of the data (a data-poor regime) and then trains the MLP
    again on them too, with the run's settings; ``planner_overrides`` change the run's planner (e.g.
    ``num_candidates``)."""
    run = load_run(run_dir)
    mlp = run.com_model(setting)
    data = run.dynamics_data(setting)
    low_level = run.low_level()
    features = low_level.action_features(data.action)
    options = {key: mlp.metadata[key] for key in TRAINING_KEYS if key in mlp.metadata}
    state, next_state = data.com_state, data.next_com_state
    if num_transitions is not None:
        state, features, next_state = (x[:num_transitions] for x in (state, features, next_state))
        mlp = train_com_model(state, features, next_state, progress=progress, **options)
    ensemble = train_com_model(state, features, next_state, model="ensemble", members=members,
                               head=head, propagation=propagation, progress=progress, **options)
    report_keys = ("heldout_loss", "heldout_rmse", "heldout_nll", "heldout_coverage_2std", "heldout_member_std",
                   "best_epoch", "train_seconds", "num_train", "num_heldout")
    models = {name: {key: trained.metadata.get(key) for key in report_keys}
              for name, trained in (("mlp", mlp), ("ensemble", ensemble))}
    variants = [("mlp", mlp, "none", 0.0)] + [(f"ensemble/{risk}", ensemble, risk, beta) for risk, beta in risks]
    planning = []
    for task_name in tasks:
        task = make_task(task_name)
        for name, model, risk, beta in variants:
            planner = run.planner(task, setting, model=model, risk=risk, beta=beta, **planner_overrides)
            env = LatentActionEnv(run.low_level(task.num_episodes), num_robots=task.num_episodes,
                                  seed=run.manifest["seed"], nthread=nthread)
            start = time.perf_counter()
            try:
                rollout = run_task(env, planner, task, progress=progress)
            finally:
                env.close()
            result = rollout.result
            planning.append({"task": task_name, "model": name, "risk": risk, "beta": beta,
                             "normalized_cost": float(np.mean(result.normalized_cost)),
                             "normalized_cost_std": float(np.std(result.normalized_cost)),
                             "success": float(np.nanmean(result.success)) if task.has_success else None,
                             "fell": int(rollout.fell.sum()), "plan_seconds": rollout.plan_seconds,
                             "seconds": time.perf_counter() - start})
    return {"run_dir": str(run_dir), "setting": setting, "num_transitions": len(state),
            "planner": {**run.manifest["planner"], **planner_overrides}, "ensemble": ensemble.metadata["model_options"],
            "models": models, "planning": planning}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir")
    parser.add_argument("--setting", default="normal")
    parser.add_argument("--members", type=int, default=5)
    parser.add_argument("--head", default="gaussian", choices=("gaussian", "deterministic"))
    parser.add_argument("--propagation", default="ts", choices=("ts", "mm", "expectation"))
    parser.add_argument("--beta", type=float, default=1.0, help="the weight of the std in risk mean_std")
    parser.add_argument("--tasks", nargs="+", default=["velocity_tracking", "goal_reaching"])
    parser.add_argument("--num-transitions", type=int, help="keep only the first transitions (MLP retrained too)")
    parser.add_argument("--num-candidates", type=int, help="the planner's samples (default: the run's)")
    parser.add_argument("--json", help="also write the report here")
    args = parser.parse_args(argv)
    risks = (("none", 0.0), ("mean_std", args.beta), ("pessimistic", 0.0))
    overrides = {} if args.num_candidates is None else {"num_candidates": args.num_candidates}
    report = ensemble_study(args.run_dir, setting=args.setting, members=args.members, head=args.head,
                            propagation=args.propagation, risks=risks, tasks=args.tasks,
                            num_transitions=args.num_transitions, **overrides)
    for name, figures in report["models"].items():
        extra = "" if figures["heldout_nll"] is None else (f", NLL {figures['heldout_nll']:.3f}, 2-std coverage "
                                                           f"{figures['heldout_coverage_2std']:.3f}")
        seconds = "" if figures["train_seconds"] is None else f", {figures['train_seconds']:.0f} s"
        print(f"{name:9s} held-out standardised MSE {figures['heldout_loss']:.4f}, RMSE (dx, dy, dyaw, vx', vy') "
              f"{np.round(figures['heldout_rmse'], 4).tolist()}{extra}, best epoch {figures['best_epoch']}{seconds}")
    print(f"\n| task | model | normalised cost | success | fell | s per plan |\n|---|---|---|---|---|---|")
    for row in report["planning"]:
        success = "-" if row["success"] is None else f"{row['success']:.2f}"
        print(f"| {row['task']} | {row['model']} | {row['normalized_cost']:.3f} +- {row['normalized_cost_std']:.3f} "
              f"| {success} | {row['fell']} | {row['plan_seconds']:.3f} |")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(report, handle, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
