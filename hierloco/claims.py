"""The paper's claims as a registry: the blocks every claim is decided with, each study's declaration of its runs and
claims, and the evidence read from the job records (``docs/claims.md``).

**Building blocks.** One claim on one robot and task is a :class:`Check`: what is compared (its :class:`Part`\\ s:
per-seed costs against per-seed costs or a constant), each part's test (:func:`part`: "better" or "close", the tests
of :mod:`hierloco.stats`, ``docs/statistics.md``), the verdict (:func:`decided`: one part's, or every part must hold
and one refuted at alpha / parts refutes) and where the paper makes the claim. :func:`seed_means` (per-episode rows)
and :func:`seed_costs` (runs) give a part its per-seed values; a claim not found to hold is matched with the cause
we checked for it (:class:`Cause`, :func:`load_causes`); :func:`checks_markdown` writes checks as a table.

**The registry.** A study declares what judging it needs in ``claims.py`` beside its ``run.py``, adding to
:data:`CLAIMS`:

- :class:`Study`: its folder under ``results/``, where its runs are (job records; or a per-episode table, or a table
  of rows of its own), the command that made it, and the checks of its own page (``<study>/verdicts.md``);
- :class:`Source`: a set of checks computed once from the :class:`Evidence` (say the comparison's claims on the
  pooled runs), which the paper's claims are decided from, and the job a new seed of a side of it runs;
- :class:`Claim`: one claim of the paper (its words, where the paper makes it, the numbers it states) with the
  source and check key that decide it, or the study it still needs;
- :class:`Counted`: a statement about the design, counted rather than tested.

**The ledger** (:func:`ledger`): ``paper_check.md`` counts one :class:`Entry` per claim of the paper and robot, its
rows (:class:`Row`) its parts, combined as a multi-part check is (:func:`entry_check`); a row repeating an earlier
section's test, or one its claim does not count (:attr:`Claim.counted`), is shown and not counted.

``hierloco verdicts`` imports every study's ``claims`` module (:meth:`ClaimRegistry.discover`: the studies of
:data:`hierloco.pipeline.methods.STUDIES`, the recipe folders and the ``hierloco.studies`` entry points), reads the
evidence (:func:`load`) and renders its pages from what is registered; it names no study.

Example (two methods on three seeds, one claim):
    >>> rows = [{"method": m, "robot": "a1", "setting": "normal", "task": "goal_reaching", "seed": s,
    ...          "normalized_cost": c + 0.01 * s} for m, c in (("lat", 0.1), ("lib", 0.5)) for s in range(3)]
    >>> lat, lib = (seed_means(rows, method=m, robot="a1", setting="normal", task="goal_reaching")
    ...             for m in ("lat", "lib"))
    >>> check = decided("lat_best", "LAT beats LIB", "a1", "normal", "goal_reaching", describe("lat", lat), "-",
    ...                 [part("lat vs lib", lat, lib, "better", names=("lat:normal", "lib:normal"))])
    >>> check.verdict, check.ours
    ('holds', 'lat 0.11 +- 0.01')
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import re
import sys
from collections import defaultdict
from dataclasses import KW_ONLY, dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Mapping

import numpy as np

from hierloco import stats
from hierloco.evidence import (Run, adopt_configs, read_findings, read_records, read_stage_reports, read_table,
                               seed_values, select)
from hierloco.io import ArtifactError, load_yaml

TASKS = ("velocity_tracking", "goal_reaching", "trajectory_tracking")
ROBOTS = ("a1", "daisy")
NOT_MEASURED = "not measured"
NOT_MEASURED_YET = "not measured yet"
PAPER_PAGE, SANITY_PAGE = "paper_check.md", "sanity_checks.md"
EXTRA = "extra (not counted)"
UNDECIDED = (stats.DOES_NOT_HOLD, stats.INCONCLUSIVE, stats.NOT_TESTABLE)


# --- building blocks -------------------------------------------------------------------------------------------------

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
    options: tuple = ()                 # the test's own options (("min_effect_rel", 0.5),), where not the defaults
    refute_parts: int = 1               # refuted at alpha / refute_parts (one of that many comparisons of a claim)


@dataclass(frozen=True)
class Check:
    """One claim on one robot and task: ``ours`` and ``paper`` as "method mean +- std" text, the ``verdict``
    (:data:`hierloco.stats.VERDICTS` or ``"not measured"``), ``detail`` (the test's numbers, or why not
    measured) and ``parts`` (each comparison tested). ``key`` names the claim in its study (what a file of causes
    and a :class:`Claim` name)."""

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


def variant_verdicts(rows, reference: str, variants, tasks, *, reference_name: str | None = None) -> str:
    """A markdown table: per robot, setting and task of ``tasks``, each method of ``variants`` against
    ``reference`` by the stated tests over seeds paired by seed (``docs/statistics.md``): "better" (a lower cost by
    at least the minimum effect) and "close" (within the equivalence margin); then how many places each variant is
    better, close, worse, not testable or undecided. ``rows``: evaluation rows (``method``, ``robot``, ``setting``,
    ``task``, ``seed``, ``episode``, ``normalized_cost``); a seed counts where both methods have it."""
    from hierloco.stats import decide_better, decide_close

    name = reference_name or reference
    lines = [f"| robot | setting | task | variant | better than {name}? | as good as {name} (close)? |",
             "|---|---|---|---|---|---|"]
    tally: dict = {}
    places = sorted({(r["robot"], r["setting"], r["task"]) for r in rows if r["task"] in tasks})
    for robot, setting, task in places:
        for method in variants:
            pairs = []
            for seed in sorted({r["seed"] for r in rows}):
                of_seed = [r for r in rows if r["seed"] == seed]
                pairs.append(tuple(seed_means(of_seed, method=m, robot=robot, setting=setting, task=task)
                                   for m in (method, reference)))
            pairs = [(a[0], b[0]) for a, b in pairs if a.size and b.size]
            if not pairs:
                continue
            a, b = (np.array(x) for x in zip(*pairs))
            better, close = decide_better(a, b, paired=True), decide_close(a, b, paired=True)
            worse = decide_better(b, a, paired=True)
            word = ("better" if better.verdict == "holds" else "worse" if worse.verdict == "holds"
                    else "close" if close.verdict == "holds" else "not testable" if "testable" in close.verdict
                    else "undecided")
            tally.setdefault(method, {}).setdefault(word, 0)
            tally[method][word] += 1
            lines.append(f"| {robot} | {setting} | {task} | {method} | {better.text()} | {close.text()} |")
    lines += ["", "| variant | better | close | worse | not testable | undecided |", "|---|---|---|---|---|---|"]
    for method, counts in tally.items():
        lines.append(f"| {method} | " + " | ".join(str(counts.get(w, 0)) for w in
                                                  ("better", "close", "worse", "not testable", "undecided")) + " |")
    return "\n".join(lines) + "\n"


def seed_costs(runs: Iterable[Run], **labels) -> np.ndarray:
    """The pooled per-seed mean costs (``S``) of the runs with these labels (:func:`hierloco.evidence.select`,
    :func:`hierloco.evidence.seed_values`)."""
    return seed_values(select(runs, **labels))[1]


def describe(name: str, values) -> str:
    """``"<name> <mean> +- <std>"`` of per-seed values, two decimals."""
    return f"{name} {np.mean(values):.2f} +- {np.std(values):.2f}"


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
                tuple(names), tuple(sorted(options.items())), parts)


def decided(key, claim, robot, setting, task, ours, paper, parts: list[Part], figure="") -> Check:
    """A check from its tested parts: one part's verdict, or several combined as :func:`hierloco.stats.decide_all`
    does (each part must hold; any part refuted at alpha / parts refutes)."""
    verdict = combined([p.decision.verdict for p in parts])
    detail = parts[0].decision.reason if len(parts) == 1 else "; ".join(f"{p.label}: {p.decision.text()}"
                                                                        for p in parts)
    return Check(key, claim, robot, setting, task, ours, paper, verdict, detail, figure, tuple(parts))


def combined(verdicts: list[str]) -> str:
    """The verdict of a claim from its parts' (:func:`decided`)."""
    if len(verdicts) == 1:
        return verdicts[0]
    if all(v == stats.NOT_TESTABLE for v in verdicts):
        return stats.NOT_TESTABLE
    if stats.DOES_NOT_HOLD in verdicts:
        return stats.DOES_NOT_HOLD
    if all(v == stats.HOLDS for v in verdicts):
        return stats.HOLDS
    return stats.INCONCLUSIVE


