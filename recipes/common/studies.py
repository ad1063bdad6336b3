"""Studies (compare, ablations, adverse, ...) as jobs on Ray: one recipe run per job, one machine to a cluster.

A :class:`Job` is one recipe run (``recipes/<method>/train.py`` with overrides, into its own run directory). 
:func:`run_jobs` submits every job as a Ray task with the cores it asks for (``num_cpus``), on a local Ray instance
started for the study, or on the cluster at ``address`` / ``RAY_ADDRESS``. Each job runs the recipe in a subprocess
with as many simulation and torch threads as it has cores, so jobs never oversubscribe the machine. Finished jobs
are reused from their run directories (a killed study, re-run, resubmits only what did not finish); a failed job
is reported with its run directory and the others go on; the rows of every job come back to the driver through Ray,
so a cluster without shared storage works too (``fetch_run_dirs=True`` also brings each run directory back). With a
``records`` directory (``recipes/common/records.py``) every finished job also leaves its small record there, and a
job whose run directory is missing is taken from its record while its stage keys are today's: a study runs in parts,
on several machines or sessions. A job that ends in a finding about its setting (``recipes/common/entry.py``:
``findings``) is not evaluable, a result rather than a failure: it is kept (``failed.json`` in its run directory and
record) and reported from there, not run again, while the stage it failed in has today's key.

Example:
    >>> jobs = [Job("lat", "outputs/lat/tiny/a1_seed0", ["preset=tiny"]), Job("lib", "outputs/lib/tiny/a1_seed0",
    ...         ["preset=tiny"])]
    >>> results = run_jobs(jobs, cores_per_job=1)   # doctest: +SKIP
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from hierloco.io import write_text
from hierloco.results import read_csv
from recipes.common import records as job_records

RECIPES = Path(__file__).resolve().parents[1]
METHODS = tuple(sorted(p.name for p in RECIPES.iterdir() if (p / "train.py").exists()))
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

    def command(self) -> list[str]:
        return [sys.executable, str(RECIPES / self.method / "train.py"), f"run_dir={self.run_dir}",
                f"nthread={self.cores}", *self.overrides]

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

    def __post_init__(self):
        self.source = self.source or self.job.run_dir


def resolve_method(name: str, variants) -> tuple[str, list[str]]:
    """A study's method: a recipe name, or a variant ``{recipe: ..., overrides: [...]}`` (e.g. ``ik_plain``: the IK
    recipe with the paper's plain footstep law); returns the recipe and the variant's overrides."""
    variants = variants or {}
    if name in variants:
        variant = variants[name]
        recipe = variant.get("recipe")
        if recipe not in METHODS:
            raise ValueError(f"variant {name!r} names no recipe (recipe: one of {', '.join(METHODS)})")
        return recipe, list(variant.get("overrides", []))
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r} (recipes: {', '.join(METHODS)}; variants: "
                         f"{', '.join(variants) or 'none'})")
    return name, []


def finished(job: Job) -> bool:
    """Whether ``job`` already finished in its run directory with the same method and overrides, and every stage
    its recipe plans today is there with the key it has today (a changed default or code path that enters a key
    makes the job run again, and the run then names the stage that changed)."""
    return job_records.holds_job(job.run_dir, job.signature()) and stages_current(job)


def planned_stages(job: Job) -> list:
    """The stages (``StageSpec``: name, key, file) the job's recipe plans today from its overrides; nothing is
    built or written."""
    import importlib

    from recipes.common.config import compose_recipe, prepare

    cfg = compose_recipe(job.method, [f"run_dir={job.run_dir}", *job.overrides])
    utils = importlib.import_module(f"recipes.{job.method}.utils")
    return [stage.spec for stage in utils.plan(cfg, prepare(cfg, utils.checks))]


def stages_current(job: Job) -> bool:
    """Whether every stage of the job's plan (its recipe's config from its overrides, planned as the recipe would
    now) is finished in its run directory with the same key; no work is done and nothing is written."""
    from hierloco.runs import RunDirectory

    try:
        return all(RunDirectory(job.run_dir, readonly=True).verify(planned_stages(job)).values())
    except Exception:  # noqa: BLE001  (any config or key problem: run the job, which reports it properly)
        return False


def recorded(job: Job, records: str) -> bool:
    """Whether the job's record under ``records`` is of this job (method, overrides) with today's stage keys."""
    directory = job_records.record_dir(records, job.run_dir)
    if not job_records.holds_job(directory, job.signature()):
        return False
    try:
        specs = planned_stages(job)
    except Exception:  # noqa: BLE001  (a config problem: run the job, which reports it properly)
        return False
    return job_records.current(directory, job.signature(), specs)


def found(job: Job, records: str | None = None) -> tuple[str, str] | None:
    """The finding a job ended in (``failed.json`` in its run directory, else in its record under ``records``) while
    the stage it failed in has today's key: ``(error, where)``, else ``None``."""
    places = [Path(job.run_dir)] + ([job_records.record_dir(records, job.run_dir)] if records else [])
    places = [place for place in places if (place / job_records.FAILED).is_file()]
    if not places:
        return None
    try:
        specs = planned_stages(job)
    except Exception:  # noqa: BLE001  (a config problem: run the job, which reports it properly)
        return None
    for place in places:
        error = job_records.finding(place, job.signature(), specs)
        if error is not None:
            return error, str(place)
    return None


