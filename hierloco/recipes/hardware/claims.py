"""The hardware claims (Li et al., RA-L 2021, Sec. IV-D), declared for ``hierloco verdicts`` (:mod:`hierloco.claims`,
``docs/claims.md``).

The hardware protocol in simulation: the low level learned on the nominal robot and kept, the CoM model learned again
on a perturbed copy from 2000 samples. One study folder per robot (``hardware_a1``, ``hardware_daisy``); the real
robot is not measured here.
"""

from __future__ import annotations

import math

import numpy as np

from hierloco.claims import (CLAIMS, SANITY_PAGE, TASKS, Check, Claim, Evidence, Source, Study, decided, describe,
                             job_minutes, part)
from hierloco.claims import seed_costs
from hierloco.evidence import Run, distinct, select

HARDWARE_PAPER = {"velocity_tracking": "Daisy hardware (Sec. IV-D, Fig. 10a): 0.56 +- 0.015",
                  "goal_reaching": "Daisy hardware (Sec. IV-D): all goals reached in 16.0 +- 1.4 steps",
                  "trajectory_tracking": "Daisy hardware (Sec. IV-D, Fig. 10a): 0.57 +- 0.05"}


def _goals(runs, method, setting) -> str:
    """How many goals the runs reached, and in how many steps."""
    chosen = distinct(select(runs, method=method, setting=setting, task="goal_reaching"))
    success = [s for r in chosen for s in r.success if not math.isnan(s)]
    steps = [s for r in chosen for s in r.steps_to_goal if not math.isnan(s)]
    if not success:
        return ""
    text = f"; goals reached {int(sum(success))}/{len(success)}"
    return text + (f" in {np.mean(steps):.1f} +- {np.std(steps):.1f} steps" if steps else "")


def hardware_checks(runs: list[Run]) -> list[Check]:
    """The hardware protocol in simulation: per robot and task, LAT solves the task on the perturbed robot (better
    than standing still), and does worse there than on the nominal robot (the paper's "worse than in simulation"),
    seed by seed; and two questions of the study, not the paper's: re-learning the model helps, and LAT beats IK on
    the perturbed robot."""
    checks = []
    for robot in sorted({r.robot for r in runs}):
        mine = [r for r in runs if r.robot == robot]
        for task in TASKS:
            nominal = seed_costs(mine, method="lat", setting="normal", task=task)
            perturbed = seed_costs(mine, method="lat", setting="hardware", task=task)
            unadapted = seed_costs(mine, method="lat", setting="hardware_unadapted", task=task)
            ik = seed_costs(mine, method="ik", setting="hardware", task=task)
            reached = _goals(mine, "lat", "hardware") if task == "goal_reaching" else ""
            paper = HARDWARE_PAPER[task]
            if perturbed.size:
                checks.append(decided(
                    "hardware_solves", "LAT solves the task on the perturbed robot, model re-learned from 2000 "
                    "samples (better than standing still)", robot, "hardware", task,
                    describe("lat", perturbed) + reached, paper,
                    [part("lat vs standing still", perturbed, 1.0, "better",
                          names=("lat:hardware", "standing still"))], "Sec. IV-D, Fig. 8, Fig. 10a"))
            if perturbed.size and nominal.size == perturbed.size:
                checks.append(decided(
                    "hardware_worse", "LAT does worse on the perturbed robot than on the nominal one", robot,
                    "hardware", task, f"nominal {describe('lat', nominal)}, perturbed {describe('lat', perturbed)}",
                    paper,
                    [part("nominal vs perturbed", nominal, perturbed, "better", paired=True,
                          names=("lat:normal", "lat:hardware"))], "Sec. IV-D"))
            if perturbed.size and unadapted.size == perturbed.size:
                checks.append(decided(
                    "hardware_relearn", "(this study's question) re-learning the CoM model on the perturbed robot "
                    "helps LAT", robot, "hardware", task,
                    f"nominal model {describe('lat', unadapted)}, re-learned {describe('lat', perturbed)}", "-",
                    [part("re-learned vs nominal model", perturbed, unadapted, "better", paired=True,
                          names=("lat:hardware", "lat:hardware_unadapted"))], "-"))
            if perturbed.size and ik.size:
                checks.append(decided(
                    "hardware_vs_ik", "(this study's question) LAT beats IK on the perturbed robot", robot,
                    "hardware", task, f"{describe('lat', perturbed)}, {describe('ik', ik)}", "-",
                    [part("lat vs ik", perturbed, ik, "better", names=("lat:hardware", "ik:hardware"))], "-"))
    return checks


