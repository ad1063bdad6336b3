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


def plot_task_paths(task, com_paths: np.ndarray, path: str | os.PathLike, *, title: str | None = None,
                    episodes: Sequence[int] | None = None) -> None:
    """CoM XY paths (``E x T x >=2``, world frame, m) of a task's episodes against its goals or reference path."""
    from hierloco.envs.tasks import GoalReaching, TrajectoryTracking

    paths = np.asarray(com_paths)
    episodes = list(range(len(paths))) if episodes is None else list(episodes)
    fig, ax = plt.subplots(figsize=(6, 6))
    colors = plt.cm.viridis(np.linspace(0, 0.9, max(1, len(paths))))
    for i, (xy, color) in enumerate(zip(paths, colors)):
        ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.2, label=None if len(paths) > 1 else "CoM")
        if isinstance(task, GoalReaching):
            goal = task.goals[episodes[i]].numpy()
            ax.scatter(*goal, marker="*", s=140, color=color, edgecolor="k", zorder=3)
            ax.add_patch(plt.Circle(goal, 0.2, fill=False, ls=":", color=color))
    if isinstance(task, TrajectoryTracking):
        ref = task.path.numpy()
        ax.plot(ref[:, 0], ref[:, 1], "k--", lw=1.0, label="reference")
        ax.legend(loc="best")
    ax.scatter([0], [0], marker="o", color="k", zorder=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.set_title(title or task.name.replace("_", " "))
    save_figure(fig, path)


def plot_velocity_tracking(task, com_paths: np.ndarray, path: str | os.PathLike, *, dt: float = CONTROL_TIMESTEP,
                           title: str | None = None) -> None:
    """World-frame CoM velocity over each task step against the velocity targets, for one episode (``T x >=2``)."""
    xy = np.asarray(com_paths)[:, :2]
    steps_per_task_step = int(round(task.step_duration / dt))
    ends = xy[steps_per_task_step - 1::steps_per_task_step]
    starts = np.concatenate([[np.zeros(2)], ends[:-1]])
    velocity = (ends - starts) / task.step_duration
    import torch

    targets = task.target(torch.zeros(len(ends), dtype=torch.long, device="cpu"),
                          torch.arange(len(ends), device="cpu")).numpy()
    fig, axes = plt.subplots(2, 1, figsize=(8, 4.5), sharex=True)
    for k, (ax, name) in enumerate(zip(axes, ("vx", "vy"))):
        t = np.arange(1, len(ends) + 1) * task.step_duration
        ax.step(t, targets[:, k], where="pre", color="k", ls="--", label="target")
        ax.plot(t, velocity[:, k], "o-", ms=3, label="achieved")
        ax.set_ylabel(f"{name} (m/s)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right")
    axes[1].set_xlabel("time (s)")
    axes[0].set_title(title or "velocity tracking")
    save_figure(fig, path)


def plot_latent_map(latents: np.ndarray, com_paths: np.ndarray, path: str | os.PathLike, *,
                    title: str | None = None) -> None:
    """CoM XY paths (``G x T x >=2``) of a grid of 2-D latents (``G x 2``), coloured by position in the grid:
    the paper's latent-space figure."""
    z = np.asarray(latents)
    paths = np.asarray(com_paths)
    span = np.ptp(z, 0)
    span[span == 0] = 1.0
    unit = (z - z.min(0)) / span
    colors = np.stack([unit[:, 0], 0.3 * np.ones(len(z)), unit[:, 1]], -1)
    fig, (ax_z, ax_xy) = plt.subplots(1, 2, figsize=(11, 5))
    ax_z.scatter(z[:, 0], z[:, 1], c=colors, s=40)
    ax_z.set_xlabel("z1")
    ax_z.set_ylabel("z2")
    ax_z.set_title("latents")
    for xy, color in zip(paths, colors):
        ax_xy.plot(xy[:, 0], xy[:, 1], color=color, lw=1.0)
        ax_xy.scatter(xy[-1, 0], xy[-1, 1], color=color, s=10)
    ax_xy.scatter([0], [0], marker="o", color="k", zorder=3)
    ax_xy.set_aspect("equal")
    ax_xy.set_xlabel("x (m)")
    ax_xy.set_ylabel("y (m)")
    ax_xy.grid(alpha=0.3)
    ax_xy.set_title("CoM paths")
    fig.suptitle(title or "CoM paths over a grid of latent actions")
    save_figure(fig, path)


def plot_comparison(rows: Sequence[dict], path: str | os.PathLike, *, setting: str = "normal",
                    tasks: Sequence[str] = ("velocity_tracking", "goal_reaching", "trajectory_tracking"),
                    title: str | None = None) -> None:
    """Bar charts like the paper's baseline figure: normalised cost (mean +- std over targets and seeds) per task
    and method, one panel per robot, from per-episode result rows."""
    rows = [r for r in rows if r["setting"] == setting and r["task"] in tasks]
    robots = sorted({r["robot"] for r in rows})
    methods = sorted({r["method"] for r in rows}, key=lambda m: (m != "lat", m))
    if not rows:
        raise ValueError(f"no result rows for setting {setting!r} and tasks {list(tasks)}")
    fig, axes = plt.subplots(1, len(robots), figsize=(5.5 * len(robots), 4), squeeze=False)
    width = 0.8 / max(1, len(methods))
    colors = plt.cm.tab10(np.arange(len(methods)))
    for ax, robot in zip(axes[0], robots):
        for m, method in enumerate(methods):
            means, stds = [], []
            for task in tasks:
                values = [r["normalized_cost"] for r in rows if (r["robot"], r["method"], r["task"]) ==
                          (robot, method, task)]
                means.append(np.mean(values) if values else np.nan)
                stds.append(np.std(values) if values else 0.0)
            x = np.arange(len(tasks)) + (m - (len(methods) - 1) / 2) * width
            ax.bar(x, means, width, yerr=stds, capsize=3, color=colors[m], label=method.upper())
        ax.set_xticks(np.arange(len(tasks)), [t.replace("_", "\n") for t in tasks])
        ax.set_ylabel("normalised cost (lower is better)")
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_title(f"{robot} ({setting})")
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].legend()
    fig.suptitle(title or "comparison of methods")
    save_figure(fig, path)


