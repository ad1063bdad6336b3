"""Where networks, training and planning run (``device``), and how their hot loops run there (``docs/gpu.md``).

Simulation always runs on CPU threads (MuJoCo); networks, their training and MPC scoring run on the configured
device. ``device=auto`` (the recipes' default) is CUDA when a GPU is present, else the CPU; :func:`resolve_device`
turns it into the device a run's stage keys record, so on a machine without a GPU every key holds ``"cpu"`` as it
always did.

The hot loops can be compiled (:func:`compile_mode`: ``torch.compile`` with CUDA graphs on a GPU,
``mode="reduce-overhead"``, and plain ``torch.compile`` on the CPU), and MPC scoring can run its network in lower
precision (:data:`PRECISIONS`, :func:`precision_context`): ``tf32`` (TensorFloat-32 matrix products on CUDA; the
CPU keeps fp32) or ``bf16`` (autocast of the model's matrix products to bfloat16, on CUDA and CPU alike).

Example:
    >>> resolve_device("cpu")
    'cpu'
    >>> resolve_device("auto") in ("cpu", "cuda")
    True
    >>> compile_mode("cpu") is None
    True
"""

from __future__ import annotations

import contextlib
from typing import Iterator

import torch

DEVICES = ("auto", "cpu", "cuda")  # and cuda:<index>
PRECISIONS = ("fp32", "tf32", "bf16")


def device_problem(device) -> str | None:
    """Why ``device`` cannot be used here (one line), or ``None`` when it can."""
    name = str(device)
    index = name.removeprefix("cuda:")
    if name not in DEVICES and not (name.startswith("cuda:") and index.isdigit()):
        return f"device must be auto, cpu, cuda or cuda:<index>, got {name!r}"
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            return f"device={name} asked but no GPU is available (device=auto uses one when there is one)"
        if name.startswith("cuda:") and int(index) >= torch.cuda.device_count():
            return f"device={name} asked but this machine has {torch.cuda.device_count()} GPU(s)"
    return None


def resolve_device(device="auto") -> str:
    """The device ``device`` names here: ``auto`` is ``"cuda"`` when a GPU is present, else ``"cpu"``; any other
    value is returned as it is (``"cpu"``, ``"cuda"``, ``"cuda:1"``). Raises ``ValueError`` for a device that
    cannot be used here."""
    name = str(device)
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    problem = device_problem(name)
    if problem is not None:
        raise ValueError(problem)
    return name


def is_cuda(device) -> bool:
    return torch.device(device).type == "cuda"


def compile_mode(device) -> str | None:
    """The ``torch.compile`` mode for hot loops on ``device``: ``"reduce-overhead"`` (CUDA graphs) on a GPU, the
    default mode (``None``) on the CPU."""
    return "reduce-overhead" if is_cuda(device) else None


def check_precision(precision: str) -> str:
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    return precision


@contextlib.contextmanager
def precision_context(precision: str, device) -> Iterator[None]:
    """Runs the block's matrix products in ``precision`` on ``device`` (``fp32``: as they are; ``tf32``:
    TensorFloat-32 on CUDA, restored after; ``bf16``: autocast to bfloat16). Results stay float32 tensors."""
    check_precision(precision)
    kind = torch.device(device).type
    if precision == "bf16":
        with torch.autocast(kind, dtype=torch.bfloat16):
            yield
    elif precision == "tf32" and kind == "cuda":
        matmul = torch.backends.cuda.matmul
        setting = "fp32_precision" if hasattr(matmul, "fp32_precision") else "allow_tf32"  # torch >= 2.9: the first
        previous = getattr(matmul, setting)
        setattr(matmul, setting, "tf32" if setting == "fp32_precision" else True)
        try:
            yield
        finally:
            setattr(matmul, setting, previous)
    else:
        yield


def synchronize(device) -> None:
    """Waits for ``device``'s queued work (a no-op on the CPU): for honest wall-clock timings."""
    if is_cuda(device):
        torch.cuda.synchronize(torch.device(device))


__all__ = ["DEVICES", "PRECISIONS", "check_precision", "compile_mode", "device_problem", "is_cuda",
           "precision_context", "resolve_device", "synchronize"]
