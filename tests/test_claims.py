"""hierloco.claims: the claim blocks, the registry studies add to, and a library that imports no recipe."""

import pytest

from hierloco.claims import Claim, ClaimRegistry, Source, Study

# the library's imports of hierloco.recipes that are no recipe's code: the package itself (the recipe folders found
# by name), its shared config groups (package data), and the `hierloco verdicts` command the CLI dispatches to
ALLOWED = {("hierloco.pipeline.methods", "hierloco.recipes"), ("hierloco.pipeline.entry", "hierloco.recipes"),
           ("hierloco.pipeline.entry", "hierloco.recipes.conf"), ("hierloco.pipeline.evaluate", "hierloco.recipes"),
           ("hierloco.pipeline.evaluate", "hierloco.recipes.conf"), ("hierloco.cli", "hierloco.recipes.verdicts")}


def test_the_docstring_examples_run():
    import doctest

    import hierloco.claims

    assert doctest.testmod(hierloco.claims).failed == 0


def test_the_registry_keeps_each_kind_in_order_and_refuses_a_second_entry_under_a_name():
    registry = ClaimRegistry()
    first, second = Study("b", command="x", order=2), Study("a", command="y", order=1)
    claim = Claim(order=1, words="words", where="Sec. I", source="s", key="k")
    registry.add(first, second, claim, Source("s", order=1, checks=lambda evidence: []))
    registry.add(Study("b", command="x", order=2))   # the same declaration again (a module imported twice)
    assert [s.name for s in registry.studies()] == ["a", "b"] and registry.claims() == [claim]
    with pytest.raises(ValueError, match="study 'b' is already registered"):
        registry.add(Study("b", command="another", order=2))
    with pytest.raises(TypeError):
        registry.add("a claim")
    registry.remove(claim)
    assert registry.claims() == []


def test_a_variant_declared_two_ways_is_refused_and_one_way_is_read_once():
    plain = {"ik_plain": {"recipe": "ik", "overrides": ["controller.footstep_law=plain"]}}
    registry = ClaimRegistry()
    registry.add(Study("a", command="x", order=1, variants=plain), Study("b", command="y", order=2, variants=plain))
    assert registry.variants() == plain
    registry.add(Study("c", command="z", order=3, variants={"ik_plain": {"recipe": "ik", "overrides": []}}))
    with pytest.raises(ValueError, match="variant 'ik_plain' is declared as"):
        registry.variants()


def test_the_library_imports_no_recipe():
    from tests.test_imports import ROOT, module_imports, module_name

    package = ROOT / "hierloco"
    known = {module_name(p) for p in package.rglob("*.py")}
    found = {(module_name(p), target) for p in package.rglob("*.py")
             if "recipes" not in p.relative_to(package).parts
             for target in module_imports(p, known) if target.startswith("hierloco.recipes")}
    assert found <= ALLOWED, sorted(found - ALLOWED)
    assert not {name for name, _ in found} & {"hierloco.claims", "hierloco.evidence", "hierloco.stats"}


def _check(key, a, b, kind="better", parts=1):
    from hierloco.claims import decided, part

    return decided(key, key, "a1", "normal", "goal_reaching", "-", "-", [part(key, a, b, kind, parts=parts)])


def test_holm_over_a_family_weakens_only_the_verdicts_that_do_not_survive_it():
    from hierloco.claims import corrected, is_borderline, p_values, verdict_text
    from hierloco.stats import benjamini_hochberg

    strong = _check("strong", [0.10, 0.11, 0.12], [0.50, 0.52, 0.51])             # holds, p = 5.2e-07
    weak = _check("weak", [0.30, 0.44, 0.35], [0.45, 0.55, 0.50])                 # holds, p = 0.0296
    refuted = _check("refuted", [0.50, 0.52, 0.51], [0.50, 0.51, 0.53])           # does not hold, refuting p = 0.0073
    assert [c.verdict for c in (strong, weak, refuted)] == ["holds", "holds", "does not hold"]
    assert p_values(weak)[0] == pytest.approx(0.02956, abs=1e-4)
    assert p_values(refuted)[1] == pytest.approx(0.00730, abs=1e-4)
    assert is_borderline(weak) and not is_borderline(strong) and not is_borderline(refuted)
    assert verdict_text(weak) == "holds (p = 0.0296; borderline)"
    assert verdict_text(refuted) == "does not hold (refuting p = 0.0073)"
    # Holm over the three establishing p-values (5.2e-07, 0.0296, 0.385): weak's becomes 2 x 0.0296 = 0.059 > 0.05;
    # the refuting ones (1.0, 0.92, 0.0073): refuted's becomes 3 x 0.0073 = 0.022 < 0.05
    assert corrected([strong, weak, refuted]) == ["holds", "inconclusive", "does not hold"]
    assert is_borderline(weak, "inconclusive") and not is_borderline(strong, "holds")
    assert corrected([weak]) == ["holds"]                                         # a family of one: no correction
    # Benjamini-Hochberg is less strict: weak's q = 3 x 0.0296 / 2 = 0.044 < 0.05
    assert corrected([strong, weak, refuted], adjust=benjamini_hochberg) == ["holds", "holds", "does not hold"]


