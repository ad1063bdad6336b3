"""The paper's claims about its baselines (Li et al., Sec. IV-B and IV-C) decided by tests over seeds.

Each claim is tested per robot and task on the seeds' mean normalised costs (each seed's mean over its episodes
first; a seed run more than once, say on two machines, counts once with the mean of its runs), with the tests of
:mod:`hierloco.stats` (``docs/statistics.md``): "better" is a significantly lower cost (one-sided Welch t at
:data:`hierloco.stats.ALPHA`) by at least the minimum effect; "close" is an equivalence test (TOST) within a margin
relative to the reference's cost; a claim where every method compared is no better than standing still is not
testable. Each claim gets "holds", "does not hold", "inconclusive", "not testable here" or, without the numbers,
"not measured", and is written as a Markdown table beside the numbers the paper states (A1's). Each claim that is
not found to hold is listed with the cause we checked for it, from a YAML file of causes (:func:`load_causes`), or
with "not checked"; a cause whose claim now holds is listed apart, so it does not go stale unseen.

    >>> rows = [{"method": m, "robot": "a1", "setting": "normal", "task": "velocity_tracking", "seed": s,
    ...          "normalized_cost": c + 0.01 * s} for m, c in (("lat", 0.1), ("lib", 0.5), ("ik", 0.105))
    ...         for s in range(3)]
    >>> [(c.key, c.verdict) for c in check_claims(rows)]
    [('learned_best', 'holds'), ('close:ik', 'holds'), ('lib_worse', 'holds')]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hierloco import stats
from hierloco.envs.tasks import GoalReaching
from hierloco.io import ArtifactError, load_yaml

LEARNED = ("lib", "sac", "sac_sac")   # the learned baselines LAT is claimed to beat on every task
MODEL_FREE = ("sac", "sac_sac")       # trained on half of the targets, claimed not to generalise to the others
IK_METHODS = ("ik", "ik_plain")       # IK with our footstep law, and with the paper's plain law
TASKS = ("velocity_tracking", "goal_reaching", "trajectory_tracking")
NOT_MEASURED = "not measured"
# the paper's stated numbers, all A1 in simulation: (robot, setting, task, method) -> "mean +- std"; where each is
# stated: Sec. IV-B with Fig. 7b (A1's baseline comparison), Sec. IV-C with Fig. 7d (A1, LAT and IK)
PAPER = {("a1", "normal", "goal_reaching", "lat"): "0.34 +- 0.02",
         ("a1", "normal", "goal_reaching", "sac"): "0.57 +- 0.06",
         ("a1", "normal", "goal_reaching", "sac_sac"): "0.92 +- 0.04",
         ("a1", "normal", "velocity_tracking", "lat"): "0.16 +- 0.10",
         ("a1", "normal", "velocity_tracking", "lib"): "0.58 +- 0.01",
         ("a1", "legs_disabled", "velocity_tracking", "lat"): "0.62 +- 0.06",
         ("a1", "legs_disabled", "velocity_tracking", "ik"): "0.91 +- 0.06"}
# the paper's figure of each claim, per robot (figures numbered in the order of the paper's source): Fig. 7a/7b the
# learned baselines (Daisy/A1), Fig. 7c/7d LAT and IK (Daisy/A1)
FIGURES = {"learned_best": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "lib_worse": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "lib_goals_close": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "sac_sac_worse": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "heldout_worse": {"daisy": "Sec. IV-B", "a1": "Sec. IV-B"},
           "close": {"daisy": "Fig. 7c, Sec. IV-C", "a1": "Fig. 7d, Sec. IV-C"},
           "damaged": {"daisy": "Fig. 7c, Sec. IV-C", "a1": "Fig. 7d, Sec. IV-C"},
           "ik_deteriorates": {"daisy": "Fig. 7c, Sec. IV-C", "a1": "Fig. 7d, Sec. IV-C"}}

# the claims by key (what a file of causes names): a word for the claim, ":<method>" for the baseline it is about
CLAIMS = ("learned_best", "close:ik", "close:ik_plain", "damaged:ik", "damaged:ik_plain", "lib_worse",
          "lib_goals_close", "sac_sac_worse", "ik_deteriorates:ik", "ik_deteriorates:ik_plain", "heldout_worse:sac",
          "heldout_worse:sac_sac")


@dataclass(frozen=True)
class Part:
    """One comparison inside a claim: per-seed costs ``a`` against ``b`` (per-seed costs, or a constant), the
    ``kind`` of test (``"better"``: ``a`` lower; ``"close"``: ``a`` within a margin of ``b``), whether the seeds
    are ``paired``, and its :class:`hierloco.stats.Decision`."""

    label: str
    a: tuple[float, ...]
    b: tuple[float, ...] | float
    kind: str
    paired: bool
    decision: stats.Decision
    names: tuple[str, str] = ("", "")   # what a and b are: (method, setting) labels for readers of the check
    options: tuple = ()                 # the test's own options (e.g. (("min_effect_rel", 0.5),)), where not the defaults


@dataclass(frozen=True)
class Check:
    """One claim on one robot and task: ``ours`` and ``paper`` as "method mean +- std" text, the ``verdict``
    (:data:`hierloco.stats.VERDICTS` or ``"not measured"``), ``detail`` (the test's numbers, or why not
    measured) and ``parts`` (each comparison tested). ``key`` is the claim's entry in :data:`CLAIMS`."""

    key: str
    claim: str
    robot: str
    setting: str
    task: str
    ours: str
    paper: str
    verdict: str
    detail: str = ""
    figure: str = ""
    parts: tuple[Part, ...] = field(default=(), compare=False)


