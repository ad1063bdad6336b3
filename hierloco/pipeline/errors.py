"""What the pipeline reports to the user in one line, and the exit codes of every recipe and study.

A user's mistake (a bad config value, an unknown robot, a run directory made with another config or in use by
another run, a corrupted artifact) prints ``error: <one line>`` and exits with :data:`EXIT_USER_ERROR` before any
work, with no traceback; a finding about the robot and its setting (:class:`hierloco.errors.Finding`) is reported
the same way and recorded; Ctrl-C or SIGTERM says where the run stopped (:data:`EXIT_INTERRUPTED`); anything else is
a bug and keeps its traceback (exit 1).
"""

from __future__ import annotations

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130


class ConfigError(ValueError):
    """A config a recipe cannot run: the message names every problem."""


def findings() -> tuple[type[BaseException], ...]:
    """The exception types that are findings about the robot and its setting (recorded, not re-run)."""
    from hierloco.errors import Finding

    return (Finding,)


def user_errors() -> tuple[type[BaseException], ...]:
    """The exception types that are the user's to fix (or findings), each reported in one line."""
    from omegaconf.errors import OmegaConfBaseException

    from hierloco.io import ArtifactError
    from hierloco.pipeline.rundir import ReadOnlyRunError, RunDirectoryError, RunLockedError

    return (ConfigError, ArtifactError, RunLockedError, ReadOnlyRunError, RunDirectoryError, OmegaConfBaseException,
            *findings())


def one_line(error: BaseException) -> str:
    """The error's message on one line (its type's name when it has none)."""
    text = " ".join(str(error).split())
    return text or type(error).__name__


__all__ = ["EXIT_INTERRUPTED", "EXIT_USER_ERROR", "ConfigError", "findings", "one_line", "user_errors"]