# --- how firm a verdict is: its p-values, multiplicity, the pre-planned seeds, the thresholds ------------------------

PLANNED_SEEDS = 3   # the seeds every study planned (0, 1, 2); seeds 3-4 were added where a verdict looked fragile


def p_values(check: Check) -> tuple[float | None, float | None]:
    """``(p that establishes it, p that refutes it)`` of a check: establishing, the largest of its parts' p (an
    intersection-union test holds when every part does); refuting, the smallest part's refuting p times the number
    of comparisons it is refuted among (Bonferroni, as :func:`decided` refutes), at most 1. ``None`` where a part
    has no p (not testable, too few seeds)."""
    live = [p for p in check.parts if p.decision.verdict != stats.NOT_TESTABLE]
    establish = [p.decision.p for p in live]
    refute = [None if p.decision.p_refute is None else min(1.0, p.decision.p_refute * p.refute_parts) for p in live]
    p_establish = max(establish) if establish and None not in establish else None
    p_refute = min((r for r in refute if r is not None), default=None)
    return p_establish, p_refute


def deciding_p(check: Check) -> float | None:
    """The p-value that decided the verdict: the refuting one for "does not hold", else the establishing one."""
    p_establish, p_refute = p_values(check)
    return p_refute if check.verdict == stats.DOES_NOT_HOLD else p_establish


