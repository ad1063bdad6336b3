"""Results tables shared by every recipe: ``results.csv``, ``episodes.csv`` and ``results.md``.

``results.csv`` has one row per (method, robot, setting, task, seed) with the columns of :data:`RESULT_COLUMNS`,
the mean over the task's episodes (targets). ``episodes.csv`` keeps the per-episode numbers (and, for trajectory tracking, the mean distance
from the CoM to the path in m), from which ``results.md`` reports mean +- std over targets and seeds.

Example:
    >>> rows = [dict(method="lat", robot="a1", setting="normal", task="goal_reaching", seed=0, episode=e,
    ...              normalized_cost=c, success=1.0, final_error=0.1) for e, c in enumerate([0.3, 0.5])]
    >>> print(markdown_table(rows).splitlines()[2])
    | lat | a1 | normal | goal_reaching | 0.40 +- 0.10 | 100% | 0.10 +- 0.00 | 1 | - | - |
"""

from __future__ import annotations

import csv
import io
import os
from collections import defaultdict
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from dataclasses import dataclass, field

from hierloco.io import ArtifactError, check_schema, load_arrays, save_arrays, write_text

RESULT_COLUMNS = ["method", "robot", "setting", "task", "seed", "normalized_cost", "success_rate", "final_error"]
EPISODE_COLUMNS = ["method", "robot", "setting", "task", "seed", "episode", "normalized_cost", "success",
                   "final_error", "path_distance", "steps_to_goal"]
GROUP = ("method", "robot", "setting", "task")


def episode_rows(rollout, *, method: str, robot: str, setting: str, seed: int) -> list[dict]:
    """Per-episode rows of a :class:`hierloco.components.evaluation.TaskRollout`."""
    result = rollout.result
    return [dict(method=method, robot=robot, setting=setting, task=result.task, seed=int(seed), episode=e,
                 normalized_cost=float(result.normalized_cost[e]), success=float(result.success[e]),
                 final_error=float(result.final_error[e])) for e in range(len(result.normalized_cost))]


def summarize_seeds(rows: Iterable[Mapping]) -> list[dict]:
    """``results.csv`` rows: per (method, robot, setting, task, seed), the mean over episodes."""
    groups = defaultdict(list)
    for row in rows:
        groups[tuple(row[k] for k in (*GROUP, "seed"))].append(row)
    out = []
    for key, members in groups.items():
        out.append({**dict(zip((*GROUP, "seed"), key)),
                    "normalized_cost": float(np.mean([m["normalized_cost"] for m in members])),
                    "success_rate": float(np.mean([m["success"] for m in members])),
                    "final_error": float(np.mean([m["final_error"] for m in members]))})
    return out


def markdown_table(rows: Iterable[Mapping]) -> str:
    """Mean +- std over targets and seeds, per (method, robot, setting, task), from per-episode rows."""
    groups = defaultdict(list)
    for row in rows:
        groups[tuple(row[k] for k in GROUP)].append(row)
    lines = ["| method | robot | setting | task | normalized cost | success | final error | seeds | path distance | "
             "steps to goal |", "|---|---|---|---|---|---|---|---|---|---|"]
    for key in sorted(groups):
        members = groups[key]
        cost = np.array([m["normalized_cost"] for m in members])
        success = np.array([m["success"] for m in members], dtype=float)
        error = np.array([m["final_error"] for m in members])
        seeds = len({m["seed"] for m in members})
        success_text = "-" if np.all(np.isnan(success)) else f"{100 * np.nanmean(success):.0f}%"
        distance = np.array([m["path_distance"] for m in members if _number(m.get("path_distance"))], dtype=float)
        distance_text = f"{distance.mean():.2f} +- {distance.std():.2f}" if len(distance) else "-"
        steps = np.array([m["steps_to_goal"] for m in members if _number(m.get("steps_to_goal"))], dtype=float)
        steps_text = f"{steps.mean():.1f} +- {steps.std():.1f}" if len(steps) else "-"  # of the goals reached
        lines.append(f"| {' | '.join(map(str, key))} | {cost.mean():.2f} +- {cost.std():.2f} | {success_text} | "
                     f"{error.mean():.2f} +- {error.std():.2f} | {seeds} | {distance_text} | {steps_text} |")
    return "\n".join(lines) + "\n"


