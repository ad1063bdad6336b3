"""The entry point of every recipe: Hydra over the recipe's ``config.yaml``, with clean errors.

A user's mistake (a bad config value, an unknown robot, a run directory made with another config or in use by
another run, a corrupted artifact, an expert library that does not walk as commanded) prints one line and exits
with status 2, before any work and with no traceback; Ctrl-C says which stage was interrupted and that re-running
resumes (status 130). Anything else is a bug and keeps its traceback (status 1).
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from typing import Callable

import hydra

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130


def user_errors() -> tuple[type[BaseException], ...]:
    """The exception types that are the user's to fix, reported in one line."""
    from omegaconf.errors import OmegaConfBaseException

    from hierloco.io import ArtifactError
    from hierloco.runs import ReadOnlyRunError, RunLockedError
    from recipes.common.config import ConfigError

    return (ConfigError, ArtifactError, RunLockedError, ReadOnlyRunError, OmegaConfBaseException, *findings())


def findings() -> tuple[type[BaseException], ...]:
    """The errors that are findings about the robot and its setting, not about the code or the command: experts
    that do not walk as commanded, a gait policy that does not reproduce them, a setting in which random actions
    only fall. The same config fails the same way on any machine, so a study records them (``failed.json``) and
    reports the job as not evaluable rather than running it again."""
    from hierloco.components.dynamics_data import DynamicsDataError
    from hierloco.components.expert_library import ExpertQualityError
    from recipes.common.stages import GaitPolicyQualityError

    return ExpertQualityError, GaitPolicyQualityError, DynamicsDataError


def one_line(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return text or type(error).__name__


def recipe_main(recipe_file: str, config_name: str = "config") -> Callable:
    """Decorates a recipe's ``main(cfg)``: returns the console entry point (call it under ``__main__``)."""
    folder = str(Path(recipe_file).resolve().parent)

    def decorate(main: Callable) -> Callable:
        @hydra.main(config_path=folder, config_name=config_name, version_base=None)
        @functools.wraps(main)
        def task(cfg):
            try:
                return main(cfg)
            except user_errors() as error:  # reported here: Hydra would add a line of its own
                print(f"error: {one_line(error)}", file=sys.stderr)
                sys.exit(EXIT_USER_ERROR)

        @functools.wraps(main)
        def entry():
            os.environ.setdefault("HYDRA_FULL_ERROR", "1")  # Hydra raises its own errors; this wrapper reports them
            from hydra.errors import HydraException

            from recipes.common.studies import die_with_parent

            die_with_parent()  # a job of a study ends with the study's worker

            try:
                return task()
            except KeyboardInterrupt:
                print(f"interrupted{_where()}; finished stages are kept: run the same command again to resume",
                      file=sys.stderr)
                sys.exit(EXIT_INTERRUPTED)
            except HydraException as error:  # a bad override, an unknown config group option
                print(f"error: {one_line(error)}", file=sys.stderr)
                sys.exit(EXIT_USER_ERROR)

        entry.body = main  # the undecorated recipe, for recipes/<method>/evaluate.py
        return entry

    return decorate


def _where() -> str:
    from recipes.common.run import CURRENT

    current, directory = CURRENT.get("stage"), CURRENT.get("run_dir")
    if current:
        return f" in stage {current!r} of {directory}"
    return f" in {directory}" if directory else ""
