"""``experts.tune=true``: the expert controller's parameters searched for the run's robot before anything is planned.

The search (:func:`hierloco.components.expert_tuning.tune_expert_parameters`, what ``hierloco-robot-check`` runs)
is a cached stage of its own, ``expert_tuning.json``, keyed by the robot's fingerprint and the search's options.
Its result changes the robot (gait period, foot lift, standing height, servo gains, command box), and so the key of
every later stage: the run takes it first, under the run directory's lock, then plans the rest with the tuned
robot. The parameters found and the YAML lines that describe them go to ``run.json`` (``expert_tuning``); a search
that finds nothing is a finding about the robot (the experts stage's error, recorded in ``failed.json``).
"""

from __future__ import annotations

import json

from hierloco.pipeline.config import section
from hierloco.pipeline.plan import JsonReport, Stage

FILENAME = "expert_tuning.json"


class TuningReport(JsonReport):
    SCHEMA = {"found": bool, "parameters": (dict, type(None)), "yaml": list, "tuned_fingerprint": str,
              "policy_overrides": dict}


def tuning_stage(cfg, robot) -> Stage:
    """The search's stage: its options (budget, experts, the policy it verifies with, both quality bars, seed)
    after the robot's fingerprint."""
    from hierloco.envs.robots import robot_fingerprint

    experts = section(cfg, "experts")
    params = {"seed": cfg.seed, "budget_seconds": float(experts.get("tune_budget", 300.0)),
              "num_experts": experts["num_experts"], "settle_time": experts["settle_time"],
              "steps_per_action": cfg.steps_per_action, "policy": section(cfg, "policy"),
              "min_reach": cfg.checks.min_expert_reach, "min_reproduced_fraction": cfg.checks.min_reproduced_fraction}
    return Stage("expert_tuning", params, {"robot": robot_fingerprint(robot)}, FILENAME, TuningReport, build_tuning)


def build_tuning(run, params) -> TuningReport:
    from hierloco.components.expert_library import ExpertQualityError
    from hierloco.components.expert_tuning import tune_expert_parameters

    result = tune_expert_parameters(run.robot, seed=params["seed"], budget_seconds=params["budget_seconds"],
                                    num_experts=params["num_experts"], settle_time=params["settle_time"],
                                    steps_per_action=params["steps_per_action"], policy=params["policy"],
                                    min_reach=params["min_reach"],
                                    min_reproduced_fraction=params["min_reproduced_fraction"])
    if not result.found:
        raise ExpertQualityError("experts.tune found no expert parameters that walk: " + "; ".join(result.limits))
    return TuningReport(json.loads(json.dumps(result.summary(), default=float)))


def tuned_robot(robot, report: dict):
    """``robot`` with the parameters of a tuning report."""
    from hierloco.components.expert_tuning import ExpertParameters

    parameters = {key: tuple(value) if isinstance(value, list) else value
                  for key, value in report["parameters"].items()}
    return ExpertParameters(**parameters).apply(robot)


__all__ = ["FILENAME", "TuningReport", "tuned_robot", "tuning_stage"]
