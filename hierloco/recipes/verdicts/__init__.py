"""Verdicts on the paper's claims, from the committed job records: each study's, the whole paper's, the fragile ones.

    hierloco verdicts                  # writes the files below under results/
    hierloco verdicts --check          # exit 1 (naming them) if any file is not what the records give

A generic aggregator: it knows no study by name. Each study declares in its own ``claims.py`` where its runs are, the
checks of its page, the sets of checks the paper's claims are decided from and the claims themselves
(:mod:`hierloco.claims`, ``docs/claims.md``); this command reads every registered study's job records
(:func:`hierloco.claims.load`), decides each claim with the tests of :mod:`hierloco.stats` (``docs/statistics.md``)
and writes:

- ``<study>/verdicts.md`` for each study with checks of its own: that study's own runs only;
- ``paper_check.md``: the ledger of every registered claim of the paper (Li et al., RA-L 2021), one entry per claim
  and robot (:func:`hierloco.claims.ledger`, ``docs/claims.md``): where the paper makes it, the numbers it states
  (with robot and figure), each entry's verdict combined from its rows, and every row (ours: one number per
  configuration, with the folders its runs come from; the test; whether it counts: a repeat of an earlier section's
  test or an extra does not); claims nothing measures yet are named with the study they need;
- ``sanity_checks.md``: the claims declared on :data:`hierloco.claims.SANITY_PAGE` (checks that only show the set-up
  behaves), rendered alike and not counted in the ledger;
- ``fragile_claims.md``: every claim that is inconclusive, or whose verdict differs between the project's runs of
  the same configuration, with the seeds a power estimate asks for and the compute they take (``builds.json``),
  and every configuration that gave different numbers when run again.

Example (on a copy of the results, writing elsewhere):
    >>> from pathlib import Path
    >>> evidence = load(Path("results"))             # doctest: +SKIP
    >>> write_all(evidence, Path("/tmp/verdicts"))    # doctest: +SKIP
"""

from __future__ import annotations

import math
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hierloco import stats
from hierloco.claims import (CLAIMS, NOT_MEASURED, NOT_MEASURED_YET, PAPER_PAGE, PLANNED_SEEDS, SANITY_PAGE, Check,
                             ClaimRegistry, Entry, Evidence, Source, Study, checks_markdown, corrected, counts_line,
                             counts_line_of, entry_counts, is_borderline, ledger, load, locate, planned, redecided,
                             seed_costs, verdict_text)
from hierloco.evidence import Run, replicates
from hierloco.io import write_text

COMMAND = "hierloco verdicts"


# --- the checks ----------------------------------------------------------------------------------------------------

def study_checks(evidence: Evidence) -> dict[str, list[Check]]:
    """Each study's checks on its own runs (the studies with runs or rows and a page: :attr:`Study.checks`)."""
    out = {}
    for study in evidence.studies:
        if study.checks is not None and (study.name in evidence.runs or study.name in evidence.rows):
            found = study.checks(evidence)
            if found is not None:
                out[study.name] = found
    return out


def paper_checks(evidence: Evidence, registry: ClaimRegistry = CLAIMS) -> dict[str, list[Check]]:
    """Each registered source's checks (:attr:`Source.checks`), the paper's claims are decided from."""
    return {source.name: source.checks(evidence) for source in registry.sources()}


def paper_claims(checks: dict[str, list[Check]], registry: ClaimRegistry = CLAIMS) -> list[tuple]:
    """Each registered claim that something here measures, in the paper's order, with the checks that decide it:
    ``(number, claim, checks)``, numbered on its page (``paper_check.md``: 1, 2, ...; ``sanity_checks.md``: S1,
    S2, ...)."""
    out, counters = [], {}
    for claim in (c for c in registry.claims() if c.source):
        counters[claim.page] = counters.get(claim.page, 0) + 1
        prefix = "" if claim.page == PAPER_PAGE else "S"
        out.append((f"{prefix}{counters[claim.page]}", claim, claim.chosen(checks)))
    return out


# --- pages ---------------------------------------------------------------------------------------------------------

