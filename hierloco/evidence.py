"""The measured runs behind a claim: per-episode costs read from job records and tables, replicates pooled.

A study keeps each finished job's verified *record* (its rows, its stage keys, what its stages took;
:mod:`hierloco.pipeline.records`, ``docs/statistics.md``). This module reads records, and per-episode tables without records,
into :class:`Run` objects, one per job, setting and task, each labelled with what was run:

- ``method``: the recipe of the job's signature, or its study name when the overrides make it a variant (the
  ``variants`` a reader is given, as a study's config declares them: ``ik_plain: {recipe: ik, overrides:
  [controller.footstep_law=plain]}`` names IK with the plain footstep law ``ik_plain``);
- ``robot``, ``setting``, ``task``, ``seed`` from the rows, ``profile`` from ``robot_profile=`` (default ``own``);
- ``factors``: the sizes the ablations and the sample-efficiency study vary (``latent_dim``, ``num_experts``,
  ``num_transitions``: CoM transitions of the run's setting, ``high_level_frames``: the environment steps the task's
  SAC high level trained on), read from the stage keys, and ``options``: the job's other overrides;
- ``config``: the key of the run's evaluation stage (a hash of every stage key before it, seed included), so two
  runs with the same ``config`` are the same configuration and seed, run twice;
- ``cpu`` (from ``builds.json``) and the job's compute in minutes (every stage's build time, ``builds.json``).

**Pooling.** Runs of one configuration on different CPUs differ in the last digits, and a closed loop (a damaged
robot, a SAC policy) can grow that into another outcome (``docs/statistics.md``). Such runs are samples of the
same configuration: :func:`seed_values` averages a seed's distinct runs (identical rows found in two places are one
run) into one value per seed, so each seed counts once in a test over seeds however often it was run, and the
spread between machines enters the test through the per-seed values.

Example (a record written here, then read back):
    >>> import tempfile, pathlib
    >>> from hierloco.pipeline import records
    >>> from hierloco.pipeline.rundir import StageSpec
    >>> job = pathlib.Path(tempfile.mkdtemp()) / "records" / "lat" / "paper" / "a1_seed0"
    >>> rows = [{"method": "lat", "robot": "a1", "setting": "normal", "task": "goal_reaching", "seed": 0,
    ...          "episode": e, "normalized_cost": c} for e, c in enumerate([0.1, float("nan")])]
    >>> spec = StageSpec("evaluation_normal_goal_reaching", {}, "evaluation/normal/goal_reaching-0123456789ab.npz")
    >>> _ = records.save(records.make_record({"method": "lat", "overrides": ["seed=0"]}, [spec], rows=rows), job)
    >>> [run] = read_records(job.parents[2])
    >>> run.method, run.config, run.cost   # a fallen robot's NaN counts as 1
    ('lat', '0123456789ab', 0.55)
    >>> seeds, values, counts = seed_values([run])
    >>> seeds.tolist(), values.tolist(), counts.tolist()
    ([0], [0.55], [1])
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

# overrides that say where and how a job ran, not what it is
BOOKKEEPING = ("preset", "robot", "seed", "progress", "settings", "eval.generalization", "eval.videos", "nthread",
               "robot_profile")
FACTORS = {"latent_dim": ("gait_policy.pt", "latent_dim"), "num_experts": ("experts.npz", "num_experts")}


@dataclass(frozen=True)
class Run:
    """One job's episodes of one setting and task. ``episodes``: ``(episode index, normalised cost)`` pairs, a
    fallen robot's NaN as 1; ``success``: per-episode success where recorded (goal reaching), else empty."""

    method: str
    robot: str
    profile: str
    setting: str
    task: str
    seed: int
    episodes: tuple[tuple[int, float], ...]
    folder: str = ""
    record: str = ""
    config: str = ""
    cpu: str = ""
    minutes: float = math.nan
    threads: int = 0
    factors: tuple[tuple[str, object], ...] = ()
    options: tuple[str, ...] = ()
    success: tuple[float, ...] = field(default=(), compare=False)
    steps_to_goal: tuple[float, ...] = field(default=(), compare=False)
    final_error: tuple[float, ...] = field(default=(), compare=False)  # m, per episode (goal or path end)
    clearance: tuple[float, ...] = field(default=(), compare=False)  # m, a navigation episode's closest CoM to a box

    @property
    def cost(self) -> float:
        """The mean normalised cost over the run's episodes."""
        return float(np.mean([c for _, c in self.episodes]))

    def factor(self, name: str, default=None):
        return dict(self.factors).get(name, default)

    def cost_of(self, episodes: Iterable[int]) -> float:
        """The mean normalised cost over the episodes with these indices (NaN when none)."""
        chosen = set(episodes)
        costs = [c for e, c in self.episodes if e in chosen]
        return float(np.mean(costs)) if costs else math.nan


