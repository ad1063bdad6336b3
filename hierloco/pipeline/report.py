"""Reporting of the recipes: per-task evaluations, their metrics, figures and videos, and the results tables.

Figures and videos are drawn from the evaluations' recordings (CoM paths, foot contacts, joint positions at 100 Hz),
so a finished run can draw them again, or render a video it did not render before, without re-evaluating.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Mapping

import numpy as np

from hierloco.envs.robots import CONTROL_TIMESTEP
from hierloco.io import ArtifactError
from hierloco.results import TaskEvaluation, episode_rows

VIDEO_FPS = 20
GAIT_DIAGRAM_ACTIONS = 6


def task_evaluation(rollout, task, *, method: str, robot: str, setting: str, seed: int) -> TaskEvaluation:
    """The :class:`TaskEvaluation` of a closed-loop rollout: rows, metrics and the recording of its episodes."""
    rows = episode_rows(rollout, method=method, robot=robot, setting=setting, seed=seed)
    result = rollout.result
    metrics = {"normalized_cost": float(np.mean(result.normalized_cost)),
               "final_error": float(np.mean(result.final_error)), "falls": float(rollout.fell.sum()),
               "plan_seconds": float(rollout.plan_seconds)}
    if task.has_success:
        metrics["success_rate"] = float(np.mean(result.success))
    for name, values in rollout.metrics.items():  # per episode, e.g. the mean distance to the path (m)
        for row, value in zip(rows, values):
            row[name] = float(value)
        finite = np.isfinite(values)  # steps to goal: of the goals reached
        metrics[name] = float(np.mean(values[finite])) if finite.any() else float("nan")
    for term, values in result.cost_terms.items():  # the named terms of the cost, per step
        metrics[f"cost_{term}"] = float(np.mean(values))
    recording = {}
    if rollout.com_paths is not None:
        recording = {"com_paths": rollout.com_paths.astype(np.float32), "foot_contacts": rollout.foot_contacts,
                     "qpos": rollout.qpos[:1]}
    return TaskEvaluation(rows, metrics, recording, {"task": task.name, "setting": setting, "method": method,
                                                     "robot": robot, "seed": int(seed)})


ROW_TOLERANCE = 1e-9  # relative: a row and what it is derived from are the same float64 computation


def _same(stored, derived) -> bool:
    """Whether a row's number is what was derived (both NaN, or equal within :data:`ROW_TOLERANCE`)."""
    if not isinstance(stored, (int, float)) or isinstance(stored, bool):
        return False
    if math.isnan(stored) or math.isnan(derived):
        return math.isnan(stored) and math.isnan(derived)
    return abs(stored - derived) <= ROW_TOLERANCE * max(1.0, abs(derived))


@functools.lru_cache(maxsize=32)
def _task(name: str, spec_text: str):
    """The task an evaluation stage evaluates, made once per process (a navigation task plans its path: seconds)."""
    from hierloco.pipeline.config import make_task_from_spec

    return make_task_from_spec(name, json.loads(spec_text))