CRITERIA = (f"Each claim is decided by a test over seeds (`docs/statistics.md`; `hierloco.stats`), alpha = "
            f"{stats.ALPHA}, d the difference of the means (better: the cost saved) with its "
            f"{1 - 2 * stats.ALPHA:.0%} interval. The rule, exactly: \"better\" **holds** when the one-sided Welch t "
            f"(paired by seed where both sides are the same seed's runs) of d > 0 gives p < alpha (the interval's "
            f"lower end above 0) **and** the point estimate d is at least the minimum effect delta = max("
            f"{stats.MIN_EFFECT_REL:.0%} of the other's mean cost, {stats.MIN_EFFECT_ABS}); it **does not hold** when "
            f"the one-sided test of d < delta gives p < alpha / comparisons (refuting p, below). The rule is not "
            f"symmetric: holding asks for significance against 0 and a point estimate at or above delta, not "
            f"significance against delta, so a verdict of \"holds\" does not mean \"lower by at least delta\"; a gain "
            f"whose interval straddles delta is inconclusive. \"close\" (TOST) **holds** when the interval of d lies "
            f"inside (-m, m), m = max({stats.EQUIV_MARGIN_REL:.0%} of the reference's mean cost, "
            f"{stats.EQUIV_MARGIN_ABS}), and **does not hold** when the 1 - alpha / comparisons interval lies wholly "
            f"outside [-m, m], either way. A comparison of methods all at {stats.NOT_TESTABLE_COST} of standing "
            f"still's cost or worse is not testable here; a claim neither established nor refuted is inconclusive at "
            f"this many seeds. A claim of several comparisons holds when each does (p: the largest), and does not "
            f"hold when one is refuted at alpha / comparisons (refuting p: the smallest times the comparisons). Beside "
            f"each verdict: the p that decided it, \"borderline\" where it lies in [{stats.BORDERLINE[0]}, "
            f"{stats.ALPHA}) or the multiplicity correction changes it, the verdict after Holm's correction over its "
            f"family (establishing and refuting p-values adjusted separately; a verdict that does not survive becomes "
            f"inconclusive), and the verdict at the pre-planned {PLANNED_SEEDS} seeds (0-2) where seeds were added "
            f"after a look.")


def _generated(source: str) -> str:
    return (f"Generated by `{COMMAND}` from {source}; do not edit, run it again. {CRITERIA}")


def study_page(study: Study, checks: list[Check], evidence: Evidence) -> str:
    """``<study>/verdicts.md``: the study's claims on its own runs, with the causes we checked (its
    ``causes.yaml``, where it keeps causes: :attr:`Study.causes`)."""
    name = study.name
    causes = []
    if study.causes is not None and (path := locate(evidence.results, f"{name}/causes.yaml")) is not None:
        causes = study.causes(path)
    body = checks_markdown(checks, title="x", causes=causes, criteria="", paper_column=study.paper_column,
                           with_causes=study.causes is not None, family=True)
    table = body[body.index("| claim |"):]
    findings = evidence.findings.get(name, [])
    note = (f"\n{len(findings)} jobs ended in a finding about their setting (not evaluable; their claims are not "
            f"testable here): " + "; ".join(sorted({f"{f['method']} on {f['robot']} ({f['profile']}) "
                                                    f"{f['settings']}" for f in findings})) + ".\n"
            if findings else "")
    return (f"# Verdicts: {name}\n\nThe study: `{study.command}`. {_generated('`' + evidence.sources[name] + '`')} "
            f"Numbers: mean +- std over seeds of each seed's mean normalised cost (a fallen robot's cost counts as "
            f"1). The family of Holm's correction: this page's checks.\n\n**{counts_line(checks)}** (after Holm's "
            f"correction: {counts_line_of(corrected(checks))}).\n{note}\n{table}")


def _values_text(values, n_folders: str) -> str:
    return f"{np.mean(values):.3f} (n={len(values)}; {n_folders})"


def ours_text(check: Check, folders: dict | None = None, folder: str = "") -> str:
    """One number per configuration of the check's comparisons: its mean over seeds, the seeds, and the folders
    its runs come from (``folders``: ``(method, robot, setting, task) -> folders``, for pooled runs, each side named
    ``"<method>:<setting>"``; else ``folder``)."""
    seen, parts = set(), []
    for part in check.parts:
        for name, values in zip(part.names, (part.a, part.b)):
            if name in seen or np.ndim(values) == 0:
                continue
            seen.add(name)
            where = folder
            if folders is not None:
                method, _, rest = name.partition(":")
                setting = rest.split(":")[0] if rest else check.setting
                setting = "normal" if setting in ("training", "held-out") else setting
                where = ", ".join(sorted(folders.get((method, check.robot, setting, check.task), ()))) or "?"
            parts.append(f"{name} {_values_text(values, where)}")
    return "; ".join(parts) if parts else check.ours


def page_entries(checks: dict[str, list[Check]], page: str, registry: ClaimRegistry = CLAIMS) -> list[Entry]:
    """The entries of one page (:data:`hierloco.claims.PAPER_PAGE` or :data:`hierloco.claims.SANITY_PAGE`;
    :func:`hierloco.claims.ledger`): its claims that something here measures, numbered in the paper's order (the
    sanity checks ``S1``, ``S2``, ...), then the paper's claims with no test here."""
    numbered = [claimed for claimed in paper_claims(checks, registry) if claimed[1].page == page]
    untested = [("", claim, []) for claim in registry.claims() if not claim.source and claim.page == page]
    sources = {source.name: source.configuration for source in registry.sources()}
    return ledger(numbered + untested, sources)