def corrected(checks: list[Check], *, adjust: Callable = stats.holm, alpha: float = stats.ALPHA) -> list[str]:
    """The verdicts of a family of checks (one claim of the paper; one study) after a multiplicity correction
    (``adjust``: :func:`hierloco.stats.holm` or :func:`hierloco.stats.benjamini_hochberg`): the establishing p-values
    of the family are adjusted together, and the refuting ones together; "holds" stays when its adjusted
    establishing p is below ``alpha``, "does not hold" when its adjusted refuting p is, every other verdict stays,
    and a verdict that does not stay becomes inconclusive. The correction only ever weakens a verdict."""
    pairs = [p_values(c) for c in checks]
    adjusted = []
    for side in (0, 1):
        index = [i for i, pair in enumerate(pairs) if pair[side] is not None]
        values = dict(zip(index, adjust([pairs[i][side] for i in index]))) if index else {}
        adjusted.append(values)
    out = []
    for i, check in enumerate(checks):
        if check.verdict == stats.HOLDS and not adjusted[0].get(i, 1.0) < alpha:
            out.append(stats.INCONCLUSIVE)
        elif check.verdict == stats.DOES_NOT_HOLD and not adjusted[1].get(i, 1.0) < alpha:
            out.append(stats.INCONCLUSIVE)
        else:
            out.append(check.verdict)
    return out


def is_borderline(check: Check, corrected_verdict: str | None = None) -> bool:
    """A verdict is borderline when its deciding p lies in :data:`hierloco.stats.BORDERLINE` (a "holds" or a "does
    not hold" at ``0.01 <= p < 0.05``), or when the multiplicity correction changes it."""
    if check.verdict not in (stats.HOLDS, stats.DOES_NOT_HOLD):
        return False
    return stats.borderline(deciding_p(check)) or (corrected_verdict is not None
                                                   and corrected_verdict != check.verdict)


def redecided(check: Check, *, seeds: int | None = None, **options) -> str:
    """The check's verdict decided again: on the first ``seeds`` seeds of each side (the seeds in order; ``None``:
    all) and/or with other thresholds (``options``: ``min_effect_rel``, ``min_effect_abs``, ``margin_rel``,
    ``margin_abs``; a part's own options win where it has them)."""
    verdicts = []
    for p in check.parts:
        a = p.a[:seeds] if seeds else p.a
        b = p.b if np.ndim(p.b) == 0 or not seeds else p.b[:seeds]
        own = dict(p.options)
        keys = ("min_effect_rel", "min_effect_abs") if p.kind == "better" else ("margin_rel", "margin_abs")
        chosen = {**{k: v for k, v in options.items() if k in keys}, **own}
        verdicts.append(part(p.label, a, b, p.kind, paired=p.paired, parts=p.refute_parts, names=p.names,
                             options=chosen).decision.verdict)
    return combined(verdicts) if verdicts else check.verdict


def planned(check: Check) -> str | None:
    """The verdict at the pre-planned :data:`PLANNED_SEEDS` seeds (seeds 0-2) where a side has more, else ``None``."""
    more = any(len(v) > PLANNED_SEEDS for p in check.parts for v in (p.a, p.b) if np.ndim(v))
    return redecided(check, seeds=PLANNED_SEEDS) if more else None


@dataclass(frozen=True)
class Cause:
    """The cause we checked for the claims ``claims`` (check keys) on ``robots`` and ``tasks`` (empty: all) that are
    not found to hold."""

    claims: tuple[str, ...]
    robots: tuple[str, ...]
    tasks: tuple[str, ...]
    text: str

    def covers(self, check: Check) -> bool:
        return (check.key in self.claims and (not self.robots or check.robot in self.robots)
                and (not self.tasks or check.task in self.tasks))


