"""Run loggers: TorchRL's CSV logger always, plus Weights & Biases (offline unless asked otherwise).

Metric names follow TorchRL's recipes: ``train/...``, ``eval/...``, ``time/...``.

Example:
    >>> import tempfile
    >>> logger = RunLogger("demo", tempfile.mkdtemp(), backends=("csv",))
    >>> logger.log_scalar("eval/normalized_cost", 0.3)
    >>> logger.close()
"""

from __future__ import annotations

import os
from typing import Iterable, Mapping

from torchrl.record.loggers.csv import CSVLogger

BACKENDS = ("csv", "wandb")


class RunLogger:
    """Sends scalars to every configured TorchRL logger.

    Args:
        exp_name: experiment name. log_dir: where logs go.
        backends: ``"csv"`` and/or ``"wandb"`` (CSV is always added).
        project: wandb project. wandb_mode: ``"offline"`` (default: never touches the network) or ``"online"``.
        config: hyperparameters recorded with the run.
    """

    def __init__(self, exp_name: str, log_dir: str | os.PathLike, *, backends: Iterable[str] = ("csv", "wandb"),
                 project: str = "hierloco", wandb_mode: str = "offline", config: Mapping | None = None,
                 group: str | None = None, tags=None):
        backends = set(backends) | {"csv"}
        unknown = backends - set(BACKENDS)
        if unknown:
            raise ValueError(f"unknown logger backends {sorted(unknown)}; known: {list(BACKENDS)}")
        if wandb_mode not in ("offline", "online"):
            raise ValueError(f"wandb_mode must be 'offline' or 'online', got {wandb_mode!r}")
        self.loggers = [CSVLogger(exp_name, log_dir=str(log_dir))]
        if "wandb" in backends:
            from torchrl.record.loggers.wandb import WandbLogger

            if wandb_mode == "offline":
                os.environ["WANDB_MODE"] = "offline"
            os.environ.setdefault("WANDB_SILENT", "true")
            self.loggers.append(WandbLogger(exp_name, offline=wandb_mode == "offline", save_dir=str(log_dir),
                                            project=project, log_env_packages=False, config=dict(config or {})))
        if config:
            for logger in self.loggers[:1]:
                logger.log_hparams(dict(config))

    @classmethod
    def null(cls) -> "RunLogger":
        logger = cls.__new__(cls)
        logger.loggers = []
        return logger

    def log_curve(self, prefix, curves, step_name="step"):
        for name, values in curves.items():
            for step, value in enumerate(values, 1):
                self.log_scalar(f"{prefix}/{name}", value, step=step)

    def log_image(self, name, path):
        pass

    def log_table(self, name, rows):
        pass

    def summary(self, values):
        pass

    def log_scalar(self, name: str, value: float, step: int = 0) -> None:
        for logger in self.loggers:
            logger.log_scalar(name, float(value), step=step)

    def log_metrics(self, metrics: Mapping[str, float], step: int = 0) -> None:
        for name, value in metrics.items():
            self.log_scalar(name, value, step)

    def log_video(self, name: str, frames, fps: int = 20, step: int = 0) -> None:
        """``T x H x W x 3`` uint8 frames to the loggers that take videos (wandb); CSV keeps none."""
        import numpy as np
        import torch

        for logger in self.loggers[1:]:
            video = torch.as_tensor(np.ascontiguousarray(np.asarray(frames).transpose(0, 3, 1, 2)))[None]
            logger.log_video(name, video, step=step, fps=fps)

    def close(self) -> None:
        for logger in self.loggers:
            experiment = getattr(logger, "experiment", None)
            if hasattr(experiment, "finish"):
                experiment.finish()
