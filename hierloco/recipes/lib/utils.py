"""Factories of the LIB recipe: its plan of stages (experts, then the shared dynamics and evaluation stages), its low
level (the experts replayed) and its config checks."""

from __future__ import annotations

from hierloco.pipeline import config, stages
from hierloco.pipeline.plan import Plan

METHOD = "lib"


def checks(c: config.Checker, robot) -> None:
    config.check_experts(c, robot)
    config.check_dynamics(c)
    config.check_planner(c, "finite")
    config.check_eval(c)
    config.check_logger(c)


def plan(cfg, robot) -> Plan:
    """Experts -> per setting: dynamics data over expert indices, model, one evaluation per task."""
    from hierloco.envs.robots import robot_fingerprint

    experts = stages.experts_stage(cfg, robot_fingerprint(robot))
    low_level = {"kind": "expert_replay", "experts": experts.digest}
    return Plan(experts=experts, settings=stages.per_setting_stages(cfg, low_level, robot))


def manifest(cfg, robot) -> dict:
    return {"low_level": {"kind": "expert_replay"}}


def make_low_level(library):
    """Action g replays expert g's recorded pattern (stateless: one object serves any number of robots)."""
    from hierloco.components.low_level import ExpertReplayLowLevel

    low_level = ExpertReplayLowLevel(library)
    return lambda num_robots: low_level
