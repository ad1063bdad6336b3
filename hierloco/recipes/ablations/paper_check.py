"""The paper's ablation claims (Li et al., Sec. IV-E, Fig. 10b-d) decided by tests over the trials.

The paper varies one setting at a time on Daisy, 10 trials per value, and states: the latent dimension (2, 3, 4)
has "no significant effect" (Fig. 10b); with more experts (10, 30, 50) "the performance on each task improves,
though the difference from 30 to 50 is minor" (Fig. 10c); 2000 dynamics samples are "a significant improvement" over
1000, and 5000 no "significant difference" from 2000 (Fig. 10d). Each statement is decided per task on the trials'
mean normalised costs (each trial's mean over its targets first) with the tests of :mod:`hierloco.stats`
(``docs/statistics.md``): "better" (``values[0]`` costs more than ``values[1]``) is a one-sided Welch t with the
minimum effect; "no significant difference" is read as *equivalence*: every pair of values within the margin
(TOST), and it does not hold when a pair is shown to differ by more than the margin (each pair refuted at alpha /
pairs). A claim about values the study did not run is "not measured". The page is written by
:func:`hierloco.claims.checks_markdown`, with the causes we checked for the claims not found to hold (a YAML
file, :func:`load_causes`).

    >>> rows = [{"method": f"latent_dim={d}", "robot": "daisy", "setting": "normal", "task": "goal_reaching",
    ...          "seed": s, "normalized_cost": 0.1 + 0.001 * s} for d in (2, 3, 4) for s in range(3)]
    >>> [(c.key, c.verdict) for c in check_claims(rows) if c.task == "goal_reaching"][0]
    ('latent_dim_no_effect', 'holds')
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from hierloco import claims as claims_lib
from hierloco import stats
from hierloco.claims import NOT_MEASURED, TASKS, Check, decided, part, seed_means


@dataclass(frozen=True)
class Claim:
    """One statement of the paper: on ablation ``name``, ``values[0]`` costs significantly more than ``values[1]``
    (``kind="better"``), or no two of ``values`` differ by more than the equivalence margin
    (``kind="no_difference"``). ``figure``: where the paper shows it."""

    key: str
    name: str
    values: tuple
    kind: str
    text: str
    paper: str
    figure: str = ""


CLAIMS = (
    Claim("latent_dim_no_effect", "latent_dim", (2, 3, 4), "no_difference",
          "latent dimension 2, 3, 4: no significant effect", "\"no significant effect on the performance\"",
          "Fig. 10b, Sec. IV-E"),
    Claim("experts_10_30_better", "num_experts", (10, 30), "better",
          "30 experts better than 10", "\"as the number of experts increases the performance on each task improves\"",
          "Fig. 10c, Sec. IV-E"),
    Claim("experts_30_50_minor", "num_experts", (30, 50), "no_difference",
          "30 and 50 experts: no significant difference", "\"the difference from 30 to 50 is minor\"",
          "Fig. 10c, Sec. IV-E"),
    Claim("samples_1000_2000_better", "dynamics_samples", (1000, 2000), "better",
          "2000 dynamics samples better than 1000", "\"a significant improvement ... 2000 data points versus 1000\"",
          "Fig. 10d, Sec. IV-E"),
    Claim("samples_2000_5000_minor", "dynamics_samples", (2000, 5000), "no_difference",
          "2000 and 5000 dynamics samples: no significant difference",
          "\"no significant difference in performance between 2000 and 5000\"", "Fig. 10d, Sec. IV-E"),
)
KEYS = tuple(claim.key for claim in CLAIMS)
PAPER_COLUMN = "the paper (Sec. IV-E, Fig. 10b-d, Daisy)"
CRITERIA = (f"Tests over the trials (`docs/statistics.md`), alpha = {stats.ALPHA}: \"better\" holds when the cost is "
            f"significantly lower (one-sided Welch t) by at least {stats.MIN_EFFECT_REL:.0%} of the other's mean, and "
            "does not hold when the gain is significantly below that; \"no significant difference\" is an "
            f"equivalence test (TOST) of every pair within {stats.EQUIV_MARGIN_REL:.0%} of the larger value's mean "
            "cost (at least "
            f"{stats.EQUIV_MARGIN_ABS}), refuted when a pair differs significantly beyond it (at alpha / pairs). "
            "Otherwise inconclusive at this many trials.")


def significant(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the mean costs of trials ``a`` and ``b`` (``S``) differ: two-sided Welch t at
    :data:`hierloco.stats.ALPHA`, by at least the minimum effect (:data:`hierloco.stats.MIN_EFFECT_REL` of the
    larger mean, at least :data:`hierloco.stats.MIN_EFFECT_ABS`).

        >>> significant(np.array([0.10, 0.11, 0.10]), np.array([0.20, 0.21, 0.20]))
        True
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    _, _, p = stats.welch_t_test(a, b)
    effect = max(stats.MIN_EFFECT_REL * max(a.mean(), b.mean()), stats.MIN_EFFECT_ABS)
    return bool(p < stats.ALPHA and abs(a.mean() - b.mean()) >= effect)


def check_claims(rows) -> list[Check]:
    """Every claim on every robot and task the rows cover; rows are the study's, ``method`` ``"<ablation>=<value>"``
    and ``seed`` the trial."""
    rows = list(rows)
    checks = []
    for robot in sorted({r["robot"] for r in rows}):
        for task in TASKS:
            for claim in CLAIMS:
                trials = {v: seed_means(rows, method=f"{claim.name}={v}", robot=robot, setting="normal", task=task)
                          for v in claim.values}
                trials = {v: t for v, t in trials.items() if t.size}
                ours = ", ".join(f"{v}: {t.mean():.2f} +- {t.std():.2f}" for v, t in trials.items()) or "-"
                checks.append(_decide(claim, trials, robot, task, ours))
    return checks


def _decide(claim: Claim, trials: dict, robot: str, task: str, ours: str) -> Check:
    missing = [v for v in claim.values if v not in trials]
    if claim.kind == "better" and missing or len(trials) < 2:
        return Check(claim.key, claim.text, robot, "normal", task, ours, claim.paper, NOT_MEASURED,
                     f"no trials of {', '.join(map(str, missing))}", claim.figure)
    if claim.kind == "better":
        worse, better = (trials[v] for v in claim.values)
        parts = [part(f"{claim.values[1]} vs {claim.values[0]}", better, worse, "better",
                      names=(f"{claim.name}={claim.values[1]}", f"{claim.name}={claim.values[0]}"))]
    else:
        pairs = list(combinations(trials, 2))
        parts = [part(f"{a} vs {b}", trials[a], trials[b], "close", parts=len(pairs),
                      names=(f"{claim.name}={a}", f"{claim.name}={b}")) for a, b in pairs]
    check = decided(claim.key, claim.text, robot, "normal", task, ours, claim.paper, parts, claim.figure)
    if claim.kind == "no_difference" and check.verdict == stats.DOES_NOT_HOLD:
        differ = ", ".join(p.label for p in parts if p.decision.verdict == stats.DOES_NOT_HOLD)
        return Check(check.key, check.claim, robot, "normal", task, ours, claim.paper, check.verdict,
                     f"differ: {differ}; " + check.detail, claim.figure, check.parts)
    return check


def load_causes(path) -> list[claims_lib.Cause]:
    """The causes (a YAML file, :func:`hierloco.claims.load_causes`) for these claims."""
    return claims_lib.load_causes(path, claims=KEYS)


def paper_check_markdown(checks: list[Check], *, title: str, causes=()) -> str:
    """The checks as ``paper_check.md``: the paper's words beside our numbers (value: mean +- std over trials)."""
    return claims_lib.checks_markdown(checks, title=title, causes=causes, criteria=CRITERIA,
                                      paper_column=PAPER_COLUMN)