def _cost(value) -> float:
    cost = float(value)
    return 1.0 if math.isnan(cost) else cost


def _float(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def method_of(signature: Mapping, variants: Mapping | None = None) -> str:
    """The study name of a job: its recipe, or the variant whose overrides it has (``variants``: name ->
    ``{"recipe": ..., "overrides": [...]}``, as a study's config declares them).

        >>> plain = {"ik_plain": {"recipe": "ik", "overrides": ["controller.footstep_law=plain"]}}
        >>> method_of({"method": "ik", "overrides": ["seed=1", "controller.footstep_law=plain"]}, plain)
        'ik_plain'
    """
    overrides = set(signature.get("overrides", []))
    for name, variant in (variants or {}).items():
        if signature.get("method") == variant["recipe"] and set(variant.get("overrides", [])) <= overrides:
            return name
    return str(signature.get("method", ""))


def _variant_overrides(variants: Mapping | None) -> set[str]:
    return {o for variant in (variants or {}).values() for o in variant.get("overrides", [])}


def _override(overrides: Sequence[str], name: str, default=None):
    for item in overrides:
        key, _, value = item.partition("=")
        if key.lstrip("+") == name:
            return value
    return default


def _json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def _runs_from_rows(rows: list[dict], **labels) -> list[Run]:
    groups: dict = defaultdict(list)
    for row in rows:
        groups[(row["method"], row["robot"], row["setting"], row["task"], int(row["seed"]))].append(row)
    runs = []
    for (method, robot, setting, task, seed), members in sorted(groups.items()):
        members.sort(key=lambda r: int(r["episode"]))
        fields = dict(labels)
        run_labels = fields.pop("per_group", lambda *_: {})(setting, task)
        runs.append(Run(method=fields.pop("method", None) or method, robot=robot,
                        profile=fields.pop("profile", None) or members[0].get("profile") or "own",
                        setting=setting, task=task, seed=seed,
                        episodes=tuple((int(r["episode"]), _cost(r["normalized_cost"])) for r in members),
                        success=tuple(_float(r.get("success")) for r in members),
                        steps_to_goal=tuple(_float(r.get("steps_to_goal")) for r in members),
                        final_error=tuple(_float(r.get("final_error")) for r in members),
                        clearance=tuple(_float(r.get("clearance")) for r in members),
                        **fields, **run_labels))
    return runs


def _record(directory: Path) -> dict:
    from hierloco.pipeline import records

    return records.read(directory)


def job_compute(record: str | os.PathLike) -> tuple[float, int, str]:
    """A job's compute from its record's ``builds``: the minutes every stage took to build (a stage copied from
    another run counts what building it took there), the most threads a stage had, and the CPU of its first stage
    (``""`` when not recorded). ``(nan, 0, "")`` without a record.

        >>> job_compute("/nonexistent")
        (nan, 0, '')
    """
    try:
        builds = _record(Path(record))["builds"]
    except ValueError:
        return math.nan, 0, ""
    if not isinstance(builds, dict) or not builds:
        return math.nan, 0, ""
    seconds = sum(float(b.get("seconds", 0.0)) for b in builds.values() if isinstance(b, dict))
    threads = max(int(b.get("threads", 0)) for b in builds.values() if isinstance(b, dict))
    cpus = [b["cpu"] for b in builds.values() if isinstance(b, dict) and b.get("cpu")]
    return seconds / 60.0, threads, (cpus[0] if cpus else "")


def read_records(root: str | os.PathLike, *, folder: str = "", variants: Mapping | None = None) -> list[Run]:
    """Every finished job's runs under ``root`` (a study's records directory: one verified ``record.json`` per job,
    at any depth; :mod:`hierloco.pipeline.records`), labelled as in the module doc (``variants``: :func:`method_of`);
    ``folder`` names the study they belong to. A record of a finding has no runs: see :func:`read_findings`. An
    edited record raises."""
    from hierloco.pipeline.records import RECORD

    runs = []
    for path in sorted(Path(root).rglob(RECORD)):
        directory = path.parent
        record = _record(directory)
        if record["rows"] is None:
            continue
        signature = record["signature"]
        overrides = list(signature.get("overrides", []))
        stages = {filename: entry.get("key", {}) for filename, entry in record["stages"].items()}
        minutes, threads, job_cpu = job_compute(directory)
        builds = record["builds"] or {}
        factors = {}
        for name, (stage_file, param) in FACTORS.items():
            key = stages.get(stage_file)
            if key and param in key.get("params", {}):
                factors[name] = key["params"][param]
        experts = stages.get("experts.npz") or {}
        for bound in ("command_low", "command_high"):
            if bound in experts.get("params", {}):
                factors[bound] = tuple(experts["params"][bound])
        options = tuple(sorted(o for o in overrides if o.partition("=")[0].lstrip("+") not in BOOKKEEPING
                               and o not in _variant_overrides(variants)))

        def per_group(setting, task, stages=stages, builds=builds, factors=factors, job_cpu=job_cpu):
            prefix = f"evaluation/{setting}/{task}-"
            keys = sorted(name.removeprefix(prefix).split(".")[0] for name in stages if name.startswith(prefix)
                          and "-" not in name.removeprefix(prefix).split(".")[0])
            data = stages.get(f"dynamics_data_{setting}.npz") or {}
            transitions = data.get("params", {}).get("num_transitions")
            frames = (stages.get(f"sac_{task}.pt") or {}).get("params", {}).get("total_frames")
            stage = builds.get(f"evaluation_{setting}_{task}", {}) if isinstance(builds, dict) else {}
            more = dict(factors, **({"num_transitions": transitions} if transitions is not None else {}),
                        **({"high_level_frames": frames} if frames is not None else {}))
            cpu = stage.get("cpu", "") if isinstance(stage, dict) else ""
            return {"config": "+".join(keys), "cpu": cpu or job_cpu, "factors": tuple(sorted(more.items()))}

        runs += _runs_from_rows(record["rows"], method=method_of(signature, variants),
                                profile=_override(overrides, "robot_profile", "own"), folder=folder,
                                record=directory.as_posix(), minutes=minutes, threads=threads, options=options,
                                per_group=per_group)
    return runs


def read_findings(root: str | os.PathLike, *, variants: Mapping | None = None) -> list[dict]:
    """The jobs under ``root`` that ended in a finding about their setting: per record its ``method``, ``robot``,
    ``seed``, ``profile``, ``settings``, the ``stage`` it stopped in and the ``error``."""
    from hierloco.pipeline.records import RECORD

    found = []
    for path in sorted(Path(root).rglob(RECORD)):
        record = _record(path.parent)
        failure = record["finding"]
        if not failure:
            continue
        overrides = record["signature"].get("overrides", [])
        found.append({"method": method_of(record["signature"], variants),
                      "robot": _override(overrides, "robot", ""), "seed": int(_override(overrides, "seed", -1)),
                      "profile": _override(overrides, "robot_profile", "own"),
                      "settings": _override(overrides, "settings", ""), "stage": failure.get("stage", ""),
                      "error": str(failure.get("error", "")).strip().splitlines()[0] if failure.get("error") else "",
                      "record": path.parent.as_posix()})
    return found


def read_stage_reports(root: str | os.PathLike, stage: str, *,
                       variants: Mapping | None = None) -> list[dict]:
    """What stage ``stage`` reported in every finished job under ``root`` whose plan has it (a verified record
    holding that stage's key and its report, e.g. ``latent_continuity``): per job its ``method``, ``robot``,
    ``seed`` and ``record``, with the report's fields. An edited record raises."""
    from hierloco.pipeline.records import RECORD

    found = []
    for path in sorted(Path(root).rglob(RECORD)):
        record = _record(path.parent)
        report = (record["report"] or {}).get(stage)
        planned = any(Path(filename).stem == stage for filename in record["stages"])
        if record["rows"] is None or not planned or not isinstance(report, dict):
            continue
        overrides = record["signature"].get("overrides", [])
        found.append({**report, "method": method_of(record["signature"], variants),
                      "robot": _override(overrides, "robot", ""), "seed": int(_override(overrides, "seed", -1)),
                      "record": path.parent.as_posix()})
    return found


def read_table(path: str | os.PathLike, *, folder: str = "", profile: str | None = None) -> list[Run]:
    """The runs of a per-episode table (``comparison.csv``, ``hardware.csv``; columns as ``episodes.csv``) that has
    no records: no stage keys (``config`` is empty), no CPU, no compute. ``profile`` overrides the table's
    ``profile`` column (default ``own``)."""
    return _runs_from_rows(_rows(Path(path)), folder=folder, record=Path(path).as_posix(),
                           **({"profile": profile} if profile else {}))


def same_run(a: Run, b: Run) -> bool:
    """Whether two runs are one run found in two places: the same labels and the same episodes to the last digit."""
    return (a.method, a.robot, a.profile, a.setting, a.task, a.seed, a.episodes) == \
        (b.method, b.robot, b.profile, b.setting, b.task, b.seed, b.episodes)


def distinct(runs: Iterable[Run]) -> list[Run]:
    """``runs`` without repeats (:func:`same_run`), the first place each was found kept."""
    kept: dict = {}
    for run in runs:
        kept.setdefault((run.method, run.robot, run.profile, run.setting, run.task, run.seed, run.episodes), run)
    return list(kept.values())


def select(runs: Iterable[Run], **labels) -> list[Run]:
    """The runs whose attributes equal ``labels`` (a factor by its name: ``latent_dim=2``; a callable tests).

        >>> run = Run("lat", "a1", "own", "normal", "goal_reaching", 0, ((0, 0.1),), factors=(("latent_dim", 3),))
        >>> len(select([run], method="lat", latent_dim=3)), len(select([run], latent_dim=2))
        (1, 0)
    """
    def matches(run: Run, name: str, wanted) -> bool:
        value = getattr(run, name) if name in Run.__dataclass_fields__ else run.factor(name)
        return wanted(value) if callable(wanted) else value == wanted

    return [run for run in runs if all(matches(run, name, wanted) for name, wanted in labels.items())]


def seed_values(runs: Iterable[Run], value=lambda run: run.cost) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pooled per-seed values: ``(seeds, values, replicates)``, each ``(S,)``. A seed's value is the mean of
    ``value(run)`` over its distinct runs (the same configuration run on other CPUs; repeats of one run count
    once), ``replicates`` how many there were.

        >>> runs = [Run("ik", "daisy", "own", "legs_disabled", "velocity_tracking", s, ((0, c),), record=r)
        ...         for s, c, r in ((0, 0.51, "x"), (1, 1.01, "x"), (1, 0.59, "y"), (0, 0.51, "y"))]
        >>> seeds, values, replicates = seed_values(runs)
        >>> seeds.tolist(), values.round(2).tolist(), replicates.tolist()
        ([0, 1], [0.51, 0.8], [1, 2])
    """
    by_seed: dict = defaultdict(list)
    for run in distinct(runs):
        by_seed[run.seed].append(value(run))
    seeds = sorted(by_seed)
    return (np.array(seeds, dtype=int), np.array([float(np.mean(by_seed[s])) for s in seeds]),
            np.array([len(by_seed[s]) for s in seeds], dtype=int))


def replicates(runs: Iterable[Run]) -> list[list[Run]]:
    """Groups of two or more distinct runs of one configuration and seed: the same ``config`` (a run without one:
    the same labels, factors and options). The same job run again, on the same or another CPU."""
    groups: dict = defaultdict(list)
    for run in distinct(runs):
        key = (run.setting, run.task, run.config) if run.config else \
            (run.method, run.robot, run.profile, run.setting, run.task, run.seed, run.factors, run.options)
        groups[key].append(run)
    return [members for members in groups.values() if len(members) > 1]


def adopt_configs(runs: Iterable[Run], reference: Iterable[Run]) -> list[Run]:
    """``runs`` from a table without records, each given the ``config`` and ``factors`` of the ``reference`` runs
    (records) with its labels (method, robot, profile, setting, task, seed), where they name exactly one
    configuration: the table is *declared* to be of the reference's configuration (say, the same study command run
    before the records were kept), which the stage keys cannot check. Runs with no such reference stay as they
    are.

        >>> keyed = Run("lat", "a1", "own", "normal", "goal_reaching", 0, ((0, 0.1),), config="abc")
        >>> table = Run("lat", "a1", "own", "normal", "goal_reaching", 0, ((0, 0.2),))
        >>> adopt_configs([table], [keyed])[0].config
        'abc'
    """
    configs: dict = defaultdict(set)
    for run in reference:
        if run.config:
            configs[(run.method, run.robot, run.profile, run.setting, run.task, run.seed)].add((run.config,
                                                                                               run.factors))
    out = []
    for run in runs:
        found = configs.get((run.method, run.robot, run.profile, run.setting, run.task, run.seed), set())
        if not run.config and len(found) == 1:
            (config, factors), = found
            run = replace(run, config=config, factors=factors)
        out.append(run)
    return out


def rows_of(runs: Iterable[Run], *, method=None) -> list[dict]:
    """Per-episode rows (``method``, ``robot``, ``setting``, ``task``, ``seed``, ``episode``, ``normalized_cost``,
    ``run``) of ``runs``, for code that reads rows; ``run`` tells a seed's replicates apart, ``method`` (a
    callable of the run) relabels."""
    rows = []
    for run in distinct(runs):
        name = method(run) if method else run.method
        rows += [{"method": name, "robot": run.robot, "setting": run.setting, "task": run.task, "seed": run.seed,
                  "episode": e, "normalized_cost": c, "run": f"{run.record}|{run.config}"} for e, c in run.episodes]
    return rows


__all__ = ["BOOKKEEPING", "FACTORS", "Run", "adopt_configs", "distinct", "job_compute", "method_of",
           "read_findings", "read_records", "read_table", "replicates", "rows_of", "same_run", "seed_values", "select"]
