"""The skeleton every study shares (compare, ablations, adverse, hardware, tune): an entry point, jobs on Ray,
the tables, and the end.

A study's ``run.py`` reads::

    @study_main(__file__)
    def main(cfg):
        planned = jobs(cfg)                                   # the recipe runs, as studies.Job
        results = run_study(cfg, planned)                     # Ray; records; dry_run prints the plan and stops
        rows = rows_of(results)
        write_tables(rows, results, Path(cfg.out_dir), name="comparison", title=..., settings=cfg.settings)
        ...                                                   # the study's own figures and checks
        end_study(results)                                    # failures listed; exit 1 if a job failed

Every table a study writes lists the jobs it could not include (failed, or not evaluable with the finding), so a
robot or seed missing from a table is always said (``docs/pipeline.md``).
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from typing import Callable, Sequence

from hierloco.pipeline.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, ConfigError
from hierloco.pipeline.studies import Job, JobResult, check_ray_address, report_failures, rows_of, run_jobs

PAPER_TASKS = ("velocity_tracking", "goal_reaching", "trajectory_tracking")


def study_main(script_file: str, config_name: str = "config") -> Callable:
    """Decorates a study's ``main(cfg)``: Hydra over the ``config.yaml`` beside ``script_file``, one-line errors
    (exit 2), Ctrl-C and SIGTERM stop the study and its jobs' recipes (finished stages kept, exit 130)."""
    import hydra

    folder = str(Path(script_file).resolve().parent)

    def decorate(main: Callable) -> Callable:
        from hierloco.pipeline.entry import (
            check_environment, describe_config, exit_at_once, information_only, one_line_errors, report_error,
            sigterm_as_interrupt,
        )

        @hydra.main(config_path=folder, config_name=config_name, version_base=None)
        @functools.wraps(main)
        def task(cfg):
            with one_line_errors():
                check_environment()
                if (address := ray_address(cfg)) and not cfg.get("dry_run", False):
                    check_ray_address(address)  # before the study's own work: a cluster that is not there
                return main(cfg)

        @functools.wraps(main)
        def entry():
            os.environ.setdefault("HYDRA_FULL_ERROR", "1")
            from hydra.errors import HydraException

            if information_only(sys.argv[1:]):  # --help, --cfg job: the config alone, no jobs
                sys.exit(describe_config(folder, f"hierloco study {Path(folder).name}", sys.argv[1:], config_name))
            sigterm_as_interrupt()
            try:
                return task()
            except KeyboardInterrupt:
                print("interrupted: the study's jobs were stopped; their finished stages are kept: run the same "
                      "command again to resume", file=sys.stderr)
                # the study's Ray is stopped and its folder removed (ray_session); Python's own shutdown after a
                # Ray connection cut short crashes in Ray's C++ teardown (a segmentation fault, or no exit at all)
                exit_at_once(EXIT_INTERRUPTED)
            except HydraException as error:
                report_error(error)
                sys.exit(EXIT_USER_ERROR)

        entry.body = main
        return entry

    return decorate


def study_robots(names, problems: list[str]) -> list:
    """The robots a study names (registered names or YAML paths), each problem added to ``problems``."""
    from hierloco.envs.robots import get_robot

    robots = []
    for name in names:
        try:
            robots.append(get_robot(name))
        except (ValueError, OSError) as error:
            problems.append(str(error))
    return robots


def method_problems(methods, variants) -> list[str]:
    """A problem per method that is neither a recipe nor one of the study's ``variants``."""
    from hierloco.pipeline.studies import resolve_method

    problems = []
    for method in methods:
        try:
            resolve_method(method, variants)
        except ValueError as error:
            problems.append(str(error))
    return problems


def seed_problems(seeds) -> list[str]:
    """A problem per seed that is not an integer >= 0, and one when there are none."""
    return [f"seed {s!r} is not an integer >= 0" for s in seeds if not (isinstance(s, int) and s >= 0)] + (
        [] if list(seeds) else ["seeds is empty"])


def ray_address(cfg) -> str | None:
    """The Ray cluster a study's jobs run on: ``ray.address``, else ``RAY_ADDRESS``; ``None``: a local instance of
    the study's own (:func:`hierloco.pipeline.studies.ray_session`)."""
    return (cfg.get("ray") or {}).get("address") or os.environ.get("RAY_ADDRESS") or None


def run_study(cfg, jobs: Sequence[Job]) -> list[JobResult]:
    """Runs ``jobs`` with the study config's Ray options (``ray.address`` or ``RAY_ADDRESS``, ``ray.cores_per_job``,
    ``ray.gpus_per_job``, ``ray.fetch_run_dirs``), ``records`` and ``dry_run``."""
    refuse(ray_problems(cfg))
    ray = cfg.get("ray") or {}
    return run_jobs(jobs, address=ray_address(cfg), cores_per_job=ray.get("cores_per_job"),
                    gpus_per_job=ray.get("gpus_per_job", 0),
                    fetch_run_dirs=bool(ray.get("fetch_run_dirs", False)), records=cfg.get("records"),
                    dry_run=bool(cfg.get("dry_run", False)))