def test_the_verdict_at_the_pre_planned_seeds_is_decided_on_seeds_0_to_2_alone():
    from hierloco.claims import planned, redecided

    # seeds 0-2 alone cannot tell the two apart; seeds 3-4, added after a look, make LAT significantly better
    lat, base = [0.30, 0.50, 0.40, 0.20, 0.21], [0.45, 0.40, 0.50, 0.52, 0.55]
    final = _check("added", lat, base)
    assert final.verdict == "holds" and planned(final) == "inconclusive"
    assert planned(_check("three", lat[:3], base[:3])) is None            # nothing added: no second verdict
    # thresholds: the same check decided again with a minimum effect of 50 % no longer holds
    assert redecided(final, min_effect_rel=0.5) != "holds" and redecided(final) == "holds"


# --- the ledger: one entry per claim of the paper and robot ----------------------------------------------------------

HOLDS = ([0.10, 0.11, 0.12], [0.50, 0.52, 0.51])        # better: holds (p = 5.2e-07)
WEAK = ([0.30, 0.44, 0.35], [0.45, 0.55, 0.50])         # better: holds (p = 0.0296)
REFUTED = ([0.50, 0.52, 0.51], [0.50, 0.51, 0.53])      # better: does not hold
UNDECIDED = ([0.30, 0.50, 0.40], [0.45, 0.40, 0.50])    # better: inconclusive
STILL = ([0.95, 0.96, 0.97], [0.97, 0.98, 0.99])        # both no better than standing still: not testable here


def _row(task, sides, names=("lat:normal", "lib:normal"), robot="a1", key="best"):
    from hierloco.claims import decided, part

    return decided(key, key, robot, "normal", task, "-", "-", [part(f"{names[0]} vs {names[1]}", *sides, "better",
                                                                    names=names)])


def test_an_entry_holds_only_when_every_part_holds():
    from hierloco.claims import Claim, entry_check, ledger, p_values

    tasks = ("velocity_tracking", "goal_reaching", "trajectory_tracking")
    for sides, verdict in ((HOLDS, "holds"), (UNDECIDED, "inconclusive"), (REFUTED, "does not hold"),
                           (STILL, "inconclusive")):
        rows = [_row(tasks[0], HOLDS), _row(tasks[1], WEAK), _row(tasks[2], sides)]
        entry = entry_check("LAT is best", "a1", rows)
        assert entry.verdict == verdict, (sides, entry.verdict)
    assert entry_check("c", "a1", [_row(tasks[0], STILL), _row(tasks[1], STILL)]).verdict == "not testable here"
    # the entry's p for "holds": the largest p of its parts (WEAK's), not the smallest
    entry = entry_check("c", "a1", [_row(tasks[0], HOLDS), _row(tasks[1], WEAK)])
    assert entry.verdict == "holds" and p_values(entry)[0] == pytest.approx(0.02956, abs=1e-4)
    # one entry per robot: A1's refuted part does not touch Daisy's entry
    claim = Claim(order=1, words="LAT is best", where="-", source="s", key="best")
    checks = [_row(tasks[0], HOLDS), _row(tasks[1], REFUTED), _row(tasks[0], HOLDS, robot="daisy"),
              _row(tasks[1], WEAK, robot="daisy")]
    entries = ledger([("1", claim, checks)])
    assert [(e.robot, e.verdict, len(e.rows)) for e in entries] == [("a1", "does not hold", 2),
                                                                    ("daisy", "holds", 2)]


