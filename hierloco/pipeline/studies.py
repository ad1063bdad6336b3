"""Studies (compare, ablations, adverse, ...) as jobs on Ray: one recipe run per job, one machine to a cluster.

A :class:`Job` is one recipe run (``recipes/<method>/train.py`` with overrides, into its own run directory). 
:func:`run_jobs` submits every job as a Ray task with the cores it asks for (``num_cpus``), on a local Ray instance
started for the study, or on the cluster at ``address`` / ``RAY_ADDRESS``. Each job runs the recipe in a subprocess
with as many simulation and torch threads as it has cores, so jobs never oversubscribe the machine. Finished jobs
are reused from their run directories (a killed study, re-run, resubmits only what did not finish); a failed job
is reported with its run directory and the others go on; the rows and record of every job come back to the driver
through Ray, and on a cluster its run directory and log too, so a cluster without shared storage works
(:func:`ray_session`; ``docs/pipeline.md``, "Studies on a Ray cluster"). A job's
rows are read from the evaluation artifacts its plan names (never from a loose CSV), so a run directory re-run with
another config is run again, not misreported. With a ``records`` directory (:mod:`hierloco.pipeline.records`) every
finished job also leaves its verified record there, and a job whose run directory is missing is taken from its
record while its stage keys are today's: a study runs in parts, on several machines or sessions. A job may keep a
per-action table in its record too (``Job.actions``, :func:`action_table`: e.g. the gait each latent action walked);
a record made before its job kept one is not taken for it, the job runs again. A job that ends in
a finding about its setting (:class:`hierloco.errors.Finding`) is not evaluable, a result rather than a failure: it
is kept (``failed.json`` in its run directory, its record) and reported from there, not run again, while the stage it
failed in has today's key.

A job may also ask for a share of a GPU (``gpus_per_job``, Ray's ``num_gpus``): its networks, training and planning
then run on ``device=cuda`` and its simulation on its cores; without one a job runs on ``device=cpu``.

Example:
    >>> jobs = [Job("lat", "outputs/lat/tiny/a1_seed0", ["preset=tiny"]), Job("lib", "outputs/lib/tiny/a1_seed0",
    ...         ["preset=tiny"])]
    >>> results = run_jobs(jobs, cores_per_job=1)   # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import math
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from hierloco.io import write_text
from hierloco.pipeline import records as job_records
from hierloco.pipeline.errors import ConfigError
from hierloco.pipeline.methods import METHODS

DONE = "job.json"  # written into a job's run directory when it finished
PARENT_PID = "HIERLOCO_PARENT_PID"  # set for a job's recipe: the worker it dies with (die_with_parent)


@dataclass
class Job:
    """One recipe run: ``method``'s recipe with ``overrides`` into ``run_dir``, on ``cores`` cores."""

    method: str
    run_dir: str
    overrides: list[str]
    cores: int = 1
    labels: dict = field(default_factory=dict)  # added to every result row (e.g. the ablation value)
    reuse_from: str | None = None  # another run directory whose finished stages this job starts from (their keys
    reuse_stages: tuple = ()       # equal to this job's own): those named here, or every one when it names none
    device: str | None = None  # where its networks run (device=...; None: the recipe's default); not in its signature
    records_from: str | None = None  # another study's records directory its record may be taken from (read only:
    #                                  e.g. the comparison's full-budget runs in the sample-efficiency study)
    actions: str | None = None  # "module:function" deriving its per-action table from its finished evaluations
    #                             (``function(job, specs) -> rows``, kept in its record: :func:`action_table`); not in
    #                             its signature, and a record without that table is not taken for it (the job runs)

    def command(self) -> list[str]:
        return [sys.executable, str(METHODS[self.method].train_script), f"run_dir={self.run_dir}",
                f"nthread={self.cores}", *self.runtime_overrides(), *self.overrides]

    def runtime_overrides(self) -> list[str]:
        """What the study adds to the job's own overrides to place it (its device), before them (so the job's own
        ``device=`` wins)."""
        return [f"device={self.device}"] if self.device is not None else []

    def signature(self) -> dict:
        return {"method": self.method, "overrides": list(self.overrides)}


@dataclass
class JobResult:
    job: Job
    ok: bool
    rows: list[dict]
    seconds: float
    reused: bool = False
    error: str = ""
    source: str = ""  # the directory its rows and timings came from: the run directory, or the job's record
    finding: bool = False  # it failed with a finding about its setting (``failed.json``): not evaluable, a result
    report: dict = field(default_factory=dict)  # the run's report.json (stage wall-clocks)
    builds: dict = field(default_factory=dict)  # the run's builds.json (what building each stage took)
    recorded_seconds: float = float("nan")  # a reused job: its wall-clock when it ran
    actions: list[dict] | None = None  # its per-action table (a job with ``Job.actions``), from wherever its rows came

    def __post_init__(self):
        self.source = self.source or self.job.run_dir


def resolve_method(name: str, variants) -> tuple[str, list[str]]:
    """A study's method: a method of the registry (:data:`hierloco.pipeline.methods.METHODS`), or a variant
    ``{recipe: ..., overrides: [...]}`` (e.g. ``ik_plain``: the IK recipe with the plain footstep law);
    returns the recipe and the variant's overrides."""
    variants = variants or {}
    if name in variants:
        variant = variants[name]
        recipe = variant.get("recipe")
        if recipe not in METHODS:
            raise ValueError(f"variant {name!r} names no recipe (recipe: one of {', '.join(METHODS.names())})")
        return recipe, list(variant.get("overrides", []))
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r} (recipes: {', '.join(METHODS.names())}; variants: "
                         f"{', '.join(variants) or 'none'})")
    return name, []


def planned_stages(job: Job) -> list:
    """The stages (``StageSpec``: name, key, file) the job's recipe plans today from its overrides; nothing is
    built or written."""
    from hierloco.pipeline.config import compose_recipe, prepare

    cfg = compose_recipe(job.method, [f"run_dir={job.run_dir}", *job.runtime_overrides(), *job.overrides])
    utils = METHODS[job.method].utils()
    planned = utils.plan(cfg, prepare(cfg, utils.checks))
    return [stage.spec for stage in (planned.stages() if hasattr(planned, "stages") else planned)]


def _plan_or_none(job: Job):
    try:
        return planned_stages(job)
    except Exception:  # noqa: BLE001  (any config problem: run the job, which reports it properly)
        return None