def execute(job: Job, fetch_run_dir: bool = False) -> dict:
    """Runs one job here (in a subprocess); returns its outcome, its result rows and optionally its run directory
    as a tar archive. This is the body of the Ray task. A job that ends in a finding (the recipe's ``failed.json``)
    comes back with ``finding`` set and its record."""
    start = time.perf_counter()
    if job.reuse_from:
        _reuse_stages(job)
    (Path(job.run_dir) / job_records.FAILED).unlink(missing_ok=True)  # only this run's finding counts
    env = {**os.environ, "OMP_NUM_THREADS": str(job.cores), "MKL_NUM_THREADS": str(job.cores),
           "WANDB_SILENT": "true"}
    log = Path(job.run_dir).parent / f"{Path(job.run_dir).name}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "a") as out:  # appended: a re-run (reusing stages) keeps the log of the run that built them
        out.write(f"=== {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}: {' '.join(job.command())}\n")
        out.flush()
        code = subprocess.run(job.command(), stdout=out, stderr=subprocess.STDOUT, cwd=os.getcwd(),
                              env={**env, PARENT_PID: str(os.getpid())}).returncode
    outcome = {"ok": code == 0, "seconds": time.perf_counter() - start, "rows": [], "error": "", "archive": None,
               "record": None, "finding": False}
    if code != 0:
        failed = Path(job.run_dir) / job_records.FAILED
        if failed.is_file():  # a finding: the same config fails the same way; kept with the job's signature
            outcome["record"] = job_records.failure_of(job.run_dir, job.signature())
            text = outcome["record"][job_records.FAILED]
            write_text(failed, text)
            outcome.update(finding=True, error=json.loads(text)["error"] + f" (log: {log})")
            return outcome
        tail = log.read_text().strip().splitlines()[-3:]
        outcome["error"] = f"exit code {code}: " + " | ".join(tail) + f" (log: {log})"
        return outcome
    outcome["rows"] = read_csv(Path(job.run_dir) / "episodes.csv")
    write_text(Path(job.run_dir) / DONE, json.dumps({"signature": job.signature(), "seconds": outcome["seconds"]}))
    outcome["record"] = job_records.files_of(job.run_dir)  # small: back to the driver, which may keep it (records)
    if fetch_run_dir:
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
            archive.add(job.run_dir, arcname=".")
        outcome["archive"] = buffer.getvalue()
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
    from hierloco.runs import ArtifactError, RunDirectory, normalized

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
    from hierloco.runs import BUILDS_NAME, RunDirectory

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


def check_records(records) -> None:
    """Refuses a ``records`` setting that is not a directory path (or null), before any work."""
    from recipes.common.config import ConfigError

    if records is None:
        return
    if not isinstance(records, str) or not records.strip():
        raise ConfigError(f"records must be a directory path or null, got {records!r}")
    if Path(records).exists() and not Path(records).is_dir():
        raise ConfigError(f"records={records} exists and is not a directory")


def _keep_record(records: str | None, job: Job, record: dict | None) -> None:
    if records and record:
        job_records.save(record, job_records.record_dir(records, job.run_dir))


def plan_text(jobs: Sequence[Job], done: dict[int, JobResult], slots: int | None,
              records: str | None = None) -> str:
    """The study's plan: every job's state (finished here, from its record, to run) and the compute each job to run
    will take: over the stages its recipe plans that are not finished yet (in its run directory, or among the stages
    it reuses), the mean recorded build time of the same stage in the finished jobs of the same method and robot
    (this study's, and with ``records``, every recorded job of that method, preset and robot: another seed's run
    of an earlier study estimates this seed's). Then the total, and what it is on ``slots`` jobs at once (``None``:
    a cluster, not said)."""
    from hierloco.runs import RunDirectory
    from recipes.common.report import job_compute

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
    timed: set[Path] = set()

    def learn(source: str | Path, key: tuple[str, str]) -> None:
        if Path(source).resolve() in timed:
            return
        timed.add(Path(source).resolve())
        stages, _ = job_compute(str(source))
        for name, seconds in stages.items():
            if seconds is not None:
                known.setdefault((*key, name), []).append(seconds / 60)

    for result in done.values():
        learn(result.source, group(result.job))
    for index, job in enumerate(jobs):
        if records and index not in done:
            here = job_records.record_dir(records, job.run_dir)
            for sibling in sorted(here.parent.glob(f"{group(job)[1]}_seed*")):
                if (sibling / "job.json").is_file():
                    learn(sibling, group(job))
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
                    + (f", about {todo_minutes / slots:.0f} min on {slots} at once" if slots else ""))
    if unknown:
        summary += (f"; {unknown} without an estimate (a stage that no finished or recorded job of the same "
                    "method and robot has built)")
    return "\n".join([summary, "", *lines]) + "\n"


