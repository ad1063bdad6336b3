"""Where do a run's plans go wrong? Replays a finished run's MPC on one task in one setting, with the seeds, planner
and CoM model its evaluation used (from the evaluation's key), and compares, at every step, what the CoM model
predicted for the action the planner chose with what the robot did.

    python recipes/adverse/trace.py outputs/lat/paper/daisy-stiff_seed0 legs_disabled velocity_tracking

Prints (and with ``--out``, writes as markdown): the replayed normalised cost beside the one the run's evaluation
recorded (the replay is the same closed loop, so they agree unless the machine's threads differ), the cost split into
its tracking and yaw terms, the heading error, and the model's errors on the chosen actions against its held-out
errors on the random actions it was trained on (``heldout_rmse``): chosen actions that the model gets much more
wrong than random ones mean the plans exploit the model's errors (Li et al., RA-L 2021, Sec. III-C, III-D).
"""

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from hierloco.components.com_model import OUTPUT_NAMES, prediction_errors
from hierloco.envs.faults import is_unadapted
from hierloco.envs.frames import wrap_angle
from hierloco.io import write_text
from hierloco.results import TaskEvaluation
from hierloco.trained import load_run
from hierloco.pipeline.config import make_task_from_spec
from hierloco.pipeline.stages import evaluation_rollout

PLANNER_KEYS = ("name", "horizon", "num_candidates", "optim_steps", "top_k", "temperature")


def evaluation_key(run_dir: Path, setting: str, task: str) -> tuple[dict, Path]:
    """The key of the run's evaluation of ``task`` in ``setting`` and its artifact (the newest, if several)."""
    keys = sorted((run_dir / "evaluation" / setting).glob(f"{task}-*.npz.key.json"), key=lambda p: p.stat().st_mtime)
    if not keys:
        found = sorted(p.name.split("-")[0] for p in (run_dir / "evaluation" / setting).glob("*.npz.key.json"))
        raise SystemExit(f"{run_dir} has no evaluation of {task!r} in setting {setting!r} (it has: "
                         f"{', '.join(found) or 'none in that setting'})")
    return json.loads(keys[-1].read_text()), keys[-1].with_name(keys[-1].name.removesuffix(".key.json"))


def trace(run_dir: str, setting: str, task_name: str, *, nthread: int | None = None,
          planner: dict | None = None) -> dict:
    """Replays the evaluation and returns its numbers (see the module doc); ``steps`` is the first episode per
    step: target, yaw error, the cost the model predicted for the chosen action and the cost it had. ``planner``
    changes the evaluation's planner options (``{"horizon": 3, "name": "cem"}``): the same run and model, planned
    otherwise."""
    run_dir = Path(run_dir)
    key, artifact = evaluation_key(run_dir, setting, task_name)
    params = {**key["params"], "planner": {**key["params"]["planner"], **(planner or {})}}
    run = load_run(run_dir)
    task = make_task_from_spec(params["task_name"], params["task"])
    trained = run.com_model("normal" if is_unadapted(setting) else setting)
    low_level = run.low_level(task.num_episodes)
    rollout = evaluation_rollout(run.robot, params, task, low_level, trained, nthread=nthread)
    trained.model.cpu()  # planned on the evaluation's device; the analysis below runs on the CPU
    result = rollout.result
    states = torch.as_tensor(result.com_states, device="cpu")  # E x (T + 1) x 5
    features = torch.as_tensor(low_level.action_features(rollout.actions), dtype=torch.float32, device="cpu")
    errors = prediction_errors(trained.model, states, features).numpy()  # E x T x 5
    episodes = torch.arange(len(states), device="cpu")[:, None] % task.num_episodes
    steps = torch.arange(task.num_steps, device="cpu")[None, :]
    with torch.no_grad():
        predicted = trained.model.predict(states[:, :-1].float(), features).double()
    predicted_cost = task.cost(states[:, :-1], predicted, episodes, steps).numpy()
    yaw_error = wrap_angle(states[:, 1:, 2] - task.start_yaw).numpy()
    recorded = (TaskEvaluation.load(artifact).metrics.get("normalized_cost") if artifact.is_file() and not planner
                else None)
    target = task.target(episodes[:1].expand(1, task.num_steps), steps)[0].numpy()
    return {
        "run_dir": str(run_dir), "setting": setting, "task": task.name, "planner": params["planner"],
        "normalized_cost": float(np.mean(result.normalized_cost)), "recorded_normalized_cost": recorded,
        "cost_terms": {term: float(np.mean(values)) for term, values in result.cost_terms.items()},
        "final_yaw_error": float(np.mean(np.abs(yaw_error[:, -1]))), "max_yaw_error": float(np.abs(yaw_error).max()),
        "predicted_cost": float(predicted_cost.mean()), "actual_cost": float(result.costs.mean()),
        "plan_rmse": dict(zip(OUTPUT_NAMES, np.sqrt(np.mean(errors ** 2, axis=(0, 1))).tolist())),
        "plan_bias": dict(zip(OUTPUT_NAMES, np.mean(errors, axis=(0, 1)).tolist())),
        "heldout_rmse": dict(zip(OUTPUT_NAMES, trained.metadata.get("heldout_rmse", [float("nan")] * 5))),
        "steps": [{"step": t, "target": target[t].tolist(), "yaw_error": float(yaw_error[0, t]),
                   "dyaw_error": float(errors[0, t, 2]), "predicted_cost": float(predicted_cost[0, t]),
                   "cost": float(result.costs[0, t])} for t in range(task.num_steps)],
    }