def evaluation_rows(run_dir: str | os.PathLike, specs) -> list[dict]:
    """The per-episode rows of a finished job: from the evaluation artifacts its plan names (``specs``), each
    validated as it loads and its rows checked against what they are derived from (its recording, its stage's
    labels, its summary: :func:`hierloco.pipeline.report.checked_rows`). Raises :class:`hierloco.io.ArtifactError`
    naming a bad one."""
    from hierloco.pipeline.report import checked_rows
    from hierloco.pipeline.validate import check_evaluation
    from hierloco.results import TaskEvaluation

    rows = []
    for spec in specs:
        if spec.name.startswith("evaluation_"):
            path = Path(run_dir) / spec.filename
            evaluation = TaskEvaluation.load(path)
            check_evaluation(evaluation, path)
            rows += checked_rows(evaluation, spec.key.get("params", {}), path)
    return rows


def finished(job: Job, specs=None) -> bool:
    """Whether ``job`` already finished in its run directory with the same method and overrides, and every stage
    its recipe plans today is there with the key it has today (a changed default or code path that enters a key
    makes the job run again, and the run then names the stage that changed)."""
    if not _holds_job(job.run_dir, job.signature()):
        return False
    specs = _plan_or_none(job) if specs is None else specs
    if specs is None:
        return False
    from hierloco.pipeline.rundir import RunDirectory

    try:
        return all(RunDirectory(job.run_dir, readonly=True).verify(specs).values())
    except Exception:  # noqa: BLE001  (a stage made with another config: the job runs and names it)
        return False


def _holds_job(run_dir: str | os.PathLike, signature: dict) -> bool:
    try:
        return json.loads((Path(run_dir) / DONE).read_text()).get("signature") == signature
    except (OSError, ValueError, AttributeError):
        return False


def _json_file(path: Path) -> dict:
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}


def run_record(job: Job, specs) -> dict:
    """The record of the job finished in its run directory: its rows derived from its planned evaluations
    (:func:`evaluation_rows`), and what its stages took as its ``job.json`` kept it when it finished
    (:func:`done_text`), not as a later run of the directory with another config left ``report.json`` and
    ``builds.json`` (a ``job.json`` from before it kept them gives those files as they are)."""
    run_dir = Path(job.run_dir)
    done = _json_file(run_dir / DONE)

    def kept(name: str) -> dict:
        return done[name] if isinstance(done.get(name), dict) else _json_file(run_dir / f"{name}.json")

    return job_records.make_record(job.signature(), specs, rows=evaluation_rows(run_dir, specs),
                                   report=kept("report"), builds=kept("builds"), seconds=done.get("seconds"),
                                   actions=action_table(job, specs))


def action_table(job: Job, specs) -> list[dict] | None:
    """The per-action table of the job's evaluations among ``specs`` in its run directory, made by the function
    ``job.actions`` names (``"package.module:function"``, called with the job and ``specs``: one row per latent
    action of every evaluated episode, with its ``setting``, ``task``, ``episode`` and ``action``; e.g. the gait study's
    :func:`hierloco.recipes.gaits.run.action_table`); ``None`` for a job that asks for none."""
    if not job.actions:
        return None
    import importlib

    module, _, name = job.actions.partition(":")
    return getattr(importlib.import_module(module), name)(job, specs)


def done_text(job: Job, seconds: float) -> str:
    """``job.json``, written when the job finished: its signature, its wall-clock, and what its stages took as its
    run left them (its ``report.json`` and ``builds.json`` now), so its record keeps the timings of the build it
    reports (:func:`run_record`)."""
    run_dir = Path(job.run_dir)
    return json.dumps({"signature": job.signature(), "seconds": seconds, "report": _json_file(run_dir / "report.json"),
                       "builds": _json_file(run_dir / "builds.json")})


def finding_record(job: Job, specs, finding: dict) -> dict:
    run_dir = Path(job.run_dir)
    return job_records.make_record(job.signature(), specs, finding=finding,
                                   builds=_json_file(run_dir / "builds.json"))


def _seconds(record: dict) -> float:
    return float(record["seconds"]) if isinstance(record.get("seconds"), (int, float)) else float("nan")


def recorded(job: Job, records: str, specs=None) -> dict | None:
    """The job's verified record under ``records`` when it is of this job (method, overrides) with today's stage
    keys, else ``None``. An edited or damaged record raises :class:`hierloco.pipeline.records.RecordError`."""
    directory = job_records.record_dir(records, job.run_dir)
    if not (directory / job_records.RECORD).is_file():
        return None
    record = job_records.read(directory)
    specs = _plan_or_none(job) if specs is None else specs
    if specs is None or record["rows"] is None or not job_records.matches(record, job.signature(), specs):
        return None
    if job.actions and record.get("actions") is None:  # made before its job kept a per-action table: run it again
        return None
    return record


def _lacks_actions(job: Job, records: str, specs) -> bool:
    """Whether ``records`` holds a current record of the job (:func:`recorded` but for this) without the per-action
    table the job asks for (``job.actions``)."""
    directory = job_records.record_dir(records, job.run_dir)
    if not job.actions or specs is None or not (directory / job_records.RECORD).is_file():
        return False
    record = job_records.read(directory)
    return (record["rows"] is not None and record.get("actions") is None
            and job_records.matches(record, job.signature(), specs))


def found(job: Job, records: str | None = None, specs=None) -> tuple[str, str, dict] | None:
    """The finding a job ended in (``failed.json`` in its run directory, else its record under ``records``) while
    the stage it failed in has today's key: ``(error, where, finding)``, else ``None``."""
    specs = _plan_or_none(job) if specs is None else specs
    if specs is None:
        return None
    failure = job_records.run_finding(job.run_dir)
    if failure is not None and _json_file(Path(job.run_dir) / job_records.FAILED).get("signature") == job.signature():
        record = job_records.make_record(job.signature(), specs, finding=failure)
        error = job_records.finding_of(record, job.signature(), specs)
        if error is not None:
            return error, job.run_dir, failure
    if records:
        directory = job_records.record_dir(records, job.run_dir)
        if (directory / job_records.RECORD).is_file():
            record = job_records.read(directory)
            error = job_records.finding_of(record, job.signature(), specs)
            if error is not None:
                return error, str(directory), record["finding"]
    return None


def execute(job: Job, fetch_run_dir: bool = False) -> dict:
    """Runs one job here (in a subprocess); returns its outcome, its result rows (from the evaluation artifacts its
    plan names) and its record. This is the body of the Ray task. A job that ends in a finding (the recipe's
    ``failed.json``) comes back with ``finding`` set and its record. With ``fetch_run_dir`` (a job on a cluster) the
    outcome also holds this run's part of the job's log (``log``, bytes) and, when the job finished or ended in a
    finding, its run directory as a gzipped tar archive (``archive``): the driver unpacks them
    (:func:`bring_back`)."""
    log = job_log(job)
    log.parent.mkdir(parents=True, exist_ok=True)
    logged = log.stat().st_size if log.exists() else 0  # where this run's part of the log begins
    outcome = _execute(job, log)
    if fetch_run_dir:
        outcome["log"] = log.read_bytes()[logged:]
        if outcome["ok"] or outcome["finding"]:
            outcome["archive"] = pack(job.run_dir)
    return outcome


