"""Factories of the LAT recipe: its plan of stages, its low level and its config checks.

The stages themselves (experts, gait policy, dynamics, evaluation) are shared with the other recipes and live in
``hierloco/pipeline/stages.py``; only recipe code reads the config, the library takes keyword arguments.
"""

from __future__ import annotations

from hierloco.pipeline import config, stages
from hierloco.pipeline.plan import Plan

METHOD = "lat"


def checks(c: config.Checker, robot) -> None:
    config.check_experts(c, robot)
    config.check_policy(c)
    config.check_dynamics(c)
    config.check_planner(c, "box")
    config.check_eval(c, replan_period(c.cfg, robot))
    config.check_logger(c)


def replan_period(cfg, robot) -> int | None:
    """The control steps of one gait period of ``robot`` (its gait policy's targets repeat every period: an action
    may be cut after whole periods), or ``None`` when the robot or the action length is bad (checked elsewhere)."""
    from hierloco.envs.locomotion import periods_per_action

    try:
        return cfg.steps_per_action // periods_per_action(robot, cfg.steps_per_action)
    except (ValueError, AttributeError, TypeError):
        return None


def plan(cfg, robot) -> Plan:
    """Experts -> gait policy -> its check (-> the latent space's continuity) -> per setting: dynamics data, model, one evaluation per task."""
    from hierloco.envs.robots import robot_fingerprint

    experts = stages.experts_stage(cfg, robot_fingerprint(robot))
    policy = stages.gait_policy_stage(cfg, experts)
    return Plan(experts=experts, gait_policy=policy, gait_policy_check=stages.gait_policy_check_stage(cfg, policy),
                latent_continuity=stages.latent_continuity_stage(cfg, policy),  # None unless eval.latent_continuity
                settings=stages.per_setting_stages(cfg, stages.latent_low_level(policy), robot))


def manifest(cfg, robot) -> dict:
    """What :func:`hierloco.load_run` needs to rebuild this run's parts."""
    return {"low_level": {"kind": "latent"}}


def make_low_level(run, trained):
    """``pi(., z)``: one stateless low level serves any number of robots."""
    from hierloco.components.low_level import LatentLowLevel

    low_level = LatentLowLevel(trained, run.robot, device=run.cfg.device)
    return lambda num_robots: low_level
