"""The navigation claim (Li et al., RA-L 2021, Sec. I, Fig. 2), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``): LAT follows a planned path through clutter to the goal, decided per
robot over seeds (each seed's value: its mean over the arenas).
"""

from __future__ import annotations

import math

import numpy as np

from hierloco.claims import CLAIMS, Check, Claim, Evidence, Source, Study, decided, describe, job_minutes, part
from hierloco.evidence import Run, distinct, seed_values, select

NAVIGATION_PREFIX = "navigation_arena"  # the study's tasks (recipes/navigation/run.py, task_name)


def navigation_checks(runs: list[Run]) -> list[Check]:
    """The navigation claim per robot, over seeds (each seed's value: its mean over the arenas): LAT follows the
    planned path (normalised cost better than standing still) and reaches the goal (the CoM's distance to it at the
    end significantly below the 0.2 m success radius); both parts must hold."""
    from hierloco.envs.tasks import SUCCESS_RADIUS

    checks = []
    for robot in sorted({r.robot for r in runs}):
        mine = select(runs, method="lat", robot=robot, setting="normal",
                      task=lambda t: t.startswith(NAVIGATION_PREFIX))
        if not mine:
            continue
        _, costs, _ = seed_values(mine)
        _, errors, _ = seed_values(mine, value=lambda r: float(np.nanmean(r.final_error)))
        success = [s for r in distinct(mine) for s in r.success if not math.isnan(s)]
        closest = [c for r in distinct(mine) for c in r.clearance if not math.isnan(c)]
        arenas = sorted({int(r.task.removeprefix(NAVIGATION_PREFIX)) for r in mine})
        ours = (f"{describe('lat', costs)}; goals reached {int(sum(success))}/{len(success)} (arenas "
                f"{', '.join(map(str, arenas))}); goal error {errors.mean():.2f} +- {errors.std():.2f} m"
                + (f"; closest CoM to a box {min(closest):.2f} m" if closest else ""))
        checks.append(decided(
            "navigation", "LAT follows a planned path through clutter to the goal (cost better than standing "
            "still, and the goal error below the 0.2 m success radius)", robot, "normal", "navigation", ours, "-",
            [part("lat vs standing still", costs, 1.0, "better", names=("lat:navigation", "standing still")),
             part(f"goal error vs {SUCCESS_RADIUS} m", errors, SUCCESS_RADIUS, "better",
                  names=("goal error (m)", f"{SUCCESS_RADIUS} m"))], "Sec. I, Fig. 2"))
    return checks


def navigation_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """One LAT job per robot and seed evaluates every arena."""
    runs = [r for r in evidence.runs.get("navigation", []) if r.robot == robot]
    return ("navigation", "lat"), "LAT navigation job (every arena)", job_minutes(runs)


STUDY = Study("navigation", order=80, records=("navigation/records",),
              command="hierloco study navigation records=results/navigation/records out_dir=results/navigation",
              checks=lambda evidence: navigation_checks(evidence.runs["navigation"]))

SOURCE = Source("navigation", order=70, checks=lambda evidence: navigation_checks(evidence.runs.get("navigation", [])),
                job=navigation_job)

NAVIGATES = Claim(
    order=18, where="Sec. I; Fig. 2 (Daisy in iGibson)", source="navigation", key="navigation",
    words="\"Our method can directly be used with waypoint navigation methods to reach a desired goal\" (ours: "
          "cluttered arenas, an A* path inflated by the robot's footprint, LAT's trajectory tracking along it)")

CLAIMS.add(STUDY, SOURCE, NAVIGATES)
