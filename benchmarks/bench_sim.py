"""Simulation throughput (``docs/index.md``, Performance): the batched simulator against native ``mujoco.rollout``
and a TorchRL loop.

All three run the same robot model, the same initial states and the same walking-like joint targets, and are
measured in physics steps per second (5 physics steps per 100 Hz control step):

- ``batched``: :meth:`BatchedSimulator.run` on ``B`` copies, one latent action (``T`` control steps) per call,
  including its input checks and the summary it returns;
- ``native``: a bare ``mujoco.rollout.Rollout(nthread).rollout`` on the simulator's own model with the controls
  already repeated per physics step and the output arrays preallocated (the ceiling for the batched simulator);
- ``torchrl``: a Python loop of ``make_env(robot)`` steps (``env.rollout`` with a policy), one copy.

Example:
    >>> from bench_sim import benchmark_robot  # doctest: +SKIP
    >>> row = benchmark_robot("a1", num_robots=64, repeats=5)  # doctest: +SKIP
    >>> row.batched / row.native  # doctest: +SKIP
    0.97
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import mujoco
import numpy as np
import torch
from mujoco import rollout as mj_rollout

from hierloco.envs import get_robot, make_env
from hierloco.envs.batched_sim import STATE_SPEC, BatchedSimulator
from hierloco.envs.robots import PHYSICS_STEPS_PER_CONTROL, RobotSpec
from hierloco.envs.scripted_gait import sinusoidal_gait

NATIVE_RATIO_TARGET = 0.7  # batched / native
TORCHRL_RATIO_TARGET = 10.0  # batched / naive TorchRL loop


@dataclass
class ThroughputRow:
    """Physics steps per second of one robot, each the best of the repeats."""

    robot: str
    num_robots: int
    control_steps: int
    batched: float
    native: float
    torchrl: float

    @property
    def native_ratio(self) -> float:
        return self.batched / self.native

    @property
    def torchrl_ratio(self) -> float:
        return self.batched / self.torchrl


def _interleaved_best_rates(workloads: dict, repeats: int) -> dict[str, float]:
    """Physics steps per second of each workload, the fastest of ``repeats`` calls after one warm-up call.

    ``workloads`` maps a name to ``(fn, physics_steps)``. The calls alternate between the workloads (one call of
    each per repeat), so that all of them see the same machine conditions: on a shared 2-core machine other
    processes change the absolute numbers far more than the ratios.
    """
    for fn, _ in workloads.values():
        fn()
    best = {name: float("inf") for name in workloads}
    for _ in range(repeats):
        for name, (fn, _) in workloads.items():
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    return {name: steps / best[name] for name, (_, steps) in workloads.items()}


def _batched_and_native_workloads(robot: RobotSpec, num_robots: int, control_steps: int, nthread: int):
    """The batched-simulator and bare-rollout calls on the same model, initial states, controls and threads."""
    sim = BatchedSimulator(robot, num_robots, init_joint_noise=0.05, seed=0, nthread=nthread)
    initial = sim.state.copy()
    targets = sinusoidal_gait(robot, num_robots, control_steps)

    def batched():
        sim.set_state(initial)
        sim.run(targets)

    # native: same model, same initial states, same controls, same threads; inputs and outputs ready
    model = sim.model
    control = np.repeat(targets, PHYSICS_STEPS_PER_CONTROL, axis=1)
    datas = [mujoco.MjData(model) for _ in range(max(1, nthread))]
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    state_out = np.empty((num_robots, control.shape[1], nstate))
    sensor_out = np.empty((num_robots, control.shape[1], model.nsensordata))
    pool = mj_rollout.Rollout(nthread=nthread if nthread > 1 else 0)

    def native():
        pool.rollout(model, datas, initial, control, state=state_out, sensordata=sensor_out)

    # the batched simulator computes exactly what native rollout does
    batched()
    native()
    if not np.array_equal(sim.state, state_out[:, -1]):
        raise RuntimeError(f"{robot.name}: batched simulator and native rollout disagree")

    def close():
        pool.close()
        sim.close()

    return batched, native, close


def _torchrl_workload(robot: RobotSpec, env_steps: int):
    """A Python loop of TorchRL env steps: ``make_env`` + ``env.rollout`` with a policy, one copy."""
    env = make_env(robot, seed=0, time_limit=1e6)
    targets = torch.as_tensor(sinusoidal_gait(robot, 1, env_steps)[0], dtype=torch.float32)

    def rollout():
        step = iter(range(env_steps))
        td = env.rollout(env_steps, policy=lambda td: td.set("action", targets[next(step)]),
                         break_when_any_done=False)
        if td["next", "done"].any():
            raise RuntimeError(f"{robot.name}: the robot fell in the TorchRL loop; the workload is not comparable")

    return rollout, env.close


def benchmark_robot(robot: str | RobotSpec, num_robots: int = 64, control_steps: int = 100, repeats: int = 8,
                    torchrl_steps: int = 500, nthread: int | None = None) -> ThroughputRow:
    """The throughput row of one robot: physics steps/s of each workload, best of ``repeats`` interleaved calls."""
    robot = get_robot(robot)
    nthread = int(nthread) if nthread is not None else (os.cpu_count() or 1)
    batched, native, close_sim = _batched_and_native_workloads(robot, num_robots, control_steps, nthread)
    naive, close_env = _torchrl_workload(robot, torchrl_steps)
    batch_steps = num_robots * control_steps * PHYSICS_STEPS_PER_CONTROL
    try:
        rates = _interleaved_best_rates({"batched": (batched, batch_steps), "native": (native, batch_steps),
                                         "torchrl": (naive, torchrl_steps * PHYSICS_STEPS_PER_CONTROL)}, repeats)
    finally:
        close_sim()
        close_env()
    return ThroughputRow(robot.name, num_robots, control_steps, **rates)


def format_table(rows: list[ThroughputRow], nthread: int) -> str:
    """A plain-text table of the rows and the target ratios (``docs/index.md``, Performance)."""
    header = (f"{'robot':<8}{'B':>5}{'T':>5}{'batched':>12}{'native':>12}{'torchrl':>12}"
              f"{'batched/native':>17}{'batched/torchrl':>18}")
    lines = [f"physics steps per second (best of repeats), {nthread} thread(s); "
             f"targets: batched/native >= {NATIVE_RATIO_TARGET:.2f}, batched/torchrl >= {TORCHRL_RATIO_TARGET:.0f}x",
             header, "-" * len(header)]
    for row in rows:
        native_mark = "ok" if row.native_ratio >= NATIVE_RATIO_TARGET else "MISS"
        torchrl_mark = "ok" if row.torchrl_ratio >= TORCHRL_RATIO_TARGET else "MISS"
        lines.append(f"{row.robot:<8}{row.num_robots:>5}{row.control_steps:>5}{row.batched:>12,.0f}"
                     f"{row.native:>12,.0f}{row.torchrl:>12,.0f}{row.native_ratio:>12.2f} {native_mark:<4}"
                     f"{row.torchrl_ratio:>12.1f}x {torchrl_mark:<4}")
    return "\n".join(lines)


def targets_met(rows: list[ThroughputRow]) -> bool:
    return all(r.native_ratio >= NATIVE_RATIO_TARGET and r.torchrl_ratio >= TORCHRL_RATIO_TARGET for r in rows)