def derived_rows(evaluation: TaskEvaluation, params: Mapping) -> tuple[str | None, dict[str, list]]:
    """What an evaluation's rows are derived from its recording (``com_paths``) and its stage's ``params``
    (``task_name``, ``task``): the task's name (the rows' label) and, per episode, ``final_error``, ``success`` and
    the task's extra metrics (:meth:`hierloco.envs.tasks.Task.extra_metrics`), scored as
    :func:`hierloco.components.evaluation.run_task` scores them (:meth:`hierloco.envs.tasks.Task.evaluate` on the
    states after each action). The start state is not recorded: a number that depends on it is ``None`` (not
    derived). ``(None, {})`` when the stage names no task; no numbers when the evaluation kept no recording."""
    import torch

    if "task_name" not in params or "task" not in params:
        return None, {}
    task = _task(params["task_name"], json.dumps(params["task"], sort_keys=True))
    paths = evaluation.recording.get("com_paths")
    if paths is None:
        return task.name, {}
    if paths.ndim != 3 or paths.shape[2] != 5 or paths.shape[1] % task.num_steps or not paths.shape[1]:
        raise ArtifactError(f"its recorded CoM paths have shape {tuple(paths.shape)}, not E x ({task.num_steps} x N) "
                            "x 5")
    count, per_action = paths.shape[0], paths.shape[1] // task.num_steps
    episodes = torch.arange(count) % task.num_episodes
    after = torch.as_tensor(np.asarray(paths[:, per_action - 1::per_action]), dtype=torch.float64)
    unknown, known = (task.evaluate(torch.cat([start, after], 1), episodes) for start in (
        torch.full((count, 1, 5), float("nan"), dtype=torch.float64), task.start_state().double().expand(count, 1, 5)))
    independent = (unknown.final_error == known.final_error) | (np.isnan(unknown.final_error)
                                                                & np.isnan(known.final_error))
    derived = {name: [float(v) if ok else None for v, ok in zip(getattr(known, name), independent)]
               for name in ("final_error", "success")}  # success follows from the final error
    for name, values in task.extra_metrics(paths, episodes.numpy()).items():
        derived[name] = [float(v) for v in np.asarray(values, dtype=np.float64)]
    return task.name, derived


def checked_rows(evaluation: TaskEvaluation, params: Mapping, where) -> list[dict]:
    """The per-episode rows of an evaluation, checked against what they are derived from (``docs/pipeline.md``,
    "What a record's digest protects"): their labels against the evaluation stage's ``params`` (setting, task, seed)
    and the evaluation's metadata (method, robot), their episodes numbered in order, their means against the summary
    saved with them, and each ``success``, ``final_error`` and extra metric against :func:`derived_rows` (its
    recording). Raises :class:`hierloco.io.ArtifactError` naming ``where`` and the first difference."""
    rows, meta = evaluation.rows, evaluation.metadata
    try:
        task_name, derived = derived_rows(evaluation, params)
    except ArtifactError as error:
        raise ArtifactError(f"{where}: {error}") from None
    expected = {"task": task_name or meta.get("task"), "setting": params.get("setting", meta.get("setting")),
                "seed": params.get("seed", meta.get("seed")), "method": meta.get("method"), "robot": meta.get("robot")}
    problems = [f"its metadata names {label} {meta[label]!r}, its stage {expected[label]!r}"
                for label in ("task", "setting", "seed") if label in meta and meta[label] != expected[label]]
    for index, row in enumerate(rows):
        for label, value in expected.items():
            if value is not None and row.get(label) != value:
                problems.append(f"row {index} is labelled {label} {row.get(label)!r}, its evaluation is of "
                                f"{label} {value!r}")
        if row.get("episode") != index:
            problems.append(f"row {index} is numbered episode {row.get('episode')!r}")
    if "com_paths" in evaluation.recording and len(evaluation.recording["com_paths"]) != len(rows):
        problems.append(f"{len(rows)} rows for {len(evaluation.recording['com_paths'])} recorded episodes")
    for name, values in derived.items():
        for index, (row, value) in enumerate(zip(rows, values)):
            if value is not None and not _same(row.get(name), value):
                problems.append(f"episode {index}'s {name} is {row.get(name)!r}, its recorded CoM path gives "
                                f"{value:.6g}")
    for name, summary in (("final_error", "final_error"), ("success", "success_rate")):
        values = [row.get(name) for row in rows]
        if summary in evaluation.metrics and all(isinstance(v, (int, float)) for v in values) and not _same(
                float(np.mean(values)), float(evaluation.metrics[summary])):
            problems.append(f"its rows' mean {name} {np.mean(values):.4g} differs from the summary it was saved with "
                            f"({evaluation.metrics[summary]:.4g})")
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ArtifactError(f"{where}: its rows do not follow from its recording and its stage: {problems[0]}{more}")
    return [dict(row) for row in rows]


