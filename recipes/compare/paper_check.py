"""The paper's claims about its baselines (Li et al., Sec. V-B and V-C) checked against a comparison's rows.

Each claim is tested per robot and task on the mean normalised cost over seeds (each seed's mean over its
episodes first), and written as a Markdown table: our numbers beside the paper's where it states them, with
"holds" / "does not hold" / "not measured". The criteria are stated in the file, so a reader can disagree with them.
Each claim that does not hold is listed with the cause we checked for it, from a YAML file of causes
(:func:`load_causes`), or with "not checked" where there is none; a cause whose claim now holds is listed apart, so it
does not go stale unseen.

    >>> rows = [{"method": m, "robot": "a1", "setting": "normal", "task": "velocity_tracking", "seed": 0,
    ...          "normalized_cost": c} for m, c in (("lat", 0.1), ("lib", 0.5), ("ik", 0.12))]
    >>> [c.verdict for c in check_claims(rows)]
    ['holds', 'holds', 'holds']
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from hierloco.envs.tasks import GoalReaching

LEARNED = ("lib", "sac", "sac_sac")   # the learned baselines LAT is claimed to beat on every task
MODEL_FREE = ("sac", "sac_sac")       # trained on half of the targets, claimed not to generalise to the others
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


# the claims by key (what a file of causes names): a word for the claim, ":<method>" for the baseline it is about
CLAIMS = ("learned_best", "close:ik", "close:ik_plain", "damaged:ik", "damaged:ik_plain", "lib_worse",
          "heldout_worse:sac", "heldout_worse:sac_sac")


@dataclass(frozen=True)
class Check:
    """One claim on one robot and task: ``ours`` and ``paper`` as "method: mean +- std" text, and the verdict.
    ``key`` is the claim's entry in :data:`CLAIMS`."""

    key: str
    claim: str
    robot: str
    setting: str
    task: str
    ours: str
    paper: str
    verdict: str  # "holds", "does not hold" or "not measured"


def seed_means(rows, *, method: str, robot: str, setting: str, task: str, episodes=None) -> np.ndarray:
    """The mean normalised cost of each seed's episodes (``S``), NaN costs (a fallen robot) counted as 1; only the
    episodes (indices) in ``episodes`` if given."""
    by_seed: dict = {}
    for row in rows:
        if episodes is not None and int(row["episode"]) not in episodes:
            continue
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
                checks.append(Check("learned_best", claim, robot, "normal", task, ours,
                                    paper("normal", task, ("lat", *LEARNED)), _better(lat.mean(), best_other)))
            for ik in IK_METHODS:
                tuned = " (the IK tuned on the training targets)" if tuned_ik.get(robot) == ik else ""
                base = stats(ik, "normal", task)
                if lat.size and base.size:
                    checks.append(Check(f"close:{ik}", f"LAT is close to {ik.upper()}{tuned} (at most {CLOSE} above)",
                                        robot, "normal", task, f"{_text('lat', lat)}, {_text(ik, base)}", "-",
                                        "holds" if lat.mean() <= base.mean() + CLOSE else "does not hold"))
                damaged, base = stats("lat", "legs_disabled", task), stats(ik, "legs_disabled", task)
                if damaged.size and base.size:
                    checks.append(Check(f"damaged:{ik}", f"LAT beats {ik.upper()}{tuned} with legs disabled", robot,
                                        "legs_disabled", task, f"{_text('lat', damaged)}, {_text(ik, base)}",
                                        paper("legs_disabled", task, ("lat", ik)), _better(damaged.mean(), base.mean())))
        lat, lib = stats("lat", "normal", "velocity_tracking"), stats("lib", "normal", "velocity_tracking")
        measured = lat.size and lib.size
        checks.append(Check("lib_worse", "LIB is worse than LAT at velocity tracking", robot, "normal",
                            "velocity_tracking", f"{_text('lat', lat)}, {_text('lib', lib)}" if measured else "-",
                            paper("normal", "velocity_tracking", ("lat", "lib")),
                            _better(lat.mean(), lib.mean()) if measured else "not measured"))
        checks += _generalisation(rows, robot)
    return checks


def _generalisation(rows, robot: str) -> list[Check]:
    """"SAC and SAC-SAC fail to generalise to new targets" (Sec. IV-B) on goal reaching, the task whose held-out
    targets are whole episodes: a model-free method's cost on its held-out goals against its training goals."""
    checks = []
    for method in MODEL_FREE:
        episodes = {int(r["episode"]) for r in rows if (r["method"], r["robot"], r["setting"], r["task"])
                    == (method, robot, "normal", "goal_reaching")}
        if len(episodes) < 2:
            continue
        training = set(GoalReaching(num_goals=max(episodes) + 1).training_episodes)
        split = {name: seed_means(rows, method=method, robot=robot, setting="normal", task="goal_reaching",
                                  episodes=chosen)
                 for name, chosen in (("training goals", training), ("held-out goals", episodes - training))}
        checks.append(Check(f"heldout_worse:{method}", f"{method.upper()} does worse on its held-out goals than on "
                            "its training goals", robot, "normal", "goal_reaching",
                            ", ".join(_text(name, means) for name, means in split.items()), "-",
                            _better(split["training goals"].mean(), split["held-out goals"].mean())))
    return checks


