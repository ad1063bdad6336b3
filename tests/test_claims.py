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
