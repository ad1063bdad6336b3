"""Run directories: each pipeline stage's artifact is cached beside the key that made it, under a lock.

A stage is named, has a *key* (a JSON-able dict of everything that changes its artifact: config values, the robot's
fingerprint, the digests of the stages it depends on) and a file. ``RunDirectory.stage(name, key, build, save, load,
filename)`` returns the stage's result: loaded from disk when the artifact exists and was made with the same key,
built (then saved atomically, key first) otherwise. An artifact made with another key is never overwritten: the run
stops with an error naming the differences. Each build's wall-clock is recorded in ``builds.json`` (stage -> seconds,
threads, host, when), so a study that reuses a stage still reports what it cost. :meth:`RunDirectory.verify` checks a whole plan of stages this way before
any work, so a refused run writes nothing. A killed run resumes at its first unfinished stage.

One process at a time writes a run directory: :meth:`RunDirectory.acquire` takes an exclusive ``flock`` on
``.lock`` (the kernel releases it when the holder dies, so a killed run's lock is taken over) and a second process is
refused at once with a message naming the holder (or, asked to, waits for it). The lock is opened without following
a link (``O_NOFOLLOW``) and written only when it is a plain file of its own: a ``.lock`` that is a symbolic link (or
a hard link, or no file) in a received directory is refused in one line, its target untouched.

A run directory may come from someone else (``docs/pipeline.md``, "Received run directories are data"): stage files
are found only inside it (:func:`hierloco.io.inside`), :meth:`RunDirectory.verify` refuses a directory holding a link
that leads out of it, and :meth:`RunDirectory.foreign_artifacts` names the stage artifacts a plan did not make, so
that a directory whose ``run.json`` is lost is not taken over by another method. A directory the process may not write
is opened read-only: every stage must then be finished, and nothing is written. :func:`check_run_dir` refuses, before
anything is written, a path that cannot be a run directory: empty, ``/``, the home or working directory, a file, a
symlink loop, or a directory of other files that hierloco did not make.

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

import errno
import fcntl
import functools
import hashlib
import json
import os
import socket
import stat
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, TypeVar

import numpy as np

from hierloco.io import TEMPORARY_PREFIX, ArtifactError, inside, write_text

T = TypeVar("T")
LOCK_NAME = ".lock"
BUILDS_NAME = "builds.json"


class ConfigMismatchError(ArtifactError):
    """A stage's artifact on disk was made with another key (config)."""


class RunLockedError(RuntimeError):
    """Another process holds the run directory."""


class ReadOnlyRunError(RuntimeError):
    """A read-only run directory lacks a stage that would have to be built."""


class RunDirectoryError(ValueError):
    """A path that cannot be (or is not this run's) run directory."""


MARKERS = ("run.json", BUILDS_NAME)  # a directory holding one of these (or a stage key) is hierloco's


def is_run_directory(path: Path) -> bool:
    """Whether ``path`` is a directory hierloco made: it holds a run manifest, a build record or a stage key at its
    top level."""
    return path.is_dir() and (any((path / name).exists() for name in MARKERS) or any(path.glob("*.key.json")))


def check_run_dir(value) -> Path:
    """``value`` as a run directory path, or :class:`RunDirectoryError` naming why it cannot be one: empty, ``/``,
    the home directory, the working directory itself (or one of its parents), an existing file (or a path under
    one), a symlink loop, or a non-empty directory that hierloco did not make. Nothing is written."""
    text = "" if value is None else str(value)
    if not text.strip():
        raise RunDirectoryError("run_dir is empty: give a directory for the run (or leave run_dir unset)")
    path = Path(text).expanduser()
    try:
        resolved = path.resolve(strict=False)
    except (OSError, RuntimeError) as error:  # a symlink loop
        raise RunDirectoryError(f"run_dir={text} cannot be resolved ({error})") from None
    if resolved == Path(resolved.anchor) or resolved == Path.home().resolve():
        raise RunDirectoryError(f"run_dir={text} is {resolved}: give a directory of its own for the run")
    if resolved == Path.cwd().resolve() or resolved in Path.cwd().resolve().parents:
        raise RunDirectoryError(f"run_dir={text} is the working directory or one of its parents: give a directory "
                                "of its own for the run")
    if path.is_symlink() and not path.exists():
        raise RunDirectoryError(f"run_dir={text} is a broken symbolic link")
    if resolved.exists() and not resolved.is_dir():
        raise RunDirectoryError(f"run_dir={text} is an existing file, not a directory")
    existing = next((parent for parent in resolved.parents if parent.exists()), None)
    if existing is not None and not existing.is_dir():  # run_dir=<file>/sub: no directory can be made under it
        raise RunDirectoryError(f"run_dir={text} is under {existing}, which is a file, not a directory")
    if resolved.is_dir():
        try:
            entries = [entry.name for entry in resolved.iterdir()]
        except OSError as error:
            raise RunDirectoryError(f"run_dir={text} cannot be listed ({error.strerror})") from None
        if entries and not is_run_directory(resolved):
            listed = ", ".join(sorted(entries)[:3]) + (", ..." if len(entries) > 3 else "")
            raise RunDirectoryError(f"run_dir={text} holds files hierloco did not make ({listed}): give an empty or "
                                    "new directory, or a run directory of a recipe")
    return path