def _entry_text(entry: Entry, fixed: str) -> str:
    if entry.check is None:
        return f"{entry.status} (not counted again)" if entry.status.startswith("same test") else entry.status
    return verdict_text(entry.check, fixed, bold=True)


def _section(number: str, claim, entries: list[Entry], evidence: Evidence, checks: dict, sources: dict,
             folders: dict) -> tuple[list[str], list[str]]:
    """One claim's section: its entries (one per robot) with their verdicts, then every row (the evidence); and the
    entries' verdicts after Holm's correction over the claim's entries. A claim its source has no check of is "not
    measured yet", with what it needs (:attr:`hierloco.claims.Claim.needs`, else the study it needs)."""
    lines = [f"## {number}. {claim.words}\n\n{claim.where}. The paper's numbers: {claim.paper}.\n"]
    rows = [row for entry in entries for row in entry.rows]
    if not rows:
        needs = claim.needs or f"no runs of the study it needs: `{claim.source}`"
        lines.append(f"**not measured yet** ({needs}).\n")
        return lines, []
    decided_ = [e for e in entries if e.check is not None]
    holm = dict(zip(map(id, decided_), corrected([e.check for e in decided_])))
    fixed = [holm.get(id(e), e.verdict) for e in decided_]
    again = [e for e in entries if not e.counted]
    verdicts = (f"Verdicts (entries, one per robot): {counts_line([e.check for e in decided_])} (after Holm's "
                f"correction over this claim's {len(decided_)} entries: {counts_line_of(fixed)})." if decided_ else
                "Verdicts (entries, one per robot): none counted here.")
    lines.append(verdicts + (f" Not counted again: {', '.join(e.robot for e in again)} (every row is a test an "
                             f"earlier section counts: {'; '.join(dict.fromkeys(e.status for e in again))})."
                             if again else "") + "\n")
    lines.append(f"| entry | verdict (the rows counted, combined) | Holm (family: this claim's entries) | at seeds "
                 f"0-{PLANNED_SEEDS - 1} | rows counted |")
    lines.append("|---|---|---|---|---|")
    for entry in entries:
        counted = sum(r.counted for r in entry.rows)
        if entry.check is None:
            lines.append(f"| {entry.robot} | {_entry_text(entry, '')} | - | - | 0 of {len(entry.rows)} |")
            continue
        lines.append(f"| {entry.robot} | {_entry_text(entry, holm[id(entry)])} | {holm[id(entry)]} | "
                     f"{planned(entry.check) or 'same seeds'} | {counted} of {len(entry.rows)} |")
    source = sources[claim.source]
    if source.folders is not None and claim.source not in folders:
        folders[claim.source] = source.folders(evidence)
    row_holm = corrected([r.check for r in rows])
    lines.append("\nThe rows (the evidence: each entry's parts):\n")
    lines.append("| robot | setting | task | claim tested | ours (per configuration) | test | counts toward the "
                 "entry | verdict | Holm (family: this claim's rows, as before) | at seeds "
                 f"0-{PLANNED_SEEDS - 1} | folder |")
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for row, fixed_row in zip(rows, row_holm):
        check = row.check
        folder = source.folder_of(check)
        ours = ours_text(check, folders[claim.source]) if source.folders is not None else \
            ours_text(check, folder=folder)
        if "goals reached" in check.ours:   # what follows the cost: the goals reached, and in how many steps
            ours += check.ours[check.ours.index(";"):]
        lines.append(f"| {check.robot} | {check.setting} | {check.task} | {check.claim} | {ours} | "
                     f"{check.detail or '-'} | {'yes' if row.counted else row.status} | "
                     f"{verdict_text(check, fixed_row, bold=True)} | {fixed_row} | "
                     f"{planned(check) or 'same seeds'} | {folder} |")
    if claim.note is not None and (note := claim.note(checks)):
        lines.append(note)
    lines.append("")
    return lines, fixed


ENTRY_RULE = ("An entry is one claim of the paper on one robot; its rows are its parts (tasks, settings, methods "
              "compared). It **holds** only when every part counted in it holds, **does not hold** when a part does "
              "not hold, is not testable here when no part is, and is **inconclusive** otherwise (an "
              "intersection-union rule, as for a claim of several comparisons); beside it its p: for \"holds\" the "
              "largest p of its parts, for \"does not hold\" the smallest refuting p (times the comparisons it is "
              "refuted among). A row whose every comparison (the same configurations on each side, the same test) "
              "an earlier section already counts is shown, marked \"same test as section N\", and not counted again "
              "(its numbers may differ a little where the earlier section pools more runs of the same "
              "configurations); "
              "a row a claim does not count (an extra, the label says why) is shown and not counted. Holm's "
              "correction runs over each claim's entries (the family: one numbered claim's entries, one per robot), "
              "establishing and refuting p-values adjusted separately.")