def seed_means(rows, *, method: str, robot: str, setting: str, task: str, episodes=None) -> np.ndarray:
    """The mean normalised cost of each seed's episodes (``S``, seeds in order), NaN costs (a fallen robot) counted
    as 1; only the episodes (indices) in ``episodes`` if given. Rows with a ``run`` field are one seed's
    replicates (the same configuration run again, say on another machine): each run's mean first, then the seed's
    mean over its runs (``docs/statistics.md``)."""
    by_seed: dict = {}
    for row in rows:
        if episodes is not None and int(row["episode"]) not in episodes:
            continue
        if (row["method"], row["robot"], row["setting"], row["task"]) == (method, robot, setting, task):
            cost = float(row["normalized_cost"])
            runs = by_seed.setdefault(row["seed"], {})
            runs.setdefault(row.get("run", ""), []).append(1.0 if math.isnan(cost) else cost)
    return np.array([np.mean([np.mean(c) for c in runs.values()]) for _, runs in sorted(by_seed.items())])


def _text(method: str, means: np.ndarray) -> str:
    return f"{method} {means.mean():.2f} +- {means.std():.2f}"


def part(label: str, a, b, kind: str, *, paired: bool = False, parts: int = 1, names=("", ""),
         options: dict | None = None) -> Part:
    """One comparison tested: per-seed costs ``a`` (``S_a``) against ``b`` (``S_b``, or a constant), ``kind``
    ``"better"`` or ``"close"``, refuted at ``alpha / parts`` when it is one of ``parts`` comparisons of a claim;
    ``options``: the test's own minimum effect or margin (``min_effect_rel=0.5``), where not the defaults.

        >>> part("lat vs lib", [0.12, 0.11, 0.13], [0.45, 0.49, 0.44], "better").decision.verdict
        'holds'
    """
    decide = stats.decide_better if kind == "better" else stats.decide_close
    a = tuple(float(x) for x in a)
    b = float(b) if np.ndim(b) == 0 else tuple(float(x) for x in b)
    options = dict(options or {})
    return Part(label, a, b, kind, paired, decide(a, b, paired=paired, refute_alpha=stats.ALPHA / parts, **options),
                tuple(names), tuple(sorted(options.items())))


