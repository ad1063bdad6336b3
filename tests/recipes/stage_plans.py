"""A recipe's planned stages at the tiny preset, and which stage keys a set of overrides changes."""
from __future__ import annotations

import importlib

from hierloco.pipeline.config import compose_recipe, prepare


def plan(recipe: str, *overrides: str) -> dict:
    """``stage name -> stage`` of ``recipe`` at ``preset=tiny`` with ``overrides`` (nothing built)."""
    cfg = compose_recipe(recipe, ["preset=tiny", *overrides])
    utils = importlib.import_module(f"hierloco.recipes.{recipe}.utils")
    return {stage.name: stage for stage in utils.plan(cfg, prepare(cfg, utils.checks)).stages()}


def changed(recipe: str, *overrides: str) -> set[str]:
    """The stages whose keys ``overrides`` change (the same stages are planned either way)."""
    before, after = plan(recipe), plan(recipe, *overrides)
    assert before.keys() == after.keys()
    return {name for name in before if before[name].digest != after[name].digest}
