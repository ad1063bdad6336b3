"""Terrain throughput (``docs/terrain.md``, Speed): the batched simulator on ``rough`` ground against flat ground.

Both run the same robot, the same number of copies, the same initial joint noise and the same walking-like joint
targets through :meth:`BatchedSimulator.run` (one latent action per call), timed as in ``bench_sim.py``: the calls
alternate between the two simulators and the fastest of the repeats is kept, so that both see the same machine
conditions. Measured in physics steps per second; the target is ``rough / flat >= 0.8`` at difficulty 0.5. The
ratio is also given in CPU time (the process's, all simulation threads): on a machine shared with other jobs, wall
time mixes in their load, CPU time much less.

    python benchmarks/bench_terrain.py --robots a1 --num-robots 32 --repeats 5

Example:
    >>> from bench_terrain import benchmark_robot  # doctest: +SKIP
    >>> benchmark_robot("a1", num_robots=64, repeats=5).ratio  # doctest: +SKIP
    0.85
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

import time

from bench_cli import check_robot_names, positive_int

from hierloco.envs import get_robot
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import PHYSICS_STEPS_PER_CONTROL
from hierloco.envs.scripted_gait import sinusoidal_gait

TERRAIN = "rough"
DIFFICULTY = 0.5
RATIO_TARGET = 0.8  # rough / flat physics steps per second


@dataclass
class TerrainRow:
    """Physics steps per second of one robot on flat and on rough ground, each the best of the repeats."""

    robot: str
    num_robots: int
    control_steps: int
    terrain: str
    flat: float
    rough: float
    cpu_ratio: float  # the same ratio measured in the process's CPU time

    @property
    def ratio(self) -> float:
        return self.rough / self.flat


def _interleaved_best(workloads: dict, repeats: int) -> tuple[dict[str, float], dict[str, float]]:
    """Physics steps per second of each workload ``name -> (fn, physics_steps)``, the fastest of ``repeats`` calls
    after a warm-up, the calls alternating between the workloads (as ``bench_sim``'s): by wall time, and by the
    process's CPU time."""
    for fn, _ in workloads.values():
        fn()
    wall = {name: float("inf") for name in workloads}
    cpu = dict(wall)
    for _ in range(repeats):
        for name, (fn, _) in workloads.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            fn()
            wall[name] = min(wall[name], time.perf_counter() - start)
            cpu[name] = min(cpu[name], time.process_time() - start_cpu)
    return ({name: steps / wall[name] for name, (_, steps) in workloads.items()},
            {name: steps / cpu[name] for name, (_, steps) in workloads.items()})


def benchmark_robot(robot: str, num_robots: int = 64, control_steps: int = 100, repeats: int = 8,
                    nthread: int | None = None, difficulty: float = DIFFICULTY) -> TerrainRow:
    """The row of one robot: the batched simulator's physics steps/s on flat and on ``rough`` ground."""
    robot = get_robot(robot)
    nthread = int(nthread) if nthread is not None else (os.cpu_count() or 1)
    targets = sinusoidal_gait(robot, num_robots, control_steps)
    terrain = {"name": TERRAIN, "difficulty": float(difficulty)}
    sims = {name: BatchedSimulator(robot, num_robots, init_joint_noise=0.05, seed=0, nthread=nthread,
                                   terrain=ground) for name, ground in (("flat", None), ("rough", terrain))}
    starts = {name: sim.state.copy() for name, sim in sims.items()}

    def workload(name):
        sim, start = sims[name], starts[name]

        def run():
            sim.set_state(start)
            sim.run(targets)

        return run

    steps = num_robots * control_steps * PHYSICS_STEPS_PER_CONTROL
    try:
        rates, cpu_rates = _interleaved_best({name: (workload(name), steps) for name in sims}, repeats)
    finally:
        for sim in sims.values():
            sim.close()
    return TerrainRow(robot.name, num_robots, control_steps, sims["rough"].terrain.describe(), **rates,
                      cpu_ratio=cpu_rates["rough"] / cpu_rates["flat"])


def format_table(rows: list[TerrainRow], nthread: int) -> str:
    """A plain-text table of the rows and the target ratio."""
    header = f"{'robot':<8}{'B':>5}{'T':>5}{'flat':>12}{'rough':>12}{'rough/flat':>13}{'in CPU time':>13}  terrain"
    lines = [f"batched simulator, physics steps per second (best of repeats), {nthread} thread(s); "
             f"target: rough/flat >= {RATIO_TARGET:.2f}", header, "-" * len(header)]
    for row in rows:
        mark = "ok" if row.ratio >= RATIO_TARGET else "MISS"
        lines.append(f"{row.robot:<8}{row.num_robots:>5}{row.control_steps:>5}{row.flat:>12,.0f}{row.rough:>12,.0f}"
                     f"{row.ratio:>9.2f} {mark:<4}{row.cpu_ratio:>12.2f}  {row.terrain}")
    return "\n".join(lines)


def targets_met(rows: list[TerrainRow]) -> bool:
    return all(row.ratio >= RATIO_TARGET for row in rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["a1", "daisy"], help="registered robot names")
    parser.add_argument("--num-robots", type=positive_int, default=64, help="B, copies simulated together")
    parser.add_argument("--control-steps", type=positive_int, default=100, help="control steps per call")
    parser.add_argument("--repeats", type=positive_int, default=8, help="timed calls of each workload, interleaved")
    parser.add_argument("--nthread", type=positive_int, default=os.cpu_count() or 1, help="simulation threads")
    parser.add_argument("--check", action="store_true", help="exit 1 when the target ratio is missed")
    args = parser.parse_args(argv)
    check_robot_names(parser, args.robots)
    rows = [benchmark_robot(name, args.num_robots, args.control_steps, args.repeats, args.nthread)
            for name in args.robots]
    print(format_table(rows, args.nthread))
    return 1 if args.check and not targets_met(rows) else 0


if __name__ == "__main__":
    sys.exit(main())
