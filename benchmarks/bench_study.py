"""A study through Ray against the same jobs run one by one with the same cores.

One by one, each job gets every core (its simulation and torch threads); through Ray, jobs of one core each run side
by side on a local Ray instance started for the study (its start-up is part of the time). Both run the same recipe
runs into fresh run directories. Target: Ray <= 1.1x one by one.

    python benchmarks/bench_study.py                       # 4 LIB runs (small preset) on A1
    python benchmarks/bench_study.py --method lat --jobs 2 --preset tiny
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from hierloco.pipeline import studies  # noqa: E402

TARGET_RATIO = 1.1  # through Ray / one by one


def make_jobs(root: Path, method: str, count: int, preset: str, cores: int) -> list[studies.Job]:
    overrides = [f"preset={preset}", "progress=false", "eval.generalization=null", "eval.videos=[]",
                 "eval.figures=false", "logger.backends=[csv]"]
    return [studies.Job(method, str(root / f"{method}_seed{seed}"), [*overrides, f"seed={seed}"], cores=cores)
            for seed in range(count)]


def benchmark(method: str = "lib", count: int = 4, preset: str = "small") -> dict:
    cores = len(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        start = time.perf_counter()
        for job in make_jobs(root / "one_by_one", method, count, preset, cores):
            outcome = studies.execute(job)
            assert outcome["ok"], outcome["error"]
        sequential = time.perf_counter() - start
        start = time.perf_counter()
        results = studies.run_jobs(make_jobs(root / "ray", method, count, preset, 1), progress_every=1e9)
        through_ray = time.perf_counter() - start
        assert all(r.ok for r in results), [r.error for r in results if not r.ok]
    return {"method": method, "jobs": count, "preset": preset, "cores": cores, "one_by_one_s": sequential,
            "ray_s": through_ray, "ratio": through_ray / sequential}


def format_row(row: dict) -> str:
    return (f"| study of {row['jobs']} {row['method'].upper()} runs ({row['preset']}), {row['cores']} cores | "
            f"one by one {row['one_by_one_s']:.0f} s | through Ray {row['ray_s']:.0f} s | "
            f"ratio {row['ratio']:.2f} (target <= {TARGET_RATIO}) |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--method", default="lib")
    parser.add_argument("--jobs", type=int, default=4)
    parser.add_argument("--preset", default="small")
    args = parser.parse_args()
    print(format_row(benchmark(args.method, args.jobs, args.preset)))