def pack(run_dir: str | os.PathLike) -> bytes:
    """A run directory as a gzipped tar archive (its paths relative to it), as a job on a cluster sends it back."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        archive.add(run_dir, arcname=".")
    return buffer.getvalue()


def job_log(job: Job) -> Path:
    """The log of a job's recipe runs: ``<run_dir>.log`` beside its run directory."""
    return Path(job.run_dir).parent / f"{Path(job.run_dir).name}.log"


def _execute(job: Job, log: Path) -> dict:
    start = time.perf_counter()
    if job.reuse_from:
        _reuse_stages(job)
    (Path(job.run_dir) / job_records.FAILED).unlink(missing_ok=True)  # only this run's finding counts
    env = {**os.environ, "OMP_NUM_THREADS": str(job.cores), "MKL_NUM_THREADS": str(job.cores),
           "WANDB_SILENT": "true"}
    with open(log, "a") as out:  # appended: a re-run (reusing stages) keeps the log of the run that built them
        out.write(f"=== {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}: {' '.join(job.command())}\n")
        out.flush()
        code = subprocess.run(job.command(), stdout=out, stderr=subprocess.STDOUT, cwd=os.getcwd(),
                              env={**env, PARENT_PID: str(os.getpid())}).returncode
    outcome = {"ok": code == 0, "seconds": time.perf_counter() - start, "rows": [], "error": "", "archive": None,
               "log": None, "record": None, "finding": False}
    specs = _plan_or_none(job)
    if code != 0:
        failure = job_records.run_finding(job.run_dir)
        if failure is not None and specs is not None:  # a finding: the same config fails the same way
            write_text(Path(job.run_dir) / job_records.FAILED,
                       json.dumps({"signature": job.signature(), **failure}, indent=2))
            outcome.update(finding=True, error=failure["error"] + f" (log: {log})",
                           record=finding_record(job, specs, failure))
            return outcome
        tail = log.read_text().strip().splitlines()[-3:]
        outcome["error"] = f"exit code {code}: " + " | ".join(tail) + f" (log: {log})"
        return outcome
    write_text(Path(job.run_dir) / DONE, done_text(job, outcome["seconds"]))
    try:
        record = run_record(job, specs)
    except Exception as error:  # noqa: BLE001  (an evaluation artifact that does not load: the job is not usable)
        outcome.update(ok=False, error=f"its results cannot be read: {error} (log: {log})")
        return outcome
    outcome.update(rows=record["rows"], record=record, report=record["report"], builds=record["builds"])
    return outcome


def die_with_parent() -> None:
    """Called by a recipe as it starts (Linux): if a study's worker started it (``HIERLOCO_PARENT_PID``), it gets a
    SIGTERM when that worker dies, so a killed study leaves no recipe running on (finished stages are kept, the run
    directory's lock is released); if the worker is already gone, it stops at once."""
    parent = os.environ.get(PARENT_PID)
    if not parent or not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != int(parent):  # the worker died before the line above
        sys.exit("the study worker that started this run is gone")


def reusable_stages(job: Job, specs=None, source_plan=None) -> list:
    """The stages of the job's plan (``specs``, else planned now) that it can start from: those ``job.reuse_from``
    holds finished with the key this job plans, of those ``job.reuse_stages`` names (of all when it names none). A
    stage made with another config is never taken, so a job may name a source that shares only its first stages.
    ``source_plan`` (the source's planned stages) stands for the source when it is a job still to run."""
    from hierloco.pipeline.rundir import ArtifactError, RunDirectory, normalized

    if not job.reuse_from:
        return []
    source = RunDirectory(job.reuse_from, readonly=True)
    planned = {spec.filename: normalized(spec.key) for spec in source_plan or ()}

    def shared(spec) -> bool:
        if source_plan is not None:
            return planned.get(spec.filename) == normalized(spec.key)
        try:
            return source.check(spec.name, spec.key, spec.filename)
        except ArtifactError:  # made with another config, or unreadable: built anew
            return False

    return [spec for spec in (planned_stages(job) if specs is None else specs)
            if (not job.reuse_stages or spec.name in job.reuse_stages) and shared(spec)]


def _reuse_stages(job: Job) -> None:
    """Copies into the job's run directory the stages it can start from (:func:`reusable_stages`) that it lacks,
    each key before its artifact and the artifact atomically: a copy cut short leaves a stage to build, never a
    stage without its key."""
    from hierloco.io import atomic_path
    from hierloco.pipeline.rundir import BUILDS_NAME, RunDirectory

    try:
        specs = reusable_stages(job)
    except Exception:  # noqa: BLE001  (a config problem: the job reports it when it runs)
        return
    source, target = RunDirectory(job.reuse_from, readonly=True), Path(job.run_dir)
    built, copied = source.builds(), {}
    for spec in specs:
        if (target / spec.filename).exists():
            continue
        for name in (f"{spec.filename}.key.json", spec.filename):
            with atomic_path(target / name) as tmp:
                shutil.copyfile(source.path / name, tmp)
        if spec.name in built:  # what building it took, so the job's compute still counts it
            copied[spec.name] = {**built[spec.name], "copied_from": str(source.path)}
    if copied:
        builds = RunDirectory(target, readonly=True).builds()
        write_text(target / BUILDS_NAME, json.dumps({**builds, **copied}, indent=1, sort_keys=True))


def _progress(done: int, running: int, failed: int, pending: int, start: float, durations: list[float],
              slots: int, finished_at: float) -> str:
    """The study's progress line. The estimate is made when a job ends (the jobs still running then taken as half
    done, each job as long as the mean of those that ran) and counts down from there."""
    now = time.perf_counter()
    line = (f"study: {done} done, {running} running, {failed} failed, {pending} pending; "
            f"elapsed {(now - start) / 60:.1f} min")
    if durations and (running or pending):
        mean = sum(durations) / len(durations)
        left = mean * (running / 2 + pending) / max(1, slots) - (now - finished_at)
        line += f", about {left / 60:.1f} min to go" if left > 0 else ", taking longer than estimated"
    return line


def check_records(records, jobs: Sequence[Job] = ()) -> None:
    """See :func:`hierloco.pipeline.records.check_records` (with the run directories ``jobs`` plan) and
    :func:`hierloco.pipeline.records.check_configs` (one config per job in a records directory)."""
    job_records.check_records(records, [job.run_dir for job in jobs])
    job_records.check_configs(records, [(job.run_dir, job.signature()) for job in jobs])


