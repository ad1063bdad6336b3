"""Factories of the LIB recipe: the expert library as a discrete action set (the rest is the shared pipeline)."""

from __future__ import annotations

from common import pipeline
from hierloco.components.low_level import ExpertReplayLowLevel
from hierloco.runs import RunDirectory

METHOD = "lib"


def validate(cfg) -> None:
    pipeline.validate(cfg, planners=("exhaustive",),
                      extra=pipeline.check_positive({"experts.num_experts": cfg.experts.num_experts}))


def prepare(cfg, run: RunDirectory, logger, reports: dict) -> pipeline.LowLevelRecipe:
    """The expert library; the low level replays expert g's recorded pattern for action g."""
    library = pipeline.stage_experts(cfg, run)
    reports["experts"] = library.metadata
    low_level = ExpertReplayLowLevel(library)
    return pipeline.LowLevelRecipe(make=lambda num_robots: low_level,
                                   config={"experts": pipeline.experts_config(cfg)})
