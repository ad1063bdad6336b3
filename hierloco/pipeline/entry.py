"""The entry point of every recipe: Hydra over the recipe's ``config.yaml``, the run opened, clean errors.

A recipe's ``train.py`` is its method body over an open run::

    from hierloco.pipeline import recipe_main
    from hierloco.recipes.lat import utils

    @recipe_main(utils)              # config.yaml beside utils.py; utils.plan / checks / manifest / METHOD
    def main(run):
        library = run.stage(run.plan.experts)
        ...
        return run.finish()

:func:`recipe_main` composes the config, opens the run (:func:`hierloco.pipeline.run.open_run`: the whole config
checked, every stage planned and its key checked, the run directory locked) and runs the body; the run directory
is released when the body returns or raises, so the jobs of a Hydra multirun on one ``run_dir`` run one after
another. A user's mistake prints ``error: <one line>`` and exits 2 before any work; Ctrl-C or SIGTERM says which
stage was interrupted and that re-running resumes (exit 130); anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import signal
import sys
from pathlib import Path
from types import ModuleType
from typing import Callable

from hierloco.pipeline.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, ConfigError, one_line, user_errors

DISK_ERRORS = (errno.ENOSPC, errno.EDQUOT)


def disk_full(error: BaseException) -> bool:
    """Whether ``error`` is the file system running out of space (or quota)."""
    return isinstance(error, OSError) and error.errno in DISK_ERRORS


def report_error(error: BaseException) -> None:
    """Prints ``error`` as the one line a user reads (a full disk says that finished stages are kept)."""
    if disk_full(error):
        where = f" writing {error.filename}" if getattr(error, "filename", None) else ""
        print(f"error: no space left on the device{where}; finished stages are kept: free some space and run the "
              "same command again to resume", file=sys.stderr)
    else:
        print(f"error: {one_line(error)}", file=sys.stderr)


@contextlib.contextmanager
def one_line_errors():
    """Within the block, a user's error (a bad config, a corrupted artifact, a run directory in use, a finding, a
    full disk) is printed as one line and ends the process with exit status 2; anything else propagates."""
    try:
        yield
    except user_errors() as error:
        report_error(error)
        sys.exit(EXIT_USER_ERROR)
    except OSError as error:
        if not disk_full(error):
            raise
        report_error(error)
        sys.exit(EXIT_USER_ERROR)


def check_environment() -> None:
    """Refuses, before any work, environment variables that would break a run later (thread counts, the
    rendering backend)."""
    from hierloco import render_backend
    from hierloco.pipeline.outputs import environment_threads

    problems = environment_threads()
    if render_backend.problem():
        problems.append(render_backend.problem())
    if problems:
        raise ConfigError("; ".join(problems))


def exit_at_once(code: int) -> None:
    """Ends the process with ``code`` once its output and logs are flushed, without Python's shutdown (exit
    handlers, the destructors of extension modules): for a process whose own clean-up is done and whose extensions
    may not survive the shutdown (a Ray driver whose connection a signal cut short)."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


