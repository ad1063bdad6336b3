"""Artifacts on disk: atomic writes and self-describing array files.

Every artifact is written to a temporary file and moved into place in one step, so a killed run never leaves a
half-written file under a final name. Temporary files are named ``.hierloco-tmp-*``; they are made beside their
destination, or, inside :func:`temporaries_in` (a run directory), at that directory's top level, where the next
run of that directory removes what a killed run left (and nothing else). Array files are ``.npz`` archives that carry their
metadata (a JSON dict) with them; a file that cannot be read gets an error that names it. A relative path read from a
file that may come from someone else (a run directory's ``outputs.json``, ``run.json``, a stage key, a record) is
turned into a path only by :func:`inside`, which refuses one that would reach outside its directory.

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
import stat
import tempfile
import zipfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path, PurePosixPath
from typing import Any, Iterator, Mapping

import numpy as np


_UMASK = os.umask(0)
os.umask(_UMASK)


TEMPORARY_PREFIX = ".hierloco-tmp-"
_TEMPORARIES: ContextVar[Path | None] = ContextVar("hierloco_temporaries", default=None)


class ArtifactError(ValueError):
    """An artifact on disk is missing, corrupted or does not match what was asked for."""


class UnsafePathError(ArtifactError):
    """A path read from a file (``outputs.json``, ``run.json``, a stage key, a record) that would lead outside the
    directory it belongs to."""


def inside(root: str | os.PathLike, relative: Any, *, source: str | os.PathLike | None = None) -> Path:
    """``root / relative`` for a relative path read from a file that may have been received from someone else (run
    directories and records travel between machines), refused with :class:`UnsafePathError` when it is not a
    non-empty relative path, climbs out of ``root`` (``..``), or passes through a symbolic link below ``root``:
    hierloco makes no links, so one there was put by someone else and may lead anywhere. ``root`` itself may be a
    link (the user's own choice). Parts that do not exist yet are fine: they are new, made by the caller. ``source``
    (the file the path was read from) is named in the message.

    Example:
        >>> import tempfile
        >>> root = tempfile.mkdtemp()
        >>> inside(root, "figures/a.png").relative_to(root).as_posix()
        'figures/a.png'
        >>> inside(root, "../thesis.tex")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        hierloco.io.UnsafePathError: '../thesis.tex' is not a path inside ...
    """
    where = f" (read from {source})" if source is not None else ""
    text = os.fspath(relative) if isinstance(relative, (str, os.PathLike)) else None
    parts = PurePosixPath(text).parts if isinstance(text, str) and "\x00" not in text else ()
    if not parts or parts[0] == "/" or ".." in parts:
        raise UnsafePathError(f"{relative!r}{where} is not a path inside {root}: only a relative path without '..' "
                              "is")
    current = Path(root)
    for part in parts:
        current = current / part
        try:
            mode = os.lstat(current).st_mode
        except (FileNotFoundError, NotADirectoryError):
            break  # new from here on
        if stat.S_ISLNK(mode):
            raise UnsafePathError(f"{relative!r}{where} passes through the symbolic link {current}: hierloco reads "
                                  f"and writes only inside {root}, never through a link")
    return Path(root, *parts)


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


# ---------------------------------------------------------------------------------------------------- YAML
YAML_MAX_BYTES = 1 << 20  # the largest YAML file hierloco reads (a robot description or a run's config: a few kB)
YAML_MAX_VALUES = 100_000  # the most values (scalars, lists, mappings) a YAML file may hold once aliases are expanded


def brief(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to at most ``limit`` characters, in bounded time whatever ``value`` holds (a list of a
    billion items, nested a thousand deep): what an error message shows of a value read from a file.

        >>> brief([[1.5] * 1000] * 1000, limit=40)
        '[[1.5, 1.5, 1.5, 1.5, 1.5, 1.5, ...],...'
        >>> brief("kp")
        "'kp'"
    """
    import reprlib

    shorter = reprlib.Repr()
    shorter.maxlevel = 3
    shorter.maxlist = shorter.maxtuple = shorter.maxdict = shorter.maxset = shorter.maxfrozenset = 6
    shorter.maxdeque = shorter.maxarray = 6
    shorter.maxstring = shorter.maxother = shorter.maxlong = limit
    text = shorter.repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _yaml_children(node) -> list:
    import yaml

    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def _check_yaml_size(root, where: str, max_values: int) -> None:
    """Refuses a composed YAML document that refers to itself through an alias, or whose aliases expand to more
    than ``max_values`` values (a "billion laughs": a few lines that nest aliases nine deep hold 9**9 values).
    Linear in the document's size: each node's expanded size is counted once."""
    sizes: dict[int, int] = {}  # id(node) -> values it holds once expanded
    open_nodes: set[int] = set()  # the nodes being counted: the ancestors of the current one
    stack = [(root, False)]
    while stack:
        node, counted = stack.pop()
        if counted:
            open_nodes.discard(id(node))
            sizes[id(node)] = size = 1 + sum(sizes[id(child)] for child in _yaml_children(node))
            if size > max_values:
                raise ArtifactError(f"{where}: its aliases (*name) expand to more than {max_values} values: hierloco "
                                    "reads no YAML that large (expand them yourself if they are meant)")
            continue
        if id(node) in sizes:
            continue
        if id(node) in open_nodes:
            raise ArtifactError(f"{where}: an alias (*name) refers to the value that holds it; a value cannot "
                                "contain itself")
        open_nodes.add(id(node))
        stack.append((node, True))
        stack += [(child, False) for child in _yaml_children(node) if id(child) not in sizes]


def parse_yaml(text: str, where: str = "YAML", *, max_values: int = YAML_MAX_VALUES) -> Any:
    """The value of the YAML document ``text`` (safe loading: plain values only, no Python objects), refused with
    :class:`ArtifactError` naming ``where`` when it is not YAML, refers to itself, or expands to more than
    ``max_values`` values through its aliases; the message never holds more than a bounded part of the text."""
    import yaml

    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_yaml_size(node, where, max_values)
        return loader.construct_document(node)
    except yaml.YAMLError as error:
        message = " ".join(str(error).split())
        raise ArtifactError(f"{where}: not a valid YAML file: {message[:300]}") from None
    except RecursionError:
        raise ArtifactError(f"{where}: its values are nested too deeply to read") from None
    finally:
        loader.dispose()


def load_yaml(path: str | os.PathLike, *, max_bytes: int = YAML_MAX_BYTES, max_values: int = YAML_MAX_VALUES) -> Any:
    """The value of the YAML file ``path``, read safely whoever wrote it (a robot description, a received run's
    ``config.yaml``, a ``causes.yaml``): :class:`ArtifactError` naming the file when it is missing, not a regular
    file, larger than ``max_bytes``, not UTF-8 text, not YAML, or when its aliases expand to more than
    ``max_values`` values (:func:`parse_yaml`). Nothing it raises formats more than a bounded part of the file.

        >>> import tempfile
        >>> path = os.path.join(tempfile.mkdtemp(), "robot.yaml")
        >>> _ = Path(path).write_text("kp: &k [1, 2]\\nkd: *k\\n")
        >>> load_yaml(path)
        {'kp': [1, 2], 'kd': [1, 2]}
    """
    path = Path(path)
    try:
        status = path.stat()
    except FileNotFoundError:
        raise ArtifactError(f"no such file: {path}") from None
    except OSError as error:
        raise ArtifactError(f"{path} cannot be read ({error.strerror or error})") from None
    if not stat.S_ISREG(status.st_mode):
        raise ArtifactError(f"{path} is not a regular file")
    try:
        with open(path, "rb") as file:
            data = file.read(max_bytes + 1)
    except OSError as error:
        raise ArtifactError(f"{path} cannot be read ({error.strerror or error})") from None
    if len(data) > max_bytes:
        raise ArtifactError(f"{path} is larger than {max_bytes} bytes: too large for a YAML file hierloco reads")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ArtifactError(f"{path} is not UTF-8 text (byte {error.start})") from None
    return parse_yaml(text, str(path), max_values=max_values)