def plot_ablations(results: dict, path: str | os.PathLike, *, title: str | None = None) -> None:
    """One panel per ablation: normalised cost (mean +- std over targets and trials) against the varied value, a
    line per task. ``results`` maps an ablation name to ``{value: per-episode result rows}``."""
    fig, axes = plt.subplots(1, len(results), figsize=(4.5 * len(results), 3.8), squeeze=False)
    for ax, (name, by_value) in zip(axes[0], results.items()):
        values = list(by_value)
        tasks = sorted({r["task"] for rows in by_value.values() for r in rows})
        for task in tasks:
            costs = [[r["normalized_cost"] for r in by_value[v] if r["task"] == task] for v in values]
            ax.errorbar(range(len(values)), [np.mean(c) for c in costs], yerr=[np.std(c) for c in costs],
                        marker="o", capsize=3, label=task.replace("_", " "))
        ax.set_xticks(range(len(values)), [str(v) for v in values])
        ax.set_xlabel(name.replace("_", " "))
        ax.set_ylabel("normalised cost")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title or "ablations")
    fig.tight_layout()
    save_figure(fig, path)


def plot_samples(rows: Sequence[dict], path: str | os.PathLike, *, tasks: Sequence[str] = ("velocity_tracking",
                 "goal_reaching"), title: str | None = None, xlabel: str = "dynamics samples after damage") -> None:
    """Normalised cost (mean +- std over targets and seeds) against a number of samples (log scale), one line per
    method and task, one panel per robot, from per-episode rows that carry a ``samples`` column."""
    robots = sorted({r["robot"] for r in rows})
    if not robots:
        raise ValueError("no result rows to plot")
    fig, axes = plt.subplots(1, len(robots), figsize=(5.5 * len(robots), 4), squeeze=False)
    for ax, robot in zip(axes[0], robots):
        for method in sorted({r["method"] for r in rows if r["robot"] == robot}):
            for task, style in zip(tasks, ("-o", "--s", ":^")):
                points = sorted({int(r["samples"]) for r in rows if (r["robot"], r["method"], r["task"]) ==
                                 (robot, method, task)})
                if not points:
                    continue
                values = [[r["normalized_cost"] for r in rows if (r["robot"], r["method"], r["task"],
                                                                   int(r["samples"])) == (robot, method, task, n)]
                          for n in points]
                ax.errorbar(points, [np.mean(v) for v in values], yerr=[np.std(v) for v in values], fmt=style,
                            capsize=3, label=f"{method.upper()} {task.replace('_', ' ')}")
        ax.set_xscale("log")
        ax.set_ylabel("normalised cost (lower is better)")
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_title(robot)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.supxlabel(xlabel)   # one label under all panels (a long one would overlap its neighbour's)
    fig.suptitle(title or "cost against dynamics samples")
    save_figure(fig, path)


