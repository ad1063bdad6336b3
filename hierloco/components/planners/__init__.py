"""MPC planners over any action box and any learned world model (SPEC 5.4)."""

from hierloco.components.planners.base import BoxPlannerBase
from hierloco.components.planners.cem import BoxCEMPlanner
from hierloco.components.planners.exhaustive import ExhaustivePlanner
from hierloco.components.planners.mppi import BoxMPPIPlanner
from hierloco.components.planners.random_shooting import RandomShootingPlanner

PLANNERS = {"random_shooting": RandomShootingPlanner, "cem": BoxCEMPlanner, "mppi": BoxMPPIPlanner,
            "exhaustive": ExhaustivePlanner}

__all__ = ["PLANNERS", "BoxCEMPlanner", "BoxMPPIPlanner", "BoxPlannerBase", "ExhaustivePlanner",
           "RandomShootingPlanner"]