def markdown(out: dict) -> str:
    recorded = out["recorded_normalized_cost"]
    lines = [f"# Plans against outcomes: `{out['run_dir']}`, {out['setting']}, {out['task']}", "",
             "- planner: " + ", ".join(f"{k}={v}" for k, v in sorted(out["planner"].items())),
             f"- normalised cost {out['normalized_cost']:.3f} (the run's evaluation: "
             + (f"{recorded:.3f})" if recorded is not None else "not on disk, or planned otherwise)"),
             "- mean cost per step: " + ", ".join(f"{k} {v:.3f}" for k, v in out["cost_terms"].items())
             + f"; the model predicted {out['predicted_cost']:.3f} for the chosen actions, they cost "
             f"{out['actual_cost']:.3f}",
             f"- heading error (rad): {out['final_yaw_error']:.2f} at the end (mean over episodes), "
             f"{out['max_yaw_error']:.2f} at most", "",
             "| model output | RMSE on the chosen actions | bias (predicted - actual) | "
             "held-out RMSE (random actions) |",
             "|---|---|---|---|"]
    lines += [f"| {name} | {out['plan_rmse'][name]:.3f} | {out['plan_bias'][name]:+.3f} | "
              f"{out['heldout_rmse'][name]:.3f} |" for name in OUTPUT_NAMES]
    lines += ["", "First episode, per step:", "", "| step | target | yaw error (rad) | dyaw predicted - actual | "
              "predicted cost | cost |", "|---|---|---|---|---|---|"]
    lines += [f"| {s['step']} | ({s['target'][0]:.2f}, {s['target'][1]:.2f}) | {s['yaw_error']:+.2f} | "
              f"{s['dyaw_error']:+.3f} | {s['predicted_cost']:.3f} | {s['cost']:.3f} |" for s in out["steps"]]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir")
    parser.add_argument("setting", help="e.g. normal, legs_disabled")
    parser.add_argument("task", help="e.g. velocity_tracking, goal_reaching")
    parser.add_argument("--nthread", type=int, default=None)
    parser.add_argument("--planner", nargs="*", default=[], metavar="KEY=VALUE",
                        help="plan otherwise, e.g. --planner horizon=3 name=cem")
    parser.add_argument("--out", help="also write the markdown here")
    args = parser.parse_args(argv)
    if not (Path(args.run_dir) / "run.json").is_file():
        sys.exit(f"{args.run_dir} is not a run directory (no run.json)")
    planner = {}
    for item in args.planner:
        name, sep, value = item.partition("=")
        if not sep or name not in PLANNER_KEYS:
            sys.exit(f"--planner takes KEY=VALUE with KEY one of {', '.join(PLANNER_KEYS)}; got {item!r}")
        planner[name] = value if name == "name" else (float(value) if name == "temperature" else int(value))
    text = markdown(trace(args.run_dir, args.setting, args.task, nthread=args.nthread, planner=planner))
    print(text)
    if args.out:
        write_text(args.out, text)


if __name__ == "__main__":
    main()