def _rounded_box(half_x: float, half_y: float, radius: float, points_per_corner: int = 9) -> np.ndarray:
    """The outline (``P x 2``, m, box frame) of the points within ``radius`` of a ``2 half_x x 2 half_y`` box: its
    sides moved out by ``radius``, joined by quarter circles about its corners.

        >>> outline = _rounded_box(0.5, 0.2, 0.1)
        >>> bool(np.allclose(outline.max(0), [0.6, 0.3]))
        True
    """
    outline = []
    for k, (cx, cy) in enumerate([(half_x, half_y), (-half_x, half_y), (-half_x, -half_y), (half_x, -half_y)]):
        angles = np.linspace(k * np.pi / 2, (k + 1) * np.pi / 2, points_per_corner)
        outline.append(np.stack([cx + radius * np.cos(angles), cy + radius * np.sin(angles)], -1))
    return np.concatenate(outline)


def plot_navigation(arena, planned_path: np.ndarray, com_paths, path: str | os.PathLike, *,
                    inflation: float | None = None, title: str | None = None,
                    labels: Sequence[str] | None = None) -> None:
    """Top view of a navigation arena: obstacles (and their inflation), the planned path (``P x 2``, m) and the CoM
    path (``T x 2``), or several (a sequence of them, e.g. one per seed, named by ``labels``), or none."""
    from matplotlib.patches import Polygon

    fig, ax = plt.subplots(figsize=(6, 6))
    for obstacle in arena.obstacles:
        c, s = np.cos(obstacle.yaw), np.sin(obstacle.yaw)
        hx, hy = obstacle.half_size[:2]
        corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]]) @ np.array([[c, s], [-s, c]])
        ax.add_patch(Polygon(corners + [obstacle.x, obstacle.y], color="#8c6d4f"))
        if inflation:  # the points within `inflation` of the box: the box grown by a disc (rounded corners)
            grown = _rounded_box(hx, hy, inflation)
            ax.add_patch(Polygon(grown @ np.array([[c, s], [-s, c]]) + [obstacle.x, obstacle.y], fill=False,
                                 ls=":", color="#8c6d4f"))
    ax.plot(planned_path[:, 0], planned_path[:, 1], "k--", lw=1.2, label="planned path")
    if com_paths is None:
        com_paths = []
    elif isinstance(com_paths, np.ndarray) and com_paths.ndim == 2:
        com_paths = [com_paths]
    colors = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e"]
    for i, com in enumerate(com_paths):
        ax.plot(com[:, 0], com[:, 1], color=colors[i % len(colors)], lw=1.5,
                label=labels[i] if labels else "CoM")
    ax.scatter(*arena.start, marker="o", color="k", zorder=3, label="start")
    ax.scatter(*arena.goal, marker="*", s=160, color="#ffbf00", edgecolor="k", zorder=3, label="goal")
    xmin, xmax, ymin, ymax = arena.bounds
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or "navigation")
    save_figure(fig, path)
