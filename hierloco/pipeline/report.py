"""Reporting of the recipes: per-task evaluations, their metrics, figures and videos, and the results tables.

Figures and videos are drawn from the evaluations' recordings (CoM paths, foot contacts, joint positions at 100 Hz),
so a finished run can draw them again, or render a video it did not render before, without re-evaluating.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hierloco.envs.robots import CONTROL_TIMESTEP
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


def task_video(evaluation: TaskEvaluation, task, robot, path: Path, *, disabled_legs=()) -> np.ndarray | None:
    """Renders the first episode of a task (MuJoCo offscreen, 20 fps) with its goals or path drawn on the floor and
    its obstacles in place; returns the frames (``T x H x W x 3``), or ``None`` when the evaluation kept no joint positions."""
    from hierloco.render import render_frames, save_video

    qpos = evaluation.recording.get("qpos")
    if qpos is None or not len(qpos):
        return None
    stride = int(round(1.0 / (VIDEO_FPS * CONTROL_TIMESTEP)))
    markers = task.markers(episode=0)
    markers = markers[:: max(1, len(markers) // 40)]
    frames = render_frames(robot, qpos[0, ::stride], disabled_legs=disabled_legs, markers=markers,
                           obstacles=task.obstacles)
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