def log_evaluation(logger, evaluation: TaskEvaluation, setting: str, name: str) -> None:
    prefix = f"eval/{setting}/{name}"  # the logger cleans names (goal_reaching_1.5m -> goal_reaching_1p5m)
    logger.log_metrics({f"{prefix}/{key}": value for key, value in evaluation.metrics.items()})


def task_figures(evaluation: TaskEvaluation, task, robot, figures: Path, *, method: str, setting: str,
                 steps_per_action: int) -> list[Path]:
    """The figures a task declares (:attr:`hierloco.envs.tasks.Task.figures`: ``paths``, ``velocity``, ``gait``)
    drawn from an evaluation's recording; returns the files written (none without a recording)."""
    from hierloco.plots import plot_gait_diagram, plot_navigation, plot_task_paths, plot_velocity_tracking

    recording = evaluation.recording
    if "com_paths" not in recording:
        return []
    name = task.name
    title = f"{method.upper()} {robot.name} ({setting}): {name}"
    paths = []
    for figure in task.figures:
        if figure == "paths":
            paths.append(figures / f"{setting}_{name}_paths.png")
            plot_task_paths(task, recording["com_paths"], paths[-1], title=title)
        elif figure == "velocity":
            paths.append(figures / f"{setting}_{name}_velocity.png")
            plot_velocity_tracking(task, recording["com_paths"][0], paths[-1], title=title)
        elif figure == "arena":  # a navigation task: the boxes, their inflation, the planned and the CoM paths
            paths.append(figures / f"{setting}_{name}_arena.png")
            plot_navigation(task.arena, task.path.numpy(), recording["com_paths"][0, :, :2], paths[-1],
                            inflation=task.inflation, title=title)
        elif figure == "gait" and "foot_contacts" in recording:
            paths.append(figures / f"{setting}_gait_during_{name}.png")
            plot_gait_diagram(recording["foot_contacts"][0, : GAIT_DIAGRAM_ACTIONS * steps_per_action],
                              robot.leg_names, paths[-1], action_steps=steps_per_action,
                              title=f"{method.upper()} {robot.name} ({setting}): gait during {name} (pink stance, "
                                    "blue swing; dashed: new action)")
    return paths