def run_jobs(jobs: Sequence[Job], *, address: str | None = None, cores_per_job: int | None = None,
             fetch_run_dirs: bool = False, records: str | None = None, dry_run: bool = False,
             progress_every: float = 30.0) -> list[JobResult]:
    """Runs ``jobs`` through Ray (see the module docstring) and returns one :class:`JobResult` per job, in order.
    With ``records`` (a directory), every finished job leaves its record there and a job missing from its run
    directory is taken from its current record (``recipes/common/records.py``). With ``dry_run``, prints the plan
    (:func:`plan_text`) and ends the study (``SystemExit(0)``) without running or writing anything."""
    import ray

    check_records(records)
    results: dict[int, JobResult] = {}
    todo = []
    address = address or os.environ.get("RAY_ADDRESS")
    from_records = 0
    for index, job in enumerate(jobs):
        if not address:  # local workers share this file system: give them absolute paths
            job.run_dir = str(Path(job.run_dir).resolve())
            job.reuse_from = str(Path(job.reuse_from).resolve()) if job.reuse_from else None
        if cores_per_job is not None:
            job.cores = int(cores_per_job)
        if finished(job):
            results[index] = JobResult(job, True, read_csv(Path(job.run_dir) / "episodes.csv"), 0.0, reused=True)
            if not dry_run:
                _keep_record(records, job, job_records.files_of(job.run_dir))
        elif records and not (Path(job.run_dir) / DONE).exists() and recorded(job, records):
            source = job_records.record_dir(records, job.run_dir)
            results[index] = JobResult(job, True, job_records.rows(source), 0.0, reused=True, source=str(source))
            from_records += 1
        elif (finding := found(job, records)) is not None:
            error, source = finding
            results[index] = JobResult(job, False, [], 0.0, reused=True, error=error, source=source, finding=True)
            if source == job.run_dir and not dry_run:
                _keep_record(records, job, job_records.failure_of(job.run_dir, job.signature()))
        else:
            todo.append(index)
    if dry_run:
        cores = max(1, jobs[0].cores) if jobs else 1
        print(plan_text(jobs, results, slots=None if address else max(1, _available_cores() // cores),
                        records=records), flush=True)
        raise SystemExit(0)
    findings = sum(r.finding for r in results.values())
    line = (f"study: {len(jobs)} jobs, {len(jobs) - len(todo) - from_records - findings} reused from their run "
            "directories" + (f", {from_records} from their records in {records}" if records else ""))
    print(line + (f", {findings} not evaluable (an earlier run's finding)" if findings else ""), flush=True)
    if todo:
        started_here = not ray.is_initialized()
        if started_here:
            if address:
                ray.init(address=address, log_to_driver=False,
                         runtime_env={"working_dir": str(RECIPES.parent), "excludes": ["outputs", ".venv", ".git"]})
            else:  # a local instance; its workers run at normal priority (Ray lowers it by default)
                os.environ.setdefault("RAY_worker_niceness", "0")
                ray.init(num_cpus=_available_cores(), include_dashboard=False, log_to_driver=False,
                         configure_logging=False)
        remote = ray.remote(execute)
        waiting = _waiting(jobs, todo)  # job -> the job of this study it starts from, which must end first
        pending: dict = {}

        def submit(indices) -> None:
            pending.update({remote.options(num_cpus=jobs[i].cores).remote(jobs[i], fetch_run_dirs): i for i in indices})

        submit(i for i in todo if i not in waiting)
        slots = max(1, int(ray.cluster_resources().get("CPU", 1)) // max(1, jobs[todo[0]].cores))
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
                if outcome.get("archive") and not Path(job.run_dir).exists():
                    with tarfile.open(fileobj=io.BytesIO(outcome["archive"]), mode="r:gz") as archive:
                        archive.extractall(job.run_dir, filter="data")
                results[index] = JobResult(job, outcome["ok"], outcome["rows"], outcome["seconds"],
                                           error=outcome["error"], finding=outcome["finding"])
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
                print(_progress(len(results) - failed, running, failed, len(pending) + len(waiting) - running, start,
                                durations, slots, finished_at), flush=True)
                last = time.perf_counter()
        if started_here:
            ray.shutdown()
    return [results[i] for i in range(len(jobs))]


def _waiting(jobs: Sequence[Job], todo: Sequence[int]) -> dict[int, int]:
    """The jobs to run that start from another job to run (``reuse_from`` its run directory): job -> that job. They
    are submitted when it ends, so they start from its finished stages."""
    to_run = {jobs[i].run_dir: i for i in todo}
    return {i: to_run[jobs[i].reuse_from] for i in todo
            if jobs[i].reuse_from in to_run and to_run[jobs[i].reuse_from] != i}


def _available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


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
    if finished(job):
        return read_csv(Path(job.run_dir) / "episodes.csv")
    outcome = execute(job)
    if not outcome["ok"]:
        raise RuntimeError(f"{job.method} run into {job.run_dir} failed: {outcome['error']}")
    return outcome["rows"]


__all__ = ["DONE", "METHODS", "Job", "JobResult", "check_records", "execute", "finished", "plan_text", "planned_stages",
           "recorded", "report_failures", "resolve_method", "rows_of", "run_here", "run_jobs"]
