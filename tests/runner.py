"""Running a recipe or study the way a user does, in this process (no interpreter start-up, no re-import) or in a
subprocess (when the behaviour under test is the process's own: a signal, a killed run, the environment at import).
"""

from __future__ import annotations

import contextlib
import io
import os
import runpy
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str

    @property
    def lines(self) -> list[str]:
        """The non-empty lines of stderr."""
        return [line for line in self.stderr.splitlines() if line.strip()]


def script(name: str) -> Path:
    """``recipes/<name>/train.py`` for a method, ``recipes/<name>/run.py`` for a study, or a path under recipes/."""
    for candidate in (ROOT / "recipes" / name / "train.py", ROOT / "recipes" / name / "run.py", ROOT / "recipes" / name):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(name)


def run_in_process(name: str, *args: str, cwd: str | os.PathLike | None = None, env: dict | None = None) -> Result:
    """Runs a recipe script with ``args`` in this process, from ``cwd`` with ``env`` set; returns its exit status
    and output."""
    path = script(name)
    saved_argv, saved_path, saved_cwd = sys.argv, list(sys.path), os.getcwd()
    saved_env = {key: os.environ.get(key) for key in (env or {})}
    out, err = io.StringIO(), io.StringIO()
    sys.argv = [str(path), *args]
    sys.path.insert(0, str(path.parent))
    os.environ.update({key: str(value) for key, value in (env or {}).items()})
    code = 0
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            runpy.run_path(str(path), run_name="__main__")
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        if isinstance(exit_.code, str):
            err.write(exit_.code + "\n")
    finally:
        sys.argv, sys.path[:] = saved_argv, saved_path
        os.chdir(saved_cwd)
        for key, value in saved_env.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return Result(code, out.getvalue(), err.getvalue())


def run_subprocess(name: str, *args: str, cwd: str | os.PathLike | None = None, env: dict | None = None,
                   timeout: float = 600) -> Result:
    """Runs a recipe script in a fresh interpreter."""
    environment = {**os.environ, "WANDB_MODE": "offline", "PYTHONPATH": str(ROOT), **(env or {})}
    done = subprocess.run([sys.executable, str(script(name)), *args], cwd=cwd or ROOT, env=environment,
                          capture_output=True, text=True, timeout=timeout)
    return Result(done.returncode, done.stdout, done.stderr)


def snapshot(folder: str | os.PathLike, *, exclude: str | os.PathLike | None = None) -> dict[str, tuple]:
    """Every file under ``folder`` (but those under ``exclude``) with its size and modification time."""
    folder = Path(folder)
    skip = Path(exclude).resolve() if exclude is not None else None
    files = {}
    for path in folder.rglob("*"):
        if path.is_file() and not (skip is not None and path.resolve().is_relative_to(skip)):
            stat = path.stat()
            files[path.relative_to(folder).as_posix()] = (stat.st_size, stat.st_mtime_ns)
    return files
