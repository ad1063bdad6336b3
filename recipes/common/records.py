"""Job records: a finished job's results without its artifacts, so a study goes on on another machine or session.

A study's run directories hold large artifacts (experts, models, buffers) and stay out of git. A *record* is the
small part of a finished job: its result rows (``episodes.csv``, ``results.csv``), what it ran (``job.json``), what
its stages took (``report.json``, ``builds.json``) and the key of every stage (``*.key.json``), a few tens of kB
per job. A study given a records directory (``records=results/<study>/jobs``) writes the record of every job it
ran or reused, and takes a job from its record when its run directory is missing (a fresh machine, a cluster
without shared storage) *only* if the record ran the same method and overrides and every stage the recipe plans
today has the key the record holds: a changed default or code path that enters a key runs the job again, exactly
as it would with its run directory at hand. A job that ended in a finding about its setting (experts that do not
walk, a fault in which every random action falls: ``recipes/common/entry.py``) leaves a record too, its
``failed.json``: a later study reports it as not evaluable, without running it, while the stage it failed in has
today's key. Records are committed like any measured table; a study that needs more
compute than one machine has is run in parts, each part adding its jobs' records.

Example:
    >>> from recipes.common.records import record_dir
    >>> record_dir("results/compare/jobs", "outputs/sac/paper/a1_seed1")
    PosixPath('results/compare/jobs/sac/paper/a1_seed1')
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterable

from hierloco.io import write_text
from hierloco.runs import StageSpec, normalized
from hierloco.results import read_csv

FAILED = "failed.json"  # a run's finding (recipes/common/entry.py: findings): the stage, its key and the error
FILES = ("job.json", "episodes.csv", "results.csv", "report.json", "builds.json")
KEYS = "*.key.json"  # anywhere below the run directory (a stage file may be in a folder)
MAX_BYTES = 2_000_000  # a record file larger than this is not a record's (an artifact under a record's name)


def record_dir(records: str | os.PathLike, run_dir: str | os.PathLike) -> Path:
    """Where the record of the job in ``run_dir`` goes: its path below ``outputs/`` (or, for a run directory
    elsewhere, its last three parts: ``<method>/<preset>/<run>``) under ``records``."""
    path = Path(run_dir)
    if path.is_absolute():
        try:
            path = path.relative_to(Path.cwd())
        except ValueError:
            path = Path(*path.parts[-3:])
    if path.parts and path.parts[0] == "outputs":
        path = Path(*path.parts[1:])
    if not path.parts or ".." in path.parts:
        raise ValueError(f"run directory {run_dir} has no place under a records directory")
    return Path(records) / path


def files_of(run_dir: str | os.PathLike) -> dict[str, str]:
    """The record of a finished job: its files' paths (relative to the run directory) -> text."""
    run_dir = Path(run_dir)
    record = _small_files(run_dir, [run_dir / name for name in FILES] + sorted(run_dir.rglob(KEYS)))
    if "job.json" not in record or "episodes.csv" not in record:
        raise ValueError(f"{run_dir} holds no finished job (job.json and episodes.csv)")
    return record


def failure_of(run_dir: str | os.PathLike, signature: dict) -> dict[str, str]:
    """The record of a job that ended in a finding (its run directory's ``failed.json``, written by the recipe):
    that file with the job's ``signature`` added, and the keys of the stages it finished."""
    run_dir = Path(run_dir)
    failure = json.loads((run_dir / FAILED).read_text())
    return {FAILED: json.dumps({"signature": signature, **failure}, indent=2),
            **_small_files(run_dir, sorted(run_dir.rglob(KEYS)))}


def _small_files(run_dir: Path, paths) -> dict[str, str]:
    return {path.relative_to(run_dir).as_posix(): path.read_text() for path in paths
            if path.is_file() and path.stat().st_size <= MAX_BYTES}


def finding(directory: str | os.PathLike, signature: dict, specs: Iterable[StageSpec]) -> str | None:
    """The error of the finding recorded in ``directory`` (a run directory or a record) for a job with this
    ``signature``, if the stage it failed in has, in today's plan ``specs``, the key it failed with (a stage's key
    holds those of the stages it depends on: the same inputs, the same failure); else ``None``."""
    try:
        failure = json.loads((Path(directory) / FAILED).read_text())
    except (OSError, ValueError):
        return None
    if failure.get("signature") != signature:
        return None
    keys = {spec.name: normalized(spec.key) for spec in specs}
    return failure.get("error") if keys.get(failure.get("stage"), object()) == failure.get("key") else None


def save(record: dict[str, str], directory: str | os.PathLike) -> bool:
    """Writes ``record`` (from :func:`files_of`) into ``directory``, each file atomically; files of an older record
    that the new one has not are removed (a record is one job's, whole). Returns whether anything changed."""
    directory = Path(directory)
    changed = False
    for name, text in record.items():
        path = directory / name
        if not path.is_file() or path.read_text() != text:
            write_text(path, text)
            changed = True
    if directory.is_dir():
        for path in sorted(directory.rglob("*")):
            if path.is_file() and path.relative_to(directory).as_posix() not in record:
                path.unlink()
                changed = True
    return changed


def holds_job(directory: str | os.PathLike, signature: dict) -> bool:
    """Whether ``directory`` (a run directory or a record) holds a finished job (``job.json`` and ``episodes.csv``)
    with this ``signature`` (method and overrides)."""
    directory = Path(directory)
    try:
        return ((directory / "episodes.csv").is_file()
                and json.loads((directory / "job.json").read_text()).get("signature") == signature)
    except (OSError, ValueError):
        return False


def current(directory: str | os.PathLike, signature: dict, specs: Iterable[StageSpec]) -> bool:
    """Whether the record in ``directory`` is of a job with this ``signature`` (method and overrides) and holds,
    for every stage of today's plan ``specs``, the same key."""
    directory = Path(directory)
    if not holds_job(directory, signature):
        return False
    try:
        for spec in specs:
            stored = json.loads((directory / f"{spec.filename}.key.json").read_text())
            if stored != normalized(spec.key):
                return False
    except (OSError, ValueError):
        return False
    return True


def rows(directory: str | os.PathLike) -> list[dict]:
    """The per-episode result rows of the record in ``directory``."""
    return read_csv(Path(directory) / "episodes.csv")


__all__ = ["FAILED", "FILES", "current", "failure_of", "files_of", "finding", "holds_job", "record_dir", "rows", "save"]
