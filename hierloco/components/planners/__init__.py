"""MPC planners over any action box and any learned world model (Li et al., RA-L 2021, Sec. III-A.2: random
shooting with 8000 samples over a horizon of 1; CEM, MPPI with warm starts and exhaustive search are options).

Planners are found by name in :data:`PLANNERS` (``planner.name`` in a recipe's config); :func:`make_planner` builds
one from a config section shared by every planner, each taking its own options from it.

Example:
    >>> PLANNERS.names()
    ['cem', 'exhaustive', 'mppi', 'random_shooting']
    >>> PLANNERS.options("cem")
    {'num_candidates': 1000, 'optim_steps': 5, 'top_k': 50}
"""

from __future__ import annotations

from typing import Any, Mapping

from hierloco.components.planners.base import PLANNERS, BoxPlannerBase
from hierloco.components.planners.cem import BoxCEMPlanner
from hierloco.components.planners.exhaustive import ExhaustivePlanner
from hierloco.components.planners.mppi import BoxMPPIPlanner
from hierloco.components.planners.random_shooting import RandomShootingPlanner

COMMON = ("name", "horizon", "risk", "beta", "compile", "precision")  # keys of a planner section that are no planner's
# own options (risk and beta tell the world model how to score a plan under a model with members:
# hierloco.envs.world_model; compile and precision how every planner scores: BoxPlannerBase.set_scoring)
SCORING_DEFAULTS = {"compile": False, "precision": "fp32"}


def make_planner(world_model, *, name: str = "random_shooting", horizon: int = 1, seed: int = 0,
                 compile: bool = False, precision: str = "fp32", **options):
    """The planner registered as ``name`` over ``world_model``, looking ``horizon`` actions ahead, scoring with
    ``compile`` and ``precision`` (:meth:`BoxPlannerBase.set_scoring`).

    ``options`` may hold the options of every planner (one config section serves them all): each planner takes
    its own (:meth:`hierloco.registry.Registry.options`) and ignores the others."""
    cls = PLANNERS[name]
    own = PLANNERS.select(name, options)
    if "finite" in cls.ACTION_SPACES and "box" not in cls.ACTION_SPACES:
        planner = cls(world_model, planning_horizon=horizon, **own)
    else:
        planner = cls(world_model, planning_horizon=horizon, seed=seed, **own)
    if compile or precision != "fp32":  # a registered planner that is no BoxPlannerBase is left as it is
        planner.set_scoring(compile=compile, precision=precision)
    return planner


def check_planner_options(name: str, section: Mapping[str, Any], *, action_space: str = "box") -> list[str]:
    """Problems with a planner section: keys that are no registered planner's option, values of the selected
    planner's options unlike their defaults, and what the planner's constructor refuses (built on a stand-in world
    model). Empty when all is well."""
    import torch

    from hierloco.devices import PRECISIONS
    from hierloco.envs.world_model import CoMWorldModelEnv

    known = {option for other in {*PLANNERS.names(), name} for option in PLANNERS.options(other)}
    problems = [f"planner has no option {key!r} (the planners' options: {', '.join(sorted(known))})"
                for key in section if key not in known and key not in COMMON]
    own = PLANNERS.select(name, section)
    problems += PLANNERS.check_options(name, own)
    if not isinstance(section.get("compile", False), bool):
        problems.append(f"planner.compile must be true or false, got {section.get('compile')!r}")
    if section.get("precision", "fp32") not in PRECISIONS:
        problems.append(f"unknown precision {section.get('precision')!r} (planner.precision: choose from "
                        f"{', '.join(PRECISIONS)})")
    if problems:
        return problems

    class _Still(torch.nn.Module):
        def predict(self, com_state, action):
            return com_state

    box = {"num_choices": 2} if action_space == "finite" else {"action_low": [-1.0], "action_high": [1.0]}
    try:
        make_planner(CoMWorldModelEnv(_Still(), **box), name=name, horizon=int(section.get("horizon", 1)), **own)
    except (TypeError, ValueError) as error:
        problems.append(f"planner {name!r}: {error}")
    return problems


__all__ = ["PLANNERS", "SCORING_DEFAULTS", "BoxCEMPlanner", "BoxMPPIPlanner", "BoxPlannerBase", "ExhaustivePlanner",
           "RandomShootingPlanner", "check_planner_options", "make_planner"]
