"""A guard against budgets that cannot end: the compute a plan will take, estimated before any work.

Each stage's cost is estimated from its params with per-unit rates measured on the project's 2-core reference
machine at one thread (the build times of the paper-scale runs: 10,000 dynamics transitions of A1 in 113 s, 400
gait-policy epochs over 50 experts in 70 s, a SAC task's 10,000 updates of 2 x 512 networks in about 15 min, ...).
The estimate is an order of magnitude, not a promise; it is there so that a typo (``dynamics.num_transitions=
1000000000``, about 2,000 hours) is caught before any work. :func:`check_budget` prints the estimate when it exceeds
:data:`SAY_ABOVE_HOURS` and refuses the run above :data:`LIMIT_HOURS` unless ``confirm_long=true``.

Example:
    >>> from hierloco.pipeline.plan import Stage
    >>> data = Stage("dynamics_data_normal", {"num_transitions": 10_000_000, "num_robots": 100}, {}, "d.npz", None,
    ...              None)
    >>> round(estimate_seconds([data], threads=1) / 3600)
    33
"""

from __future__ import annotations

from typing import Iterable

from hierloco.pipeline.errors import ConfigError

SAY_ABOVE_HOURS = 2.0
LIMIT_HOURS = 24.0

# core-seconds per unit, at one thread (see the module docstring)
TRANSITION = 0.012          # one dynamics transition of N = 100 control steps (simulation and low level)
EXPERT = 0.15               # one expert run to steady state and recorded
POLICY_SAMPLE_EPOCH = 3.5e-5  # one (expert, step) sample for one epoch of the 2 x 512 gait policy
MODEL_SAMPLE_EPOCH = 1.2e-5   # one transition for one epoch of the 2 x 512 CoM model (an upper bound: early stop)
PLANNED_SEQUENCE = 2.5e-6   # one candidate action sequence scored, per action of the horizon
CLOSED_LOOP_ACTION = 0.02   # one action simulated in closed-loop evaluation
SAC_UPDATE = 0.08           # one SAC update of 2 x 512 networks on a batch of 512
HIGH_LEVEL_FRAME = 0.006    # one high-level action simulated while SAC collects
LOW_LEVEL_FRAME = 0.0008    # one 100 Hz control step simulated while SAC-SAC's low level collects


def _scale(params: dict, hidden: int = 512, batch: int | None = None) -> float:
    scale = (params.get("hidden", hidden) / hidden) ** 2
    if batch is not None:
        scale *= params.get("batch_size", batch) / batch
    return scale


def stage_seconds(name: str, params: dict) -> float:
    """The estimated core-seconds of one stage (0 for stages too cheap to matter)."""
    steps = params.get("steps_per_action", 100) / 100
    if name == "experts":
        return EXPERT * params.get("num_experts", 0) * (1 + params.get("settle_time", 0.0))
    if name == "gait_policy":
        return POLICY_SAMPLE_EPOCH * params.get("epochs", 0) * 50 * 100 * _scale(params)
    if name.startswith("dynamics_data_"):
        return TRANSITION * params.get("num_transitions", 0) * steps
    if name.startswith("dynamics_model_"):
        return MODEL_SAMPLE_EPOCH * params.get("max_epochs", 0) * 10_000 * _scale(params)
    if name.startswith("evaluation_"):
        planner = params.get("planner", {})
        sequences = planner.get("num_candidates", 0) * planner.get("horizon", 1)
        if planner.get("name") in ("cem", "mppi"):
            sequences *= planner.get("optim_steps", 1)
        return 300 * (CLOSED_LOOP_ACTION + PLANNED_SEQUENCE * sequences)
    if name == "sac_low_level":
        frames = params.get("total_frames", 0)
        return frames * (LOW_LEVEL_FRAME + params.get("updates_per_frame", 0) * SAC_UPDATE * _scale(params, 512, 512))
    if name.startswith("sac_"):
        frames = params.get("total_frames", 0)
        return frames * (HIGH_LEVEL_FRAME + params.get("updates_per_frame", 0) * SAC_UPDATE * _scale(params, 512, 512))
    return 0.0


def estimate_seconds(stages: Iterable, threads: int = 1) -> float:
    """The estimated wall-clock of ``stages`` on ``threads`` threads (simulation spreads over them)."""
    return sum(stage_seconds(stage.name, stage.params) for stage in stages) / max(1, threads)


def check_budget(stages: Iterable, *, threads: int, confirmed: bool) -> None:
    """Says the estimate of the stages still to build when it is long; refuses above :data:`LIMIT_HOURS` unless
    ``confirmed``."""
    hours = estimate_seconds(stages, threads) / 3600
    if hours > LIMIT_HOURS and not confirmed:
        raise ConfigError(f"this run would take about {hours:,.0f} h on {threads} thread(s) (estimated from its "
                          f"sizes); check the config, or add +confirm_long=true to run it anyway")
    if hours > SAY_ABOVE_HOURS:
        print(f"estimated compute: about {hours:,.1f} h on {threads} thread(s)", flush=True)


__all__ = ["LIMIT_HOURS", "SAY_ABOVE_HOURS", "check_budget", "estimate_seconds", "stage_seconds"]