def ledger_page(evidence: Evidence, checks: dict[str, list[Check]], page: str = PAPER_PAGE,
                registry: ClaimRegistry = CLAIMS) -> str:
    """``paper_check.md`` (``page``: :data:`hierloco.claims.PAPER_PAGE`): every registered claim of the paper as
    entries, one per robot (:func:`page_entries`), each with its rows, the claims with no test here, the statements
    counted rather than tested and the tally's sensitivity; or ``sanity_checks.md``
    (:data:`hierloco.claims.SANITY_PAGE`): the sanity checks, rendered alike."""
    sources = {source.name: source for source in registry.sources()}
    notes = "".join(f"{source.note} " for source in sources.values() if source.note)
    paper = page == PAPER_PAGE
    records = _generated('the job records of ' + ', '.join(f'`{v}`' for v in evidence.sources.values()))
    if paper:
        lines = ["# The paper's claims, judged with statistics\n",
                 "Li, Calandra, Pathak, Tian, Meier, Rai, *Planning in Learned Latent Action Spaces for "
                 "Generalizable Legged Locomotion*, RA-L 2021: every claim its text and figures make (figures "
                 "numbered in the order of the paper's source), the numbers it states with their robot and figure "
                 "(its normalisation is not ours: orderings and ratios compare, absolute values do not), ours, the "
                 "test and the verdict, one entry per claim and robot.",
                 f"\n{records}\n"]
    else:
        lines = ["# Sanity checks: the set-up behaves as it should\n",
                 "Checks that only show the set-up behaves (damage hurts a controller; a method walks better than "
                 "standing still), not a claim of the paper's results, so they are not counted in the ledger of "
                 "[`paper_check.md`](paper_check.md); decided and shown as its claims are.",
                 f"\n{records}\n"]
    lines.append("**Ours**: per configuration, the mean over seeds of each seed's mean normalised cost, the number of "
                 f"seeds and the folders under `results/` its runs come from. {notes}Each study's verdicts on its own "
                 f"runs: `<study>/verdicts.md`. {ENTRY_RULE}\n")
    entries = page_entries(checks, page, registry)
    folders: dict = {}
    fixed_all: list[str] = []
    for number in dict.fromkeys(e.section for e in entries if e.section):
        mine = [e for e in entries if e.section == number]
        found, fixed = _section(number, mine[0].claim, mine, evidence, checks, sources, folders)
        lines += found
        fixed_all += fixed
    untested = [e for e in entries if not e.section]
    if paper:
        claims = list(dict.fromkeys(e.claim for e in untested))
        lines.append("## Claims not measured yet, or not testable here\n")
        lines.append("Each counted as one entry per robot it is about, with this verdict.\n")
        lines.append("| claim | where | verdict | why; what it needs | entries (robots) |")
        lines.append("|---|---|---|---|---|")
        lines += [f"| {c.words} | {c.where} | {c.status} | {c.needs} | {', '.join(c.robots)} |" for c in claims]
        counted = [(statement, found) for statement in registry.counted() if (found := statement.count(evidence))]
        if counted:
            lines.append("\n## Statements about the design, counted rather than tested\n")
            lines += [statement.words + "; ".join(found) + "." for statement, found in counted]
        lines.append("")
    tested = [e for e in entries if e.check is not None]
    if paper:
        lines += sensitivity(evidence, [e.check for e in tested], unit="entries")
    tally = entry_counts(entries)
    no_test = [e for e in entries if e.counted and e.check is None]
    borderline = sum(is_borderline(e.check, h) for e, h in zip(tested, fixed_all))
    later = [(e.check, v) for e in tested if (v := planned(e.check)) is not None]
    repeated = sum(1 for e in entries if e.section and not e.counted)
    names = {stats.HOLDS: "hold", stats.DOES_NOT_HOLD: "do not hold", stats.INCONCLUSIVE: "inconclusive",
             stats.NOT_TESTABLE: "not testable here", NOT_MEASURED_YET: "not measured yet"}
    whole = ", ".join(f"{n} {names[v]}" for v, n in tally.items() if n or v != NOT_MEASURED_YET)
    head = (f"**{'The ledger' if paper else 'The sanity checks'}: {sum(tally.values())} entries, one per "
            f"{'claim of the paper' if paper else 'check'} and robot: {whole}**"
            + (f" ({len(tested)} with a test: {counts_line([e.check for e in tested])}; {len(no_test)} with no test "
               f"here, listed below)" if no_test else "") + ". "
            f"**After Holm's correction within each claim** (the family: one numbered claim's entries, one per "
            f"robot): {counts_line_of(fixed_all)}. {borderline} entry verdicts are borderline. At the pre-planned "
            f"{PLANNED_SEEDS} seeds (seeds 0-{PLANNED_SEEDS - 1}; the {len(later)} entries with a side run on more "
            f"seeds, added where verdicts looked fragile: optional stopping), {sum(c.verdict != v for c, v in later)} "
            f"entry verdicts differ from the final ones."
            + (f" {repeated} entries repeat an earlier section's tests and are not counted again." if repeated else ""))
    if paper:
        rows = [(claim, chosen) for _, claim, chosen in paper_claims(checks, registry)]
        every = [c for _, chosen in rows for c in chosen]
        holm_rows = [v for _, chosen in rows for v in corrected(chosen)]
        sanity = [c for c in registry.claims() if c.source and c.page == SANITY_PAGE]
        head += (f" Per row, as before (every row of every section, the sanity checks, the repeated tests and the "
                 f"extras included): {counts_line(every)}; after Holm's correction within each claim's rows "
                 f"{counts_line_of(holm_rows)}.")
        questions = "; ".join(study.questions for study in registry.studies() if study.questions)
        if sanity:
            head += (f"\n\nSanity checks ({len(sanity)}: "
                     + "; ".join(f"S{i}. {c.words}" for i, c in enumerate(sanity, 1))
                     + ") show only that the set-up behaves, not a result of the paper: they are on "
                       "[`sanity_checks.md`](sanity_checks.md), not counted here.")
        head += (" The studies' own questions" + (f" ({questions})" if questions else "")
                 + " are decided on each study's `verdicts.md` only, not counted here.")
    lines.insert(4, head + "\n")
    return "\n".join(lines) + "\n"


