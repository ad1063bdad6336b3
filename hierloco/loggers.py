"""Run loggers on TorchRL's loggers: CSV always, plus Weights & Biases (offline unless asked) and TensorBoard.

Every :class:`RunLogger` is one invocation of a run: its experiment name comes from TorchRL's
``generate_exp_name(prefix, name)`` (``<prefix>_<name>_<uuid8>_<date-time>``) and everything it writes lives in the
experiment folder ``<log_dir>/<exp_name>/``:

- ``scalars/<metric>.csv`` (``step,value`` lines) and ``texts/hparams0.txt``: TorchRL's ``CSVLogger``;
- ``tables/<name>.csv`` (:meth:`RunLogger.log_table`) and ``summary.json`` (:meth:`RunLogger.summary`);
- ``wandb/offline-run-*`` (sync later with ``wandb sync <that folder>``) or the online run;
- ``tensorboard/`` event files (``tensorboard --logdir <log_dir>``).

A resumed, repeated or refused invocation therefore never appends to an earlier invocation's files, and the
hyper-parameters are logged once per invocation.

Metric names follow TorchRL's recipes (``train/...``, ``eval/...``, ``time/...``). Each ``/``-separated component is
cleaned by :func:`metric_component`: wandb reads ``.`` in a metric name as nesting, so a task called
``goal_reaching_1.5m`` is logged as ``goal_reaching_1p5m`` (otherwise its chart loses its step axis). On wandb every
metric is plotted against the step of its group (``eval/normal/goal_reaching/step`` for
``eval/normal/goal_reaching/normalized_cost``: TorchRL's convention), so callers pass real steps (epochs, frames).

``wandb_mode="online"`` first checks within a few seconds that the wandb server answers; when it does not (no
network, no login) a single line says so and the run carries on with the other backends. ``"offline"`` never
touches the network.

Example:
    >>> import tempfile
    >>> logger = RunLogger("a1_seed0", tempfile.mkdtemp(), prefix="lat", backends=("csv",), config={"seed": 0})
    >>> logger.log_scalar("eval/normal/goal_reaching_1.5m/normalized_cost", 0.3, step=0)
    >>> logger.log_curve("train/dynamics", {"heldout_loss": [0.9, 0.5, 0.4]}, step_name="epoch")
    >>> (logger.experiment_dir / "scalars/eval/normal/goal_reaching_1p5m/normalized_cost.csv").read_text()
    '0,0.3\\n'
    >>> logger.close()
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import socket
import sys
import threading
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence
from urllib.parse import urlparse

import numpy as np

from hierloco.io import write_text

BACKENDS = ("csv", "wandb", "tensorboard")
WANDB_MODES = ("offline", "online")
WANDB_INIT_TIMEOUT = 6.0  # s: how long wandb.init may take online before the run goes on without it
WANDB_PROBE_TIMEOUT = 3.0  # s: how long the wandb server has to accept a connection
DEFAULT_WANDB_URL = "https://api.wandb.ai"


# ---------------------------------------------------------------------------------------------------- names
def metric_component(text: Any) -> str:
    """One component of a metric path, safe for every backend (wandb reads ``.`` as nesting, ``/`` as a section).

    A decimal point between digits becomes ``p`` (``1.5m`` -> ``1p5m``); any other character outside
    ``[A-Za-z0-9_-]`` becomes ``_``; repeated and leading/trailing ``_`` are dropped.

    Example:
        >>> metric_component("goal_reaching_1.5m"), metric_component(" plan time (s) ")
        ('goal_reaching_1p5m', 'plan_time_s')
    """
    cleaned = re.sub(r"(?<=\d)\.(?=\d)", "p", str(text).strip())
    cleaned = re.sub(r"[^A-Za-z0-9_\-]", "_", cleaned)
    cleaned = re.sub(r"_+", "_", cleaned).strip("_")
    if not cleaned:
        raise ValueError(f"metric name component {text!r} has no letters or digits")
    return cleaned


def metric_name(*parts: Any) -> str:
    """A ``/``-joined metric path from ``parts`` (each may hold ``/``), every component cleaned by
    :func:`metric_component`; empty components (stray or doubled ``/``) are dropped.

    Example:
        >>> metric_name("eval", "normal/", "goal_reaching_1.5m", "normalized_cost")
        'eval/normal/goal_reaching_1p5m/normalized_cost'
    """
    components = [c for part in parts for c in str(part).split("/") if c.strip()]
    if not components:
        raise ValueError(f"empty metric name from {parts!r}")
    return "/".join(metric_component(c) for c in components)


def flatten_config(config: Mapping, prefix: str = "") -> dict[str, Any]:
    """A nested config as one level of ``a/b/c`` keys with bool, int, float or str values (lists as text), the form
    TensorBoard's hyper-parameter view takes.

    Example:
        >>> flatten_config({"robot": "a1", "planner": {"horizon": 1, "names": ["cem", "mppi"]}})
        {'robot': 'a1', 'planner/horizon': 1, 'planner/names': "['cem', 'mppi']"}
    """
    flat: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten_config(value, f"{name}/"))
        elif isinstance(value, (bool, int, float, str)):
            flat[name] = value
        elif isinstance(value, np.generic):
            flat[name] = value.item()
        else:
            flat[name] = str(value)
    return flat


def _json_default(value):
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if hasattr(value, "tolist"):  # torch tensors
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _as_float(name: str, value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"metric {name!r} must be a number, got {value!r}") from error


def _check_step(step) -> int:
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 0:
        raise ValueError(f"step must be a non-negative integer (an epoch, a frame count), got {step!r}")
    return int(step)


# ---------------------------------------------------------------------------------------------------- wandb
def _wandb_server_url() -> str:
    """The wandb server this process would talk to (``WANDB_BASE_URL``, then wandb's own settings)."""
    url = os.environ.get("WANDB_BASE_URL")
    if url:
        return url
    try:
        from wandb.sdk import wandb_setup

        return str(wandb_setup.singleton().settings.base_url or DEFAULT_WANDB_URL)  # loads settings, starts nothing
    except Exception:  # noqa: BLE001 - an unexpected wandb layout falls back to the public server
        return DEFAULT_WANDB_URL


def _unreachable(url: str, timeout: float) -> str | None:
    """Why the server at ``url`` cannot be reached within ``timeout`` s (DNS and TCP connect), or ``None``."""
    parsed = urlparse(url)
    host = parsed.hostname
    if not host:
        return f"bad wandb server address {url!r}"
    port = parsed.port or (443 if parsed.scheme == "https" else 80)
    outcome: dict[str, BaseException | None] = {}

    def probe():
        try:
            socket.create_connection((host, port), timeout=timeout).close()
            outcome["error"] = None
        except OSError as error:
            outcome["error"] = error

    thread = threading.Thread(target=probe, name="wandb-probe", daemon=True)  # DNS has no timeout of its own
    thread.start()
    thread.join(timeout)
    if "error" not in outcome:
        return f"no answer from {host}:{port} within {timeout:g} s"
    error = outcome["error"]
    if error is None:
        return None
    return f"{host}:{port}: {getattr(error, 'strerror', None) or error}"


def _first_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__


# ---------------------------------------------------------------------------------------------------- logger
class RunLogger:
    """Sends metrics, curves, images, tables and a summary to TorchRL's CSV logger and the chosen other backends.

    Args:
        name: what the run is, e.g. ``"a1_seed0"``; the experiment name is
            ``torchrl.record.loggers.generate_exp_name(prefix, name)``, unique per invocation.
        log_dir: the folder holding one experiment folder per invocation.
        prefix: the first part of the experiment name (TorchRL recipes use the algorithm, e.g. ``"lat"``).
        backends: any of ``"csv"``, ``"wandb"``, ``"tensorboard"`` (CSV is always added).
        project: the wandb project. group: the wandb group (e.g. ``"lat/a1/paper"``: method/robot/preset), so the
            seeds of one configuration are shown together. tags: wandb tags.
        wandb_mode: ``"offline"`` (default; writes ``wandb/offline-run-*``, never touches the network) or
            ``"online"``.
        wandb_init_timeout: s that ``wandb.init`` may take online before the run goes on without wandb.
        config: hyper-parameters, logged once (CSV ``texts/hparams0.txt``, the wandb run config, TensorBoard
            hparams).

    Attributes:
        exp_name: the unique experiment name. experiment_dir: ``log_dir / exp_name``.
        active_backends: the backends that are logging (wandb drops out when it cannot start).
        wandb_problem: why wandb was dropped (the line printed on stderr), else ``None``.

    Example:
        >>> import tempfile
        >>> with RunLogger("demo", tempfile.mkdtemp(), backends=("csv",)) as logger:
        ...     logger.log_metrics({"eval/success_rate": 0.5, "time/plan_seconds": 0.1}, step=3)
        ...     _ = logger.summary({"eval/success_rate": 0.5})
        >>> sorted(p.name for p in logger.experiment_dir.iterdir())
        ['scalars', 'summary.json', 'texts', 'videos']
    """

    def __init__(self, name: str, log_dir: str | os.PathLike, *, prefix: str = "hierloco",
                 backends: Iterable[str] = ("csv", "wandb"), project: str = "hierloco", group: str | None = None,
                 tags: Sequence[str] = (), wandb_mode: str = "offline",
                 wandb_init_timeout: float = WANDB_INIT_TIMEOUT, config: Mapping | None = None):
        if isinstance(backends, str):
            raise ValueError(f"backends must be a list of names, got the string {backends!r}")
        wanted = set(backends) | {"csv"}
        unknown = wanted - set(BACKENDS)
        if unknown:
            raise ValueError(f"unknown logger backends {sorted(unknown)}; known: {list(BACKENDS)}")
        if wandb_mode not in WANDB_MODES:
            raise ValueError(f"wandb_mode must be 'offline' or 'online', got {wandb_mode!r}")
        for label, value in [("name", name), ("prefix", prefix), ("project", project)]:
            if not isinstance(value, str) or not value.strip():
                raise ValueError(f"{label} must be a non-empty string, got {value!r}")
        if group is not None and (not isinstance(group, str) or not group.strip()):
            raise ValueError(f"group must be a non-empty string or None, got {group!r}")
        if isinstance(tags, str) or not all(isinstance(t, str) and t for t in tags):
            raise ValueError(f"tags must be a list of non-empty strings, got {tags!r}")
        if not (isinstance(wandb_init_timeout, (int, float)) and math.isfinite(wandb_init_timeout)
                and wandb_init_timeout > 0):
            raise ValueError(f"wandb_init_timeout must be a positive number of seconds, got {wandb_init_timeout!r}")
        if config is not None and not isinstance(config, Mapping):
            raise ValueError(f"config must be a mapping, got {type(config).__name__}")
        from torchrl.record.loggers import generate_exp_name
        from torchrl.record.loggers.csv import CSVLogger

        self.exp_name = generate_exp_name(prefix, name)
        self.log_dir = Path(log_dir)
        self.experiment_dir = self.log_dir / self.exp_name
        self.wandb_problem: str | None = None
        self._closed = False
        self.loggers: dict[str, Any] = {"csv": CSVLogger(self.exp_name, log_dir=str(self.log_dir))}
        try:
            if "tensorboard" in wanted:
                from torchrl.record.loggers.tensorboard import TensorboardLogger

                self.loggers["tensorboard"] = TensorboardLogger("tensorboard", log_dir=str(self.experiment_dir))
            if "wandb" in wanted:
                wandb_logger = self._open_wandb(project=project, group=group, tags=list(tags), mode=wandb_mode,
                                                init_timeout=float(wandb_init_timeout), config=dict(config or {}))
                if wandb_logger is not None:
                    self.loggers["wandb"] = wandb_logger
            if config:
                flat = flatten_config(config)
                for backend in ("csv", "tensorboard"):  # wandb got the config with its run
                    if backend in self.loggers:
                        self.loggers[backend].log_hparams(flat)
        except BaseException:  # e.g. a full disk: what was opened is closed (its files too), then the error goes on
            try:
                self.close()
            except Exception:  # noqa: BLE001  (the first error is the one to report)
                pass
            raise

    # ------------------------------------------------------------------------------------------------ wandb
    def _open_wandb(self, *, project, group, tags, mode, init_timeout, config):
        """TorchRL's ``WandbLogger``, or ``None`` after one line on stderr when wandb cannot start."""
        try:
            import wandb
            from torchrl.record.loggers.wandb import WandbLogger
        except ImportError as error:
            return self._drop_wandb(f"cannot import wandb ({error})")
        saved = {key: os.environ.get(key) for key in ("WANDB_MODE", "WANDB_SILENT")}
        if saved["WANDB_SILENT"] is None:
            os.environ["WANDB_SILENT"] = "true"  # wandb's own chatter (its login line) goes; our one line stays
        try:
            url = None
            if mode == "online":
                url = _wandb_server_url()
                reason = _unreachable(url, min(WANDB_PROBE_TIMEOUT, init_timeout))
                if reason:
                    return self._drop_wandb(f"cannot reach the server ({reason})")
            settings = wandb.Settings(mode=mode, init_timeout=init_timeout, silent=True,
                                      **({"base_url": url} if url else {}))
            logger = WandbLogger(self.exp_name, offline=mode == "offline", save_dir=str(self.experiment_dir),
                                 project=project, group=group, tags=tags, config=config, mode=mode,
                                 settings=settings, log_env_packages=False)
        except Exception as error:  # noqa: BLE001 - any failure of wandb leaves the other backends running
            return self._drop_wandb(f"could not start ({_first_line(error)})")
        finally:
            for key, value in saved.items():  # TorchRL's offline logger sets WANDB_MODE process-wide
                if value is None:
                    os.environ.pop(key, None)
                else:
                    os.environ[key] = value
        if mode == "online":
            print(f"wandb: logging online to {getattr(logger.experiment, 'url', None) or url}", file=sys.stderr,
                  flush=True)
        return logger

    def _drop_wandb(self, reason: str) -> None:
        others = "CSV" + (" and TensorBoard" if "tensorboard" in self.loggers else "")
        self.wandb_problem = f"wandb: {reason}; logging to {others} only"
        print(self.wandb_problem, file=sys.stderr, flush=True)
        return None

    @property
    def active_backends(self) -> tuple[str, ...]:
        return tuple(self.loggers)

    # ------------------------------------------------------------------------------------------------ scalars
    def log_scalar(self, name: str, value: float, step: int = 0) -> None:
        """``value`` of metric ``name`` (cleaned by :func:`metric_name`) at ``step`` (an epoch, a frame count)."""
        name, value, step = metric_name(name), _as_float(name, value), _check_step(step)
        for logger in self.loggers.values():
            logger.log_scalar(name, value, step=step)

    def log_metrics(self, metrics: Mapping[str, float], step: int = 0) -> None:
        """Several metrics at one ``step`` (one wandb row)."""
        clean = {metric_name(k): _as_float(k, v) for k, v in metrics.items()}
        step = _check_step(step)
        for logger in self.loggers.values():
            logger.log_metrics(clean, step=step)

    def log_curve(self, prefix: str, curves: Mapping[str, Sequence[float]], step_name: str = "epoch", *,
                  steps: Sequence[int] | None = None, first_step: int = 1) -> None:
        """Whole histories after the fact: ``curves[name][i]`` is ``<prefix>/<name>`` at step ``steps[i]``.

        Args:
            prefix: the metric group, e.g. ``"train/dynamics_normal"``.
            curves: name -> values (e.g. the per-epoch held-out loss); curves may have different lengths.
            step_name: what the steps count (``"epoch"``, ``"frames"``); on wandb the curves are plotted against
                ``<prefix>/<step_name>``, on CSV and TensorBoard it is the step column.
            steps: the step of each entry (increasing integers); default ``first_step, first_step + 1, ...``.
        """
        prefix, step_key = metric_name(prefix), metric_name(prefix, step_name)
        values = {}
        for name, curve in curves.items():
            array = np.asarray(curve, dtype=float) if not isinstance(curve, str) else None
            if array is None or array.ndim != 1:
                raise ValueError(f"curve {name!r} must be a 1-D sequence of numbers")
            values[metric_name(prefix, name)] = array
        if not values:
            raise ValueError("log_curve needs at least one curve")
        length = max(len(v) for v in values.values())
        if steps is None:
            steps = list(range(_check_step(first_step), _check_step(first_step) + length))
        steps = [_check_step(s) for s in steps]
        if len(steps) < length or any(b <= a for a, b in zip(steps, steps[1:])):
            raise ValueError(f"steps must be {length} increasing integers, got {steps}")
        for name, array in values.items():
            for i, value in enumerate(array):
                for backend in ("csv", "tensorboard"):
                    if backend in self.loggers:
                        self.loggers[backend].log_scalar(name, float(value), step=steps[i])
        if "wandb" in self.loggers:
            run = self.loggers["wandb"].experiment
            run.define_metric(step_key)
            for name in values:
                run.define_metric(name, step_metric=step_key)
            for i, step in enumerate(steps[:length]):
                run.log({step_key: step, **{n: float(a[i]) for n, a in values.items() if i < len(a)}})

    # ------------------------------------------------------------------------------------------------ media
    def log_image(self, name: str, png_path: str | os.PathLike, step: int = 0, caption: str | None = None) -> None:
        """A PNG figure to wandb (``wandb.Image``) and TensorBoard; CSV keeps none (the file is on disk already)."""
        name, step, path = metric_name(name), _check_step(step), Path(png_path)
        if not path.is_file():
            raise ValueError(f"no such image: {path}")
        from PIL import Image

        try:
            with Image.open(path) as image:
                pixels = np.asarray(image.convert("RGB"))
        except OSError as error:
            raise ValueError(f"cannot read image {path}: {error}") from error
        if "wandb" in self.loggers:
            import wandb

            self.loggers["wandb"].log_metrics({name: wandb.Image(str(path), caption=caption)}, step=step)
        if "tensorboard" in self.loggers:
            self.loggers["tensorboard"].experiment.add_image(name, pixels, global_step=step, dataformats="HWC")

    def log_video(self, name: str, frames, fps: int = 20, step: int = 0) -> None:
        """``T x H x W x 3`` uint8 frames to wandb; CSV keeps none, TensorBoard neither (torch's video writer needs
        the moviepy 1 API, and the project uses moviepy 2 for its MP4 files)."""
        import torch

        name, step = metric_name(name), _check_step(step)
        array = np.asarray(frames)
        if array.ndim != 4 or array.shape[-1] != 3 or array.dtype != np.uint8:
            raise ValueError(f"frames must be T x H x W x 3 uint8, got {array.dtype} {array.shape}")
        video = torch.as_tensor(np.ascontiguousarray(array.transpose(0, 3, 1, 2)), device="cpu")[None]
        if "wandb" in self.loggers:
            self.loggers["wandb"].log_video(name, video, step=step, fps=fps)

    def log_table(self, name: str, rows: Sequence[Mapping[str, Any]], step: int = 0) -> Path:
        """Rows of a table (e.g. per-episode results): a wandb ``Table``, ``tables/<name>.csv`` in the experiment
        folder, a Markdown table in TensorBoard's text tab. Columns are the keys in first-seen order; returns the
        CSV path."""
        name, step = metric_name(name), _check_step(step)
        if isinstance(rows, Mapping) or not len(rows) or not all(isinstance(r, Mapping) for r in rows):
            raise ValueError(f"table {name!r} needs a non-empty list of dicts (one per row)")
        columns = list(dict.fromkeys(str(k) for row in rows for k in row))
        data = [[row.get(c) for c in columns] for row in rows]
        text = io.StringIO()
        writer = csv.writer(text, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows([["" if v is None else v for v in line] for line in data])
        path = self.experiment_dir / "tables" / f"{name}.csv"
        write_text(path, text.getvalue())
        if "wandb" in self.loggers:
            import wandb

            self.loggers["wandb"].log_metrics({name: wandb.Table(columns=columns, data=data)}, step=step)
        if "tensorboard" in self.loggers:
            lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
            lines += ["| " + " | ".join("" if v is None else str(v) for v in line) + " |" for line in data]
            self.loggers["tensorboard"].experiment.add_text(name, "\n".join(lines), global_step=step)
        return path

    def summary(self, values: Mapping[str, Any]) -> Path:
        """Final numbers of the run: the wandb run summary; ``summary.json`` in the experiment folder (merged with
        earlier calls). Returns the JSON path."""
        clean = {metric_name(k): v for k, v in values.items()}
        try:
            json.dumps(clean, default=_json_default)
        except TypeError as error:
            raise ValueError(f"summary values must be numbers, strings or lists: {error}") from error
        path = self.experiment_dir / "summary.json"
        stored = json.loads(path.read_text()) if path.exists() else {}
        stored.update(json.loads(json.dumps(clean, default=_json_default)))
        write_text(path, json.dumps(stored, indent=2, sort_keys=True))
        if "wandb" in self.loggers:
            self.loggers["wandb"].experiment.summary.update(stored)
        return path

    def log_artifact(self, paths, name: str, kind: str = "model", metadata: Mapping[str, Any] | None = None) -> bool:
        """Logs the file(s) ``paths`` as one wandb artifact ``name`` of type ``kind`` (checkpoints: ``model``),
        offline too (``wandb sync`` uploads it with the run); returns whether an artifact was logged (no wandb:
        nothing)."""
        if "wandb" not in self.loggers:
            return False
        import wandb

        clean = re.sub(r"[^A-Za-z0-9_.-]", "-", name)
        artifact = wandb.Artifact(clean, type=kind, metadata=dict(metadata or {}))
        for path in [paths] if isinstance(paths, (str, os.PathLike)) else paths:
            artifact.add_file(str(path), name=Path(path).name)
        self.loggers["wandb"].experiment.log_artifact(artifact)
        return True

    @property
    def wandb_run(self) -> dict | None:
        """``{"id", "project", "group", "mode", "dir"}`` of the wandb run this logger writes, or ``None``."""
        if "wandb" not in self.loggers:
            return None
        run = self.loggers["wandb"].experiment
        return {"id": run.id, "project": run.project, "group": run.group,
                "mode": "offline" if run.settings.mode == "offline" else "online", "dir": str(run.dir)}

    # ------------------------------------------------------------------------------------------------ end
    def close(self) -> None:
        """Flushes and closes every backend (finishes the wandb run); calling it again does nothing. Every backend
        and file is closed even when one fails (a full disk: a CSV file's last lines cannot be written, yet the file
        is closed, so nothing is left for TorchRL's ``CSVExperiment.__del__`` to fail on later); the first failure
        is raised after all of them are closed."""
        if self._closed:
            return
        self._closed = True
        failures: list[BaseException] = []

        def attempt(action: Callable[[], Any]) -> None:
            try:
                action()
            except Exception as error:  # noqa: BLE001  (raised below, once everything else is closed)
                failures.append(error)

        for backend, logger in self.loggers.items():
            attempt(logger.close)
            if backend == "csv":
                for handle in logger.experiment.files.values():
                    attempt(handle.close)  # a failed flush still closes the file (io's close always does)
            if backend == "wandb":
                import wandb

                if wandb.run is None:  # no other run in this process: wait until wandb has written its files
                    attempt(wandb.teardown)
        if failures:
            raise failures[0]

    def __enter__(self) -> "RunLogger":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class NullLogger:
    """A logger that logs nothing (a run directory opened read-only writes no logs); the API of
    :class:`RunLogger`."""

    def log_scalar(self, name, value, step=0) -> None: ...
    def log_metrics(self, metrics, step=0) -> None: ...
    def log_curve(self, prefix, curves, step_name="epoch", **kwargs) -> None: ...
    def log_image(self, name, png_path, step=0, caption=None) -> None: ...
    def log_video(self, name, frames, fps=20, step=0) -> None: ...
    def log_table(self, name, rows, step=0) -> None: ...
    def summary(self, values) -> None: ...
    def log_artifact(self, path, name, kind="model", metadata=None) -> bool: return False
    wandb_run = None
    def close(self) -> None: ...


__all__ = ["BACKENDS", "NullLogger", "RunLogger", "flatten_config", "metric_component", "metric_name"]
