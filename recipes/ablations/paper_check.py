"""The paper's ablation claims (Li et al., Sec. IV-E) checked against an ablation study's rows.

The paper varies one setting at a time on Daisy, 10 trials per value, and states: the latent dimension (2, 3, 4)
has "no significant effect"; with more experts (10, 30, 50) "the performance on each task improves, though the
difference from 30 to 50 is minor"; 2000 dynamics samples are "a significant improvement" over 1000, and 5000 no
"significant difference" from 2000. Each statement is checked per task on the trials' mean normalised costs (each
trial's mean over its targets first): a difference between two values is *significant* when it is larger than
:data:`TIE` and than two standard errors of the difference (Welch, over the trials). A claim about values the study
did not run is "not measured". The page is written by :func:`recipes.compare.paper_check.paper_check_markdown`, with
the causes we checked for the claims that do not hold (a YAML file, :func:`load_causes`).

    >>> rows = [{"method": f"latent_dim={d}", "robot": "daisy", "setting": "normal", "task": "goal_reaching",
    ...          "seed": s, "normalized_cost": 0.1 + 0.01 * s} for d in (2, 3, 4) for s in range(3)]
    >>> [(c.key, c.verdict) for c in check_claims(rows) if c.task == "goal_reaching"][0]
    ('latent_dim_no_effect', 'holds')
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from recipes.compare import paper_check
from recipes.compare.paper_check import TASKS, TIE, Check, seed_means


@dataclass(frozen=True)
class Claim:
    """One statement of the paper: on ablation ``name``, ``values[0]`` costs significantly more than ``values[1]``
    (``kind="better"``), or no two of ``values`` differ significantly (``kind="no_difference"``)."""

    key: str
    name: str
    values: tuple
    kind: str
    text: str
    paper: str


CLAIMS = (
    Claim("latent_dim_no_effect", "latent_dim", (2, 3, 4), "no_difference",
          "latent dimension 2, 3, 4: no significant effect", "\"no significant effect on the performance\""),
    Claim("experts_10_30_better", "num_experts", (10, 30), "better",
          "30 experts better than 10", "\"as the number of experts increases the performance on each task improves\""),
    Claim("experts_30_50_minor", "num_experts", (30, 50), "no_difference",
          "30 and 50 experts: no significant difference", "\"the difference from 30 to 50 is minor\""),
    Claim("samples_1000_2000_better", "dynamics_samples", (1000, 2000), "better",
          "2000 dynamics samples better than 1000", "\"a significant improvement ... 2000 data points versus 1000\""),
    Claim("samples_2000_5000_minor", "dynamics_samples", (2000, 5000), "no_difference",
          "2000 and 5000 dynamics samples: no significant difference",
          "\"no significant difference in performance between 2000 and 5000\""),
)
KEYS = tuple(claim.key for claim in CLAIMS)
CRITERIA = (f"A difference is significant when it is larger than {TIE} and than two standard errors of the difference "
            "(Welch, over the trials).")


def significant(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the mean costs of trials ``a`` and ``b`` (``S``) differ by more than :data:`TIE` and two standard
    errors of the difference."""
    spread = sum(x.var(ddof=1) / x.size for x in (a, b) if x.size > 1)
    return abs(a.mean() - b.mean()) > max(TIE, 2 * np.sqrt(spread))


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
                checks.append(Check(claim.key, claim.text, robot, "normal", task, ours, claim.paper,
                                    _verdict(claim, trials)))
    return checks


def _verdict(claim: Claim, trials: dict) -> str:
    if claim.kind == "better":
        if len(trials) < 2:
            return "not measured"
        worse, better = (trials[v] for v in claim.values)
        if not significant(worse, better):
            return "does not hold (no significant difference)"
        return "holds" if worse.mean() > better.mean() else "does not hold (the opposite)"
    if len(trials) < 2:
        return "not measured"
    differ = [f"{a} vs {b}" for a, b in combinations(trials, 2) if significant(trials[a], trials[b])]
    return f"does not hold ({', '.join(differ)})" if differ else "holds"


def load_causes(path) -> list[paper_check.Cause]:
    """The causes (a YAML file, as :func:`recipes.compare.paper_check.load_causes`) for these claims."""
    return paper_check.load_causes(path, claims=KEYS)


def paper_check_markdown(checks: list[Check], *, title: str, causes=()) -> str:
    """The checks as ``paper_check.md``: the paper's words beside our numbers (value: mean +- std over trials)."""
    return paper_check.paper_check_markdown(checks, title=title, causes=causes, criteria=CRITERIA,
                                            paper_column="the paper (Sec. IV-E)")