def _json_default(value):
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


def normalized(key: dict) -> dict:
    """The key as it is stored: tuples as lists, numpy scalars and arrays as numbers and lists, others as str."""
    return json.loads(json.dumps(key, default=_json_default))


def digest(key: dict) -> str:
    """A short hex digest of a key (12 characters of its sha256), for the keys of the stages that depend on it."""
    text = json.dumps(normalized(key), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


@functools.cache
def cpu_description() -> str:
    """This machine's CPU model and the instruction set torch's kernels use, e.g. ``"AMD EPYC (AVX512)"``: floating-point
    results, and so a long training run's trajectory, can differ between CPUs (``benchmarks/sac_reproducibility.py``),
    so every stage's build records it (``builds.json``). Found once per process."""
    import platform

    import torch

    try:
        name = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                    if line.startswith("model name"))
    except (OSError, StopIteration):
        name = platform.processor() or "unknown CPU"
    return f"{name} ({torch.backends.cpu.get_cpu_capability()})"


def _describe_holder(fd: int) -> str:
    """Who holds the lock open as ``fd`` (what its holder wrote into it)."""
    try:
        info = json.loads(os.pread(fd, 65536, 0).decode() or "{}")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        info = {}
    if not isinstance(info, dict):
        info = {}
    return f"pid {info.get('pid', '?')} on {info.get('host', '?')} since {info.get('started', '?')}: " \
           f"{info.get('command', '?')}"


