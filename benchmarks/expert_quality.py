"""Do the expert gaits walk as commanded? The expert-library diagnosis for the built-in robots and the 20 kg test
quadruped (tests/fixtures/quadruped20) with its derived 0.5 s gait period and with a too-short 0.2 s one.

    PYTHONPATH=. .venv/bin/python benchmarks/expert_quality.py                 # paper scale and CI preset, 3 seeds
    PYTHONPATH=. .venv/bin/python benchmarks/expert_quality.py --seeds 1 --robots quadruped20@0.2

For each robot and preset (paper: 50 experts settled 3 s; tiny: 6 experts settled 1 s) and seed: whether the
library passes (:func:`hierloco.components.expert_library.diagnose_expert_library`), its worst reach (the
threshold is 0.4 of the box half-width), and per axis the mean signed and worst absolute error of achieved minus
commanded (vx, vy in m/s, yaw rate in rad/s), with the fitted slope. Prints a Markdown table and the wall time.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

from hierloco.components.expert_library import MIN_REACH, build_expert_library, diagnose_expert_library
from hierloco.envs.robots import get_robot

FIXTURE = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "quadruped20" / "quadruped20.yaml"
PRESETS = {"paper": (50, 3.0), "tiny": (6, 1.0)}


def robot_for(label: str):
    """``a1``, ``daisy``, ``quadruped20`` (derived period) or ``quadruped20@<period in s>``."""
    name, _, period = label.partition("@")
    robot = get_robot(str(FIXTURE) if name == "quadruped20" else name)
    return robot.replace(gait_period=float(period)) if period else robot


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["a1", "daisy", "quadruped20", "quadruped20@0.2"])
    parser.add_argument("--presets", nargs="+", default=list(PRESETS), choices=list(PRESETS))
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    print(f"threshold: reach >= {MIN_REACH} towards both edges of every axis")
    print("| robot | gait period (s) | preset | seed | passes | worst reach | mean error (vx, vy, wz) | "
          "worst abs error (vx, vy, wz) | slope (vx, vy, wz) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label in args.robots:
        robot = robot_for(label)
        for preset in args.presets:
            num_experts, settle_time = PRESETS[preset]
            for seed in range(args.seeds):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)  # the report below says it
                    library = build_expert_library(robot, num_experts, seed=seed, settle_time=settle_time,
                                                   progress=False)
                report = diagnose_expert_library(library, robot=robot)
                axes = report.axes
                print(f"| {robot.name} | {robot.gait_period} | {preset} | {seed} | {'yes' if report.ok else 'NO'} | "
                      f"{report.worst_reach:.2f} | {', '.join(f'{a.mean_error:+.3f}' for a in axes)} | "
                      f"{', '.join(f'{a.worst_abs_error:.3f}' for a in axes)} | "
                      f"{', '.join(f'{a.slope:.2f}' for a in axes)} |", flush=True)
    print(f"wall time {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
