"""The robot check (``hierloco-robot-check``) against the experts stage, on the fixture robots.

For each robot: the whole check as the command runs it by default (screening, verification with a gait policy of
150 epochs of 512 units, what made the difference: :func:`hierloco.components.expert_tuning.tune_expert_parameters`),
then the experts stage as the small preset builds it (30 experts settled 3 s,
:func:`hierloco.components.expert_library.build_expert_library`) for the robot with what the check found. Both are
timed in wall-clock and in this
process's CPU seconds: on a shared machine the wall-clock grows with the load, the CPU seconds much less, and a
check of C CPU seconds takes at most about C s of wall-clock on cores of its own. Targets: the check within
``TARGET_SECONDS`` (3 minutes) of CPU on 2 cores, i.e. at most ``TARGET_SECONDS`` wall-clock on an idle 2-core
machine; the ratio to the experts stage is printed as the load-independent number to compare between machines.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_robot_check.py                     # every fixture, minutes each
    PYTHONPATH=. .venv/bin/python benchmarks/bench_robot_check.py --robots quadruped50 --check
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from hierloco.components.expert_library import ExpertQualityError, build_expert_library  # noqa: E402
from hierloco.components.expert_tuning import tune_expert_parameters  # noqa: E402
from hierloco.envs.robots import get_robot  # noqa: E402

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "fixtures"
ROBOTS = {
    "quadruped9": FIXTURES / "quadruped9" / "quadruped9.yaml",
    "quadruped20": FIXTURES / "quadruped20" / "quadruped20.yaml",
    "quadruped40": FIXTURES / "quadruped40" / "quadruped40.yaml",
    "quadruped50": FIXTURES / "quadruped50" / "quadruped50.yaml",
    "hexapod10": FIXTURES / "hexapod10" / "hexapod10.yaml",
    "hexapod10_wave": FIXTURES / "hexapod10" / "hexapod10_wave.yaml",
}
TARGET_SECONDS = 180.0  # CPU s of the whole check (2 cores: at most this wall-clock on an idle machine)
EXPERTS, SETTLE_TIME = 30, 3.0  # the small preset's experts stage (recipes/conf/experts/small.yaml)


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _load() -> str:
    return ", ".join(f"{x:.1f}" for x in os.getloadavg())


def benchmark_robot(name: str, budget_seconds: float = 300.0) -> dict:
    """The check, then the experts stage on the robot with what it found (what a recipe builds once the lines are
    pasted): wall-clock and CPU seconds of both, and what the check found."""
    robot = get_robot(str(ROBOTS[name]))
    load = _load()
    wall, cpu = time.perf_counter(), _cpu()
    result = tune_expert_parameters(robot, budget_seconds=budget_seconds,
                                    policy={"epochs": 150, "hidden": 512, "latent_dim": 3})
    check_wall, check_cpu = time.perf_counter() - wall, _cpu() - cpu
    wall, cpu = time.perf_counter(), _cpu()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            build_expert_library(result.tuned_robot(), EXPERTS, settle_time=SETTLE_TIME, seed=0, progress=False)
    except ExpertQualityError:
        pass  # not found: the stage stops as a recipe's would, and that is its time
    experts_wall, experts_cpu = time.perf_counter() - wall, _cpu() - cpu
    changed = result.params.changed(result.reference) if result.params is not None else []
    return {"robot": name, "found": result.found, "changed": changed,
            "needed": [d.name for d in result.differences if d.needed],
            "margin": [d.name for d in result.differences if d.margin],
            "overrides": result.override_lines(), "verifications": len(result.verifications),
            "experts_wall": experts_wall, "experts_cpu": experts_cpu, "check_wall": check_wall,
            "check_cpu": check_cpu, "ratio_wall": check_wall / experts_wall, "ratio_cpu": check_cpu / experts_cpu,
            "load": f"{load} -> {_load()}"}


def format_table(rows: list[dict]) -> str:
    lines = ["| robot | found | changed (made the difference; more margin) | overrides | experts stage wall / CPU s | "
             "check wall / CPU s | ratio wall / CPU | CPU within target | load average (1, 5, 15 min) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['robot']} | {'yes' if r['found'] else 'NO'} | {', '.join(r['changed']) or '-'} "
            f"({', '.join(r['needed']) or '-'}{'; margin: ' + ', '.join(r['margin']) if r['margin'] else ''}) | {' '.join(r['overrides']) or '-'} | {r['experts_wall']:.0f} / "
            f"{r['experts_cpu']:.0f} | {r['check_wall']:.0f} / {r['check_cpu']:.0f} | {r['ratio_wall']:.1f} / "
            f"{r['ratio_cpu']:.1f} | {'yes' if r['check_cpu'] <= TARGET_SECONDS else 'NO'} "
            f"(<= {TARGET_SECONDS:.0f}) | {r['load']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=list(ROBOTS), choices=list(ROBOTS))
    parser.add_argument("--budget", type=float, default=300.0, help="the check's --budget (s, default 300)")
    parser.add_argument("--check", action="store_true", help="exit 1 when a robot is not found or over the target")
    args = parser.parse_args(argv)
    print(f"{len(os.sched_getaffinity(0))} cores; load average {_load()}", flush=True)
    rows = []
    for name in args.robots:
        print(f"benchmarking the check on {name} ...", flush=True)
        rows.append(benchmark_robot(name, args.budget))
        print(format_table(rows[-1:]).splitlines()[-1], flush=True)
    print("\n" + format_table(rows))
    if args.check and not all(r["found"] and r["check_cpu"] <= TARGET_SECONDS for r in rows):
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