def sigterm_as_interrupt() -> None:
    """SIGTERM (a study stopping its jobs, a cluster's scheduler) stops the run like Ctrl-C: finished stages are
    kept and the run directory is released."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt

    try:
        signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread (a Hydra launcher's worker thread): left as it is
        pass


def recipe_main(utils: ModuleType, config_name: str = "config") -> Callable:
    """Decorates a recipe's ``main(run)`` (see the module docstring); returns the console entry point. ``utils`` is
    the recipe's factories module: ``METHOD``, ``plan(cfg, robot)``, ``checks(checker, robot)``, ``manifest(cfg,
    robot)``; ``config.yaml`` sits beside it. ``entry.run(cfg, evaluation_out=None)`` runs the body on a composed
    config (evaluation: ``recipes/evaluate.py``)."""
    import hydra

    from hierloco.pipeline.run import open_run

    folder = str(Path(utils.__file__).resolve().parent)
    active: dict = {}  # the run this entry point has open, for the interruption message

    def decorate(body: Callable) -> Callable:
        def run(cfg, evaluation_out: Path | None = None):
            check_environment()
            opened = open_run(cfg, utils.METHOD, utils.plan, utils.checks, getattr(utils, "manifest", None),
                              evaluation_out=evaluation_out)
            active["run"] = opened
            try:
                with opened:
                    return body(opened)
            finally:
                active.pop("run", None)

        @hydra.main(config_path=folder, config_name=config_name, version_base=None)
        @functools.wraps(body)
        def task(cfg):
            with one_line_errors():  # reported here: Hydra would add a line of its own
                return run(cfg)

        @functools.wraps(body)
        def entry():
            os.environ.setdefault("HYDRA_FULL_ERROR", "1")  # Hydra raises its own errors; this wrapper reports them
            from hydra.errors import HydraException

            from hierloco.pipeline.studies import die_with_parent

            if information_only(sys.argv[1:]):  # --help, --cfg job: the config alone, no run
                sys.exit(describe_config(folder, f"hierloco train {utils.METHOD}", sys.argv[1:], config_name))
            die_with_parent()  # a job of a study ends with the study's worker
            sigterm_as_interrupt()
            try:
                return task()
            except KeyboardInterrupt:
                where = active["run"].where() if "run" in active else ""
                print(f"interrupted{where}; finished stages are kept: run the same command again to resume",
                      file=sys.stderr)
                sys.exit(EXIT_INTERRUPTED)
            except HydraException as error:  # a bad override, an unknown config group option
                report_error(error)
                sys.exit(EXIT_USER_ERROR)

        entry.run = run
        entry.body = body
        entry.utils = utils
        return entry

    return decorate


# Hydra's flags that only describe the config: answered without importing the recipe (torch, MuJoCo) or running it
INFORMATION_FLAGS = ("--help", "-h", "--hydra-help", "--cfg", "-c", "--info", "-i", "--shell-completion", "-sc")


def information_only(arguments: list[str]) -> bool:
    """Whether ``arguments`` ask Hydra for information only (help, the composed config), not for a run."""
    return any(a in INFORMATION_FLAGS or a.startswith(("--cfg=", "--info=")) for a in arguments)


def config_groups(folder, config_name: str = "config") -> dict[str, list[str]]:
    """The config groups a recipe composes from (its own folder's and the shared ``hierloco/recipes/conf``), each
    with its options: ``{"planner": ["cem", ...], ...}``."""
    from hierloco.recipes import conf

    groups: dict[str, set[str]] = {}
    for root in (Path(folder), Path(next(iter(conf.__path__)))):
        for path in root.rglob("*.yaml"):
            group = path.parent.relative_to(root).as_posix()
            if path.parent != root and "__pycache__" not in group:
                groups.setdefault(group, set()).add(path.stem)
    return {group: sorted(options) for group, options in sorted(groups.items())}


def help_text(folder, name: str, config_name: str = "config") -> str:
    """``--help`` of a recipe: what it is (its config's opening comment), how to override, its config groups."""
    lines = (Path(folder) / f"{config_name}.yaml").read_text().splitlines()
    about = [line.lstrip("# ").rstrip() for line in lines[:next((i for i, l in enumerate(lines)
                                                                  if not l.startswith("#")), 0)]]
    text = [f"{name}: " + (about[0] if about else ""), *about[1:], "",
            f"usage: {name} [group=option ...] [key=value ...] [-m for a sweep over comma-separated values]",
            "  (Hydra's override grammar; --cfg job prints the composed config, --info how it was composed)", "",
            "config groups (group=option):"]
    text += [f"  {group}: {', '.join(options)}" for group, options in config_groups(folder, config_name).items()]
    return "\n".join(text) + "\n\nconfig (key=value overrides any of it):\n"


def describe_config(folder, name: str, arguments: list[str], config_name: str = "config") -> int:
    """Hydra's information flags (``--help``, ``--cfg job``, ``--info``, ...) for the recipe in ``folder``: its
    config composed with ``arguments``, without importing the recipe (torch, MuJoCo), so they answer in about a
    second. Returns the exit status."""
    import hydra

    @hydra.main(config_path=str(folder), config_name=config_name, version_base=None)
    def show(cfg):  # Hydra answers the information flags itself and never calls this
        return None

    os.environ.setdefault("HYDRA_FULL_ERROR", "1")
    from hydra.errors import HydraException

    if "--help" in arguments or "-h" in arguments:
        print(help_text(folder, name, config_name), end="")
        arguments = ["--cfg", "job", *[a for a in arguments if a not in ("--help", "-h")]]
    saved = sys.argv
    sys.argv = [name, *arguments]
    try:
        show()
    except SystemExit as done:
        return done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
    except (HydraException, ValueError) as error:  # a bad override; flags Hydra will not combine (-m with --cfg)
        report_error(error)
        return EXIT_USER_ERROR
    finally:
        sys.argv = saved
    return 0


__all__ = ["INFORMATION_FLAGS", "check_environment", "config_groups", "describe_config", "help_text", "information_only", "disk_full", "one_line_errors", "recipe_main", "report_error"]