def task_video(evaluation: TaskEvaluation, task, robot, path: Path, *, disabled_legs=(),
               terrain=None) -> np.ndarray | None:
    """Renders the first episode of a task (MuJoCo offscreen, 20 fps) on its ground (``terrain``, default flat) with
    its goals or path drawn on it and its obstacles in place; returns the frames (``T x H x W x 3``), or ``None``
    when the evaluation kept no joint positions."""
    from hierloco.render import render_frames, save_video

    qpos = evaluation.recording.get("qpos")
    if qpos is None or not len(qpos):
        return None
    stride = int(round(1.0 / (VIDEO_FPS * CONTROL_TIMESTEP)))
    markers = task.markers(episode=0)
    markers = markers[:: max(1, len(markers) // 40)]
    frames = render_frames(robot, qpos[0, ::stride], disabled_legs=disabled_legs, markers=markers,
                           obstacles=task.obstacles, terrain=terrain)
    save_video(frames, path, fps=VIDEO_FPS)
    return frames


def latent_map(low_level, robot, path: Path, *, method: str, seed: int) -> Path | None:
    """The 2-D latent map figure (CoM paths over a grid of actions), only for a 2-D continuous action space."""
    from hierloco.components.evaluation import latent_grid_paths
    from hierloco.plots import plot_latent_map

    if low_level.action_dim != 2 or low_level.num_choices is not None:
        return None
    latents, paths = latent_grid_paths(low_level, seed=seed)
    plot_latent_map(latents, paths, path, title=f"{method.upper()} {robot.name}: CoM paths over a grid of 2-D "
                                                "actions (3 s each)")
    return path


def headline(evaluations: dict) -> float:
    """The mean normalised cost over the evaluated tasks of the first setting (what a sweeper minimises)."""
    costs = [e.metrics["normalized_cost"] for (setting, _), e in evaluations.items()
             if setting == next(iter(evaluations))[0]]
    return float(np.mean(costs)) if costs else float("nan")


def job_compute(report: dict, builds: dict) -> dict[str, float | None]:
    """The stages a finished run needs (its ``report.json``'s ``stage_seconds``) -> the seconds building each took
    (its ``builds.json``; ``None`` when not recorded, as for stages built before ``builds.json`` existed)."""
    stages = (report or {}).get("stage_seconds") or {}
    return {name: (builds or {}).get(name, {}).get("seconds") for name in stages}


def _reuse_word(result, source: str) -> str:
    if not result.reused:
        return "no"
    return "yes" if source == result.job.run_dir else "from its record"


def _robot_name(job) -> str:
    """The robot a job's run is on, for the compute table: its run directory's ``<robot>_seed<N>`` name (with a
    profile: ``a1-stiff``), else its ``robot=`` override (a YAML robot by its file's stem)."""
    name = Path(job.run_dir).name
    if "_seed" in name:
        return name.rsplit("_seed", 1)[0]
    robot = next((o.split("=", 1)[1] for o in reversed(job.overrides) if o.startswith("robot=")), "-")
    return Path(robot).stem if robot.endswith((".yaml", ".yml")) else robot


def wallclock_markdown(results) -> str:
    """``wallclock.md``: each job's wall-clock in this study and the compute its stages took when they were built
    (reused stages included), then the compute per method and robot, and what that is on the study's cores."""
    lines = ["# Wall-clock per job", "",
             "*this study*: the job's wall-clock now (a reused job or stage costs nothing); *compute*: the sum, over the "
             "stages the job needs, of what building each took (`builds.json`), with the threads it had then.", "",
             "| method | run directory (or record) | this study (min) | compute (min) | threads | stages not recorded | reused |",
             "|---|---|---|---|---|---|---|"]
    per_method: dict[tuple[str, str], list[float]] = {}
    copied = 0.0  # seconds of stages a job copied from another run (``reuse_from``): counted again in that job
    for result in results:
        source = result.source  # the run directory, or the job's record
        seconds = result.recorded_seconds if result.reused else result.seconds
        method = result.job.labels.get("method", result.job.method)
        stages = job_compute(result.report, result.builds)
        known = [v for v in stages.values() if v is not None]
        missing = sum(v is None for v in stages.values())
        threads = sorted({b.get("threads") for n, b in result.builds.items() if n in stages and b.get("threads")})
        compute = sum(known) if stages else float("nan")
        robot = _robot_name(result.job)
        if stages and not missing:
            per_method.setdefault((method, robot), []).append(compute)
            copied += sum(v for n, v in stages.items() if v is not None and "copied_from" in result.builds.get(n, {}))
        lines.append(f"| {method} | {source} | {seconds / 60:.1f} | {compute / 60:.1f} | "
                     f"{', '.join(map(str, threads)) or '-'} | {missing} | {_reuse_word(result, source)} |")
    if per_method:
        lines += ["", "## Compute per method and robot (jobs with every stage recorded)", "",
                  "| method | robot | jobs | compute per job (min) | compute in all (min) |", "|---|---|---|---|---|"]
        for (method, robot), values in per_method.items():
            lines.append(f"| {method} | {robot} | {len(values)} | {sum(values) / len(values) / 60:.1f} | "
                         f"{sum(values) / 60:.1f} |")
        total = sum(sum(v) for v in per_method.values())
        once = (f" ({(total - copied) / 60:.1f} min with each stage counted once: {copied / 60:.1f} min are stages "
                "copied from another run, counted in every job that uses them)") if copied else ""
        lines += ["", f"In all {total / 60:.1f} min of compute{once}."]
    return "\n".join(lines) + "\n"