def paper_page(evidence: Evidence, checks: dict[str, list[Check]], registry: ClaimRegistry = CLAIMS) -> str:
    """``paper_check.md`` (:func:`ledger_page`)."""
    return ledger_page(evidence, checks, PAPER_PAGE, registry)


def sanity_page(evidence: Evidence, checks: dict[str, list[Check]], registry: ClaimRegistry = CLAIMS) -> str:
    """``sanity_checks.md`` (:func:`ledger_page`)."""
    return ledger_page(evidence, checks, SANITY_PAGE, registry)


# --- how the tally depends on the thresholds -------------------------------------------------------------------------

def noise(evidence: Evidence, task: str = "trajectory_tracking", walks: float = 0.1) -> list[float]:
    """The seed-to-seed standard deviations (ddof 1) of the per-seed costs of every configuration (method, robot,
    setting) on ``task`` with 3 or more seeds and a mean cost below ``walks`` (the methods that walk it)."""
    runs = [r for found in evidence.runs.values() for r in found if r.task == task]
    out = []
    for method, robot, setting in sorted({(r.method, r.robot, r.setting) for r in runs}):
        values = seed_costs(runs, method=method, robot=robot, setting=setting, task=task)
        if len(values) >= 3 and values.mean() < walks:
            out.append(float(values.std(ddof=1)))
    return out


def sensitivity(evidence: Evidence, checks: list[Check], unit: str = "checks") -> list[str]:
    """The section of ``paper_check.md`` on how the tally of ``checks`` depends on the minimum effect, the margin and
    the 0.01 floor, and on the multiplicity correction's family, with the measured noise the floor is set against."""
    def row(name, verdicts):
        return f"| {name} | " + " | ".join(str(sum(v == k for v in verdicts)) for k in stats.VERDICTS) + " |"

    spread = noise(evidence)
    lines = ["## How the tally depends on the thresholds\n",
             f"The same {unit} decided again with other thresholds (a comparison's own thresholds, where it states "
             "them, kept), and with the multiplicity correction over other families.\n",
             "| rule | " + " | ".join(stats.VERDICTS) + " |", "|---|---|---|---|---|",
             row(f"as decided (min effect {stats.MIN_EFFECT_REL:.0%}, margin {stats.EQUIV_MARGIN_REL:.0%}, floor "
                 f"{stats.MIN_EFFECT_ABS})", [c.verdict for c in checks]),
             row("no floor (relative criteria only)", [redecided(c, min_effect_abs=0.0, margin_abs=0.0)
                                                      for c in checks])]
    lines += [row(f"min effect {rel:.0%}", [redecided(c, min_effect_rel=rel) for c in checks]) for rel in (0.05, 0.2)]
    lines += [row(f"margin {rel:.0%}", [redecided(c, margin_rel=rel) for c in checks]) for rel in (0.1, 0.4)]
    single = "check" if unit == "checks" else "checked entry"
    lines += [row(f"Holm over every {single} of the page (one family)", corrected(checks)),
              row(f"Benjamini-Hochberg over every {single} of the page",
                  corrected(checks, adjust=stats.benjamini_hochberg))]
    if spread:
        lines.append(f"\n**The floor against the noise.** The seed-to-seed standard deviation of the "
                     f"trajectory-tracking cost of the {len(spread)} configurations that walk it (mean cost below "
                     f"0.1, 3 or more seeds): median {np.median(spread):.4f}, largest {max(spread):.4f}. The floor "
                     f"{stats.MIN_EFFECT_ABS} is "
                     f"kept: it is at or above the largest of them, so a difference below it is within one seed's "
                     f"spread of the noisiest configuration; without it (the row above) the saturated "
                     f"trajectory-tracking costs are decided on differences smaller than that.")
    return lines + [""]


