"""Artifacts on disk: atomic writes and self-describing array files.

Every artifact is written to a temporary file and moved into place in one step, so a killed run never leaves a
half-written file under a final name. Temporary files are named ``.hierloco-tmp-*``; they are made beside their
destination, or, inside :func:`temporaries_in` (a run directory), at that directory's top level, where the next
run of that directory removes what a killed run left (and nothing else). Array files are ``.npz`` archives that carry their
metadata (a JSON dict) with them; a file that cannot be read gets an error that names it.

Example:
    >>> import numpy as np, tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "x.npz")
    >>> save_arrays(path, {"a": np.arange(3)}, {"robot": "a1"})
    >>> arrays, meta = load_arrays(path)
    >>> arrays["a"].tolist(), meta["robot"]
    ([0, 1, 2], 'a1')
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np


_UMASK = os.umask(0)
os.umask(_UMASK)


TEMPORARY_PREFIX = ".hierloco-tmp-"
_TEMPORARIES: ContextVar[Path | None] = ContextVar("hierloco_temporaries", default=None)


class ArtifactError(ValueError):
    """An artifact on disk is missing, corrupted or does not match what was asked for."""


@contextmanager
def temporaries_in(directory: str | os.PathLike) -> Iterator[None]:
    """Within the block, atomic writes to files under ``directory`` stage their temporary file at its top level."""
    token = _TEMPORARIES.set(Path(directory).absolute())
    try:
        yield
    finally:
        _TEMPORARIES.reset(token)


def _staging_directory(path: Path) -> Path:
    top = _TEMPORARIES.get()
    if top is not None and path.absolute().is_relative_to(top):
        top.mkdir(parents=True, exist_ok=True)
        return top
    return path.parent


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yields a temporary path (``.hierloco-tmp-*``); on success it replaces ``path`` atomically, on error it
    vanishes."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f"{TEMPORARY_PREFIX}{path.name}.", suffix=path.suffix,
                               dir=_staging_directory(path))
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600 files; artifacts get the usual permissions
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Writes ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)


def save_arrays(path: str | os.PathLike, arrays: Mapping[str, np.ndarray], metadata: Mapping[str, Any]) -> None:
    """Saves named arrays and a JSON-able metadata dict to a ``.npz`` file, atomically."""
    payload = {name: np.asarray(value) for name, value in arrays.items()}
    payload["__metadata__"] = np.asarray(json.dumps(dict(metadata), sort_keys=True))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **payload)


def load_arrays(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Loads a file written by :func:`save_arrays`; raises :class:`ArtifactError` naming the file if it is bad."""
    path = Path(path)
    if not path.is_file():
        raise ArtifactError(f"no such artifact: {path}")
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
        metadata = json.loads(str(arrays.pop("__metadata__")))
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError, EOFError) as error:
        raise ArtifactError(f"corrupted artifact {path}: {error}") from error
    return arrays, metadata


def save_checkpoint(path: str | os.PathLike, kind: str, version: int, payload: Mapping[str, Any]) -> None:
    """Saves a torch checkpoint tagged with its ``kind`` and format ``version``, atomically."""
    import torch

    buffer = io.BytesIO()  # torch names the archive after the file: save to memory so the bytes never depend on it
    torch.save({**payload, "kind": kind, "format": version}, buffer)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(buffer.getvalue())


def load_checkpoint(path: str | os.PathLike, kind: str, version: int, map_location="cpu") -> dict:
    """Loads a checkpoint written by :func:`save_checkpoint` (weights only, no code); raises :class:`ArtifactError`
    naming the file when it is missing, damaged, or of another kind or version."""
    import torch

    description = kind.replace("_", " ")
    try:
        payload = torch.load(path, map_location=map_location, weights_only=True)
    except FileNotFoundError:
        raise ArtifactError(f"no such {description} checkpoint: {path}") from None
    except Exception as error:  # torch raises many types for a damaged file
        raise ArtifactError(f"corrupted {description} checkpoint {path}: {error}") from error
    if not isinstance(payload, dict) or payload.get("kind") != kind or payload.get("format") != version:
        raise ArtifactError(f"{path} is not a {description} checkpoint of format {version}")
    return payload


def save_json(path: str | os.PathLike, obj: Any) -> None:
    """Writes ``obj`` as JSON to ``path`` atomically (NumPy scalars and arrays become numbers and lists)."""
    def default(value):
        if isinstance(value, (np.generic, np.ndarray)):
            return value.tolist()
        raise TypeError(f"{type(value).__name__} is not JSON-serialisable")

    write_text(path, json.dumps(obj, indent=1, default=default))


def check_schema(obj: Any, schema: Mapping[str, Any], where: str) -> None:
    """Checks that ``obj`` is a dict holding every key of ``schema`` with a value of the given type (a type, a
    tuple of types, or a nested schema dict); raises :class:`ArtifactError` naming ``where`` and the key."""
    if not isinstance(obj, dict):
        raise ArtifactError(f"{where}: expected a JSON object, got {type(obj).__name__}")
    for key, kind in schema.items():
        if key not in obj:
            raise ArtifactError(f"{where}: missing {key!r}")
        if isinstance(kind, Mapping):
            check_schema(obj[key], kind, f"{where}[{key!r}]")
            continue
        kinds = kind if isinstance(kind, tuple) else (kind,)
        value = obj[key]
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):  # True is not a number
            raise ArtifactError(f"{where}: {key!r} should be {getattr(kind, '__name__', kind)}, got "
                                f"{type(obj[key]).__name__}")


def load_json(path: str | os.PathLike, schema: Mapping[str, Any] | None = None) -> Any:
    """Reads a JSON artifact and checks it against ``schema`` (see :func:`check_schema`); a missing, unreadable or
    malformed file raises :class:`ArtifactError` naming it."""
    path = Path(path)
    try:
        obj = json.loads(path.read_text())
    except FileNotFoundError:
        raise ArtifactError(f"no such artifact: {path}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ArtifactError(f"corrupted artifact {path}: {error}") from error
    if schema is not None:
        check_schema(obj, schema, f"corrupted artifact {path}")
    return obj
