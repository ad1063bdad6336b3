"""Job records: a finished job's results without its artifacts, verified when read, so a study goes on elsewhere.

A study's run directories hold large artifacts (experts, models, buffers) and stay out of git. A *record* is the
small part of a finished job, one file ``record.json``: what ran (the job's method and overrides: its
*signature*), the key of every stage its recipe planned, the per-episode result rows of its evaluations (read from
the evaluation artifacts those keys name, never from a loose CSV), what its stages took (``report``, ``builds``),
for a job that asks for one a per-action table derived from the same evaluations (``actions``: one row per latent
action of every evaluated episode, e.g. the gait it walked; :attr:`hierloco.pipeline.studies.Job.actions`), and a
digest over all of it. A record without a per-action table has no ``actions`` field at all, so the records made
before it existed verify unchanged. A study given a records directory (``records=results/<study>/records``) writes the
record of every job it ran or reused, and takes a job from its record when its run directory is missing (a fresh
machine, a cluster without shared storage) *only* if the record verifies (its digest), ran the same method and
overrides, and holds for every stage the recipe plans today the key it has today. An edited or incomplete record
is refused in one line naming the file. A job that ended in a finding about its setting
(:class:`hierloco.errors.Finding`) leaves a record too, holding the finding (stage, key, error): a later study
reports it as not evaluable, without running it, while that stage has today's key.

Records live apart from run directories: a records directory that is, holds or sits inside a run directory, one
that exists or one the study plans, is refused before any job (:func:`check_records`), and saving a record writes its
one file and deletes nothing. A records directory keeps one config per job: a record of the same job (its place)
made with another method or overrides is refused before any job, never overwritten (:func:`check_configs`).

What the digest protects: it detects accidents (a truncated copy, a merge gone wrong, a hand edit that forgot it),
not a deliberate edit with a recomputed digest. A record's rows are also checked against its own stages (labels,
episodes, success against the final error) when read, and re-derived from the job's evaluation artifacts wherever
they are present; for a shared record store, sign records with a key of your own (``HIERLOCO_RECORD_KEY`` names
a key file: HMAC-SHA256, :func:`record_key`): a signed record is verified when read, and with a key set an unsigned
or wrongly signed one is refused (``docs/pipeline.md``, "What a record's digest protects").

Example:
    >>> from hierloco.pipeline.records import record_dir
    >>> record_dir("results/compare/records", "outputs/sac/paper/a1_seed1")
    PosixPath('results/compare/records/sac/paper/a1_seed1')
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import sys
from pathlib import Path
from typing import Iterable

from hierloco.io import ArtifactError, write_text
from hierloco.pipeline.errors import ConfigError
from hierloco.pipeline.rundir import StageSpec, normalized

FAILED = "failed.json"  # a run's finding (hierloco.errors.Finding): the stage, its key and the error
RECORD = "record.json"
FORMAT = 2
KEY_VARIABLE = "HIERLOCO_RECORD_KEY"  # names the user's key file: records are then signed, and must be when read
MAC = "hmac"  # the field of a signed record: HMAC-SHA256 of its digest with the user's key (outside the digest)
KEY_BYTES = (16, 4096)  # the least and the most a key file holds


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


def check_records(records, run_dirs: Iterable[str | os.PathLike] = ()) -> None:
    """Refuses, before any work, a ``records`` setting that is not a directory path (or null), or that is, holds
    or sits inside a run directory (records and run directories never mix): one that exists, or one of ``run_dirs``
    (the run directories the study plans, which need not exist yet: ``records=outputs`` on a fresh machine would
    put every record inside a future run directory). Also reads the record key (:func:`record_key`), so a bad key
    file is refused before any work."""
    if records is None:
        return
    record_key()
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
    where = path.resolve()
    for run_dir in run_dirs:
        run = Path(run_dir).resolve()
        if where == run or where.is_relative_to(run):
            raise ConfigError(f"records={records} is (or is inside) the run directory {run_dir} this study plans: "
                              "records live apart from run directories (e.g. records=results/<study>/records)")
        if run.is_relative_to(where):
            raise ConfigError(f"records={records} would hold the run directory {run_dir} this study plans (its "
                              "records would lie inside run directories): records live apart from run directories "
                              "(e.g. records=results/<study>/records)")


def check_configs(records, jobs: Iterable[tuple[str | os.PathLike, dict]]) -> None:
    """Refuses, before any work, a study whose jobs (``(run_dir, signature)`` pairs) would replace a record of
    another config in ``records``: a records directory keeps one record per job, and a job's record is taken or
    replaced only by the same job (method and overrides; a changed stage key, as after a code change, is the same
    job, and its new record replaces the stale one). Two jobs of one study with one place in it are refused too."""
    if records is None:
        return
    places: dict[Path, str] = {}
    for run_dir, signature in jobs:
        directory = record_dir(records, run_dir)
        if directory in places and places[directory] != str(run_dir):
            raise ConfigError(f"records={records}: the jobs in {places[directory]} and {run_dir} would share one "
                              f"record ({directory}); give their run directories distinct last three parts")
        places[directory] = str(run_dir)
        if not (directory / RECORD).is_file():
            continue
        there = read(directory)["signature"]
        if there != signature:
            raise ConfigError(f"records={records} holds a record of {run_dir} made with another config "
                              f"({_difference(there, signature)}): a records directory keeps one config per job; "
                              f"give this study its own (records=...), or remove {directory / RECORD}")


def _difference(there: dict, here: dict) -> str:
    """What differs between two job signatures, in a bounded line."""
    if there.get("method") != here.get("method"):
        return f"method {str(there.get('method'))[:40]!r} there, {str(here.get('method'))[:40]!r} here"
    old, new = list(there.get("overrides") or []), list(here.get("overrides") or [])
    only = lambda a, b: ", ".join([str(o)[:60] for o in a if o not in b][:3]) or "none"  # noqa: E731
    if set(map(str, old)) == set(map(str, new)):
        return "the same overrides in another order"
    return f"overrides only there: {only(old, new)}; only here: {only(new, old)}"


def _digest(body: dict) -> str:
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def record_key() -> bytes | None:
    """The user's key for signing records: the contents of the key file ``HIERLOCO_RECORD_KEY`` names (16 to 4096
    bytes, e.g. ``python -c "import secrets; print(secrets.token_hex(32))" > ~/.config/hierloco/record.key``),
    else ``None`` (records are not signed). A key file that cannot be read, or holds too little or too much, is a
    :class:`ConfigError` in one line."""
    name = os.environ.get(KEY_VARIABLE, "")
    if not name.strip():
        return None
    path = Path(name).expanduser()
    try:
        if not path.is_file():
            raise ConfigError(f"{KEY_VARIABLE}={name} is not a key file (it names a file holding the key that signs "
                              "records: docs/pipeline.md)")
        with open(path, "rb") as file:
            key = file.read(KEY_BYTES[1] + 1).strip()
    except OSError as error:
        raise ConfigError(f"{KEY_VARIABLE}={name}: cannot read the key file ({error.strerror or error})") from None
    if not KEY_BYTES[0] <= len(key) <= KEY_BYTES[1]:
        raise ConfigError(f"{KEY_VARIABLE}={name}: a record key file holds {KEY_BYTES[0]} to {KEY_BYTES[1]} bytes, "
                          f"this one {'more' if len(key) > KEY_BYTES[1] else len(key)}")
    return key


def _mac(key: bytes, digest: str) -> str:
    return hmac.new(key, digest.encode(), hashlib.sha256).hexdigest()


def _clean(value):
    """JSON-able values, with non-finite floats as strings (so a record is plain JSON)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