# --- fragile claims ------------------------------------------------------------------------------------------------

def _identity(check: Check) -> tuple:
    return check.key, check.robot, check.setting, check.task, tuple(p.label for p in check.parts)


@dataclass
class Need:
    """The seeds that would decide a check: ``needed`` per method (``None`` when no count up to 100 reaches the
    power, or when ``spread_unknown``: a side measured on one seed, so no power can be estimated), ``sides`` the
    configurations compared with their seeds now, ``(name, seeds)``; ``study`` where its runs are (as its source
    names them, :meth:`hierloco.claims.Source.study_of`), ``source`` the source whose jobs more seeds run,
    ``section`` whether it is a claim of the paper or a study's own question, and why it is listed."""

    check: Check
    study: str
    needed: int | None
    sides: list = field(default_factory=list)
    reason: str = ""
    section: str = "paper"
    spread_unknown: bool = False
    source: Source | None = None


def power_options(options) -> dict:
    """The options of a part's decision that its power depends on (thresholds and alpha; not, say, the
    ``not_testable`` level, which decides whether it is testable at all)."""
    import inspect

    accepted = set(inspect.signature(stats.power).parameters) - {"a", "b", "n", "kind", "paired"}
    return {key: value for key, value in dict(options).items() if key in accepted}


def seeds_for(check: Check, study: str, reason: str, section: str = "paper", source: Source | None = None) -> Need:
    """How many seeds per method would decide ``check`` (:func:`hierloco.stats.seeds_needed`, the measured means
    and spreads taken as the truth): each comparison not yet decided (all of them when the verdict differs between
    runs), the fewest seeds for a comparison pointing to a refutation, else the most any comparison needs."""
    undecided = [p for p in check.parts if p.decision.verdict == stats.INCONCLUSIVE] or list(check.parts)
    undecided = [p for p in undecided if p.decision.verdict != stats.NOT_TESTABLE]
    counts, refuting = [], []
    sides = []
    for part in undecided:
        for name, values in zip(part.names, (part.a, part.b)):
            if np.ndim(values) and name not in [s[0] for s in sides]:
                sides.append((name, len(values)))
    if any(np.ndim(v) and len(v) < 2 for part in undecided for v in (part.a, part.b)):
        return Need(check, study, None, sides, reason, section, spread_unknown=True, source=source)
    for part in undecided:
        n = stats.seeds_needed(part.a, part.b, kind=part.kind, paired=part.paired, **power_options(part.options))
        counts.append(n)
        d, threshold = part.decision.estimate, part.decision.threshold
        if (part.kind == "better" and d < threshold) or (part.kind == "close" and abs(d) > threshold):
            refuting.append(n)
    if any(n is not None for n in refuting):
        needed = min(n for n in refuting if n is not None)
    elif counts and all(n is not None for n in counts):
        needed = max(counts)
    else:
        needed = None
    return Need(check, study, needed, sides, reason, section, source=source)


def job_of(evidence: Evidence, need: Need, side: str) -> tuple[tuple | None, str, list[float]]:
    """The job a new seed of configuration ``side`` (a side of the need's comparison) runs, as its source says
    (:meth:`hierloco.claims.Source.job_of`): ``(key, words, minutes of each such job recorded)``; ``key`` is
    ``None`` for a side that needs no job (standing still)."""
    if side == "standing still":
        return None, "-", []
    return need.source.job_of(evidence, need.check.robot, side)


def fragile(evidence: Evidence, checks: dict[str, list[Check]],
            registry: ClaimRegistry = CLAIMS) -> tuple[list[Need], dict]:
    """The fragile claims, each with its :class:`Need`: the paper's claims (:func:`paper_claims`) that are
    inconclusive, or decided differently by the project's sets of runs of the same configurations
    (:attr:`hierloco.claims.Source.sets`); then the studies' own questions (:attr:`hierloco.claims.Source.questions`)
    that are inconclusive. Also returns the verdicts per set of runs where they differ."""
    sources = {source.name: source for source in registry.sources()}
    needs, differ, listed = [], {}, set()
    table = defaultdict(dict)
    for source in sources.values():
        for name, found in (source.sets(evidence) if source.sets is not None else {}).items():
            for check in found:
                table[(source.name, _identity(check))][name] = check.verdict
    for _, claim, chosen in paper_claims(checks, registry):
        source = sources[claim.source]
        for check in chosen:
            study = source.study_of(check)
            measured = {k: v for k, v in table.get((source.name, _identity(check)), {}).items() if v != NOT_MEASURED}
            if source.sets is not None and len(set(measured.values())) > 1:
                differ[_identity(check)] = measured
                needs.append(seeds_for(check, study, "differs", source=source))
            elif check.verdict == stats.INCONCLUSIVE:
                needs.append(seeds_for(check, study, "inconclusive", source=source))
            listed.add(id(check))
    for source in sources.values():
        if source.questions is None:
            continue
        for check in checks.get(source.name, []):
            if id(check) not in listed and source.questions(check) and check.verdict == stats.INCONCLUSIVE:
                needs.append(seeds_for(check, source.study_of(check), "inconclusive", section="study",
                                       source=source))
    return needs, differ