@dataclass(frozen=True)
class Cause:
    """The cause we checked for the claims ``claims`` (keys of :data:`CLAIMS`) on ``robots`` and ``tasks`` (empty:
    all) that do not hold."""

    claims: tuple[str, ...]
    robots: tuple[str, ...]
    tasks: tuple[str, ...]
    text: str

    def covers(self, check: Check) -> bool:
        return (check.key in self.claims and (not self.robots or check.robot in self.robots)
                and (not self.tasks or check.task in self.tasks))


def load_causes(path, claims: tuple[str, ...] = CLAIMS) -> list[Cause]:
    """The causes in the YAML file ``path``: a list of ``{claims: [...], robots: [...], tasks: [...], cause: text}``
    (``robots`` and ``tasks`` optional), each claim one of ``claims`` (the keys of the checks the causes are for).
    Raises ValueError naming every malformed entry.

        >>> import tempfile
        >>> f = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
        >>> _ = f.write("- {claims: [lib_worse], robots: [a1], cause: LIB's experts cover two speeds.}")
        >>> f.close()
        >>> load_causes(f.name)[0].claims
        ('lib_worse',)
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"causes: no file {str(path)!r}")
    try:
        entries = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ValueError(f"causes: {path} is not YAML: {error}") from None
    if not isinstance(entries, list):
        raise ValueError(f"causes: {path} must hold a list of entries, got {type(entries).__name__}")
    causes, problems = [], []
    for i, entry in enumerate(entries):
        where = f"causes: {path} entry {i}"
        if not isinstance(entry, dict):
            problems.append(f"{where} is not a mapping")
            continue
        unknown = sorted(set(entry) - {"claims", "robots", "tasks", "cause"})
        lists = {name: entry.get(name, []) for name in ("claims", "robots", "tasks")}
        bad = [name for name, value in lists.items() if not (isinstance(value, list)
                                                             and all(isinstance(v, str) for v in value))]
        text = entry.get("cause")
        problems += [f"{where}: unknown fields {unknown} (claims, robots, tasks, cause)"] if unknown else []
        problems += [f"{where}: {name} must be a list of names" for name in bad]
        if not bad:
            problems += [f"{where}: unknown claim {c!r} ({', '.join(claims)})" for c in lists["claims"]
                         if c not in claims]
            problems += [f"{where}: unknown task {t!r} ({', '.join(TASKS)})" for t in lists["tasks"] if t not in TASKS]
            problems += [f"{where}: claims is empty"] if not lists["claims"] else []
        problems += [f"{where}: cause must be a non-empty text"] if not (isinstance(text, str) and text.strip()) else []
        if not problems:
            causes.append(Cause(tuple(lists["claims"]), tuple(lists["robots"]), tuple(lists["tasks"]),
                                " ".join(text.split())))
    if problems:
        raise ValueError("; ".join(problems))
    return causes


CRITERIA = (f"\"Close\" means LAT's mean at most {CLOSE} above IK's; \"better\", \"worse\" and \"best\" mean by more "
            f"than {TIE}.")


def paper_check_markdown(checks: list[Check], *, title: str, causes: list[Cause] = (), criteria: str = CRITERIA,
                         paper_column: str = "paper (numbers it states; A1 only)") -> str:
    """The checks as a Markdown page (``paper_check.md``), each claim that does not hold with its numbered cause
    from ``causes`` (the first that covers it) or "not checked". ``criteria`` says what the verdicts mean;
    ``paper_column`` heads the column of what the paper says."""
    numbers: dict[Cause, int] = {}

    def cause_of(check: Check) -> str:
        if not check.verdict.startswith("does not hold"):
            return ""
        cause = next((c for c in causes if c.covers(check)), None)
        if cause is None:
            return "not checked"
        return f"[{numbers.setdefault(cause, len(numbers) + 1)}](#cause-{numbers[cause]})"

    lines = [f"# The paper's claims, checked\n\n{title}. Normalised cost, mean +- std over seeds (each seed's mean "
             f"over its targets); a fallen robot's cost counts as 1. {criteria}\n",
             f"| claim | robot | setting | task | ours | {paper_column} | verdict | cause |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {c.claim} | {c.robot} | {c.setting} | {c.task} | {c.ours} | {c.paper} | {c.verdict} | "
              f"{cause_of(c)} |" for c in checks]
    held = sum(c.verdict == "holds" for c in checks)
    failed = [c for c in checks if c.verdict.startswith("does not hold")]
    unexplained = sum(cause_of(c) == "not checked" for c in failed)
    lines.append(f"\n{held} hold, {len(failed)} do not hold ({len(failed) - unexplained} with the cause we checked, "
                 f"{unexplained} not checked).")
    if numbers:
        lines.append("\n## The causes we checked\n")
        lines += [f"<a id=\"cause-{n}\"></a>{n}. {cause.text}\n" for cause, n in numbers.items()]
    stale = [c for c in causes if c not in numbers]
    if stale:
        lines.append("\n## Causes given for claims that hold or were not measured here\n")
        lines += [f"- ({', '.join(c.claims)}; {', '.join(c.robots) or 'every robot'}; "
                  f"{', '.join(c.tasks) or 'every task'}) {c.text}" for c in stale]
    return "\n".join(lines) + "\n"