def _from_records(job: Job, records: str | None, specs) -> tuple[Path, dict] | None:
    """The job's current record and where it lies: under the study's ``records``, else under the directory
    ``job.records_from`` names (read only), else ``None``. Where the job's run directory holds evaluations its plan
    names (a record that came with its run directory), the record's rows are re-derived from them
    (:func:`evaluation_rows`) and must be the same: a record whose rows differ is refused
    (:class:`hierloco.pipeline.records.RecordError`, one line naming both)."""
    for root in (records, job.records_from):
        if root and (record := recorded(job, root, specs)) is not None:
            directory = job_records.record_dir(root, job.run_dir)
            _check_with_run(job, specs, record, directory / job_records.RECORD)
            return directory, record
        if root and _lacks_actions(job, root, specs):
            print(f"study: the record {job_records.record_dir(root, job.run_dir) / job_records.RECORD} holds no "
                  f"per-action table (it was made before its job kept one): running the job again", flush=True)
    return None


def _measured(row: dict) -> dict:
    """``row`` without the metrics it does not have (``None`` or NaN: a table of several tasks fills a column one
    task lacks, such as a goal's ``path_distance``, with NaN), so a record and its run's evaluations compare by what
    was measured."""
    def missing(value) -> bool:
        return value is None or value == "nan" or (isinstance(value, float) and math.isnan(value))

    return {name: value for name, value in row.items() if not missing(value)}


def _same_value(a, b) -> bool:
    """Two values of a row are the same: equal labels, or numbers equal to 1e-9 relative (a metric re-derived from
    the recorded CoM paths may differ in its last digits from one BLAS thread count to another; an edit does not)."""
    numbers = (int, float)
    if isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool) and not isinstance(b, bool):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    return job_records.canonical(a) == job_records.canonical(b)


