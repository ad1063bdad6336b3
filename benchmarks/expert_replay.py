"""Are the expert gaits steady open loop? Each expert's recorded period of joint targets, replayed open loop and
repeated from standing, measured as the gait policy's check measures pi(., z_g) (Li et al., Sec. III-B): the mean
CoM velocity over the last actions against the expert's recorded velocity.

    PYTHONPATH=. .venv/bin/python benchmarks/expert_replay.py outputs/lat/paper/a1_seed0 outputs/lat/paper/a1-stiff_seed0

A gait policy cannot reproduce an expert better than the expert's own targets replayed open loop: where these do
not reproduce it either, a failed gait-policy check is the physics (feet slipping, a gait that changes from cycle
to cycle), not the policy's fit. Prints per run directory (its robot and actuator profile from ``run.json``) the
fraction within 0.05 m/s, the median error, falls, and the median change of the replayed velocity from one action to
the next, beside the gait policy's own check (``gait_policy_check.json``) when the run has one.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from hierloco.components.evaluation import action_velocities
from hierloco.components.expert_library import ExpertLibrary
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import get_robot
from hierloco.envs.robots.profiles import with_profile


def replay(run_dir: Path, num_actions: int = 4) -> dict:
    run = json.loads((run_dir / "run.json").read_text())
    robot = with_profile(get_robot(run["robot"]), run.get("robot_profile", "own"))
    library = ExpertLibrary.load(run_dir / "experts.npz")
    targets = np.asarray(library.joint_targets)  # G x N x J: one recorded action of each expert
    sim = BatchedSimulator(robot, len(targets), seed=0, nthread=1)
    results = [sim.run(targets) for _ in range(num_actions)]
    sim.close()
    velocities, fell = action_velocities(results, targets.shape[1])
    error = np.linalg.norm(np.mean(velocities, 0) - library.velocity_local, axis=-1)
    error[fell] = np.inf
    out = {"run_dir": str(run_dir), "robot": run["robot"], "profile": run.get("robot_profile", "own"),
           "reproduced": float(np.mean(error <= 0.05)), "median_error": float(np.median(error)),
           "fell": int(fell.sum()),
           "cycle_change": float(np.median(np.linalg.norm(velocities[-1] - velocities[-2], axis=-1)))}
    check = run_dir / "gait_policy_check.json"
    if check.exists():
        policy = json.loads(check.read_text())
        out["policy_reproduced"] = policy["reproduced_fraction"]
        out["policy_median_error"] = float(np.median(np.asarray(policy["reproduction_error"], dtype=float)))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dirs", nargs="+", type=Path, help="run directories with experts.npz")
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.run_dirs if not (d / "experts.npz").exists() or not (d / "run.json").exists()]
    if missing:
        parser.error(f"no experts.npz and run.json in: {', '.join(missing)}")
    print("| run directory | robot | profile | expert targets replayed: within 0.05 m/s | median error m/s | fell | "
          "change per action m/s | gait policy: within 0.05 m/s | gait policy median m/s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for run_dir in args.run_dirs:
        r = replay(run_dir)
        policy = (f"{100 * r['policy_reproduced']:.0f}% | {r['policy_median_error']:.3f}"
                  if "policy_reproduced" in r else "- | -")
        print(f"| {r['run_dir']} | {r['robot']} | {r['profile']} | {100 * r['reproduced']:.0f}% | "
              f"{r['median_error']:.3f} | {r['fell']} | {r['cycle_change']:.3f} | {policy} |")


if __name__ == "__main__":
    main()
