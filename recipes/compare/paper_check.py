"""The paper's claims about its baselines (Li et al., Sec. V-B and V-C) checked against a comparison's rows.

Each claim is tested per robot and task on the mean normalised cost over seeds (each seed's mean over its
episodes first), and written as a Markdown table: our numbers beside the paper's where it states them, with
"holds" / "does not hold" / "not measured". The criteria are stated in the file, so a reader can disagree with them.

    >>> rows = [{"method": m, "robot": "a1", "setting": "normal", "task": "velocity_tracking", "seed": 0,
    ...          "normalized_cost": c} for m, c in (("lat", 0.1), ("lib", 0.5), ("ik", 0.12))]
    >>> [c.verdict for c in check_claims(rows)]
    ['holds', 'holds', 'holds']
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LEARNED = ("lib", "sac", "sac_sac")   # the learned baselines LAT is claimed to beat on every task
IK_METHODS = ("ik", "ik_plain")       # IK with our footstep law, and with the paper's plain law
TASKS = ("velocity_tracking", "goal_reaching", "trajectory_tracking")
CLOSE = 0.1                           # "close to IK": LAT's mean cost at most this much above IK's
TIE = 0.02                            # "better" / "worse" / "best": by more than this (else a tie, not a win)
# the paper's stated numbers (A1), for the table: (robot, setting, task, method) -> "mean +- std"
PAPER = {("a1", "normal", "goal_reaching", "lat"): "0.34 +- 0.02",
         ("a1", "normal", "goal_reaching", "sac"): "0.57 +- 0.06",
         ("a1", "normal", "goal_reaching", "sac_sac"): "0.92 +- 0.04",
         ("a1", "normal", "velocity_tracking", "lat"): "0.16 +- 0.10",
         ("a1", "normal", "velocity_tracking", "lib"): "0.58 +- 0.01",
         ("a1", "legs_disabled", "velocity_tracking", "lat"): "0.62 +- 0.06",
         ("a1", "legs_disabled", "velocity_tracking", "ik"): "0.91 +- 0.06"}


@dataclass(frozen=True)
class Check:
    """One claim on one robot and task: ``ours`` and ``paper`` as "method: mean +- std" text, and the verdict."""

    claim: str
    robot: str
    setting: str
    task: str
    ours: str
    paper: str
    verdict: str  # "holds", "does not hold" or "not measured"


def seed_means(rows, *, method: str, robot: str, setting: str, task: str) -> np.ndarray:
    """The mean normalised cost of each seed's episodes (``S``), NaN costs (a fallen robot) counted as 1."""
    by_seed: dict = {}
    for row in rows:
        if (row["method"], row["robot"], row["setting"], row["task"]) == (method, robot, setting, task):
            cost = float(row["normalized_cost"])
            by_seed.setdefault(row["seed"], []).append(1.0 if math.isnan(cost) else cost)
    return np.array([np.mean(costs) for _, costs in sorted(by_seed.items())])


def _better(lower: float, higher: float) -> str:
    """The verdict on "``lower`` is better (a lower cost) than ``higher``"."""
    if abs(higher - lower) <= TIE:
        return f"does not hold (a tie, within {TIE})"
    return "holds" if lower < higher else "does not hold"


def _text(method: str, means: np.ndarray) -> str:
    return f"{method} {means.mean():.2f} +- {means.std():.2f}"


def check_claims(rows, tuned_ik: dict | None = None) -> list[Check]:
    """Every claim on every robot and task the rows cover (see the module doc). ``tuned_ik`` (robot -> ``ik`` or
    ``ik_plain``) marks the IK claims of the variant tuned on the training targets (``recipes/tune``), the fair IK."""
    rows = list(rows)
    tuned_ik = dict(tuned_ik or {})
    checks = []
    for robot in sorted({r["robot"] for r in rows}):
        def stats(method, setting, task):
            return seed_means(rows, method=method, robot=robot, setting=setting, task=task)

        def paper(setting, task, methods):
            known = [f"{m} {PAPER[(robot, setting, task, m)]}" for m in methods if (robot, setting, task, m) in PAPER]
            return ", ".join(known) or "-"

        for task in TASKS:
            lat = stats("lat", "normal", task)
            others = {m: stats(m, "normal", task) for m in LEARNED}
            others = {m: s for m, s in others.items() if s.size}
            claim = "LAT is best among the learned methods"
            if lat.size and others:
                best_other = min(s.mean() for s in others.values())
                ours = ", ".join([_text("lat", lat)] + [_text(m, s) for m, s in others.items()])
                checks.append(Check(claim, robot, "normal", task, ours, paper("normal", task, ("lat", *LEARNED)),
                                    _better(lat.mean(), best_other)))
            for ik in IK_METHODS:
                tuned = " (the IK tuned on the training targets)" if tuned_ik.get(robot) == ik else ""
                base = stats(ik, "normal", task)
                if lat.size and base.size:
                    checks.append(Check(f"LAT is close to {ik.upper()}{tuned} (at most {CLOSE} above)", robot, "normal",
                                        task, f"{_text('lat', lat)}, {_text(ik, base)}", "-",
                                        "holds" if lat.mean() <= base.mean() + CLOSE else "does not hold"))
                damaged, base = stats("lat", "legs_disabled", task), stats(ik, "legs_disabled", task)
                if damaged.size and base.size:
                    checks.append(Check(f"LAT beats {ik.upper()}{tuned} with legs disabled", robot, "legs_disabled", task,
                                        f"{_text('lat', damaged)}, {_text(ik, base)}",
                                        paper("legs_disabled", task, ("lat", ik)),
                                        _better(damaged.mean(), base.mean())))
        lat, lib = stats("lat", "normal", "velocity_tracking"), stats("lib", "normal", "velocity_tracking")
        measured = lat.size and lib.size
        checks.append(Check("LIB is worse than LAT at velocity tracking", robot, "normal", "velocity_tracking",
                            f"{_text('lat', lat)}, {_text('lib', lib)}" if measured else "-",
                            paper("normal", "velocity_tracking", ("lat", "lib")),
                            _better(lat.mean(), lib.mean()) if measured else "not measured"))
    return checks


def paper_check_markdown(checks: list[Check], *, title: str) -> str:
    """The checks as a Markdown page (``paper_check.md``)."""
    lines = [f"# The paper's claims, checked\n\n{title}. Normalised cost, mean +- std over seeds (each seed's mean "
             f"over its targets); a fallen robot's cost counts as 1. \"Close\" means LAT's mean at most {CLOSE} "
             f"above IK's; \"better\", \"worse\" and \"best\" mean by more than {TIE}.\n",
             "| claim | robot | setting | task | ours | paper (numbers it states; A1 only) | verdict |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {c.claim} | {c.robot} | {c.setting} | {c.task} | {c.ours} | {c.paper} | {c.verdict} |"
              for c in checks]
    held = sum(c.verdict == "holds" for c in checks)
    failed = sum(c.verdict.startswith("does not hold") for c in checks)
    return "\n".join(lines) + f"\n\n{held} hold, {failed} do not hold.\n"
