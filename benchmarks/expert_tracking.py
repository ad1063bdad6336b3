"""How well the expert controller tracks its commands, and how long a 50-expert library takes to build.

    .venv/bin/python benchmarks/expert_tracking.py [--robots a1 daisy] [--seeds 3]
    .venv/bin/python benchmarks/expert_tracking.py --feedback-steps auto --ik-solver vectorised --skip-library
    .venv/bin/python benchmarks/expert_tracking.py --footstep-law plain

For each robot: commands (+-0.2, 0), (0, +-0.2) m/s, turns in place and two corners of the command box, run
closed loop from standing; the mean CoM velocity and yaw rate over 5 s after 2 s of settling, averaged over seeds
(initial joint noise), with the worst absolute error over seeds and axes. The defaults are the experts' controller
(feedback every step, reference IK, integral law); the options select the IK low level's variants.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hierloco.components.expert_library import build_expert_library
from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import get_robot

SETTLE_STEPS, MEASURE_STEPS = 200, 500


def commands_for(robot) -> np.ndarray:
    hi, lo = np.asarray(robot.command_high), np.asarray(robot.command_low)
    yaw = 0.8 * hi[2]
    return np.array([[0.2, 0, 0], [-0.2, 0, 0], [0, 0.2, 0], [0, -0.2, 0], [0, 0, yaw], [0, 0, -yaw], 0.9 * hi,
                     [0.9 * lo[0], 0.9 * hi[1], 0.9 * lo[2]]])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["a1", "daisy"])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--feedback-steps", default="1",
                        help="control steps per feedback update, 'swing' (one swing phase) or 'auto' (the IK low "
                             "level's default, a swing phase split into parts of at most 0.25 s)")
    parser.add_argument("--footstep-law", default="integral", choices=["integral", "plain"])
    parser.add_argument("--ik-solver", default="reference", choices=["reference", "vectorised"])
    parser.add_argument("--skip-library", action="store_true", help="do not time a 50-expert library build")
    args = parser.parse_args(argv)
    print(f"feedback every {args.feedback_steps} step(s), {args.footstep_law} footstep law, {args.ik_solver} IK\n")
    print("| robot | command (vx, vy, wz) | achieved, mean over seeds | worst error | fell |")
    print("|---|---|---|---|---|")
    for name in args.robots:
        robot = get_robot(name)
        commands = commands_for(robot)
        achieved, fell = [], np.zeros(len(commands), bool)
        start = time.perf_counter()
        for seed in range(args.seeds):
            sim = BatchedSimulator(robot, len(commands), init_joint_noise=0.05, seed=seed)
            controller = RaibertController(robot, len(commands), footstep_law=args.footstep_law,
                                           ik_solver=args.ik_solver)
            feedback = {"swing": controller.swing_steps, "auto": controller.swing_chunk_steps()}.get(
                args.feedback_steps) or int(args.feedback_steps)
            out = run_closed_loop(sim, controller, commands, SETTLE_STEPS + MEASURE_STEPS, ramp_steps=100,
                                  feedback_steps=feedback)
            fell |= out.failed.any(1)
            achieved.append(np.c_[out.com_velocity_local[:, SETTLE_STEPS:].mean(1),
                                  out.yaw_rate[:, SETTLE_STEPS:].mean(1)])
        seconds = time.perf_counter() - start
        achieved = np.array(achieved)  # seeds x commands x 3
        for i, command in enumerate(commands):
            mean = achieved[:, i].mean(0)
            worst = np.abs(achieved[:, i] - command).max()
            print(f"| {name} | ({command[0]:+.2f}, {command[1]:+.2f}, {command[2]:+.2f}) | "
                  f"({mean[0]:+.3f}, {mean[1]:+.3f}, {mean[2]:+.3f}) | {worst:.3f} | {'yes' if fell[i] else 'no'} |")
        print(f"| {name} | mean worst error {np.mean(np.abs(achieved - commands).max((0, 2))):.3f}, "
              f"{args.seeds} x {SETTLE_STEPS + MEASURE_STEPS} steps in {seconds:.1f} s | | | |")
        if args.skip_library:
            continue
        start = time.perf_counter()
        build_expert_library(robot, 50, seed=0, progress=False)
        print(f"| {name} | 50-expert library built in {time.perf_counter() - start:.1f} s | | | |")


if __name__ == "__main__":
    main()