def _number(value) -> bool:
    try:
        return value is not None and value != "" and not np.isnan(float(value))
    except (TypeError, ValueError):
        return False


def csv_text(rows: Iterable[Mapping], columns: list[str]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def read_csv(path: str | os.PathLike) -> list[dict]:
    """Rows of a results/episodes CSV with numbers parsed."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for key, value in row.items():
            if key in ("seed", "episode"):
                row[key] = int(value)
            elif key in ("normalized_cost", "success_rate", "success", "final_error", "path_distance", "steps_to_goal"):
                row[key] = float(value) if value != "" else float("nan")
    return rows


def write_results(run_dir: str | os.PathLike, episodes: list[dict], extra_markdown: str = "") -> str:
    """Writes ``results.csv``, ``episodes.csv`` and ``results.md`` into ``run_dir`` atomically; returns the table."""
    run_dir = Path(run_dir)
    write_text(run_dir / "episodes.csv", csv_text(episodes, EPISODE_COLUMNS))
    write_text(run_dir / "results.csv", csv_text(summarize_seeds(episodes), RESULT_COLUMNS))
    table = markdown_table(episodes)
    write_text(run_dir / "results.md", "# Results\n\nNormalized cost: mean per-step task cost / that of a robot "
                                       "standing still (1 = no better than standing, 0 = perfect); mean +- std "
                                       "over targets and seeds.\n\n" + table + extra_markdown)
    return table


EVALUATION_FORMAT = 1
RECORDING_KEYS = ("com_paths", "foot_contacts", "qpos")


@dataclass
class TaskEvaluation:
    """One evaluated task: per-episode result rows, summary metrics, and what its episodes recorded.

    Attributes:
        rows: one dict per episode with the columns of :data:`EPISODE_COLUMNS`.
        metrics: named summary numbers (``normalized_cost``, ``success_rate``, ``cost_<term>``, ...).
        recording: ``com_paths`` (``E x (T * N) x 5`` world CoM states at 100 Hz), ``foot_contacts``
            (``E x (T * N) x L``), ``qpos`` (``1 x (T * N) x nq``, the first episode, for videos); any may be absent.
        metadata: what was evaluated (task, setting, method, robot, seed).
    """

    rows: list
    metrics: dict
    recording: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    def save(self, path: str | os.PathLike) -> None:
        save_arrays(path, {k: v for k, v in self.recording.items() if v is not None},
                    {"kind": "task_evaluation", "format": EVALUATION_FORMAT, "rows": self.rows,
                     "metrics": self.metrics, "metadata": self.metadata})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TaskEvaluation":
        """Reads and validates an evaluation; a malformed one raises :class:`ArtifactError` naming the file."""
        arrays, meta = load_arrays(path)
        where = f"corrupted evaluation {path}"
        check_schema(meta, {"kind": str, "format": int, "rows": list, "metrics": dict, "metadata": dict}, where)
        if meta["kind"] != "task_evaluation" or meta["format"] != EVALUATION_FORMAT:
            raise ArtifactError(f"{path} is not a task evaluation of format {EVALUATION_FORMAT}")
        if not meta["rows"]:
            raise ArtifactError(f"{where}: no episodes")
        for row in meta["rows"]:
            check_schema(row, {"method": str, "robot": str, "setting": str, "task": str, "seed": int, "episode": int,
                               "normalized_cost": (int, float), "success": (int, float),
                               "final_error": (int, float)}, where)
        if set(arrays) - set(RECORDING_KEYS):
            raise ArtifactError(f"{where}: unexpected arrays {sorted(set(arrays) - set(RECORDING_KEYS))}")
        return cls(meta["rows"], meta["metrics"], arrays, meta["metadata"])