def decided(key, claim, robot, setting, task, ours, paper, parts: list[Part], figure="") -> Check:
    """A check from its tested parts: one part's verdict, or several combined as :func:`hierloco.stats.decide_all`
    does (each part must hold; any part refuted at alpha / parts refutes)."""
    verdicts = [p.decision.verdict for p in parts]
    if len(parts) == 1:
        verdict = verdicts[0]
    elif all(v == stats.NOT_TESTABLE for v in verdicts):
        verdict = stats.NOT_TESTABLE
    elif stats.DOES_NOT_HOLD in verdicts:
        verdict = stats.DOES_NOT_HOLD
    elif all(v == stats.HOLDS for v in verdicts):
        verdict = stats.HOLDS
    else:
        verdict = stats.INCONCLUSIVE
    detail = parts[0].decision.reason if len(parts) == 1 else "; ".join(f"{p.label}: {p.decision.text()}"
                                                                        for p in parts)
    return Check(key, claim, robot, setting, task, ours, paper, verdict, detail, figure, tuple(parts))


def check_claims(rows, tuned_ik: dict | None = None) -> list[Check]:
    """Every claim on every robot and task the rows cover (see the module doc). ``tuned_ik`` (robot -> ``ik`` or
    ``ik_plain``) marks the IK claims of the variant tuned on the training targets (``recipes/tune``), the fair IK."""
    rows = list(rows)
    tuned_ik = dict(tuned_ik or {})
    checks = []
    for robot in sorted({r["robot"] for r in rows}):
        def means(method, setting, task):
            return seed_means(rows, method=method, robot=robot, setting=setting, task=task)

        def paper(setting, task, methods):
            known = [f"{m} {PAPER[(robot, setting, task, m)]}" for m in methods if (robot, setting, task, m) in PAPER]
            return ", ".join(known) or "-"

        def figure(key):
            return FIGURES[key.split(":")[0]].get(robot, "")

        for task in TASKS:
            lat = means("lat", "normal", task)
            others = {m: s for m in LEARNED if (s := means(m, "normal", task)).size}
            if lat.size and others:
                ours = ", ".join([_text("lat", lat)] + [_text(m, s) for m, s in others.items()])
                checks.append(decided("learned_best", "LAT is best among the learned methods", robot, "normal",
                                       task, ours, paper("normal", task, ("lat", *LEARNED)),
                                       [part(f"vs {m}", lat, s, "better", parts=len(others),
                                              names=("lat:normal", f"{m}:normal")) for m, s in others.items()],
                                       figure("learned_best")))
            sac, sac_sac = means("sac", "normal", task), means("sac_sac", "normal", task)
            if sac.size and sac_sac.size:
                checks.append(decided("sac_sac_worse", "SAC-SAC's user-defined action space does worse than SAC's "
                                       "learned one", robot, "normal", task,
                                       f"{_text('sac', sac)}, {_text('sac_sac', sac_sac)}",
                                       paper("normal", task, ("sac", "sac_sac")),
                                       [part("sac vs sac_sac", sac, sac_sac, "better",
                                              names=("sac:normal", "sac_sac:normal"))], figure("sac_sac_worse")))
            for ik in IK_METHODS:
                tuned = " (the IK tuned on the training targets)" if tuned_ik.get(robot) == ik else ""
                base = means(ik, "normal", task)
                if lat.size and base.size:
                    checks.append(decided(f"close:{ik}", f"LAT is close to {ik.upper()}{tuned} (within "
                                           f"{stats.EQUIV_MARGIN_REL:.0%})", robot, "normal", task,
                                           f"{_text('lat', lat)}, {_text(ik, base)}", "-",
                                           [part(f"lat vs {ik}", lat, base, "close",
                                                  names=("lat:normal", f"{ik}:normal"))], figure("close")))
                damaged, damaged_ik = means("lat", "legs_disabled", task), means(ik, "legs_disabled", task)
                if damaged.size and damaged_ik.size:
                    checks.append(decided(f"damaged:{ik}", f"LAT beats {ik.upper()}{tuned} with legs disabled",
                                           robot, "legs_disabled", task,
                                           f"{_text('lat', damaged)}, {_text(ik, damaged_ik)}",
                                           paper("legs_disabled", task, ("lat", ik)),
                                           [part(f"lat vs {ik}", damaged, damaged_ik, "better",
                                                  names=("lat:legs_disabled", f"{ik}:legs_disabled"))],
                                           figure("damaged")))
                if base.size and damaged_ik.size:
                    checks.append(decided(f"ik_deteriorates:{ik}", f"{ik.upper()}{tuned} deteriorates with legs "
                                           "disabled", robot, "legs_disabled", task,
                                           f"normal {_text(ik, base)}, legs disabled {_text(ik, damaged_ik)}",
                                           paper("legs_disabled", task, (ik,)),
                                           [part(f"{ik} normal vs legs disabled", base, damaged_ik, "better",
                                                  names=(f"{ik}:normal", f"{ik}:legs_disabled"))],
                                           figure("ik_deteriorates")))
        lat, lib = means("lat", "normal", "velocity_tracking"), means("lib", "normal", "velocity_tracking")
        claim = "LIB is worse than LAT at velocity tracking"
        known = paper("normal", "velocity_tracking", ("lat", "lib"))
        if lat.size and lib.size:
            checks.append(decided("lib_worse", claim, robot, "normal", "velocity_tracking",
                                   f"{_text('lat', lat)}, {_text('lib', lib)}", known,
                                   [part("lat vs lib", lat, lib, "better", names=("lat:normal", "lib:normal"))],
                                   figure("lib_worse")))
        else:
            checks.append(Check("lib_worse", claim, robot, "normal", "velocity_tracking", "-", known, NOT_MEASURED,
                                "LAT and LIB are not both in the rows", figure("lib_worse")))
        lat, lib = means("lat", "normal", "goal_reaching"), means("lib", "normal", "goal_reaching")
        if lat.size and lib.size:
            checks.append(decided("lib_goals_close", "LIB generalises well to goal reaching (close to LAT, "
                                   f"within {stats.EQUIV_MARGIN_REL:.0%})", robot, "normal", "goal_reaching",
                                   f"{_text('lib', lib)}, {_text('lat', lat)}", "-",
                                   [part("lib vs lat", lib, lat, "close", names=("lib:normal", "lat:normal"))],
                                   figure("lib_goals_close")))
        checks += _generalisation(rows, robot)
    return checks


