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