def _open_lock(lock: Path, flags: int) -> int:
    """``lock`` opened with ``flags``, never through a symbolic link; refused (:class:`RunDirectoryError`) unless it
    is a plain file with no other name (a hard link would let the lock's JSON overwrite another file)."""
    try:
        fd = os.open(lock, flags | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise RunDirectoryError(f"{lock} is a symbolic link, not the lock file hierloco makes: remove the link "
                                    "(its target is left as it is) or choose another run_dir") from None
        raise
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or info.st_nlink != 1:
        os.close(fd)
        what = "not a plain file" if not stat.S_ISREG(info.st_mode) else f"a file with {info.st_nlink} names"
        raise RunDirectoryError(f"{lock} is {what}, not the lock file hierloco makes: remove it or choose another "
                                "run_dir")
    return fd


def outward_links(root: Path) -> list[str]:
    """The symbolic links under ``root`` (relative paths) that lead out of it or nowhere; links that stay inside
    (a tracker's ``latest-run``) are not listed, nor the links to files that Weights & Biases makes in its own run
    folder (``logs/<run>/wandb/...``: its ``debug-core.log`` leads to the log of its service in the user's cache),
    which hierloco never writes through (a run's logs go to a folder of its own)."""
    top = root.resolve()
    found = []
    for folder, directories, files in os.walk(root):
        for name in directories + files:
            path = Path(folder, name)
            parts = path.relative_to(root).parts
            if name in files and parts[0] == "logs" and "wandb" in parts[1:-1]:
                continue
            if path.is_symlink():
                try:
                    target = path.resolve(strict=True)
                except (OSError, RuntimeError):
                    target = None
                if target is None or not target.is_relative_to(top):
                    found.append(path.relative_to(root).as_posix())
    return sorted(found)


def _diff(stored: dict, wanted: dict, prefix: str = "") -> list[str]:
    lines = []
    for key in sorted(set(stored) | set(wanted)):
        a, b = stored.get(key, "<missing>"), wanted.get(key, "<missing>")
        if isinstance(a, dict) and isinstance(b, dict):
            lines += _diff(a, b, f"{prefix}{key}.")
        elif a != b:
            lines.append(f"{prefix}{key}: {a!r} on disk, {b!r} asked")
    return lines


@dataclass(frozen=True)
class StageSpec:
    """One stage of a plan: its ``name``, its ``key`` and its artifact ``filename`` (relative to the run
    directory)."""

    name: str
    key: dict
    filename: str

    @property
    def digest(self) -> str:
        return digest(self.key)


class RunDirectory:
    """A directory holding one run's stage artifacts, each beside a ``<artifact>.key.json``.

    Args:
        path: the directory (created on the first write, not before).
        readonly: open without writing; default: read-only when the directory exists and is not writable.
    """

    def __init__(self, path: str | os.PathLike, *, readonly: bool | None = None):
        self.path = Path(path)
        if readonly is None:
            readonly = self.path.exists() and not os.access(self.path, os.W_OK)
        self.readonly = bool(readonly)
        self.timings: dict[str, float] = {}
        self.reused: dict[str, bool] = {}
        self.build_seconds: dict[str, float | None] = {}  # what building each stage took, when it was built
        self.current: str | None = None  # the stage being built or loaded
        self._interrupted_seconds = 0.0  # what killed builds of the current stage took (count_interrupted_seconds)
        self._lock_fd: int | None = None

    # ------------------------------------------------------------------------------------------------ lock
    def holder(self) -> str | None:
        """Who holds the run directory (pid, host, start, command), or ``None`` when it is free. Writes nothing."""
        lock = self.path / LOCK_NAME
        if self._lock_fd is not None or not (lock.is_symlink() or lock.exists()):
            return None
        fd = _open_lock(lock, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(fd, fcntl.LOCK_UN)
            return None
        except BlockingIOError:
            return _describe_holder(fd)
        finally:
            os.close(fd)

    def check_free(self) -> None:
        """Raises :class:`RunLockedError` naming the holder when another process holds the directory."""
        who = self.holder()
        if who is not None:
            raise RunLockedError(f"run directory {self.path} is in use by {who}; wait for it to finish or choose "
                                 "another run_dir")

    def acquire(self, holder: str | None = None, *, wait: bool = False, poll: float = 2.0) -> None:
        """Takes the run directory for this process; if another process has it, raises :class:`RunLockedError`
        naming the holder, or with ``wait`` says so once and waits for it. A lock left by a killed process is taken
        over, and the temporary files it left (``.hierloco-tmp-*`` at the top level) are removed. No-op when
        read-only."""
        if self.readonly or self._lock_fd is not None:
            return
        self.path.mkdir(parents=True, exist_ok=True)
        fd = _open_lock(self.path / LOCK_NAME, os.O_RDWR | os.O_CREAT)
        said = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if not wait:
                    holder = _describe_holder(fd)
                    os.close(fd)
                    raise RunLockedError(f"run directory {self.path} is in use by {holder}; wait for it to finish "
                                         "or choose another run_dir") from None
                if not said:
                    print(f"waiting for run directory {self.path}, in use by {_describe_holder(fd)}", flush=True)
                    said = True
                time.sleep(poll)
        info = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
                "command": holder or " ".join(sys.argv)}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(info).encode(), 0)
        self._lock_fd = fd
        for leftover in self.path.glob(f"{TEMPORARY_PREFIX}*"):  # half-written files of a killed run
            if stat.S_ISREG(os.lstat(leftover).st_mode):  # plain files only: nothing is removed through a link
                leftover.unlink(missing_ok=True)

    def release(self) -> None:
        if self._lock_fd is not None:
            fcntl.flock(self._lock_fd, fcntl.LOCK_UN)
            os.close(self._lock_fd)
            self._lock_fd = None

    def __enter__(self) -> "RunDirectory":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    # ------------------------------------------------------------------------------------------------ keys
    def builds(self) -> dict[str, dict]:
        """``builds.json``: stage -> ``{"seconds", "threads", "host", "cpu", "finished"}`` of its last build, with
        ``interrupted_seconds`` where it resumed killed builds (:meth:`count_interrupted_seconds`) (``{}`` if
        none was recorded, as for runs made before it existed; ``cpu`` (:func:`cpu_description`) is missing in builds
        recorded before it was)."""
        try:
            builds = json.loads((self.path / BUILDS_NAME).read_text())
        except (OSError, ValueError):
            return {}
        return builds if isinstance(builds, dict) else {}

    def count_interrupted_seconds(self, seconds: float) -> None:
        """Adds ``seconds`` that killed builds of the stage being built spent before this one resumed from their
        checkpoint (a build that checkpoints knows it: :func:`hierloco.components.sac.train_sac` returns it as
        ``seconds["before_resume"]``). The stage's ``builds.json`` entry then holds the whole build's time in
        ``seconds`` and that part as ``interrupted_seconds``, so compute tables count a resumed stage in full."""
        if not seconds >= 0:
            raise ValueError(f"interrupted seconds must be >= 0, got {seconds}")
        self._interrupted_seconds += float(seconds)

    def _record_build(self, name: str, seconds: float, interrupted: float = 0.0) -> None:
        threads = os.environ.get("OMP_NUM_THREADS", "")
        threads = int(threads) if threads.strip().isdigit() else (
            len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count())
        builds = {**self.builds(), name: {"seconds": round(seconds, 3), "threads": threads, "host": socket.gethostname(),
                                          "cpu": cpu_description(),
                                          "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                          **({"interrupted_seconds": round(interrupted, 3)} if interrupted else {})}}
        write_text(self.path / BUILDS_NAME, json.dumps(builds, indent=1, sort_keys=True))

    def key_path(self, filename: str) -> Path:
        return inside(self.path, f"{filename}.key.json")

    def foreign_artifacts(self, filenames: Iterable[str]) -> list[str]:
        """What at the top level of the directory a plan making ``filenames`` cannot claim, sorted: the stage
        artifacts (files with a ``<file>.key.json``) it does not make, or, when the directory holds no stage key at
        all, every file but the lock and temporary files (a run's results without the stages that would tell whose
        they are). Empty for a new or empty directory and for one holding only the plan's stages."""
        planned = {f"{name}.key.json" for name in filenames}
        try:
            entries = [name for name in os.listdir(self.path)
                       if name != LOCK_NAME and not name.startswith(TEMPORARY_PREFIX)]
        except (FileNotFoundError, NotADirectoryError):
            return []
        keys = [name for name in entries if name.endswith(".key.json")]
        if not keys:
            return sorted(entries)
        return sorted(name.removesuffix(".key.json") for name in keys if name not in planned)

    def check(self, name: str, key: dict, filename: str) -> bool:
        """True if the stage is done with this key, False if not started; raises on a mismatch."""
        artifact, key_path = inside(self.path, filename), self.key_path(filename)
        if not artifact.exists():
            return False
        if not key_path.exists():
            raise ConfigMismatchError(f"{artifact} exists but {key_path.name} does not: cannot tell which config "
                                      "made it; use another run directory or remove the file")
        try:
            stored = json.loads(key_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise ArtifactError(f"corrupted stage key {key_path}: {error}") from error
        if not isinstance(stored, dict):
            raise ArtifactError(f"corrupted stage key {key_path}: not a JSON object")
        wanted = normalized(key)
        if stored != wanted:
            raise ConfigMismatchError(f"stage {name!r} in {self.path} was made with another config:\n  "
                                      + "\n  ".join(_diff(stored, wanted))
                                      + "\nuse another run directory (run_dir=...) or remove that stage's files")
        return True

    def verify(self, plan: Iterable[StageSpec]) -> dict[str, bool]:
        """Checks every stage of ``plan`` against the directory before any work: ``name -> done``. Raises one
        :class:`ConfigMismatchError` listing every mismatched stage, or :class:`ReadOnlyRunError` when the directory
        is read-only and a stage is not done; a :class:`RunDirectoryError` when the directory holds a symbolic link
        that leads out of it (:func:`outward_links`: what is written there would land elsewhere)."""
        links = outward_links(self.path) if self.path.is_dir() else []
        if links:
            listed = ", ".join(links[:3]) + (", ..." if len(links) > 3 else "")
            raise RunDirectoryError(f"run directory {self.path} holds symbolic links that lead out of it ({listed}): "
                                    "hierloco writes only inside its run directory; remove them or choose another "
                                    "run_dir")
        done, problems = {}, []
        for spec in plan:
            try:
                done[spec.name] = self.check(spec.name, spec.key, spec.filename)
            except ConfigMismatchError as error:
                problems.append(str(error).split("\nuse another")[0])
        if problems:
            raise ConfigMismatchError("\n".join(problems) + "\nuse another run directory (run_dir=...) or remove "
                                                            "those stages' files")
        missing = [name for name, finished in done.items() if not finished]
        if self.readonly and missing:
            raise ReadOnlyRunError(f"run directory {self.path} is read-only and these stages are not finished: "
                                   f"{', '.join(missing)}")
        return done

    # ------------------------------------------------------------------------------------------------ stages
    def stage(self, name: str, key: dict, build: Callable[[], T], save: Callable[[T, Path], Any],
              load: Callable[[Path], T], filename: str) -> T:
        """The result of stage ``name``: cached if done with ``key``, else built and saved."""
        artifact = inside(self.path, filename)
        start = time.perf_counter()
        self.current = name
        if self.check(name, key, filename):
            result = load(artifact)
            self.reused[name] = True
            self.build_seconds[name] = self.builds().get(name, {}).get("seconds")
        else:
            if self.readonly:
                raise ReadOnlyRunError(f"run directory {self.path} is read-only and stage {name!r} is not finished")
            write_text(self.key_path(filename), json.dumps(normalized(key), indent=2, sort_keys=True))
            self._interrupted_seconds = 0.0
            result = build()
            save(result, artifact)
            self.reused[name] = False
            self.build_seconds[name] = time.perf_counter() - start + self._interrupted_seconds
            self._record_build(name, self.build_seconds[name], self._interrupted_seconds)
        self.current = None
        self.timings[name] = time.perf_counter() - start
        return result
