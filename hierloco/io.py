"""Artifacts on disk: atomic writes and self-describing array files.

Every artifact is written to a temporary file beside its destination and moved into place in one step, so a
killed run never leaves a half-written file under a final name. Array files are ``.npz`` archives that carry their
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

import json
import os
import tempfile
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np


_UMASK = os.umask(0)
os.umask(_UMASK)


class ArtifactError(ValueError):
    """An artifact on disk is missing, corrupted or does not match what was asked for."""


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yields a temporary path beside ``path``; on success it replaces ``path`` atomically, on error it vanishes."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
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

    with atomic_path(path) as tmp:
        torch.save({**payload, "kind": kind, "format": version}, tmp)


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
