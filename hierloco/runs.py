"""Run directories: each pipeline stage's artifact is cached with the config that made it (``docs/index.md``,
Runs and artifacts).

``RunDirectory.stage(name, config, build, save, load)`` returns the stage's result: loaded from disk when the
artifact exists and was made with the same config, built (then saved atomically, config first) otherwise. An
artifact made with a different config is never overwritten: the run stops with an error that names the
differences, before any work. A killed run therefore resumes at its first unfinished stage, losing no finished
stage.

Example:
    >>> import json, tempfile
    >>> run = RunDirectory(tempfile.mkdtemp())
    >>> from hierloco.io import write_text
    >>> save = lambda obj, path: write_text(path, json.dumps(obj))  # savers write atomically
    >>> load = lambda path: json.loads(path.read_text())
    >>> run.stage("numbers", {"n": 3}, lambda: list(range(3)), save, load, "numbers.json")
    [0, 1, 2]
    >>> run.stage("numbers", {"n": 3}, lambda: 1 / 0, save, load, "numbers.json")  # cached: not rebuilt
    [0, 1, 2]
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Callable, TypeVar

import numpy as np

from hierloco.io import ArtifactError, write_text

T = TypeVar("T")


class ConfigMismatchError(ArtifactError):
    """A stage's artifact on disk was made with another config."""


def _json_default(value):
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


def _normalized(config: dict) -> dict:
    """The config as it is stored: tuples as lists, numpy scalars and arrays as numbers and lists, others as str."""
    return json.loads(json.dumps(config, default=_json_default))


def _diff(stored: dict, wanted: dict, prefix: str = "") -> list[str]:
    lines = []
    for key in sorted(set(stored) | set(wanted)):
        a, b = stored.get(key, "<missing>"), wanted.get(key, "<missing>")
        if isinstance(a, dict) and isinstance(b, dict):
            lines += _diff(a, b, f"{prefix}{key}.")
        elif a != b:
            lines.append(f"{prefix}{key}: {a!r} on disk, {b!r} asked")
    return lines


class RunDirectory:
    """A directory holding one run's stage artifacts, each beside a ``<name>.config.json``."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        self.timings: dict[str, float] = {}
        self.reused: dict[str, bool] = {}

    def config_path(self, name: str) -> Path:
        return self.path / f"{name}.config.json"

    def check(self, name: str, config: dict, filename: str) -> bool:
        """True if the stage is done with this config, False if not started; raises on a mismatch."""
        artifact, config_path = self.path / filename, self.config_path(name)
        if not artifact.exists():
            return False
        if not config_path.exists():
            raise ConfigMismatchError(f"{artifact} exists but {config_path.name} does not: cannot tell which config "
                                      "made it; use another run directory or remove the file")
        try:
            stored = json.loads(config_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise ArtifactError(f"corrupted stage config {config_path}: {error}") from error
        if not isinstance(stored, dict):
            raise ArtifactError(f"corrupted stage config {config_path}: not a JSON object")
        wanted = _normalized(config)
        if stored != wanted:
            raise ConfigMismatchError(f"stage {name!r} in {self.path} was made with another config:\n  "
                                      + "\n  ".join(_diff(stored, wanted))
                                      + "\nuse another run directory (run_dir=...) or remove that stage's files")
        return True

    def stage(self, name: str, config: dict, build: Callable[[], T], save: Callable[[T, Path], Any],
              load: Callable[[Path], T], filename: str) -> T:
        """The result of stage ``name``: cached if done with ``config``, else built and saved."""
        artifact = self.path / filename
        start = time.perf_counter()
        if self.check(name, config, filename):
            result = load(artifact)
            self.reused[name] = True
        else:
            write_text(self.config_path(name), json.dumps(_normalized(config), indent=2, sort_keys=True))
            result = build()
            save(result, artifact)
            self.reused[name] = False
        self.timings[name] = time.perf_counter() - start
        return result