def refuse(problems: Sequence[str]) -> None:
    """Raises one :class:`ConfigError` naming every problem (each once, in order), when there are any: a study's
    config check ends with it, before any work."""
    if problems:
        raise ConfigError("bad config: " + "; ".join(dict.fromkeys(problems)))


def ray_problems(cfg) -> list[str]:
    """A problem when the study's ``ray.cores_per_job`` is not an integer >= 1."""
    cores = (cfg.get("ray") or {}).get("cores_per_job", 1)
    return [] if isinstance(cores, int) and not isinstance(cores, bool) and cores >= 1 else [
        f"ray.cores_per_job must be an integer >= 1, got {cores!r}"]


def chosen_targets() -> str:
    """The study's choice in the ``targets`` config group (``paper``, ``fair``: ``docs/tasks.md``), for a study whose
    config composes it (the comparison); ``paper`` otherwise, or outside a Hydra run."""
    from hydra.core.hydra_config import HydraConfig

    if not HydraConfig.initialized():
        return "paper"
    return HydraConfig.get().runtime.choices.get("targets") or "paper"


def main_tasks(cfg) -> tuple[str, ...]:
    """The tasks a study tabulates: ``tasks`` when the study's config names them, else the main tasks
    (``eval.tasks``) of the LAT recipe at the study's preset and targets (:func:`chosen_targets`)."""
    if cfg.get("tasks"):
        return tuple(cfg.tasks)
    from hierloco.pipeline.config import compose_recipe

    targets = chosen_targets()
    chosen = [f"targets={targets}"] if targets != "paper" else []
    return tuple(compose_recipe("lat", [f"preset={cfg.get('preset_name', 'paper')}", *chosen]).eval.tasks)


def missing_markdown(results: Sequence[JobResult]) -> str:
    """The jobs a study's tables leave out, and why (failed, or not evaluable: the finding); empty when none."""
    missing = [r for r in results if not r.ok]
    if not missing:
        return ""
    lines = ["", "## Jobs not in this table", "", "| method | run directory | why |", "|---|---|---|"]
    for result in missing:
        why = ("not evaluable: " if result.finding else "failed: ") + " ".join(result.error.split())
        lines.append(f"| {result.job.labels.get('method', result.job.method)} | {result.job.run_dir} | "
                     f"{why.replace('|', '/')} |")
    return "\n".join(lines) + "\n"


def write_tables(rows: list[dict], results: Sequence[JobResult], out: Path, *, name: str, title: str, settings=(),
                 tasks: Sequence[str] = PAPER_TASKS) -> str:
    """A study's outputs in ``out``: ``<name>.csv`` (per-episode rows), ``<name>.md`` (mean +- std over targets and
    seeds, then the jobs left out), ``wallclock.md`` and a bar chart per setting; returns the Markdown table."""
    from hierloco.io import write_text
    from hierloco.pipeline.report import wallclock_markdown
    from hierloco.results import EPISODE_COLUMNS, csv_text, markdown_table

    write_text(out / "wallclock.md", wallclock_markdown(results))
    missing = missing_markdown(results)
    if not rows:
        write_text(out / f"{name}.md", f"# {name.capitalize()}\n\n{title}. No job finished.\n" + missing)
        return ""
    table = markdown_table(rows)
    columns = EPISODE_COLUMNS + [k for k in rows[0] if k not in EPISODE_COLUMNS]
    write_text(out / f"{name}.csv", csv_text(rows, columns))
    write_text(out / f"{name}.md", f"# {name.capitalize()}\n\n{title}. Normalised cost, mean +- std over targets and "
                                   "seeds (1 = no better than standing still).\n\n" + table + missing)
    if settings:
        from hierloco.plots import plot_comparison

        for setting in settings:
            if any(r["setting"] == setting and r["task"] in tasks for r in rows):
                plot_comparison(rows, out / f"{name}_{setting}.png", setting=setting, tasks=tasks, title=title)
    return table


def end_study(results: Sequence[JobResult]) -> None:
    """Lists the failed and not evaluable jobs; exits 1 when a job failed (a finding is a result, not a failure)."""
    if report_failures(results):
        sys.exit(1)


__all__ = ["PAPER_TASKS", "ConfigError", "EXIT_INTERRUPTED", "end_study", "main_tasks", "method_problems",
           "missing_markdown",
           "ray_address", "rows_of", "run_study", "seed_problems", "study_main", "study_robots", "write_tables"]
