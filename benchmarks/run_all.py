"""hierloco's performance suite (``docs/index.md``, Performance): every number comes from this one run, as ratios
on this machine.

    ./run.sh bench                                  # A1 and Daisy, B = 64, best of 8
    ./run.sh bench --robots a1 --num-robots 32 --repeats 3
    ./run.sh bench --check                          # exit 1 when a target ratio is missed

Simulation: batched simulator vs native mujoco.rollout vs a naive TorchRL loop, and on rough ground vs flat ground
(bench_terrain.py). Planning: one MPC call vs the bare model forward pass. The IK baseline's low level vs LAT's
(dynamics data and an evaluation-sized closed loop). SAC: one SAC update vs a plain update of the same networks
(bench_sac.py, more options there). Studies: a study through Ray vs the same jobs one by one (bench_study.py, run on
its own: it takes minutes). LAT end to end at paper scale is timed by the recipe itself (report.json,
stage_seconds).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import bench_ik
import bench_planner
import bench_sac
import bench_sim
import bench_study
import bench_terrain
from bench_cli import check_robot_names, positive_int as _positive_int


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["a1", "daisy"], help="registered robot names")
    parser.add_argument("--num-robots", type=_positive_int, default=64, help="B, copies simulated together")
    parser.add_argument("--control-steps", type=_positive_int, default=100,
                        help="control steps per batched call (one latent action: 100 = 500 physics steps)")
    parser.add_argument("--repeats", type=_positive_int, default=8,
                        help="timed calls of each workload after a warm-up, interleaved; the fastest is kept")
    parser.add_argument("--torchrl-steps", type=_positive_int, default=500, help="env steps per TorchRL rollout")
    parser.add_argument("--nthread", type=_positive_int, default=os.cpu_count() or 1, help="simulation threads")
    parser.add_argument("--no-study", action="store_true", help="skip the study benchmark (Ray vs one by one)")
    parser.add_argument("--out", help="also write the tables to this Markdown file (atomically)")
    parser.add_argument("--check", action="store_true", help="exit 1 when a target ratio is missed")
    args = parser.parse_args(argv)
    check_robot_names(parser, args.robots)
    return args


def _machine() -> str:
    import torch

    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return (f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {len(os.sched_getaffinity(0))} cores "
            f"({platform.processor() or platform.machine()}); torch {torch.__version__}; load average {load}")


def main(argv=None) -> int:
    args = parse_args(argv)
    sections = []

    def report(title: str, table: str) -> None:
        print("\n" + table, flush=True)
        sections.append(f"## {title}\n\n```\n{table}\n```\n")

    machine = _machine()
    rows = []
    for name in args.robots:
        print(f"benchmarking {name} ...", flush=True)
        rows.append(bench_sim.benchmark_robot(name, num_robots=args.num_robots, control_steps=args.control_steps,
                                              repeats=args.repeats, torchrl_steps=args.torchrl_steps,
                                              nthread=args.nthread))
    report("Simulation", bench_sim.format_table(rows, args.nthread))
    print("\nbenchmarking the batched simulator on rough ground ...", flush=True)
    terrain_rows = [bench_terrain.benchmark_robot(name, args.num_robots, args.control_steps, args.repeats, args.nthread)
                    for name in args.robots]
    report("Terrain", bench_terrain.format_table(terrain_rows, args.nthread))
    print("\nbenchmarking one MPC call ...", flush=True)
    planner_rows = [bench_planner.benchmark_planner(robots=1), bench_planner.benchmark_planner(robots=8)]
    report("Planning", bench_planner.format_table(planner_rows))
    print("\nbenchmarking the IK low level against LAT's ...", flush=True)
    ik_rows = [row for name in args.robots for row in bench_ik.benchmark_robot(name)]
    report("IK baseline vs LAT", bench_ik.format_table(ik_rows))
    print("\nbenchmarking one SAC update ...", flush=True)
    sac_rows = [bench_sac.benchmark_update(size, size, 1, repeats=args.repeats, before=True) for size in (256, 512)]
    report("SAC update", bench_sac.format_updates(sac_rows))
    study_ok = True
    if not args.no_study:
        print("\nbenchmarking a study through Ray against the same jobs one by one ...", flush=True)
        study = bench_study.benchmark()
        study_ok = study["ratio"] <= bench_study.TARGET_RATIO
        report("Study through Ray", bench_study.format_row(study))
    if args.out:
        from hierloco.io import write_text

        write_text(args.out, f"# `./run.sh bench`\n\n{machine} (at the start); load at the end "
                             f"{', '.join(f'{x:.1f}' for x in os.getloadavg())}\n\n" + "\n".join(sections))
        print(f"\ntables written to {args.out}")
    if args.check and (not bench_sim.targets_met(rows) or not bench_terrain.targets_met(terrain_rows)
                       or any(r.ratio > 2.0 for r in planner_rows)
                       or not bench_ik.targets_met(ik_rows) or any(r.ratio > bench_sac.TARGET_RATIO for r in sac_rows)
                       or not study_ok):
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
