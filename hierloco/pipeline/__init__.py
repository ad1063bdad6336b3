"""The pipeline under every recipe: keyed stages, runs, locks, config checks, entry points, studies and records.

``docs/pipeline.md`` explains it ("write a recipe"). The modules, from the bottom up:

- :mod:`~hierloco.pipeline.rundir`: a run directory, each stage's artifact beside its key, under a lock;
- :mod:`~hierloco.pipeline.plan`: :class:`Stage` (params + what it depends on = its key) and :class:`Plan` (a
  recipe's stages as named handles);
- :mod:`~hierloco.pipeline.config`: the config checks (every problem in one error, before any work);
- :mod:`~hierloco.pipeline.stages`: the stages LAT, LIB, IK and SAC share (experts, gait policy, CoM dynamics,
  evaluation);
- :mod:`~hierloco.pipeline.run`: :func:`open_run` and :class:`Run` (a run in progress, its results and outputs);
- :mod:`~hierloco.pipeline.entry`: :func:`recipe_main`, a recipe's entry point with one-line errors and exit codes;
- :mod:`~hierloco.pipeline.evaluate`: evaluating a trained run (``recipes/evaluate.py``);
- :mod:`~hierloco.pipeline.methods`: the registry of methods (recipes);
- :mod:`~hierloco.pipeline.studies`, :mod:`~hierloco.pipeline.study`, :mod:`~hierloco.pipeline.records`: studies as
  jobs on Ray, their tables, and the verified records that let a study run in parts.
"""

from __future__ import annotations

_EXPORTS = {"recipe_main": "hierloco.pipeline.entry", "open_run": "hierloco.pipeline.run",
            "Run": "hierloco.pipeline.run", "Plan": "hierloco.pipeline.plan", "Stage": "hierloco.pipeline.plan",
            "METHODS": "hierloco.pipeline.methods", "ConfigError": "hierloco.pipeline.errors"}


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'hierloco.pipeline' has no attribute {name!r}")


__all__ = list(_EXPORTS)
