"""The IK baseline's low level against LAT's on the same robots and action count (target: IK <= 1.5x LAT).

    .venv/bin/python benchmarks/bench_ik.py                       # A1 and Daisy, about a minute
    .venv/bin/python benchmarks/bench_ik.py --robots a1 --per-step --repeats 3
    ./run.sh bench                                                # with the other benchmarks

Two workloads per robot, each timed for both low levels, interleaved, fastest of ``--repeats`` after a warm-up call:

- ``data``: CoM dynamics data, :func:`collect_transitions` of ``--robots-data x --actions`` random actions on a
  :class:`LatentActionEnv` (the recipes' dynamics-data stage, scaled down);
- ``eval``: an evaluation-sized closed loop, ``--robots-eval`` robots for ``--eval-actions`` chained random actions
  (goal reaching runs 8 robots for 30 actions); the MPC call both methods make before each action is left out, so
  the ratio is an upper bound on the evaluation stage's.

A third table times the IK solvers alone (:class:`LegKinematics` ``"reference"`` vs ``"vectorised"``) on the foot
targets of one IK action (``--robots-data`` robots), solved in chunks of the low level's feedback interval, each
chunk warm started from the pose before it.

LAT is a :class:`LatentLowLevel` whose gait policy is trained for a few epochs on a few experts (the speed does not
depend on its quality: ``pi(., z)`` is one forward pass, then one ``mujoco.rollout`` call per action). IK is the
default :class:`CommandLowLevel` (feedback once per swing phase, vectorised IK); ``--per-step`` adds the per-step
loop with the reference IK (how the experts are recorded) for comparison.

Example:
    >>> from bench_ik import benchmark_robot  # doctest: +SKIP
    >>> rows = benchmark_robot("a1")  # doctest: +SKIP
    >>> [round(r.ratio, 2) for r in rows]  # doctest: +SKIP
    [1.1, 1.3]
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

import numpy as np
from bench_sim import _interleaved_best_rates
from bench_cli import check_robot_names, positive_int

from hierloco.components.dynamics_data import collect_transitions
from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy import train_gait_policy
from hierloco.components.kinematics import LegKinematics
from hierloco.components.low_level import CommandLowLevel, LatentLowLevel
from hierloco.envs import get_robot
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots import CONTROL_TIMESTEP

RATIO_TARGET = 1.5  # IK / LAT


@dataclass
class IKRow:
    """Seconds of one workload for LAT and IK (and the per-step IK loop when measured)."""

    robot: str
    workload: str
    robots: int
    actions: int
    lat_seconds: float
    ik_seconds: float
    per_step_seconds: float | None = None

    @property
    def ratio(self) -> float:
        return self.ik_seconds / self.lat_seconds


def _tiny_lat(robot, num_experts: int = 4, epochs: int = 30):
    """A few experts (one gait period of settling) and a gait policy fitted to them for a few epochs."""
    library = build_expert_library(robot, num_experts, seed=0, settle_time=robot.gait_period, progress=False)
    periods = round(library.steps_per_action * CONTROL_TIMESTEP / robot.gait_period)
    trained = train_gait_policy(library.joint_targets, periods_per_action=periods, epochs=epochs, progress=False)
    return trained


def _data_workload(low_level, num_robots: int, actions: int):
    """``collect_transitions`` of ``num_robots x actions`` random actions (the env is built outside the timing)."""
    env = LatentActionEnv(low_level, num_robots=num_robots, seed=0)

    def run():
        collect_transitions(env, num_robots * actions, episode_length=20, seed=0, progress=False)
    return run


def _eval_workload(low_level, num_robots: int, actions: int):
    """``actions`` chained random actions on ``num_robots`` robots from standing, as an evaluation episode runs."""
    sim = BatchedSimulator(low_level.robot, num_robots, init_joint_noise=0.02, seed=0)

    def run():
        sim.reset()
        low_level.reset()
        rng = np.random.default_rng(0)
        for _ in range(actions):
            low_level.run(sim, rng.uniform(low_level.action_low, low_level.action_high,
                                           (num_robots, low_level.action_dim)))
    return run


def benchmark_robot(robot: str, *, data_robots: int = 100, data_actions: int = 2, eval_robots: int = 8,
                    eval_actions: int = 10, repeats: int = 1, per_step: bool = False) -> list[IKRow]:
    """The ``data`` and ``eval`` rows of one robot (see the module docstring)."""
    spec = get_robot(robot)
    trained = _tiny_lat(spec)
    makers = {"lat": lambda b: LatentLowLevel(trained, spec), "ik": lambda b: CommandLowLevel(spec, b)}
    if per_step:
        makers["per_step"] = lambda b: CommandLowLevel(spec, b, feedback_steps=1, ik_solver="reference")
    rows = []
    for workload, make, robots, actions in (("data", _data_workload, data_robots, data_actions),
                                            ("eval", _eval_workload, eval_robots, eval_actions)):
        # one "step" per call: the rates are calls per second of the fastest call, after a warm-up call each
        rates = _interleaved_best_rates({name: (make(m(robots), robots, actions), 1) for name, m in makers.items()},
                                        repeats)
        seconds = {name: 1.0 / rate for name, rate in rates.items()}
        rows.append(IKRow(spec.name, workload, robots, actions, seconds["lat"], seconds["ik"], seconds.get("per_step")))
    return rows


@dataclass
class SolverRow:
    """Milliseconds per control step of the two IK solvers on the same ``robots x chunk x L`` foot batches."""

    robot: str
    robots: int
    chunk: int
    reference_ms: float
    vectorised_ms: float

    @property
    def speedup(self) -> float:
        return self.reference_ms / self.vectorised_ms


def benchmark_solvers(robot: str, *, num_robots: int = 100, repeats: int = 1) -> SolverRow:
    """The IK solvers on the feet of one action of the IK low level (see the module docstring)."""
    spec = get_robot(robot)
    low = CommandLowLevel(spec, num_robots)
    sim = BatchedSimulator(spec, num_robots, seed=0)
    rng = np.random.default_rng(0)
    poses = low.run(sim, rng.uniform(low.action_low, low.action_high, (num_robots, 3))).joint_targets  # B x N x J
    sim.close()
    k = low.feedback_steps
    solvers = {name: LegKinematics(spec, solver=name) for name in LegKinematics.SOLVERS}
    feet = solvers["reference"].forward(poses)  # B x N x L x 3, reachable

    def solve(kinematics):
        def run():
            for start in range(1, poses.shape[1] - k + 1, k):
                kinematics.inverse(feet[:, start:start + k], np.repeat(poses[:, start - 1:start], k, 1))
        return run
    steps = (poses.shape[1] - 1) // k * k
    rates = _interleaved_best_rates({name: (solve(kin), steps) for name, kin in solvers.items()}, repeats)
    return SolverRow(spec.name, num_robots, k, 1000 / rates["reference"], 1000 / rates["vectorised"])


def format_solver_table(rows: list[SolverRow]) -> str:
    lines = ["| robot | robots x chunk | reference ms / step | vectorised ms / step | speed-up |", "|---|---|---|---|---|"]
    lines += [f"| {r.robot} | {r.robots} x {r.chunk} | {r.reference_ms:.2f} | {r.vectorised_ms:.2f} | {r.speedup:.1f}x |"
              for r in rows]
    return "\n".join(lines)


def format_table(rows: list[IKRow]) -> str:
    lines = [f"IK low level vs LAT's (target: IK / LAT <= {RATIO_TARGET})", "",
             "| robot | workload | robots x actions | LAT s | IK s | IK / LAT | per-step IK s | per-step / LAT |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        per_step = ("-", "-") if r.per_step_seconds is None else (f"{r.per_step_seconds:.2f}",
                                                                   f"{r.per_step_seconds / r.lat_seconds:.1f}")
        lines.append(f"| {r.robot} | {r.workload} | {r.robots} x {r.actions} | {r.lat_seconds:.2f} | "
                     f"{r.ik_seconds:.2f} | {r.ratio:.2f} | {per_step[0]} | {per_step[1]} |")
    return "\n".join(lines)


def targets_met(rows: list[IKRow]) -> bool:
    return all(r.ratio <= RATIO_TARGET for r in rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["a1", "daisy"], help="registered robot names")
    parser.add_argument("--robots-data", type=positive_int, default=100, help="robots collecting dynamics data")
    parser.add_argument("--actions", type=positive_int, default=2, help="actions per robot in the data workload")
    parser.add_argument("--robots-eval", type=positive_int, default=8, help="robots in the evaluation workload")
    parser.add_argument("--eval-actions", type=positive_int, default=10, help="actions in the evaluation workload")
    parser.add_argument("--repeats", type=positive_int, default=1, help="timed calls of each workload")
    parser.add_argument("--per-step", action="store_true", help="also time the per-step loop (reference IK)")
    parser.add_argument("--check", action="store_true", help=f"exit 1 when IK / LAT exceeds {RATIO_TARGET}")
    args = parser.parse_args(argv)
    check_robot_names(parser, args.robots)
    rows, solver_rows = [], []
    for name in args.robots:
        print(f"benchmarking the IK low level on {name} ...", flush=True)
        rows += benchmark_robot(name, data_robots=args.robots_data, data_actions=args.actions,
                                eval_robots=args.robots_eval, eval_actions=args.eval_actions, repeats=args.repeats,
                                per_step=args.per_step)
        solver_rows.append(benchmark_solvers(name, num_robots=args.robots_data, repeats=args.repeats))
    print()
    print(format_table(rows))
    print()
    print(format_solver_table(solver_rows))
    print(f"\n({os.cpu_count()} cores; the MPC call before each evaluation action is the same for both and left out)")
    return 1 if args.check and not targets_met(rows) else 0


if __name__ == "__main__":
    sys.exit(main())
