"""MPC planners over any action box and any learned world model (Li et al., RA-L 2021, Sec. III-A.2: random
shooting with 8000 samples over a horizon of 1; CEM, MPPI with warm starts and exhaustive search are options)."""

from hierloco.components.planners.base import BoxPlannerBase
from hierloco.components.planners.cem import BoxCEMPlanner
from hierloco.components.planners.exhaustive import ExhaustivePlanner
from hierloco.components.planners.mppi import BoxMPPIPlanner
from hierloco.components.planners.random_shooting import RandomShootingPlanner

PLANNERS = {"random_shooting": RandomShootingPlanner, "cem": BoxCEMPlanner, "mppi": BoxMPPIPlanner,
            "exhaustive": ExhaustivePlanner}

__all__ = ["PLANNERS", "BoxCEMPlanner", "BoxMPPIPlanner", "BoxPlannerBase", "ExhaustivePlanner",
           "RandomShootingPlanner"]
