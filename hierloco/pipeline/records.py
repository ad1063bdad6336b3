"""Job records: a finished job's results without its artifacts, verified when read, so a study goes on elsewhere.

A study's run directories hold large artifacts (experts, models, buffers) and stay out of git. A *record* is the
small part of a finished job, one file ``record.json``: what ran (the job's method and overrides: its
*signature*), the key of every stage its recipe planned, the per-episode result rows of its evaluations (read from
the evaluation artifacts those keys name, never from a loose CSV), what its stages took (``report``, ``builds``),
and a digest over all of it. A study given a records directory (``records=results/<study>/records``) writes the
record of every job it ran or reused, and takes a job from its record when its run directory is missing (a fresh
machine, a cluster without shared storage) *only* if the record verifies (its digest), ran the same method and
overrides, and holds for every stage the recipe plans today the key it has today. An edited or incomplete record
is refused in one line naming the file. A job that ended in a finding about its setting
(:class:`hierloco.errors.Finding`) leaves a record too, holding the finding (stage, key, error): a later study
reports it as not evaluable, without running it, while that stage has today's key.

Records live apart from run directories: a records directory that is, holds or sits inside a run directory is
refused before any job (:func:`check_records`), and saving a record writes its one file and deletes nothing.

Example:
    >>> from hierloco.pipeline.records import record_dir
    >>> record_dir("results/compare/records", "outputs/sac/paper/a1_seed1")
    PosixPath('results/compare/records/sac/paper/a1_seed1')
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from typing import Iterable

from hierloco.io import ArtifactError, write_text
from hierloco.pipeline.errors import ConfigError
from hierloco.pipeline.rundir import StageSpec, normalized

FAILED = "failed.json"  # a run's finding (hierloco.errors.Finding): the stage, its key and the error
RECORD = "record.json"
FORMAT = 2


class RecordError(ArtifactError):
    """A record that is edited, incomplete or not a record."""


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


def check_records(records) -> None:
    """Refuses, before any work, a ``records`` setting that is not a directory path (or null), or that is, holds
    or sits inside a run directory (records and run directories never mix)."""
    if records is None:
        return
    if not isinstance(records, str) or not records.strip():
        raise ConfigError(f"records must be a directory path or null, got {records!r}")
    path = Path(records)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"records={records} exists and is not a directory")
    for parent in [path.resolve(), *path.resolve().parents]:
        if (parent / "run.json").is_file():
            raise ConfigError(f"records={records} is (or is inside) the run directory {parent}: records live apart "
                              "from run directories (e.g. records=results/<study>/records)")
    if path.is_dir():
        for marker in ("run.json", "builds.json"):
            found = next(path.rglob(marker), None)
            if found is not None:
                raise ConfigError(f"records={records} holds a run directory ({found.parent}): records live apart "
                                  "from run directories (e.g. records=results/<study>/records)")


def _digest(body: dict) -> str:
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _clean(value):
    """JSON-able values, with non-finite floats as strings (so a record is plain JSON)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


def _restore(value):
    if isinstance(value, str) and value in ("nan", "inf", "-inf"):
        return float(value)
    if isinstance(value, dict):
        return {k: _restore(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_restore(v) for v in value]
    return value


def make_record(signature: dict, specs: Iterable[StageSpec], *, rows: list[dict] | None = None,
                finding: dict | None = None, report: dict | None = None, builds: dict | None = None,
                seconds: float | None = None) -> dict:
    """A record: the job's ``signature``, each planned stage's key (by its file), and either its ``rows`` or the
    ``finding`` it ended in, with what it took; sealed with a digest over all of it."""
    body = {"format": FORMAT, "signature": signature,
            "stages": {spec.filename: {"name": spec.name, "key": normalized(spec.key)} for spec in specs},
            "rows": _clean(rows) if rows is not None else None, "finding": finding,
            "report": _clean(report or {}), "builds": builds or {}, "seconds": seconds}
    return _restored({**body, "digest": _digest(body)})


def _restored(record: dict) -> dict:
    """A record as code uses it: non-finite numbers as floats (on disk they are strings, so the file is JSON)."""
    return {**record, "rows": _restore(record["rows"]), "report": _restore(record["report"])}


def read(directory: str | os.PathLike) -> dict:
    """The verified record in ``directory`` (``record.json``); raises :class:`RecordError` naming the file when it
    is unreadable, incomplete or edited (its digest)."""
    path = Path(directory) / RECORD
    try:
        record = json.loads(path.read_text())
    except FileNotFoundError:
        raise RecordError(f"no record at {path}") from None
    except (OSError, ValueError) as error:
        raise RecordError(f"record {path} is unreadable: {error}") from None
    fields = ("format", "signature", "stages", "rows", "finding", "report", "builds", "seconds", "digest")
    if not isinstance(record, dict) or any(field not in record for field in fields):
        raise RecordError(f"record {path} is incomplete (a record holds {', '.join(fields)})")
    body = {key: value for key, value in record.items() if key != "digest"}
    if record["format"] != FORMAT or _digest(body) != record["digest"]:
        raise RecordError(f"record {path} was edited or is damaged (its digest does not match its contents); "
                          "restore it from git or remove it to run the job again")
    if (record["rows"] is None) == (record["finding"] is None):
        raise RecordError(f"record {path} holds neither rows nor a finding")
    return _restored(record)


def save(record: dict, directory: str | os.PathLike) -> bool:
    """Writes ``record`` as ``directory/record.json`` atomically (nothing else is written or removed); returns
    whether it changed."""
    path = Path(directory) / RECORD
    text = json.dumps(_clean(record), indent=1, sort_keys=True, allow_nan=False) + "\n"
    if path.is_file() and path.read_text() == text:
        return False
    write_text(path, text)
    return True


def matches(record: dict, signature: dict, specs: Iterable[StageSpec]) -> bool:
    """Whether ``record`` is of a job with this ``signature`` and holds, for every stage of today's plan
    ``specs``, the key it has today."""
    if record["signature"] != signature:
        return False
    stages = record["stages"]
    return all(stages.get(spec.filename, {}).get("key") == normalized(spec.key) for spec in specs)


def finding_of(record: dict, signature: dict, specs: Iterable[StageSpec]) -> str | None:
    """The error of the finding ``record`` holds for a job with this ``signature``, if the stage it failed in has,
    in today's plan ``specs``, the key it failed with; else ``None``."""
    finding = record.get("finding")
    if not finding or record["signature"] != signature:
        return None
    keys = {spec.name: normalized(spec.key) for spec in specs}
    return finding.get("error") if keys.get(finding.get("stage"), object()) == finding.get("key") else None


def run_finding(run_dir: str | os.PathLike) -> dict | None:
    """The finding a recipe left in ``run_dir`` (``failed.json``: stage, key, error), or ``None``."""
    try:
        failure = json.loads((Path(run_dir) / FAILED).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(failure, dict) or not {"stage", "key", "error"} <= set(failure):
        return None
    return {"stage": failure["stage"], "key": failure["key"], "error": failure["error"]}


__all__ = ["FAILED", "RECORD", "RecordError", "check_records", "finding_of", "make_record", "matches", "read",
           "record_dir", "run_finding", "save"]