def hardware_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """The job a new seed of ``side`` (``"<method>:<setting>"``) runs: the method's hardware job on the robot (its
    compute from the records, else from the study's ``wallclock.md``)."""
    study, method = f"hardware_{robot}", side.partition(":")[0]
    minutes = job_minutes(r for r in evidence.runs.get(study, []) if r.method == method and r.robot == robot)
    if not minutes and (method, robot) in evidence.compute_tables.get(study, {}):
        minutes = [evidence.compute_tables[study][(method, robot)]]
    return ("hardware", study, method), f"{method} hardware job", minutes


STUDIES = (
    Study("hardware_a1", order=30, records=("hardware_a1/records",), robot="a1",
          command="hierloco study hardware 'robots=[a1]' records=results/hardware_a1/records",
          checks=lambda evidence: hardware_checks(evidence.runs["hardware_a1"]),
          paper_column="the paper (real Daisy; ours: a perturbed copy in simulation)"),
    Study("hardware_daisy", order=40, records=("hardware_daisy/records",), table="hardware_daisy/hardware.csv",
          robot="daisy",
          command="hierloco study hardware 'robots=[daisy]' 'methods=[lat,ik]' 'seeds=[0,1,2,3,4]' "
                  "records=results/hardware_daisy/records out_dir=results/hardware_daisy",
          checks=lambda evidence: hardware_checks(evidence.runs["hardware_daisy"]),
          paper_column="the paper (real Daisy; ours: a perturbed copy in simulation)"),
)

SOURCE = Source(
    "hardware", order=40,
    checks=lambda evidence: [c for study in STUDIES if study.name in evidence.runs
                             for c in hardware_checks(evidence.runs[study.name])],
    folder=lambda check: f"hardware_{check.robot}", study=lambda check: f"hardware_{check.robot}", job=hardware_job)

DAISY_HARDWARE = ("Daisy hardware (Sec. IV-D, Fig. 10a): velocity tracking 0.56 +- 0.015, trajectory tracking "
                  "0.57 +- 0.05, all goals reached in 16.0 +- 1.4 steps (4 goals x 3 trials)")

PAPER_CLAIMS = (
    Claim(order=9, words="on hardware LAT, its low level kept from simulation and its dynamics learned from 2000 "
                         "samples, \"achieves multiple locomotion tasks\" (ours: a perturbed robot in simulation; a "
                         "sanity check: LAT walks better than standing still)",
          where="Abstract; Sec. IV-D; Fig. 1, 8, 10a", paper=DAISY_HARDWARE, source="hardware", key="hardware_solves",
          page=SANITY_PAGE),
    Claim(order=10, words="on hardware \"its performance was worse than in simulation\"", where="Sec. IV-D",
          paper=DAISY_HARDWARE, source="hardware", key="hardware_worse"),
    Claim(order=10.1, words="slipping \"and other unobserved factors are directly absorbed in our dynamics\"",
          where="Sec. III-C", status="not testable here",
          needs="a measure of foot slip per latent action beside the CoM velocity it gives: the records hold "
                "per-episode costs, not slip"),
    Claim(order=10.2, words="controllers with lower CoM height or large roll and pitch give slower CoM motion, "
                            "absorbed by the dynamics", where="Sec. III-C", status="not testable here",
          needs="each latent's CoM height, roll and pitch beside its velocity: not recorded"),
    Claim(order=10.3, words="the hardware gap's causes (1/5 of the samples; noisy joint tracking, slipping and CoM "
                            "estimation; fast controllers that did not transfer), and that more hardware samples "
                            "would reduce it", where="Sec. IV-D", status="not testable here", robots=("daisy",),
          needs="a verdict over seeds per factor: the factors are studied one at a time in `hardware_a1_factors/` and "
                "`hardware_daisy_factors/` (their READMEs) without a stated test, and no study varies the samples on "
                "the perturbed robot"),
    Claim(order=100, words="the same results on the real Daisy (Fig. 8, 10a)", where="Sec. IV-D", robots=("daisy",),
          needs="a real robot: the hardware studies here perturb a simulated copy (mass, motors, friction, latency, "
                "CoM noise), which is what they measure"),
)

CLAIMS.add(*STUDIES, SOURCE, *PAPER_CLAIMS)