def _seeds_text(need: Need) -> str:
    if need.spread_unknown:
        return "unknown (a side has one seed: no spread measured)"
    return "more than 100" if need.needed is None else f"{need.needed} per method"


def sections(registry: ClaimRegistry = CLAIMS) -> dict[str, str]:
    """The sections of ``fragile_claims.md``: the paper's claims, and the studies' own questions (each study's
    :attr:`hierloco.claims.Study.questions`)."""
    questions = "; ".join(study.questions for study in registry.studies() if study.questions)
    return {"paper": "The paper's claims",
            "study": "The studies' own questions" + (f" ({questions})" if questions else "")}


def fragile_page(evidence: Evidence, checks: dict[str, list[Check]], registry: ClaimRegistry = CLAIMS) -> str:
    """``fragile_claims.md``."""
    needs, differ = fragile(evidence, checks, registry)
    pooling = "".join(f" {source.pooling}" for source in registry.sources() if source.pooling)
    lines = ["# Fragile claims: inconclusive, or decided differently by runs of the same configuration\n",
             _generated("the job records of " + ", ".join(f"`{v}`" for v in evidence.sources.values())) + "\n",
             "## How runs of one configuration are pooled\n",
             "A configuration is what a run's evaluation stage key names (the stage keys in the record: every stage's "
             "parameters, the robot's fingerprint and the seed). Runs with the same key are the same job run again "
             "(another study, session or machine); on another CPU the floating-point differences grow, in a closed "
             "loop, into other numbers (below). They are samples of the same configuration and seed, so they are "
             "pooled as such (`hierloco.evidence.seed_values`): each run's mean over its episodes, then each seed's "
             "mean over its distinct runs (a run found twice, say a record and a table made from it, counts once), "
             "and the test runs over the seeds. A seed never counts twice, the machines' differences enter through "
             "the per-seed values, and more runs of a seed make its value more exact, not the test more confident."
             f"{pooling}\n",
             "**Seeds needed**: for each comparison not yet decided (every comparison of a claim whose verdict "
             "differs between sets of runs), the fewest seeds per method at which the test reaches a verdict with "
             f"probability {stats.POWER:.0%}, the measured means and spreads taken as the truth "
             "(`hierloco.stats.seeds_needed`, a shifted-t approximation); \"more than 100\" where the measured "
             "difference is too close to the minimum effect or margin for its spread, so that seeds alone will not "
             "decide it. **Compute**: the extra seeds times the measured compute of one such job (`builds.json` of "
             "its records: every stage's build time, copied stages included, 1 thread); the same job measured on "
             "different machines took different times, so the range is given.\n"]
    totals: dict = {}
    headings = sections(registry)
    for section, heading in headings.items():
        chosen = [n for n in needs if n.section == section]
        lines.append(f"## {heading} ({len(chosen)})\n")
        lines.append("| claim | robot | setting | task | runs | verdict (per set of runs, where they differ) | "
                     "seeds that would decide it | seeds now -> needed, per configuration (+extra x min per job) |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for need in chosen:
            c, extra = need.check, []
            for name, have in need.sides:
                key, words, minutes = job_of(evidence, need, name)
                more = 0 if need.needed is None else max(0, need.needed - have)
                per_job = float(np.mean(minutes)) if minutes else math.nan
                extra.append(f"{name}: {have} -> {'?' if need.needed is None else max(have, need.needed)}"
                             + (f" (+{more} x {per_job:.1f})" if more and minutes else ""))
                if key is not None and need.needed is not None:
                    full = (section, c.robot, key)
                    more = max(0, more - totals.get(("paper", c.robot, key), (0,))[0]) if section != "paper" \
                        else more
                    if more > totals.get(full, (0,))[0]:
                        totals[full] = (more, words, minutes)
            verdicts = differ.get(_identity(c))
            seen = ", ".join(f"{k}: {v}" for k, v in verdicts.items()) if verdicts else c.verdict
            lines.append(f"| {c.claim} | {c.robot} | {c.setting} | {c.task} | {need.study} | {seen} | "
                         f"{_seeds_text(need)} | {'; '.join(extra) or '-'} |")
        lines.append("")
    lines.append("## The compute the extra seeds need\n")
    lines.append("Per job to run (one job of a method serves every claim on its robot, settings and tasks), the most "
                 "extra seeds any claim above asks of it, times its measured compute per job (mean, and the range "
                 "over the jobs recorded). The second table counts only the seeds beyond the first's.\n")
    for section, heading in headings.items():
        rows = sorted((k, v) for k, v in totals.items() if k[0] == section)
        if not rows:
            continue
        lines.append(f"### {heading}\n")
        lines.append("| robot | job | extra seeds | compute per job (min) | compute (min) |")
        lines.append("|---|---|---|---|---|")
        total = 0.0
        for (_, robot, _), (more, words, minutes) in rows:
            if minutes:
                mean = float(np.mean(minutes))
                spread = f"{mean:.1f} ({min(minutes):.1f}-{max(minutes):.1f}, {len(minutes)} jobs)"
                total += more * mean
                lines.append(f"| {robot} | {words} | {more} | {spread} | {more * mean:.0f} |")
            else:
                lines.append(f"| {robot} | {words} | {more} | not recorded | - |")
        lines.append(f"\nIn all {total:.0f} min ({total / 60:.1f} h) of compute at 1 thread per job for the claims a "
                     "finite number of seeds decides.\n")
    lines += replicate_section(evidence)
    return "\n".join(lines) + "\n"


def replicate_section(evidence: Evidence, shown: float = 0.02) -> list[str]:
    """The configurations run more than once whose runs differ: per configuration and seed, each run's mean cost,
    its folder and CPU; those differing by at least ``shown`` are listed."""
    runs = [r for found in evidence.runs.values() for r in found] + evidence.archived
    groups = replicates(runs)
    places = defaultdict(lambda: (set(), set()))   # one run found in several places: every folder and CPU named
    for r in runs:
        folders, cpus = places[(r.method, r.robot, r.profile, r.setting, r.task, r.seed, r.episodes)]
        folders.add(r.folder)
        cpus.update([r.cpu] if r.cpu else [])

    def where(run: Run) -> str:
        folders, cpus = places[(run.method, run.robot, run.profile, run.setting, run.task, run.seed, run.episodes)]
        return f"{', '.join(sorted(folders))}; {', '.join(sorted(cpus)) or 'CPU not recorded'}"

    spread = lambda g: max(r.cost for r in g) - min(r.cost for r in g)  # noqa: E731
    listed = sorted((g for g in groups if spread(g) >= shown), key=lambda g: -spread(g))
    lines = [f"## Configurations run more than once\n",
             f"{len(groups)} configuration-and-seed groups were run more than once with different numbers "
             f"({sum(spread(g) < 0.001 for g in groups)} of them within 0.001 of each other); the "
             f"{len(listed)} that differ by {shown} or more in mean normalised cost:\n",
             "| method | robot | profile | setting | task | seed | runs: mean cost (folders; CPU) | spread |",
             "|---|---|---|---|---|---|---|---|"]
    for group in listed:
        r = group[0]
        each = "; ".join(f"{g.cost:.3f} ({where(g)})" for g in sorted(group, key=lambda g: g.folder))
        lines.append(f"| {r.method} | {r.robot} | {r.profile} | {r.setting} | {r.task} | {r.seed} | {each} | "
                     f"{spread(group):.3f} |")
    return lines


# --- writing -------------------------------------------------------------------------------------------------------

def pages(evidence: Evidence, registry: ClaimRegistry = CLAIMS) -> dict[str, str]:
    """Every file this module writes, relative to ``results/``, and its text."""
    studies = {study.name: study for study in evidence.studies}
    out = {f"{name}/verdicts.md": study_page(studies[name], checks, evidence)
           for name, checks in study_checks(evidence).items()}
    checks = paper_checks(evidence, registry)
    out[PAPER_PAGE] = paper_page(evidence, checks, registry)
    out[SANITY_PAGE] = sanity_page(evidence, checks, registry)
    out["fragile_claims.md"] = fragile_page(evidence, checks, registry)
    return out


def write_all(evidence: Evidence, out: Path) -> list[Path]:
    """Writes :func:`pages` under ``out``; returns the paths written."""
    written = []
    for relative, text in pages(evidence).items():
        path = Path(out) / relative
        write_text(path, text)
        written.append(path)
    return written


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default="results", help="the results folder to read (default: results)")
    parser.add_argument("--out", default=None, help="where to write (default: the results folder)")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a file is not up to date")
    args = parser.parse_args(argv)
    results = Path(args.results)
    if not results.is_dir():
        print(f"error: no results folder {results}", file=sys.stderr)
        return 2
    evidence = load(results)
    if args.check:
        stale = [rel for rel, text in pages(evidence).items()
                 if not (results / rel).is_file() or (results / rel).read_text() != text]
        for rel in stale:
            print(f"not up to date: {results / rel}")
        return 1 if stale else 0
    for path in write_all(evidence, Path(args.out) if args.out else results):
        print(f"wrote {path}")
    return 0


__all__ = ["COMMAND", "Need", "fragile", "ledger_page", "load", "main", "page_entries", "pages", "paper_checks",
           "sanity_page", "study_checks", "write_all"]