def load_causes(path, claims: tuple[str, ...]) -> list[Cause]:
    """The causes in the YAML file ``path``: a list of ``{claims: [...], robots: [...], tasks: [...], cause: text}``
    (``robots`` and ``tasks`` optional), each claim one of ``claims`` (the keys of the checks the causes are for).
    Raises ValueError naming every malformed entry.

        >>> import tempfile
        >>> f = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
        >>> _ = f.write("- {claims: [lib_worse], robots: [a1], cause: LIB's experts cover two speeds.}")
        >>> f.close()
        >>> load_causes(f.name, claims=("lib_worse",))[0].claims
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


def counts_line(checks) -> str:
    """How many checks got each verdict, e.g. ``"3 hold, 1 do not hold, 0 inconclusive, 0 not testable here"``
    (and how many were not measured, where any were)."""
    tally = {v: sum(c.verdict == v for c in checks) for v in (*stats.VERDICTS, NOT_MEASURED)}
    if not tally[NOT_MEASURED]:
        del tally[NOT_MEASURED]
    names = {stats.HOLDS: "hold", stats.DOES_NOT_HOLD: "do not hold", stats.INCONCLUSIVE: "inconclusive",
             stats.NOT_TESTABLE: "not testable here", NOT_MEASURED: "not measured"}
    return ", ".join(f"{n} {names[v]}" for v, n in tally.items())


def verdict_text(check: Check, corrected_verdict: str | None = None, *, bold: bool = False) -> str:
    """The verdict with the p-value that decided it and, where it is, "borderline" (:func:`is_borderline`), e.g.
    ``"holds (p = 0.0498; borderline)"`` (``bold``: the verdict alone in bold)."""
    p = deciding_p(check) if check.verdict in (stats.HOLDS, stats.DOES_NOT_HOLD, stats.INCONCLUSIVE) else None
    which = "refuting " if check.verdict == stats.DOES_NOT_HOLD else ""
    notes = ([f"{which}p = {p:.3g}"] if p is not None else []) + \
        (["borderline"] if is_borderline(check, corrected_verdict) else [])
    return (f"**{check.verdict}**" if bold else check.verdict) + (f" ({'; '.join(notes)})" if notes else "")


def counts_line_of(verdicts: list[str]) -> str:
    """:func:`counts_line` of bare verdicts."""
    return counts_line([Check("", "", "", "", "", "", "", v) for v in verdicts])


def checks_markdown(checks: list[Check], *, title: str, criteria: str, paper_column: str, causes: list[Cause] = (),
                    with_causes: bool = True, family: bool = False) -> str:
    """The checks as a Markdown page (a study's ``paper_check.md``), each claim not found to hold (does not hold,
    inconclusive, not testable here) with its numbered cause from ``causes`` (the first that covers it) or "not
    checked". ``criteria`` says what the verdicts mean; ``paper_column`` heads the column of what the paper says;
    ``with_causes=False`` leaves the causes out (a study that keeps none); ``family``: each verdict with its deciding
    p, borderline marked, and the verdict after Holm's correction over the checks as one family (:func:`corrected`)
    and at the pre-planned seeds (:func:`planned`) beside it."""
    numbers: dict[Cause, int] = {}

    def cause_of(check: Check) -> str:
        if check.verdict not in UNDECIDED:
            return ""
        cause = next((c for c in causes if c.covers(check)), None)
        if cause is None:
            return "not checked"
        return f"[{numbers.setdefault(cause, len(numbers) + 1)}](#cause-{numbers[cause]})"

    holm = corrected(checks) if family else []
    extra = " Holm (family: this page) | at seeds 0-2 |" if family else ""
    lines = [f"# The paper's claims, checked\n\n{title}. Normalised cost, mean +- std over seeds (each seed's mean "
             f"over its targets); a fallen robot's cost counts as 1. {criteria}\n",
             f"| claim | robot | setting | task | ours | {paper_column} | verdict | test |" + extra
             + (" cause |" if with_causes else ""),
             "|---|---|---|---|---|---|---|---|" + ("---|---|" if family else "") + ("---|" if with_causes else "")]
    lines += [f"| {c.claim} | {c.robot} | {c.setting} | {c.task} | {c.ours} | {c.paper} | "
              f"{verdict_text(c, holm[i]) if family else c.verdict} | {c.detail or '-'} |"
              + (f" {holm[i]} | {planned(c) or 'same seeds'} |" if family else "")
              + (f" {cause_of(c)} |" if with_causes else "") for i, c in enumerate(checks)]
    open_ = [c for c in checks if c.verdict in UNDECIDED]
    unexplained = sum(cause_of(c) == "not checked" for c in open_)
    after = f"; after Holm's correction over the page: {counts_line_of(holm)}" if family else ""
    lines.append(f"\n{counts_line(checks)}{after}" + (f" ({len(open_) - unexplained} of the {len(open_)} not found to "
                                                       f"hold with the cause we checked, {unexplained} not checked)."
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


def job_minutes(runs: Iterable[Run]) -> list[float]:
    """The compute of each distinct job among ``runs`` (minutes; a job's runs share its record)."""
    return list({r.record: r.minutes for r in runs if not math.isnan(r.minutes)}.values())


def folders_of(runs: Iterable[Run]) -> dict:
    """``(method, robot, setting, task) -> the folders its runs come from``."""
    found = defaultdict(set)
    for run in runs:
        found[(run.method, run.robot, run.setting, run.task)].add(run.folder)
    return found


# --- what a study declares -------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Study:
    """A study folder under ``results/`` (``name``) and how to read it: its job records (``records``: folders
    relative to ``results/``, the first that exists is read), else a per-episode table without records
    (``table``), or a table of rows of its own read in place of records (``rows``, described by ``rows_note``), or
    rows of its own made from its records in place of its runs (``rows_from(folder) -> (rows, incomplete)``: the
    rows, and the records that lack what the rows need, :attr:`Evidence.incomplete`; described by ``rows_note``);
    ``robot``: only this robot's runs; ``reports``: stages whose reports are read from its records;
    ``archived``: tables without records (``<folder>/comparison.csv``) declared to be of this study's configurations
    (:func:`hierloco.evidence.adopt_configs`); ``variants`` and ``names``: the method variants its records hold
    (``{name: {recipe, overrides}}``, as a study's config declares them) and a method's name in the claims where
    not its own; ``pooled``: its runs of the paper's configurations are pooled with the other studies' of the same
    configurations.

    Its own page, ``<study>/verdicts.md``, holds ``checks(evidence)`` (none: no page; the hook is called only when
    the study has runs or rows), each check not found to hold with its cause when ``causes`` (a loader of
    ``<study>/causes.yaml``) is given; ``paper_column`` heads the column of what the paper says. ``questions``: how
    ``fragile_claims.md`` names the study's own questions, where it has any (:attr:`Source.questions`). ``order``:
    where it stands among the studies."""

    name: str
    _: KW_ONLY
    command: str
    order: float
    records: tuple[str, ...] = ()
    table: str = ""
    rows: str = ""
    rows_note: str = ""
    rows_from: Callable | None = field(default=None, compare=False)
    robot: str = ""
    reports: tuple[str, ...] = ()
    archived: tuple[str, ...] = ()
    variants: Mapping = field(default_factory=dict, compare=False)
    names: Mapping = field(default_factory=dict, compare=False)
    pooled: bool = False
    checks: Callable | None = field(default=None, compare=False)
    causes: Callable | None = field(default=None, compare=False)
    paper_column: str = "the paper"
    questions: str = ""


@dataclass(frozen=True)
class Source:
    """A set of checks the paper's claims are decided from, computed once: ``checks(evidence) -> [Check]``.

    ``folder(check)``: the folder under ``results/`` a check's runs come from (default ``name``); ``study(check)``:
    the runs a new seed adds to, as ``fragile_claims.md`` names them (default ``name``); ``job(evidence, robot,
    side)``: the job a new seed of ``side`` (a part's name) runs, ``(key, words, minutes of each such job
    recorded)``, one key per job however many claims ask for it (default: a job of its own, compute unknown);
    ``folders(evidence)``: for pooled runs, ``(method, robot, setting, task) -> folders`` (:func:`folders_of`);
    ``sets(evidence)``: the same checks on each set of the project's runs of the same configurations (the verdicts
    that differ between them make a claim fragile); ``questions(check)``: the checks that are the study's own
    questions rather than the paper's, listed in ``fragile_claims.md`` when inconclusive; ``note`` and ``pooling``:
    what ``paper_check.md`` and ``fragile_claims.md`` say about how its runs are pooled; ``alias(name)``: the
    configuration a side's name stands for where this source names it otherwise (say ``"lat:10000"`` for the
    comparison's ``"lat:normal"``; :meth:`configuration`). ``order``: where it stands among the sources."""

    name: str
    _: KW_ONLY
    order: float
    checks: Callable = field(compare=False)
    folder: Callable | None = field(default=None, compare=False)
    study: Callable | None = field(default=None, compare=False)
    job: Callable | None = field(default=None, compare=False)
    folders: Callable | None = field(default=None, compare=False)
    sets: Callable | None = field(default=None, compare=False)
    questions: Callable | None = field(default=None, compare=False)
    alias: Callable | None = field(default=None, compare=False)
    note: str = ""
    pooling: str = ""

    def configuration(self, name: str) -> str:
        """The configuration a side's name (a :class:`Part`'s ``names``) stands for in the terms every source
        shares (``"<method>:<setting>"``), where this source names it otherwise (:attr:`alias`): how
        :func:`ledger` finds a test another claim already made."""
        return self.alias(name) if self.alias is not None else name

    def folder_of(self, check: Check) -> str:
        return self.folder(check) if self.folder else self.name

    def study_of(self, check: Check) -> str:
        return self.study(check) if self.study else self.name

    def job_of(self, evidence: "Evidence", robot: str, side: str) -> tuple[tuple | None, str, list[float]]:
        if self.job is not None:
            return self.job(evidence, robot, side)
        return (self.name, side), f"{side} ({self.name})", []


@dataclass(frozen=True)
class Claim:
    """One claim of the paper: ``words`` (its text, with what ours tests where that differs), ``where`` the paper
    makes it, ``paper`` the numbers it states (robot and figure); decided by the checks of source ``source`` whose
    key (before any ``:``) is ``key`` (and that ``select`` keeps, when given). ``note(checks)``: a line the page adds
    below its table (``checks``: every source's). A claim nothing here can measure has no source, ``needs``
    says what it would need (or what is measured of it outside a test), and ``status`` whether it is "not measured
    yet" or "not testable here"; a claim with a source may say in ``needs`` what its section asks for while its
    source has no check of it (it is "not measured yet" then). ``robots``: the robots it is about (one entry of the
    ledger per robot, where it has no checks). ``counted(check)``: whether a check counts toward its robot's entry
    (default: every check); the others stay on the page labelled ``extra`` (say the IK variant the paper did not
    use). ``page``: :data:`PAPER_PAGE` (``paper_check.md``) or :data:`SANITY_PAGE` (``sanity_checks.md``: a check
    that only shows the set-up behaves, not a claim of the paper's results). ``order``: its place in the paper."""

    _: KW_ONLY
    order: float
    words: str
    where: str
    paper: str = "-"
    source: str = ""
    key: str = ""
    select: Callable | None = field(default=None, compare=False)
    note: Callable | None = field(default=None, compare=False)
    needs: str = ""
    status: str = "not measured yet"   # a claim with no source: "not measured yet", or "not testable here" (why: needs)
    robots: tuple[str, ...] = ROBOTS   # the robots it is about: one entry of the ledger each
    counted: Callable | None = field(default=None, compare=False)
    extra: str = ""
    page: str = PAPER_PAGE

    def chosen(self, checks: dict[str, list[Check]]) -> list[Check]:
        """The checks that decide it."""
        return [c for c in checks.get(self.source, []) if c.key.split(":")[0] == self.key
                and (self.select is None or self.select(c))]


@dataclass(frozen=True)
class Counted:
    """A statement of the paper about the design, counted rather than tested: ``words`` (ending where the counts
    follow) and ``count(evidence)``, the counts as phrases (none: not shown). ``order``: its place."""

    _: KW_ONLY
    order: float
    words: str
    count: Callable = field(compare=False)


class ClaimRegistry:
    """The studies, sources, claims and counted statements the studies add (:meth:`add`; each declared with keyword
    arguments, a study's and a source's name first), each kept in its ``order``. Adding an equal entry again is a
    no-op; another entry under a taken name raises ``ValueError``."""

    KINDS = {Study: "study", Source: "source", Claim: "claim", Counted: "counted statement"}

    def __init__(self):
        self._entries: dict[type, dict[str, object]] = {kind: {} for kind in self.KINDS}

    @staticmethod
    def _name(entry) -> str:
        return entry.name if isinstance(entry, (Study, Source)) else entry.words

    def add(self, *entries) -> None:
        for entry in entries:
            kind = type(entry)
            if kind not in self.KINDS:
                raise TypeError(f"a claims registry holds {', '.join(k.__name__ for k in self.KINDS)}, not "
                                f"{kind.__name__}")
            name = self._name(entry)
            known = self._entries[kind].get(name)
            if known is not None and known is not entry and known != entry:
                raise ValueError(f"{self.KINDS[kind]} {name!r} is already registered")
            self._entries[kind][name] = entry

    def remove(self, *entries) -> None:
        """Removes entries (a test that added a study of its own removes it afterwards)."""
        for entry in entries:
            self._entries[type(entry)].pop(self._name(entry), None)

    def _sorted(self, kind: type) -> list:
        return sorted(self._entries[kind].values(), key=lambda e: (e.order, self._name(e)))

    def studies(self) -> list[Study]:
        return self._sorted(Study)

    def sources(self) -> list[Source]:
        return self._sorted(Source)

    def claims(self) -> list[Claim]:
        return self._sorted(Claim)

    def counted(self) -> list[Counted]:
        return self._sorted(Counted)

    def variants(self) -> dict:
        """Every study's method variants (``{name: {recipe, overrides}}``); one name declared two ways raises."""
        found: dict = {}
        for study in self.studies():
            for name, variant in study.variants.items():
                variant = {"recipe": variant["recipe"], "overrides": list(variant.get("overrides", []))}
                if found.setdefault(name, variant) != variant:
                    raise ValueError(f"variant {name!r} is declared as {found[name]} and, by {study.name}, as "
                                     f"{variant}")
        return found

    def names(self) -> dict:
        """Every study's names of methods in the claims (method -> name)."""
        return {method: name for study in self.studies() for method, name in study.names.items()}

    def discover(self) -> None:
        """Imports the ``claims`` module of every study that has one and is not imported yet
        (:data:`hierloco.pipeline.methods.STUDIES`: the recipe folders, the ``hierloco.studies`` entry points and the
        study folders named in this process); each adds its entries."""
        from hierloco.pipeline.methods import STUDIES

        for name in STUDIES.names():
            module = f"{STUDIES[name].package}.claims"
            if module not in sys.modules and importlib.util.find_spec(module) is not None:
                importlib.import_module(module)


CLAIMS = ClaimRegistry()


# --- the ledger: one entry per claim of the paper and robot -----------------------------------------------------------

@dataclass(frozen=True)
class Row:
    """One check shown under an entry of the ledger, and why it does not count toward it where it does not
    (``status``: ``""`` counted; ``"same test as section N"``, a repeat of a test an earlier section counts; or the
    claim's label for an extra, :attr:`Claim.extra`)."""

    check: Check
    status: str = ""

    @property
    def counted(self) -> bool:
        return not self.status


@dataclass(frozen=True)
class Entry:
    """One claim of the paper on one robot, the unit of the ledger's tally (``docs/claims.md``): its ``rows`` (the
    checks on that robot, each a part of the entry unless its status says otherwise), ``check`` the entry decided
    from the counted rows (:func:`entry_check`; ``None`` where it has none), ``section`` the claim's number on its
    page, and ``status`` where it has no check: ``"same test as section N"`` (every row repeats an earlier test: not
    counted again), or a claim with no test here (``"not testable here"``, ``"not measured yet"``)."""

    section: str
    claim: Claim
    robot: str
    rows: tuple[Row, ...] = ()
    check: Check | None = None
    status: str = ""

    @property
    def verdict(self) -> str:
        """The entry's verdict, or its status where it has no check."""
        return self.check.verdict if self.check is not None else self.status

    @property
    def counted(self) -> bool:
        """Whether the tally counts it: every entry but one whose every row repeats an earlier section's test."""
        return self.check is not None or self.status in (stats.NOT_TESTABLE, NOT_MEASURED_YET)


def entry_check(claim: str, robot: str, checks: list[Check]) -> Check:
    """One entry decided from its rows (its parts), as a multi-part check is (:func:`combined`, an
    intersection-union rule): it holds only when every row holds, does not hold when a row does not hold, is not
    testable when none is, and is inconclusive otherwise; rows not measured are left out (all of them: not measured).
    Its parts are every part of its rows, so its p-values (:func:`p_values`: for "holds" the largest p of its parts),
    the multiplicity correction, the verdict at the pre-planned seeds and under other thresholds are the entry's.

        >>> holds = decided("k", "c", "a1", "normal", "goal_reaching", "-", "-", [part("x", [0.1, 0.11, 0.12],
        ...                 [0.5, 0.52, 0.51], "better")])
        >>> refuted = decided("k", "c", "a1", "normal", "trajectory_tracking", "-", "-", [part("x", [0.5, 0.52, 0.51],
        ...                   [0.5, 0.51, 0.53], "better")])
        >>> entry_check("c", "a1", [holds]).verdict, entry_check("c", "a1", [holds, refuted]).verdict
        ('holds', 'does not hold')
    """
    live = [c for c in checks if c.verdict != NOT_MEASURED]
    verdict = combined([c.verdict for c in live]) if live else NOT_MEASURED
    tasks = ", ".join(dict.fromkeys(c.task for c in live))
    return Check("entry", claim, robot, "-", tasks, "-", "-", verdict, "", "", tuple(p for c in live for p in c.parts))


def comparisons(check: Check, configuration: Callable[[str], str] | None = None) -> set[tuple]:
    """What a check tests, one tuple per part: robot, setting, task, the configuration each side stands for
    (``configuration``: a side's name in the terms every source shares, :meth:`Source.configuration`), the kind of
    test, pairing and options. Two checks with the same tuples run the same test on the same configurations."""
    name = configuration or (lambda n: n)
    return {(check.robot, check.setting, check.task, name(p.names[0]), name(p.names[1]), p.kind, p.paired, p.options)
            for p in check.parts}


def ledger(claimed: list[tuple], configuration: Mapping[str, Callable] | None = None) -> list[Entry]:
    """The entries of one page, in its order: ``claimed`` is ``(section, claim, checks)`` per claim (a claim with no
    source, or no checks, gets one entry per robot of :attr:`Claim.robots` with its status, and a robot of
    :attr:`Claim.robots` its checks do not cover one "not measured yet"); ``configuration``:
    per source, the configuration each side's name stands for (:meth:`Source.configuration`). A check whose every
    comparison an earlier section's counted check already makes (:func:`comparisons`) is shown as "same test as
    section N" and not counted again; a check the claim does not count (:attr:`Claim.counted`) is shown as its
    extra; each robot's counted checks are its entry (:func:`entry_check`).

        >>> best = Claim(order=1, words="LAT is best", where="-", source="s", key="best", robots=("a1",))
        >>> again = Claim(order=2, words="LIB is worse than LAT", where="-", source="s", key="worse")
        >>> lat, lib = [0.1, 0.11, 0.12], [0.5, 0.52, 0.51]
        >>> check = lambda key: decided(key, key, "a1", "normal", "velocity_tracking", "-", "-",
        ...                             [part("lat vs lib", lat, lib, "better", names=("lat:normal", "lib:normal"))])
        >>> [(e.section, e.verdict, e.counted) for e in ledger([("1", best, [check("best")]),
        ...                                                     ("2", again, [check("worse")])])]
        [('1', 'holds', True), ('2', 'same test as section 1', False), ('2', 'not measured yet', True)]
    """
    configuration = dict(configuration or {})
    seen: dict[tuple, str] = {}
    order = [section for section, *_ in claimed]
    entries = []
    for section, claim, checks in claimed:
        if not claim.source or not checks:
            status = claim.status if not claim.source else NOT_MEASURED_YET
            entries += [Entry(section, claim, robot, status=status) for robot in claim.robots]
            continue
        name = configuration.get(claim.source)
        rows = []
        for check in checks:
            tested = comparisons(check, name)
            if claim.counted is not None and not claim.counted(check):
                rows.append(Row(check, claim.extra or EXTRA))
            elif tested and tested <= set(seen):
                earlier = ", ".join(sorted({seen[t] for t in tested}, key=order.index))
                rows.append(Row(check, f"same test as section {earlier}"))
            else:
                rows.append(Row(check))
        for row in rows:
            for tested in (comparisons(row.check, name) if row.counted else ()):
                seen.setdefault(tested, section)
        for robot in dict.fromkeys(c.robot for c in checks):
            mine = tuple(r for r in rows if r.check.robot == robot)
            counted = [r.check for r in mine if r.counted]
            repeats = sorted({r.status for r in mine if r.status.startswith("same test")})
            entries.append(Entry(section, claim, robot, mine, entry_check(claim.words, robot, counted) if counted
                                 else None, "" if counted else "; ".join(repeats) or EXTRA))
        measured = {c.robot for c in checks}
        entries += [Entry(section, claim, robot, status=NOT_MEASURED_YET) for robot in claim.robots
                    if robot not in measured]  # a robot its source has no runs of yet
    return entries


def entry_counts(entries: list[Entry]) -> dict[str, int]:
    """How many counted entries got each verdict (:data:`hierloco.stats.VERDICTS`, then "not measured yet")."""
    counted = [e for e in entries if e.counted]
    tally = {v: sum(e.verdict == v for e in counted) for v in stats.VERDICTS}
    tally[NOT_MEASURED_YET] = sum(e.verdict in (NOT_MEASURED, NOT_MEASURED_YET) for e in counted)
    return tally



# --- the evidence --------------------------------------------------------------------------------------------------

@dataclass
class Evidence:
    """What the registered studies hold under ``results``: each study's runs (``runs[name]``), its findings (jobs
    not evaluable), its stages' reports (``reports[name][stage]``), its rows of its own (``rows[name]``) and, for
    rows made from records (:attr:`Study.rows_from`), the records that lack what they need (``incomplete[name]``,
    their folders: a claim read from such rows is not measured yet), where each was read from (``sources``), the
    archived tables' runs, the compute of a study without records (``compute_tables[name]``: ``(method, robot) ->
    minutes per job``), and the studies themselves."""

    results: Path
    studies: tuple[Study, ...] = ()
    runs: dict[str, list[Run]] = field(default_factory=dict)
    findings: dict[str, list[dict]] = field(default_factory=dict)
    reports: dict[str, dict[str, list[dict]]] = field(default_factory=dict)
    rows: dict[str, list[dict]] = field(default_factory=dict)
    incomplete: dict[str, list[str]] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    archived: list[Run] = field(default_factory=list)
    compute_tables: dict[str, dict] = field(default_factory=dict)


def locate(results: Path, relative: str) -> Path | None:
    """``results/<relative>``, or the same under ``results/archive/``, or ``None``."""
    for base in (results, results / "archive"):
        if (base / relative).exists():
            return base / relative
    return None


def _shown(path: Path, results: Path) -> str:
    try:
        return (Path(results.name) / path.relative_to(results)).as_posix()
    except ValueError:
        return path.as_posix()


def _wallclock(path: Path) -> dict:
    """``(method, robot) -> minutes per job`` from a study's ``wallclock.md`` (for a study without records)."""
    table = {}
    if path.is_file():
        for match in re.finditer(r"^\| (\w+) \| (\w+) \| \d+ \| ([\d.]+) \| [\d.]+ \|$", path.read_text(), re.M):
            table[(match[1], match[2])] = float(match[3])
    return table


def load(results, names: Mapping | None = None, *, registry: ClaimRegistry | None = None) -> Evidence:
    """Reads every registered study (:meth:`ClaimRegistry.discover` first) and its archived tables under
    ``results``, each run's method under its name in the claims (``names``: method -> name; default the studies'
    :attr:`Study.names`)."""
    from hierloco.results import read_csv

    registry = CLAIMS if registry is None else registry
    registry.discover()
    results = Path(results)
    studies = tuple(registry.studies())
    variants = registry.variants()
    evidence = Evidence(results, studies)
    names = registry.names() if names is None else dict(names)
    for study in studies:
        found = next((p for p in (locate(results, r) for r in study.records) if p is not None), None)
        if study.rows_from is not None:
            if found is not None:
                rows, evidence.incomplete[study.name] = study.rows_from(found)
                evidence.rows[study.name] = [{**row, "robot": study.robot} if study.robot else row for row in rows]
                evidence.sources[study.name] = _shown(found, results) + study.rows_note
        elif study.rows:
            if (table := locate(results, study.rows)) is not None:
                evidence.rows[study.name] = [{**row, "robot": study.robot} for row in read_csv(table)]
                evidence.sources[study.name] = _shown(table, results) + study.rows_note
        elif found is not None:
            evidence.runs[study.name] = [r for r in read_records(found, folder=study.name, variants=variants)
                                         if not study.robot or r.robot == study.robot]
            evidence.findings[study.name] = read_findings(found, variants=variants)
            evidence.sources[study.name] = _shown(found, results)
            for stage in study.reports:
                evidence.reports.setdefault(study.name, {})[stage] = read_stage_reports(found, stage,
                                                                                        variants=variants)
        elif study.table and (table := locate(results, study.table)) is not None:
            evidence.runs[study.name] = [r for r in read_table(table, folder=study.name)
                                         if not study.robot or r.robot == study.robot]
            evidence.findings[study.name] = []
            evidence.sources[study.name] = _shown(table, results) + " (a table: no records)"
            if (clock := locate(results, f"{study.name}/wallclock.md")) is not None:
                evidence.compute_tables[study.name] = _wallclock(clock)
    for study in studies:
        reference = evidence.runs.get(study.name, [])
        for name in study.archived:
            table = locate(results, f"{name}/comparison.csv")
            if table is not None:
                evidence.archived += adopt_configs(read_table(table, folder=name), reference)
                evidence.sources[name] = (_shown(table, results) + f" (archived table: same configuration as "
                                          f"{study.name})")
    if names:
        evidence.runs = {study: [replace(r, method=names.get(r.method, r.method)) for r in runs]
                         for study, runs in evidence.runs.items()}
        evidence.archived = [replace(r, method=names.get(r.method, r.method)) for r in evidence.archived]
    return evidence


__all__ = ["CLAIMS", "Cause", "Check", "Claim", "ClaimRegistry", "Counted", "EXTRA", "Entry", "Evidence",
           "NOT_MEASURED", "NOT_MEASURED_YET", "PAPER_PAGE", "Part", "ROBOTS", "Row", "SANITY_PAGE", "comparisons",
           "entry_check", "entry_counts", "ledger",
           "PLANNED_SEEDS", "combined", "corrected", "counts_line_of", "deciding_p", "is_borderline", "p_values",
           "planned", "redecided", "verdict_text",
           "Source", "Study", "TASKS", "UNDECIDED", "checks_markdown", "counts_line", "decided", "describe",
           "folders_of", "job_minutes", "load", "load_causes", "locate", "part", "seed_costs", "seed_means"]
