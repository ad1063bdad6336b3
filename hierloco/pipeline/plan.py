"""Stages and plans: what a recipe will build, each stage with the key that identifies its artifact.

A :class:`Stage` is one cached artifact: ``params`` are the values its builder is called with (config values,
nothing else) and ``after`` the digests of what it depends on (the robot's fingerprint, the stages upstream);
together they are its *key*. A builder receives only ``params`` and the upstream artifacts, so everything that
changes an artifact is in its key by construction.

A recipe's ``plan(cfg, robot)`` returns a :class:`Plan`: the stages as named handles (``plan.experts``,
``plan.settings[0].model``) that its ``train.py`` hands to :meth:`hierloco.pipeline.run.Run.stage`. No stage name
is written twice: the handle carries it. ``docs/pipeline.md`` explains keys, caching and plans.

Example:
    >>> from hierloco.pipeline.plan import Plan, Stage
    >>> square = Stage("square", {"n": 3}, {}, "square.json", JsonReport, lambda run, params: JsonReport(
    ...     value=params["n"] ** 2))
    >>> plan = Plan(square=square)
    >>> [stage.name for stage in plan.stages()], len(square.digest)
    (['square'], 12)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

from hierloco.io import load_json, save_json
from hierloco.pipeline.rundir import StageSpec, digest


@dataclass(frozen=True)
class Stage:
    """One cached stage: ``build(run, params, *inputs)`` makes the artifact (a class with ``save(path)`` and
    ``load(path)``), stored as ``filename`` beside its key ``{params, after}``; ``check(run, artifact)`` raises when
    an artifact (built or cached) is unfit."""

    name: str
    params: dict
    after: dict
    filename: str
    artifact: Any  # the artifact's class, or "package.module:Class" (imported when the stage runs)
    build: Callable
    check: Callable | None = None

    @property
    def artifact_class(self):
        """The artifact's class (imported now when given as ``"package.module:Class"``)."""
        if isinstance(self.artifact, str):
            import importlib

            module, _, name = self.artifact.partition(":")
            return getattr(importlib.import_module(module), name)
        return self.artifact

    @property
    def key(self) -> dict:
        return {"params": self.params, "after": self.after}

    @property
    def digest(self) -> str:
        return digest(self.key)

    @property
    def spec(self) -> StageSpec:
        return StageSpec(self.name, self.key, self.filename)

    @property
    def trains(self) -> bool:
        """Whether the stage trains something (every stage but the evaluations; ``evaluate.py`` builds none)."""
        return not self.name.startswith("evaluation_")


def _stages_of(value) -> Iterator[Stage]:
    if isinstance(value, Stage):
        yield value
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _stages_of(item)
    elif isinstance(value, dict):
        for item in value.values():
            yield from _stages_of(item)
    elif hasattr(value, "stages"):
        yield from value.stages()


class Plan:
    """A recipe's stages as named handles, in the order they run.

    ``Plan(experts=..., gait_policy=..., settings=[SettingPlan(...), ...])``: attributes are stages, lists of them,
    or groups (anything with ``stages()``). :meth:`stages` lists every stage once, in order.
    """

    def __init__(self, **parts):
        self.__dict__.update(parts)

    def stages(self) -> list[Stage]:
        """Every stage once, in the plan's order; a name given to two stages with different keys is a recipe's
        mistake (one would shadow the other), a ``ValueError`` naming it."""
        seen, ordered = {}, []
        for part in self.__dict__.values():
            for stage in _stages_of(part):
                if stage.name not in seen:
                    seen[stage.name] = stage
                    ordered.append(stage)
                elif seen[stage.name].digest != stage.digest:
                    raise ValueError(f"the plan names two different stages {stage.name!r} (keys {seen[stage.name].digest}"
                                     f" and {stage.digest}): a recipe's stages need names of their own")
        return ordered

    def __iter__(self) -> Iterator[Stage]:
        return iter(self.stages())

    def __repr__(self) -> str:
        return f"Plan({', '.join(stage.name for stage in self.stages())})"


@dataclass
class SettingPlan:
    """One setting of a model-based plan: its CoM data and model, and the evaluations that plan with that model
    (for ``normal``, also those of the ``<setting>_unadapted`` settings)."""

    setting: str
    data: Stage
    model: Stage
    evaluations: list[Stage] = field(default_factory=list)

    def stages(self) -> list[Stage]:
        return [self.data, self.model, *self.evaluations]


@dataclass
class TaskPlan:
    """One task of a model-free plan: the agent trained for it and its evaluations (the task and its
    generalisation variants)."""

    task: str
    agent: Stage
    evaluations: list[Stage] = field(default_factory=list)

    def stages(self) -> list[Stage]:
        return [self.agent, *self.evaluations]


class JsonReport(dict):
    """A stage artifact that is a JSON object, validated against ``SCHEMA`` when loaded."""

    SCHEMA: dict = {}

    def save(self, path) -> None:
        save_json(path, dict(self))

    @classmethod
    def load(cls, path) -> "JsonReport":
        return cls(load_json(path, cls.SCHEMA))


__all__ = ["JsonReport", "Plan", "SettingPlan", "Stage", "TaskPlan"]