LABELS = ("method", "robot", "setting", "task", "gait", "needed")  # a row's text columns (an action's gait)


def _restore(value):
    """The non-finite numbers :func:`_clean` wrote as strings, as floats again; a row's labels (:data:`LABELS`)
    stay text, so a task named ``nan`` or ``inf`` is still a name."""
    if isinstance(value, str) and value in ("nan", "inf", "-inf"):
        return float(value)
    if isinstance(value, dict):
        return {k: v if k in LABELS else _restore(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_restore(v) for v in value]
    return value


def make_record(signature: dict, specs: Iterable[StageSpec], *, rows: list[dict] | None = None,
                finding: dict | None = None, report: dict | None = None, builds: dict | None = None,
                seconds: float | None = None, actions: list[dict] | None = None) -> dict:
    """A record: the job's ``signature``, each planned stage's key (by its file), and either its ``rows`` or the
    ``finding`` it ended in, with what it took; with ``actions`` (a job with rows only) its per-action table, each
    row naming its ``setting``, ``task``, ``episode`` and ``action`` (0, 1, ... in each evaluated episode); sealed
    with a digest over all of it. Without ``actions`` the record has no such field (its digest is what it was before
    per-action tables existed)."""
    body = {"format": FORMAT, "signature": signature,
            "stages": {spec.filename: {"name": spec.name, "key": normalized(spec.key)} for spec in specs},
            "rows": _clean(rows) if rows is not None else None, "finding": finding,
            "report": _clean(report or {}), "builds": builds or {}, "seconds": seconds,
            **({"actions": _clean(actions)} if actions is not None else {})}
    return _restored({**body, "digest": _digest(body)})


def _restored(record: dict) -> dict:
    """A record as code uses it: non-finite numbers as floats (on disk they are strings, so the file is JSON)."""
    return {**record, "rows": _restore(record["rows"]), "report": _restore(record["report"]),
            **({"actions": _restore(record["actions"])} if "actions" in record else {})}


def read(directory: str | os.PathLike) -> dict:
    """The verified record in ``directory`` (``record.json``); raises :class:`RecordError` naming the file when it
    is unreadable, incomplete, edited (its digest), its rows disagree with its stages, or, with a key set
    (:func:`record_key`), it is not signed with that key."""
    return _read(directory, record_key())


def _read(directory: str | os.PathLike, key: bytes | None) -> dict:
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
    body = {key: value for key, value in record.items() if key not in ("digest", MAC)}
    if record["format"] != FORMAT or _digest(body) != record["digest"]:
        raise RecordError(f"record {path} was edited or is damaged (its digest does not match its contents); "
                          "restore it from git or remove it to run the job again")
    if key is not None and not isinstance(record.get(MAC), str):
        raise RecordError(f"record {path} is not signed, and {KEY_VARIABLE} is set: a record is taken only when "
                          "signed with that key (python -m hierloco.pipeline.records sign <records> signs the records "
                          "you trust)")
    if key is not None and not hmac.compare_digest(record[MAC], _mac(key, record["digest"])):
        raise RecordError(f"record {path} is not signed with the key {KEY_VARIABLE} names: it was edited, or signed "
                          "with another key")
    if (record["rows"] is None) == (record["finding"] is None):
        raise RecordError(f"record {path} holds neither rows nor a finding")
    problem = _rows_problem(record) if record["rows"] is not None else None
    if not problem and "actions" in record:
        problem = _actions_problem(record)
    if problem:
        raise RecordError(f"record {path}: its rows do not agree with its stages ({problem}); restore it from git or "
                          "remove it to run the job again")
    return _restored(record)


def _task_label(params: dict) -> str:
    """The task name an evaluation stage's rows carry: its ``task_name``, with ``_train`` for a training split
    (:func:`hierloco.pipeline.config.make_task_from_spec`)."""
    split = (params.get("task") or {}).get("split") if isinstance(params.get("task"), dict) else None
    return f"{params.get('task_name')}_train" if split == "train" else str(params.get("task_name"))


def _rows_problem(record: dict) -> str | None:
    """What in a record's rows disagrees with its own stages, or ``None``: every row belongs to one of its
    evaluation stages (setting, task, seed), every evaluation stage has rows numbered 0, 1, ... in order, a job's
    rows are of one method and robot, and a row's success is its final error within the success radius (or NaN, for
    a task without a success criterion). What it cannot see (a cost or final error edited with a recomputed
    digest) is the key's to see (:func:`record_key`) or the evaluation artifacts' (``checked_rows``)."""
    from hierloco.envs.tasks import SUCCESS_RADIUS

    stages = {}
    for entry in record["stages"].values():
        key = entry.get("key") if isinstance(entry, dict) else None
        params = key.get("params") if isinstance(key, dict) else None
        if isinstance(params, dict) and str(entry.get("name", "")).startswith("evaluation_") and \
                "task_name" in params and "setting" in params:
            stages[(params["setting"], _task_label(params))] = params.get("seed")
    episodes: dict[tuple, list] = {}
    for index, row in enumerate(record["rows"]):
        if not isinstance(row, dict):
            return f"row {index} is not a mapping"
        group = (row.get("setting"), row.get("task"))
        if stages and group not in stages:
            return (f"row {index} is of setting {str(group[0])[:40]!r} and task {str(group[1])[:40]!r}, which no stage "
                    "evaluates")
        if stages and row.get("seed") != stages[group]:
            return f"row {index} is of seed {str(row.get('seed'))[:20]}, its stage of seed {stages[group]}"
        episodes.setdefault(group, []).append(row.get("episode"))
        success, error = _restore(row.get("success")), _restore(row.get("final_error"))
        if isinstance(success, (int, float)) and isinstance(error, (int, float)) and not math.isnan(success) \
                and float(success) != float(error <= SUCCESS_RADIUS):
            return f"row {index}'s success is {success}, its final error {error:.4g} m"
    if len({(row.get("method"), row.get("robot")) for row in record["rows"]}) > 1:
        return "its rows are of more than one method or robot"
    missing = [f"{setting}/{task}" for setting, task in stages if (setting, task) not in episodes]
    if missing:
        return f"no rows of {', '.join(missing[:3])}"
    for (setting, task), numbers in episodes.items():
        if numbers != list(range(len(numbers))):
            return f"the rows of {setting}/{task} are numbered {str(numbers)[:60]}, not 0, 1, ..."
    return None


def _actions_problem(record: dict) -> str | None:
    """What in a record's per-action table (``actions``) disagrees with its rows, or ``None``: a table belongs to a
    record with rows, each of its rows is a mapping of an evaluated episode (its setting, task and episode among the
    record's rows), and every evaluated episode has its actions numbered 0, 1, ... in order."""
    actions = record["actions"]
    if record["rows"] is None or not isinstance(actions, list):
        return "a per-action table is a list of rows beside the record's rows"
    evaluated = {(row.get("setting"), row.get("task"), row.get("episode")) for row in record["rows"]}
    numbers: dict[tuple, list] = {episode: [] for episode in evaluated}
    for index, row in enumerate(actions):
        if not isinstance(row, dict):
            return f"action row {index} is not a mapping"
        episode = (row.get("setting"), row.get("task"), row.get("episode"))
        if episode not in numbers:
            return (f"action row {index} is of {str(episode[0])[:40]}/{str(episode[1])[:40]} episode "
                    f"{str(episode[2])[:20]}, which no row evaluates")
        numbers[episode].append(row.get("action"))
    for (setting, task, episode), found in sorted(numbers.items(), key=str):
        if found != list(range(len(found))) or not found:
            return (f"the actions of {setting}/{task} episode {episode} are numbered {str(found)[:60] or 'none'}, not "
                    "0, 1, ...")
    return None


def save(record: dict, directory: str | os.PathLike) -> bool:
    """Writes ``record`` as ``directory/record.json`` atomically (nothing else is written or removed), signed with
    the user's key when one is set (:func:`record_key`); returns whether it changed."""
    path = Path(directory) / RECORD
    record = {key: value for key, value in record.items() if key != MAC}
    key = record_key()
    if key is not None:
        record[MAC] = _mac(key, record["digest"])
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


def canonical(value) -> str:
    """A record's value (rows, stage keys) as one canonical text: two values are the same when their texts are (NaN
    the same as NaN)."""
    return json.dumps(_clean(value), sort_keys=True)


def sign(root: str | os.PathLike) -> int:
    """Signs, with the user's key (:func:`record_key`, required), every record under ``root`` that verifies (its
    digest and rows) and is not signed with that key yet; returns how many it signed. Sign only records you trust:
    the key vouches for them from then on."""
    if record_key() is None:
        raise ConfigError(f"{KEY_VARIABLE} is not set: it names the key file that signs records (docs/pipeline.md)")
    return sum(save(_read(path.parent, None), path.parent) for path in sorted(Path(root).rglob(RECORD)))


def main(argv: list[str] | None = None) -> int:
    """``python -m hierloco.pipeline.records sign <records>``: signs the records there (:func:`sign`)."""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0] != "sign":
        print("usage: python -m hierloco.pipeline.records sign <records directory>", file=sys.stderr)
        return 2
    try:
        count = sign(argv[1])
    except (ConfigError, RecordError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"signed {count} record(s) under {argv[1]} with the key {KEY_VARIABLE} names")
    return 0


__all__ = ["FAILED", "KEY_VARIABLE", "RECORD", "RecordError", "canonical", "check_configs", "check_records",
           "finding_of", "make_record", "matches", "read", "record_dir", "record_key", "run_finding", "save", "sign"]


if __name__ == "__main__":
    sys.exit(main())