def _same_row(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all(_same_value(a[name], b[name]) for name in a)


def _check_with_run(job: Job, specs, record: dict, where: Path) -> None:
    """Refuses ``record`` when its rows differ from those derived from the evaluations its job's run directory holds
    with today's keys (none there: nothing to compare)."""
    from hierloco.pipeline.rundir import RunDirectory

    if not Path(job.run_dir).is_dir():
        return
    run = RunDirectory(job.run_dir, readonly=True)
    present = []
    for spec in specs:
        try:
            if spec.name.startswith("evaluation_") and run.check(spec.name, spec.key, spec.filename):
                present.append(spec)
        except Exception:  # noqa: BLE001  (made with another config, or unreadable: not this record's evaluation)
            continue
    if not present:
        return
    order = lambda row: (str(row.get("setting")), str(row.get("task")), row.get("episode", 0))  # noqa: E731
    derived = sorted((_measured(row) for row in evaluation_rows(job.run_dir, present)), key=order)
    groups = {(row["setting"], row["task"]) for row in derived}
    held = sorted((_measured(row) for row in record["rows"] if (row.get("setting"), row.get("task")) in groups),
                  key=order)
    if len(held) == len(derived) and all(_same_row(there, here) for there, here in zip(derived, held)):
        _check_actions_with_run(job, present, record, where)
        return
    first = f"{len(derived)} rows there, {len(held)} in the record"
    for there, here in zip(derived, held):
        differ = [name for name in sorted(set(there) | set(here)) if not _same_value(there.get(name), here.get(name))]
        if differ:
            first = (f"{there.get('setting')}/{there.get('task')} episode {there.get('episode')}: " + ", ".join(
                f"{name} {there.get(name)!r} there, {here.get(name)!r} in the record" for name in differ[:2]))[:300]
            break
    if _another_build(record, job.run_dir):
        raise job_records.RecordError(
            f"record {where}: the job's run directory {job.run_dir} holds another build of it (its stages were made "
            f"again after the record's), whose evaluations differ from the record's rows ({first}): keep the one you "
            "want (move the run directory away to use the record, or the record to use the run directory)")
    raise job_records.RecordError(f"record {where}: its rows differ from the evaluations in the job's run directory "
                                  f"{job.run_dir} ({first}); the record or that run directory was edited: remove the "
                                  "one you do not trust")


def _check_actions_with_run(job: Job, present, record: dict, where: Path) -> None:
    """Refuses ``record`` when its per-action table differs from the one derived from the evaluations its job's
    run directory holds with today's keys (``present``), as :func:`_check_with_run` does its rows."""
    if not job.actions or record.get("actions") is None:
        return
    order = lambda row: (str(row.get("setting")), str(row.get("task")), row.get("episode", 0),  # noqa: E731
                         row.get("action", 0))
    derived = sorted((_measured(row) for row in action_table(job, present)), key=order)
    groups = {(row["setting"], row["task"]) for row in derived}
    held = sorted((_measured(row) for row in record["actions"] if (row.get("setting"), row.get("task")) in groups),
                  key=order)
    if len(held) == len(derived) and all(_same_row(there, here) for there, here in zip(derived, held)):
        return
    first = next((f"{there.get('task')} episode {there.get('episode')} action {there.get('action')}"
                  for there, here in zip(derived, held) if not _same_row(there, here)),
                 f"{len(derived)} actions there, {len(held)} in the record")
    raise job_records.RecordError(f"record {where}: its per-action table differs from the evaluations in the job's "
                                  f"run directory {job.run_dir} ({first[:200]}); the record or that run directory was "
                                  "edited: remove the one you do not trust")


def _another_build(record: dict, run_dir: str) -> bool:
    """Whether the run directory's stages were built at other times than the record's (``builds.json`` against the
    record's ``builds``: a stage both name with another ``finished`` time): the job was run again since, and a
    difference in its rows is a new build's (training on another thread count differs in its last digits and
    beyond), not an edit."""
    try:
        here = json.loads((Path(run_dir) / "builds.json").read_text())
    except (OSError, ValueError):
        return False
    recorded = record.get("builds") or {}
    if not isinstance(here, dict) or not isinstance(recorded, dict):
        return False
    return any(isinstance(here.get(name), dict) and isinstance(entry, dict)
               and here[name].get("finished") != entry.get("finished")
               for name, entry in recorded.items() if name in here)


def _keep_record(records: str | None, job: Job, record: dict | None) -> None:
    """Saves the job's ``record`` under ``records``, saying so when it replaces a record of the same job and stage
    keys whose rows differ (the rows derived from the job's evaluations replace an edited record)."""
    if not (records and record):
        return
    directory = job_records.record_dir(records, job.run_dir)
    try:
        old = job_records.read(directory) if (directory / job_records.RECORD).is_file() else None
    except job_records.RecordError:
        old = None
    if old is not None and old["rows"] is not None and record["rows"] is not None and \
            old["signature"] == record["signature"] and \
            job_records.canonical(old["stages"]) == job_records.canonical(record["stages"]) and \
            job_records.canonical(old["rows"]) != job_records.canonical(record["rows"]):
        print(f"study: the record {directory / job_records.RECORD} differed from the evaluations in {job.run_dir}: "
              "replaced by their rows", flush=True)
    job_records.save(record, directory)


def check_ray_address(address: str, timeout: float = 10.0) -> None:
    """Refuses, in one line and within ``timeout`` seconds, a Ray address that does not answer (``host:port``,
    ``ray://host:port``); ``auto`` and ``local`` are left to Ray."""
    import socket
    from urllib.parse import urlparse

    if address in ("auto", "local"):
        return
    parsed = urlparse(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parsed.hostname, parsed.port
    except ValueError:
        host = port = None
    if not host or not port:
        raise ConfigError(f"ray.address={address!r} is not host:port (or ray://host:port)")
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as error:
        raise ConfigError(f"cannot reach a Ray cluster at {address} ({error.strerror or error}): start it, or leave "
                          "ray.address and RAY_ADDRESS unset for a local instance") from None


# What a job on a cluster takes from the driver's environment (the rendering backend, the W&B mode): the rest of
# its environment is the node's.
FORWARDED_ENV = ("MUJOCO_GL", "PYOPENGL_PLATFORM", "WANDB_MODE")
# What a cluster's copy of the project leaves out (besides what the project's .gitignore names, which Ray leaves
# out too): run directories, the virtual environment, git's history.
CLUSTER_EXCLUDES = ["outputs", ".venv", ".git", "__pycache__", "*.egg-info"]
_SOCKET_ROOM = 66  # what Ray adds to its temporary folder for its sockets (session_<time>_<pid>/sockets/plasma_store)


def project_root() -> Path:
    """The project's folder (the checkout holding ``hierloco/``; for an installed package, the working directory):
    on a cluster, every job runs in a copy of it."""
    import hierloco

    checkout = Path(next(iter(hierloco.__path__))).resolve().parent
    return checkout if (checkout / "pyproject.toml").is_file() else Path.cwd().resolve()


def cluster_runtime_env() -> dict:
    """Ray's ``runtime_env`` of a study's jobs on a cluster: the project (:func:`project_root`, without
    :data:`CLUSTER_EXCLUDES`) uploaded as their working directory, so every node runs this machine's code and a
    job's relative run directory lies in that copy (it comes back, :func:`bring_back`); the variables of
    :data:`FORWARDED_ENV` this process has."""
    return {"working_dir": str(project_root()), "excludes": list(CLUSTER_EXCLUDES),
            "env_vars": {name: os.environ[name] for name in FORWARDED_ENV if name in os.environ}}


def _private_temp_dir() -> str:
    """A new folder for a local Ray instance's files (sessions, sockets, logs): in the temporary folder
    (``TMPDIR``), or ``/tmp`` where that path is too long for Ray's sockets (108 bytes on Linux)."""
    root = tempfile.gettempdir()
    if len(os.path.join(root, "hierloco-ray-xxxxxxxx")) + _SOCKET_ROOM > 107:
        root = "/tmp"
    return tempfile.mkdtemp(prefix="hierloco-ray-", dir=root)


# Ray's logger that says, as every local instance starts, that it uses token authentication (Ray's default)
_TOKEN_NOTICE = "ray._private.authentication.authentication_token_setup"


@contextlib.contextmanager
def _quiet(logger: str):
    """Within the block, ``logger`` says only errors."""
    import logging

    log = logging.getLogger(logger)
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _set_sigterm(handler) -> None:
    if handler is not None:
        with contextlib.suppress(ValueError):  # not the main thread: signals are the main thread's
            signal.signal(signal.SIGTERM, handler)


@contextlib.contextmanager
def ray_session(address: str | None = None):
    """Ray for a study, shut down when the block ends, however it ends (Ctrl-C and SIGTERM included, so the jobs
    stop with it). With ``address`` (``host:port``, ``ray://host:port``): the cluster there, its jobs running in a
    copy of the project (:func:`cluster_runtime_env`); a cluster that refuses this process (token authentication:
    ``RAY_AUTH_MODE=token`` and the cluster's token) is a :class:`ConfigError` in one line. Without: a local
    instance of this study's own (``address="local"``, in a private temporary folder removed at the end), whatever
    other Ray clusters this machine runs or left their address behind (Ray's ``ray_current_cluster``). The
    process's SIGTERM handler stays (``ray.init`` puts its own in, which ends the process without a word). A Ray
    already initialised in this process (a notebook's, a test's) is used as it is and left running."""
    import ray

    if ray.is_initialized():
        yield
        return
    handler = signal.getsignal(signal.SIGTERM)
    temp_dir = None
    # As this process joins Ray, Ray's core puts in a C++ handler for SIGTERM (a stack dump, then abort: exit 134),
    # which a SIGTERM during ray.init would meet. Ray's switch for it is RAY_DISABLE_FAILURE_SIGNAL_HANDLER, read as
    # Ray is imported; set here for this process alone (the Ray processes it starts keep their crash reports).
    constants = ray._private.ray_constants
    failure_handler = getattr(constants, "RAY_DISABLE_FAILURE_SIGNAL_HANDLER", False)
    constants.RAY_DISABLE_FAILURE_SIGNAL_HANDLER = True
    try:
        try:
            if address:
                _connect(address)
            else:  # its workers run at normal priority (Ray lowers it by default)
                from hierloco.envs.batched_sim import available_cores

                os.environ.setdefault("RAY_worker_niceness", "0")
                temp_dir = _private_temp_dir()
                with _quiet(_TOKEN_NOTICE):
                    ray.init(address="local", num_cpus=available_cores(), include_dashboard=False,
                             log_to_driver=False, configure_logging=False, _temp_dir=temp_dir)
        except SystemExit as exit_:  # Ray's SIGTERM handler, while ray.init ran: what SIGTERM does in this process
            if exit_.code == signal.SIGTERM and callable(handler):
                handler(signal.SIGTERM, None)
            raise
        if callable(handler):
            _set_sigterm(handler)
        yield
    finally:
        ray.shutdown()  # also stops the processes of a ray.init that a signal cut short (not yet initialized)
        constants.RAY_DISABLE_FAILURE_SIGNAL_HANDLER = failure_handler
        _set_sigterm(handler)
        if temp_dir is not None:
            _remove_folder(temp_dir)


def _processes_naming(folder: str) -> list[int]:
    """This user's live processes (not this one, not zombies) whose command line names ``folder``: the Ray
    processes of a local instance started in it (every one is given its session folder). Empty where there is no
    ``/proc``."""
    found, me, uid = [], os.getpid(), os.getuid()
    try:
        entries = os.listdir("/proc")
    except OSError:
        return found
    needle = folder.encode()
    for name in entries:
        if not name.isdigit() or int(name) == me:
            continue
        try:
            if os.stat(f"/proc/{name}").st_uid != uid:
                continue
            with open(f"/proc/{name}/cmdline", "rb") as cmdline:
                if needle not in cmdline.read():
                    continue
            with open(f"/proc/{name}/stat") as stat:
                if stat.read().rpartition(") ")[2].split()[0] == "Z":
                    continue
        except OSError:  # gone meanwhile
            continue
        found.append(int(name))
    return found


def _remove_folder(path: str, patience_s: float = 15.0) -> None:
    """Removes the folder this process made for its own Ray instance, after stopping every process still naming it:
    a ``ray.init`` cut short by a signal leaves processes that ``ray.shutdown`` does not know (a runtime-env agent
    its raylet was starting), and they write logs into the folder. Each round kills what names the folder (SIGKILL:
    ``ray.shutdown`` already asked) and removes the folder; done once no process names it and it stays gone for a
    second."""
    deadline = time.monotonic() + patience_s
    quiet_since = None
    while time.monotonic() < deadline:
        left = _processes_naming(path)
        for pid in left:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        if left or os.path.exists(path):
            shutil.rmtree(path, ignore_errors=True)
            quiet_since = None
        elif quiet_since is None:
            quiet_since = time.monotonic()
        elif time.monotonic() - quiet_since >= 1.0:
            return
        time.sleep(0.2)


def _connect(address: str) -> None:
    """Joins the cluster at ``address`` (see :func:`ray_session`). What Ray's core prints to the process's stderr
    while it tries (one warning a second) is read, not shown: a refusal becomes one line."""
    import ray

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as said:
        os.dup2(said.fileno(), 2)
        try:
            ray.init(address=address, log_to_driver=False, configure_logging=False,
                     runtime_env=cluster_runtime_env())
            error = None
        except (ConnectionError, RuntimeError, ray.exceptions.RayError) as raised:
            error = raised
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        if error is None:
            return
        said.seek(0)
        text = said.read().decode(errors="replace")
    from hierloco.pipeline.errors import one_line

    if "InvalidAuthToken" in text or isinstance(error, ray.exceptions.AuthenticationError):
        raise ConfigError(f"the Ray cluster at {address} refused this process: it asks for a token (Ray's token "
                          "authentication); set RAY_AUTH_MODE=token and the cluster's token (RAY_AUTH_TOKEN, or the "
                          "file RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token names) in this process's environment "
                          "(docs/pipeline.md)") from None
    raise ConfigError(f"cannot join the Ray cluster at {address}: {one_line(error)[:300]}") from None


def bring_back(job: Job, outcome: dict) -> str | None:
    """Writes here what a job on a cluster sent back (:func:`execute` with ``fetch_run_dir``): this run's part of
    its log, appended to :func:`job_log` (unless that log already ends with it: storage shared with the node), and
    its run directory, unpacked (tarfile's ``data`` filter: nothing outside the folder) into a new folder that then
    takes the run directory's place when none is here or an empty one. A run directory that is here already is
    left as it is: it is the node's own when storage is shared (its ``job.json`` or ``failed.json`` the same), else
    the line returned says that the job's run directory was not brought back (its rows and record were)."""
    log, text = job_log(job), outcome.get("log")
    if text and not (log.is_file() and log.read_bytes().endswith(text)):
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, "ab") as out:
            out.write(text)
    if not outcome.get("archive"):
        return None
    run_dir = Path(job.run_dir)
    if run_dir.is_dir() and any(run_dir.iterdir()):
        with tarfile.open(fileobj=io.BytesIO(outcome["archive"]), mode="r:gz") as archive:
            for name in (DONE, job_records.FAILED):
                member = next((m for m in archive.getmembers() if m.name == f"./{name}" and m.isfile()), None)
                if member is not None and (run_dir / name).is_file() and \
                        archive.extractfile(member).read() == (run_dir / name).read_bytes():
                    return None
        return (f"{run_dir} here holds another run: the run directory job {job.method} made on the cluster was not "
                "brought back (its rows and record were); move it away and run the study again to fetch it")
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    incoming = Path(tempfile.mkdtemp(prefix=f".{run_dir.name}.incoming-", dir=run_dir.parent))
    try:
        with tarfile.open(fileobj=io.BytesIO(outcome["archive"]), mode="r:gz") as archive:
            archive.extractall(incoming, filter="data")
        os.rename(incoming, run_dir)
    except BaseException:
        shutil.rmtree(incoming, ignore_errors=True)
        raise
    return None


def machine_slots(cores_per_job: int, gpus_per_job: float = 0.0, *, cores: int | None = None,
                  gpus: int | None = None) -> tuple[int, str]:
    """How many jobs this machine runs at once (its cores over ``cores_per_job``, and its GPUs over ``gpus_per_job``
    when jobs ask for a share of one), and the machine in words."""
    from hierloco.envs.batched_sim import available_cores

    cores = available_cores() if cores is None else int(cores)
    if gpus is None:
        import torch

        gpus = torch.cuda.device_count() if torch.cuda.is_available() else 0
    slots = max(1, cores // max(1, int(cores_per_job)))
    words = (f"{cores} cores, {gpus} GPU{'s' if gpus != 1 else ''}; "
             f"{cores_per_job} core{'s' if cores_per_job != 1 else ''}")
    if gpus_per_job > 0:
        slots = min(slots, max(0, int(gpus / gpus_per_job + 1e-9)))
        words += f" and {gpus_per_job:g} GPU"
    words += " a job"
    return slots, words


def plan_text(jobs: Sequence[Job], done: dict[int, JobResult], slots: int | None,
              records: str | None = None, machine: str | None = None) -> str:
    """The study's plan: every job's state (finished here, from its record, to run) and the compute each job to run
    will take: over the stages its recipe plans that are not finished yet (in its run directory, or among the stages
    it reuses), the mean recorded build time of the same stage in the finished jobs of the same method and robot
    (this study's, and with ``records``, every recorded job of that method, preset and robot: another seed's run
    of an earlier study estimates this seed's). Then the total, and the wall-clock it makes on ``slots`` jobs at once
    on ``machine`` (its cores and GPUs, in words; ``slots=None``: a cluster, not said). Build times are those of the
    machines that recorded them: a job moved to a GPU (``gpus_per_job``) is estimated from its CPU runs."""
    from hierloco.pipeline.rundir import RunDirectory
    from hierloco.pipeline.report import job_compute

    def group(job: Job) -> tuple[str, str]:
        return job.labels.get("method", job.method), Path(job.run_dir).name.rsplit("_seed", 1)[0]

    def finished_stages(directory: str | None, specs) -> set:
        if not directory or not Path(directory).is_dir():
            return set()
        try:
            return {name for name, ok in RunDirectory(directory, readonly=False).verify(specs).items() if ok}
        except Exception:  # noqa: BLE001  (a stage made with another config: it will be built, and the run says so)
            return set()

    known: dict[tuple, list[float]] = {}
    timed: set[str] = set()

    def learn(source: str, report: dict, builds: dict, key: tuple[str, str]) -> None:
        if source in timed:
            return
        timed.add(source)
        for name, seconds in job_compute(report, builds).items():
            if seconds is not None:
                known.setdefault((*key, name), []).append(seconds / 60)

    for result in done.values():
        learn(str(Path(result.source).resolve()), result.report, result.builds, group(result.job))
    for index, job in enumerate(jobs):
        if records and index not in done:
            here = job_records.record_dir(records, job.run_dir)
            for sibling in sorted(here.parent.glob(f"{group(job)[1]}_seed*")):
                try:
                    record = job_records.read(sibling)
                except job_records.RecordError:
                    continue
                learn(str(sibling.resolve()), record["report"], record["builds"], group(job))
    lines = ["| method | run directory | state | compute (min) |", "|---|---|---|---|"]
    todo_minutes, unknown = 0.0, 0
    to_run = {job.run_dir: job for index, job in enumerate(jobs) if index not in done}
    for index, job in enumerate(jobs):
        method, _ = group(job)
        if index in done:
            state = "finished here" if done[index].source == job.run_dir else f"from its record ({done[index].source})"
            if done[index].finding:
                state = f"not evaluable ({done[index].source}: {done[index].error})"
            lines.append(f"| {method} | {job.run_dir} | {state} | |")
            continue
        try:
            specs = planned_stages(job)
        except Exception:  # noqa: BLE001  (a config problem: the job reports it when it runs)
            specs = None
        minutes = None
        if specs is not None:
            source = to_run.get(job.reuse_from)  # a job of this study it starts from, once that has run
            try:
                source_plan = planned_stages(source) if source is not None else None
            except Exception:  # noqa: BLE001
                source_plan = []
            have = finished_stages(job.run_dir, specs) | {spec.name for spec in reusable_stages(job, specs,
                                                                                                  source_plan)}
            times = [known.get((*group(job), spec.name)) for spec in specs if spec.name not in have]
            if all(times):
                minutes = sum(sum(t) / len(t) for t in times)
        if minutes is None:
            unknown += 1
        else:
            todo_minutes += minutes
        cell = f"about {minutes:.0f}" if minutes is not None else "?"
        lines.append(f"| {method} | {job.run_dir} | to run | {cell} |")
    left = len(jobs) - len(done)
    findings = sum(result.finding for result in done.values())
    summary = (f"study plan: {len(jobs)} jobs, {len(done)} finished"
               + (f" ({findings} not evaluable: a finding)" if findings else "") + f", {left} to run")
    if left > unknown:
        summary += (f": about {todo_minutes:.0f} min of compute" + (f" for {left - unknown} of them" if unknown else "")
                    + (f", about {todo_minutes / slots:.0f} min of wall-clock on {slots} at once"
                       + (f" (this machine: {machine})" if machine else "") if slots else ""))
    elif slots == 0:
        summary += f"; this machine ({machine}) cannot run a job: it has too few GPUs for ray.gpus_per_job"
    if unknown:
        summary += (f"; {unknown} without an estimate (a stage that no finished or recorded job of the same "
                    "method and robot has built)")
    return "\n".join([summary, "", *lines]) + "\n"


def run_jobs(jobs: Sequence[Job], *, address: str | None = None, cores_per_job: int | None = None,
             gpus_per_job: float = 0.0, fetch_run_dirs: bool = False, records: str | None = None,
             dry_run: bool = False, progress_every: float = 30.0) -> list[JobResult]:
    """Runs ``jobs`` through Ray (see the module docstring) and returns one :class:`JobResult` per job, in order.
    ``gpus_per_job`` (e.g. 0.25: four jobs share a GPU) is each job's ``num_gpus``: its networks run on ``cuda``;
    with ``0`` they run on the CPU (the keys of CPU runs and records).
    With ``records`` (a directory), every finished job leaves its record there and a job missing from its run
    directory is taken from its current record (``hierloco/pipeline/records.py``). With ``dry_run``, prints the plan
    (:func:`plan_text`) and ends the study (``SystemExit(0)``) without running or writing anything. Ray is started
    or joined by :func:`ray_session`; on a cluster (``address``) every job's run directory and log come back here
    (:func:`bring_back`), as they do everywhere with ``fetch_run_dirs``."""
    check_records(records, jobs)
    for root in dict.fromkeys(job.records_from for job in jobs if job.records_from):
        check_records(root)
    gpus_per_job = check_gpus_per_job(gpus_per_job, jobs)
    address = address or os.environ.get("RAY_ADDRESS")
    if address and not dry_run:
        check_ray_address(address)
    results: dict[int, JobResult] = {}
    todo = []
    from_records, borrowed = 0, {}  # taken from records: all, and those from another study's (by directory)
    for index, job in enumerate(jobs):
        if not address:  # local workers share this file system: give them absolute paths
            job.run_dir = str(Path(job.run_dir).resolve())
            job.reuse_from = str(Path(job.reuse_from).resolve()) if job.reuse_from else None
        if cores_per_job is not None:
            job.cores = int(cores_per_job)
        job.device = "cuda" if gpus_per_job > 0 else "cpu"  # a task without a GPU share sees none under Ray
        specs = _plan_or_none(job)
        record = None
        if specs is not None and finished(job, specs):
            try:
                record = run_record(job, specs)
            except Exception as error:  # noqa: BLE001  (an evaluation that does not load: run the job again)
                print(f"study: {job.run_dir}: {error}; running the job again", flush=True)
        if record is not None:
            results[index] = JobResult(job, True, record["rows"], 0.0, reused=True, report=record["report"],
                                       builds=record["builds"], recorded_seconds=_seconds(record),
                                       actions=record.get("actions"))
            if not dry_run:
                _keep_record(records, job, record)
        elif specs is not None and not (Path(job.run_dir) / DONE).exists() and (
                taken := _from_records(job, records, specs)) is not None:
            source, recorded_job = taken
            if records is None or not source.is_relative_to(Path(records)):
                borrowed[job.records_from] = borrowed.get(job.records_from, 0) + 1
            results[index] = JobResult(job, True, recorded_job["rows"], 0.0, reused=True, source=str(source),
                                       report=recorded_job["report"], builds=recorded_job["builds"],
                                       recorded_seconds=_seconds(recorded_job), actions=recorded_job.get("actions"))
            from_records += 1
        elif (finding := found(job, records, specs)) is not None:
            error, source, failure = finding
            results[index] = JobResult(job, False, [], 0.0, reused=True, error=error, source=source, finding=True)
            if source == job.run_dir and not dry_run:
                _keep_record(records, job, finding_record(job, specs, failure))
        else:
            todo.append(index)
    if dry_run:
        slots, machine = machine_slots(max(1, jobs[0].cores) if jobs else 1, gpus_per_job)
        print(plan_text(jobs, results, slots=None if address else slots, records=records, machine=machine),
              flush=True)
        raise SystemExit(0)
    findings = sum(r.finding for r in results.values())
    line = (f"study: {len(jobs)} jobs, {len(jobs) - len(todo) - from_records - findings} reused from their run "
            "directories" + (f", {from_records - sum(borrowed.values())} from their records in {records}" if records
                             else "")
            + "".join(f", {n} from the records in {root}" for root, n in borrowed.items()))
    print(line + (f", {findings} not evaluable (an earlier run's finding)" if findings else ""), flush=True)
    if todo:
        import ray

        fetch = fetch_run_dirs or bool(address)  # a cluster's nodes need not share this machine's file system
        with ray_session(address):
            remote = ray.remote(execute)
            waiting = _waiting(jobs, todo)  # job -> the job of this study it starts from, which must end first
            pending: dict = {}

            def submit(indices) -> None:
                pending.update({remote.options(num_cpus=jobs[i].cores, num_gpus=gpus_per_job).remote(
                    jobs[i], fetch): i for i in indices})

            submit(i for i in todo if i not in waiting)
            slots = max(1, int(ray.cluster_resources().get("CPU", 1)) // max(1, jobs[todo[0]].cores))
            if gpus_per_job > 0:
                slots = max(1, min(slots, int(ray.cluster_resources().get("GPU", 0) / gpus_per_job + 1e-9)))
            start, last, durations = time.perf_counter(), 0.0, []
            finished_at = start
            while pending or waiting:
                if not pending:  # what is left waits on itself (jobs that name each other): run it as it is
                    submit(list(waiting))
                    waiting.clear()
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=progress_every)
                for ref in ready:
                    index = pending.pop(ref)
                    job = jobs[index]
                    try:
                        outcome = ray.get(ref)
                    except Exception as error:  # the worker died
                        outcome = {"ok": False, "rows": [], "seconds": 0.0, "error": str(error), "archive": None,
                                   "finding": False}
                    if fetch and (said := bring_back(job, outcome)):
                        print(f"study: {said}", flush=True)
                    results[index] = JobResult(job, outcome["ok"], outcome["rows"], outcome["seconds"],
                                               error=outcome["error"], finding=outcome["finding"],
                                               report=outcome.get("report") or {}, builds=outcome.get("builds") or {},
                                               actions=(outcome.get("record") or {}).get("actions"))
                    _keep_record(records, job, outcome.get("record"))
                    durations.append(outcome["seconds"])
                    finished_at = time.perf_counter()
                    if not outcome["ok"]:
                        said = "is not evaluable" if outcome["finding"] else "failed"
                        print(f"study: job {job.method} {job.run_dir} {said}: {outcome['error']}", flush=True)
                    released = [i for i, after in waiting.items() if after == index]
                    for i in released:
                        del waiting[i]
                    submit(released)
                if time.perf_counter() - last >= progress_every or not (pending or waiting):
                    failed = sum(not r.ok for r in results.values())
                    running = min(len(pending), slots)
                    print(_progress(len(results) - failed, running, failed, len(pending) + len(waiting) - running,
                                    start, durations, slots, finished_at), flush=True)
                    last = time.perf_counter()
    return [results[i] for i in range(len(jobs))]


def check_gpus_per_job(gpus_per_job, jobs: Sequence[Job] = ()) -> float:
    """``gpus_per_job`` as a float (a fraction up to 1, or a whole number of GPUs), or a :class:`ConfigError`;
    also refuses a job that asks for ``device=cuda`` in its overrides without a GPU share (Ray would hide the GPU)."""
    value = 0.0 if gpus_per_job is None else gpus_per_job
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            0 <= value <= 1 or float(value).is_integer()):
        raise ConfigError(f"ray.gpus_per_job must be 0, a fraction of a GPU (e.g. 0.25) or a whole number of GPUs, "
                          f"got {gpus_per_job!r}")
    if value == 0:
        asking = [job.run_dir for job in jobs if any(o.split("=", 1)[0].lstrip("+") == "device" and
                                                     o.split("=", 1)[1].startswith("cuda") for o in job.overrides)]
        if asking:
            raise ConfigError(f"{len(asking)} job(s) ask for device=cuda (e.g. {asking[0]}) but ray.gpus_per_job is 0: "
                              "give each a GPU share (ray.gpus_per_job=0.25)")
    return float(value)


def _waiting(jobs: Sequence[Job], todo: Sequence[int]) -> dict[int, int]:
    """The jobs to run that start from another job to run (``reuse_from`` its run directory): job -> that job. They
    are submitted when it ends, so they start from its finished stages."""
    to_run = {jobs[i].run_dir: i for i in todo}
    return {i: to_run[jobs[i].reuse_from] for i in todo
            if jobs[i].reuse_from in to_run and to_run[jobs[i].reuse_from] != i}


def rows_of(results: Sequence[JobResult]) -> list[dict]:
    """The per-episode rows of the successful jobs, each with its job's labels."""
    return [{**row, **result.job.labels} for result in results if result.ok for row in result.rows]


def report_failures(results: Sequence[JobResult]) -> int:
    """Prints the failed jobs with their run directories; returns how many failed other than with a finding about
    their setting (those are results: the job is not evaluable, and the study's tables say so)."""
    for result in results:
        if not result.ok:
            said = "not evaluable" if result.finding else "failed"
            print(f"{said}: {result.job.method} in {result.job.run_dir}: {result.error}", file=sys.stderr)
    return sum(not r.ok and not r.finding for r in results)


def run_here(job: Job) -> list[dict]:
    """Runs one job on this machine without Ray (a study that needs a single run, e.g. navigation's LAT run);
    returns its rows, raising with the job's log when it fails."""
    specs = _plan_or_none(job)
    if specs is not None and finished(job, specs):
        return evaluation_rows(job.run_dir, specs)
    outcome = execute(job)
    if not outcome["ok"]:
        raise RuntimeError(f"{job.method} run into {job.run_dir} failed: {outcome['error']}")
    return outcome["rows"]


__all__ = ["CLUSTER_EXCLUDES", "DONE", "FORWARDED_ENV", "Job", "JobResult", "action_table", "bring_back",
           "check_gpus_per_job", "check_ray_address", "check_records", "cluster_runtime_env", "evaluation_rows",
           "execute", "finished", "job_log", "machine_slots", "pack", "plan_text", "planned_stages", "project_root",
           "ray_session", "recorded", "report_failures", "resolve_method", "rows_of", "run_here", "run_jobs"]