def _generalisation(rows, robot: str) -> list[Check]:
    """"SAC and SAC-SAC fail to generalise to new targets" (Sec. IV-B) on goal reaching, the task whose held-out
    targets are whole episodes: a model-free method's cost on its held-out goals against its training goals, seed
    by seed (the same policy on both halves: a paired test)."""
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
        checks.append(decided(f"heldout_worse:{method}", f"{method.upper()} does worse on its held-out goals than "
                               "on its training goals", robot, "normal", "goal_reaching",
                               ", ".join(_text(name, means) for name, means in split.items()), "-",
                               [part("training vs held-out goals", split["training goals"], split["held-out goals"],
                                      "better", paired=True, names=(f"{method}:training", f"{method}:held-out"))],
                               FIGURES["heldout_worse"].get(robot, "")))
    return checks


@dataclass(frozen=True)
class Cause:
    """The cause we checked for the claims ``claims`` (keys of :data:`CLAIMS`) on ``robots`` and ``tasks`` (empty:
    all) that are not found to hold."""

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
        entries = load_yaml(path)  # read safely: a shared causes file holds no YAML bomb
    except ArtifactError as error:
        raise ValueError(f"causes: {error}") from None
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


CRITERIA = (f"Tests over seeds (`docs/statistics.md`, `hierloco.stats`), alpha = {stats.ALPHA}: \"better\", "
            f"\"beats\", \"worse\" and \"best\" hold when the cost is significantly lower (one-sided Welch t) by at "
            f"least {stats.MIN_EFFECT_REL:.0%} of the other's mean (and {stats.MIN_EFFECT_ABS}), and do not hold when "
            f"the gain is significantly below that; \"best\" needs every comparison to hold. \"Close\" is an "
            f"equivalence test (TOST) with a margin of {stats.EQUIV_MARGIN_REL:.0%} of the reference's mean (at least "
            f"{stats.EQUIV_MARGIN_ABS}). A comparison of methods that are all at {stats.NOT_TESTABLE_COST} of "
            f"standing still's cost or worse is not testable here; otherwise a claim neither established nor refuted "
            f"is inconclusive at this many seeds. d: the difference of the means with its {1 - 2 * stats.ALPHA:.0%} "
            "interval.")