def test_a_test_an_earlier_section_makes_counts_once():
    from hierloco.claims import Claim, Source, entry_counts, ledger

    best = Claim(order=1, words="LAT is best", where="-", source="pooled", key="best", robots=("a1",))
    worse = Claim(order=2, words="LIB is worse than LAT", where="-", source="pooled", key="worse", robots=("a1",))
    budget = Claim(order=3, words="LAT beats SAC at equal samples", where="-", source="budgets", key="budget",
                   robots=("a1",))
    first = [_row("velocity_tracking", HOLDS), _row("velocity_tracking", HOLDS, ("lat:normal", "sac:normal"))]
    again = [_row("velocity_tracking", HOLDS, key="worse")]
    # the budget study names the comparison's configurations by their budget: 10000 is the comparison's own
    budgets = Source("budgets", order=2, checks=lambda evidence: [],
                     alias=lambda name: name.replace(":10000", ":normal"))
    at = [_row("velocity_tracking", REFUTED, ("lat:2000", "sac:2000"), key="budget"),
          _row("velocity_tracking", HOLDS, ("lat:10000", "sac:10000"), key="budget")]
    entries = ledger([("1", best, first), ("2", worse, again), ("3", budget, at)],
                     {"budgets": budgets.configuration})
    assert [(e.section, e.verdict, e.counted) for e in entries] == [
        ("1", "holds", True), ("2", "same test as section 1", False), ("3", "does not hold", True)]
    assert [r.status for r in entries[1].rows] == ["same test as section 1"]
    assert [r.status for r in entries[2].rows] == ["", "same test as section 1"]
    assert len(entries[2].check.parts) == 1                      # the 10000 row is not a part of it again
    assert entry_counts(entries) == {"holds": 1, "does not hold": 1, "inconclusive": 0, "not testable here": 0,
                                     "not measured yet": 0}
    # a check with one comparison of its own is no repeat: it counts
    mixed = [_row("velocity_tracking", HOLDS, key="worse"), _row("goal_reaching", HOLDS, key="worse")]
    assert ledger([("1", best, first), ("2", worse, mixed)])[1].counted


def test_a_robot_a_claim_s_source_has_no_runs_of_is_not_measured_yet():
    """A claim about both robots whose source has checks of one: the other robot's entry is "not measured yet" (the
    ledger keeps one entry per claim and robot), and it counts as such."""
    from hierloco.claims import Claim, entry_counts, ledger

    best = Claim(order=1, words="LAT is best", where="-", source="fair", key="best")
    entries = ledger([("1", best, [_row("velocity_tracking", HOLDS)])])
    assert [(e.robot, e.verdict, e.counted) for e in entries] == [("a1", "holds", True),
                                                                   ("daisy", "not measured yet", True)]
    assert entry_counts(entries)["not measured yet"] == 1


def test_the_extra_ik_variant_is_shown_and_not_counted(tmp_path):
    from hierloco.claims import Claim, ledger
    from hierloco.recipes.verdicts import load, pages
    from tests.recipes.test_verdicts import results_tree

    # in the ledger: the variant a claim does not count neither refutes nor establishes its entry
    close = Claim(order=1, words="close to IK", where="-", source="pooled", key="close", extra="extra (not counted)",
                  counted=lambda check: check.key == "close:ik", robots=("a1",))
    rows = [_row("velocity_tracking", HOLDS, ("lat:normal", "ik:normal"), key="close:ik"),
            _row("velocity_tracking", REFUTED, ("lat:normal", "ik_plain:normal"), key="close:ik_plain")]
    (entry,) = ledger([("1", close, rows)])
    assert entry.verdict == "holds" and [r.status for r in entry.rows] == ["", "extra (not counted)"]
    # on the page: A1's tuned IK is ours (the comparison's config); the plain law's rows are shown, marked extra
    paper = pages(load(results_tree(tmp_path / "results")))["paper_check.md"]
    section = paper[paper.index('close to IK in the normal setting'):paper.index("outperforms IK in adverse")]
    plain = [line for line in section.splitlines() if line.startswith("| a1 | normal |") and "IK_PLAIN" in line]
    tuned = [line for line in section.splitlines() if line.startswith("| a1 | normal |") and "IK (the IK tuned" in line]
    assert len(plain) == 3 and all("| extra (not counted): not the IK tuned" in line for line in plain)
    assert len(tuned) == 3 and all("| yes |" in line for line in tuned)
    assert "| 3 of 6 |" in next(line for line in section.splitlines() if line.startswith("| a1 | **"))


def test_sanity_checks_are_on_their_own_page_and_not_in_the_ledger(tmp_path):
    from hierloco.recipes.verdicts import load, pages
    from tests.recipes.test_verdicts import results_tree

    written = pages(load(results_tree(tmp_path / "results")))
    paper, sanity = written["paper_check.md"], written["sanity_checks.md"]
    assert "deteriorates with legs disabled" not in paper and "## S1. with two hind legs disabled" in sanity
    assert "| a1 | legs_disabled | velocity_tracking | IK (the IK tuned on the training targets) deteriorates" in sanity
    assert "[`sanity_checks.md`](sanity_checks.md)" in paper and "not counted here" in paper
    # the ledger's tally counts entries; the old per-row tally (sanity checks included) stays beside it
    head = next(line for line in paper.splitlines() if line.startswith("**The ledger: "))
    assert "one per claim of the paper and robot" in head and "Per row, as before" in head
    assert not [line for line in paper.splitlines() if line.startswith("## ") and "deteriorates" in line]
