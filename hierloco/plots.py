"""Figures: gait diagrams, latent maps and task paths (matplotlib, written atomically as PNG).

Example:
    >>> import numpy as np, tempfile, os
    >>> contacts = np.tile([[1, 0], [0, 1]], (50, 1)).astype(bool)  # T x L
    >>> duty = plot_gait_diagram(contacts, ["A", "B"], os.path.join(tempfile.mkdtemp(), "gait.png"))
    >>> duty.round(2).tolist()
    [0.5, 0.5]
"""

from __future__ import annotations

import os
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hierloco.envs.robots import CONTROL_TIMESTEP  # noqa: E402
from hierloco.io import atomic_path  # noqa: E402

STANCE_COLOR = "#e377c2"  # pink, as in the paper's gait figure
SWING_COLOR = "#1f77b4"  # blue


def save_figure(fig, path: str | os.PathLike) -> None:
    """Saves ``fig`` to ``path`` atomically and closes it."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight", format=os.path.splitext(str(path))[1][1:] or "png")
    plt.close(fig)


def plot_gait_diagram(foot_contacts: np.ndarray, leg_names: Sequence[str], path: str | os.PathLike, *,
                      dt: float = CONTROL_TIMESTEP, action_steps: int | None = None, title: str | None = None
                      ) -> np.ndarray:
    """Stance (pink) and swing (blue) of each leg over time, from ``T x L`` boolean foot contacts.

    ``action_steps`` draws a line at each latent-action boundary. Returns each leg's duty factor (``L``, the
    fraction of time in stance).
    """
    contacts = np.asarray(foot_contacts, dtype=bool)
    if contacts.ndim != 2 or contacts.shape[1] != len(leg_names):
        raise ValueError(f"foot_contacts must be T x {len(leg_names)}, got {contacts.shape}")
    steps, legs = contacts.shape
    fig, ax = plt.subplots(figsize=(max(6.0, min(18.0, steps * dt * 1.5)), 0.45 * legs + 1.2))
    for leg in range(legs):
        for value, color in ((True, STANCE_COLOR), (False, SWING_COLOR)):
            runs = _runs(contacts[:, leg] == value)
            ax.broken_barh([(start * dt, length * dt) for start, length in runs], (leg - 0.4, 0.8), color=color)
    if action_steps:
        for boundary in range(action_steps, steps, action_steps):
            ax.axvline(boundary * dt, color="k", lw=0.8, ls="--")
    ax.set_yticks(range(legs), list(leg_names))
    ax.set_ylim(legs - 0.5, -0.5)
    ax.set_xlim(0, steps * dt)
    ax.set_xlabel("time (s)")
    ax.set_title(title or "gait diagram (pink: stance, blue: swing)")
    save_figure(fig, path)
    return contacts.mean(0)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, length)`` of each run of True in a 1-D mask."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(s), int(e - s)) for s, e in zip(edges[::2], edges[1::2])]