UNDECIDED = (stats.DOES_NOT_HOLD, stats.INCONCLUSIVE, stats.NOT_TESTABLE)


def counts_line(checks) -> str:
    """How many checks got each verdict, e.g. ``"3 hold, 1 do not hold, 0 inconclusive, 0 not testable here"``
    (and how many were not measured, where any were)."""
    tally = {v: sum(c.verdict == v for c in checks) for v in (*stats.VERDICTS, NOT_MEASURED)}
    if not tally[NOT_MEASURED]:
        del tally[NOT_MEASURED]
    names = {stats.HOLDS: "hold", stats.DOES_NOT_HOLD: "do not hold", stats.INCONCLUSIVE: "inconclusive",
             stats.NOT_TESTABLE: "not testable here", NOT_MEASURED: "not measured"}
    return ", ".join(f"{n} {names[v]}" for v, n in tally.items())


def paper_check_markdown(checks: list[Check], *, title: str, causes: list[Cause] = (), criteria: str = CRITERIA,
                         paper_column: str = "paper (A1's numbers: Fig. 7b, Sec. IV-B; legs disabled Fig. 7d, "
                                             "Sec. IV-C)", with_causes: bool = True) -> str:
    """The checks as a Markdown page (``paper_check.md``), each claim not found to hold (does not hold,
    inconclusive, not testable here) with its numbered cause from ``causes`` (the first that covers it) or "not
    checked". ``criteria`` says what the verdicts mean; ``paper_column`` heads the column of what the paper says;
    ``with_causes=False`` leaves the causes out (a study that keeps none)."""
    numbers: dict[Cause, int] = {}

    def cause_of(check: Check) -> str:
        if check.verdict not in UNDECIDED:
            return ""
        cause = next((c for c in causes if c.covers(check)), None)
        if cause is None:
            return "not checked"
        return f"[{numbers.setdefault(cause, len(numbers) + 1)}](#cause-{numbers[cause]})"

    lines = [f"# The paper's claims, checked\n\n{title}. Normalised cost, mean +- std over seeds (each seed's mean "
             f"over its targets); a fallen robot's cost counts as 1. {criteria}\n",
             f"| claim | robot | setting | task | ours | {paper_column} | verdict | test |"
             + (" cause |" if with_causes else ""),
             "|---|---|---|---|---|---|---|---|" + ("---|" if with_causes else "")]
    lines += [f"| {c.claim} | {c.robot} | {c.setting} | {c.task} | {c.ours} | {c.paper} | {c.verdict} | "
              f"{c.detail or '-'} |" + (f" {cause_of(c)} |" if with_causes else "") for c in checks]
    open_ = [c for c in checks if c.verdict in UNDECIDED]
    unexplained = sum(cause_of(c) == "not checked" for c in open_)
    lines.append(f"\n{counts_line(checks)}" + (f" ({len(open_) - unexplained} of the {len(open_)} not found to hold "
                                                f"with the cause we checked, {unexplained} not checked)."
                                                if with_causes else "."))
    if numbers:
        lines.append("\n## The causes we checked\n")
        lines += [f"<a id=\"cause-{n}\"></a>{n}. {cause.text}\n" for cause, n in numbers.items()]
    stale = [c for c in causes if c not in numbers]
    if stale:
        lines.append("\n## Causes given for claims that hold or were not measured here\n")
        lines += [f"- ({', '.join(c.claims)}; {', '.join(c.robots) or 'every robot'}; "
                  f"{', '.join(c.tasks) or 'every task'}) {c.text}" for c in stale]
    return "\n".join(lines) + "\n"
