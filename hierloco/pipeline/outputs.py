"""A run's optional outputs: trackers, figures and videos, each tied to the evaluation it was drawn from.

The results tables (``results.csv``, ``episodes.csv``, ``results.md``) are written first, by
:meth:`hierloco.pipeline.run.Run.finish`; what this module writes comes after and may fail without losing them: a
failing tracker, figure or video is one ``warning:`` line and an entry of ``report.json``'s ``warnings``.

``outputs.json`` in the output folder lists every figure and video with the key digest of the evaluation it was
drawn from. A run re-draws figures from the evaluations its plan names, renders a video again when its evaluation
changed (another planner, another task option), and removes the figures and videos it made before whose
evaluation is no longer planned, or whose evaluation kept no recording to draw them from. Files it did not make
(not listed) are never touched.

A run directory may come from someone else, so ``outputs.json`` is data: an entry is taken only when it is a figure
or video this module writes (:data:`MANAGED`: ``figures/*.png``, ``videos/*.mp4``), inside the output folder and
through no symbolic link (:func:`hierloco.io.inside`); any other entry (``../thesis.tex``, ``experts.npz``,
``figures/thesis.tex``) is left alone, with a warning. Nothing is drawn into a ``figures/`` or ``videos/`` that is a
link.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path, PurePosixPath

from hierloco.io import UnsafePathError, inside, write_text
from hierloco.pipeline.errors import one_line

OUTPUTS = "outputs.json"
MANAGED = {"figures": (".png",), "videos": (".mp4",)}  # the folders this module writes into, and what it writes there


def _rendering_available() -> str | None:
    """Why videos cannot be rendered here (``None`` when they can): ``MUJOCO_GL=disable`` or no EGL/OSMesa."""
    from hierloco import render_backend

    return render_backend.unavailable()


class Outputs:
    """Draws and logs a finished run's optional outputs into ``out`` (see the module docstring)."""

    def __init__(self, out: Path, cfg, robot, method: str, logger):
        self.out, self.cfg, self.robot, self.method, self.logger = Path(out), cfg, robot, method, logger
        self.warnings: list[str] = []
        self.made: dict[str, str] = {}  # relative path -> the evaluation digest it was drawn from ("run": the run)
        self._folders: dict[str, Path | None] = {}
        try:
            before = json.loads(inside(self.out, OUTPUTS).read_text())
            before = {str(k): str(v) for k, v in before.get("files", {}).items()}
        except (OSError, ValueError, AttributeError):  # UnsafePathError too: an outputs.json that is a link
            before = {}
        self.before = {relative: digest for relative, digest in before.items() if self._managed(relative)}
        foreign = sorted(set(before) - set(self.before))
        if foreign:
            listed = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
            self.note(f"{OUTPUTS} lists files this run does not write ({listed}): left as they are")

    def warn(self, what: str, error: BaseException) -> None:
        self.note(f"{what} failed: {one_line(error)}")

    def note(self, line: str) -> None:
        """A ``warning:`` line, kept in ``report.json``'s ``warnings``."""
        print(f"warning: {line}")
        self.warnings.append(line)

    def _relative(self, path: Path) -> str:
        return path.relative_to(self.out).as_posix()

    def _managed(self, relative: str) -> bool:
        """Whether ``relative`` (an entry of ``outputs.json``) is a file this module writes: a figure or video
        directly in its folder (:data:`MANAGED`), inside the output folder through no link."""
        parts = PurePosixPath(relative).parts
        if len(parts) != 2 or parts[0] not in MANAGED or PurePosixPath(relative).suffix not in MANAGED[parts[0]]:
            return False
        try:
            inside(self.out, relative)
        except UnsafePathError:
            return False
        return True

    def _folder(self, name: str) -> Path | None:
        """The output folder ``name`` (``figures``, ``videos``) to write into, or ``None`` (said once) when it is a
        link or not a directory: nothing is written through it."""
        if name not in self._folders:
            try:
                folder = inside(self.out, name)
                if folder.exists() and not folder.is_dir():
                    raise UnsafePathError(f"{folder} is not a directory")
                self._folders[name] = folder
            except UnsafePathError as error:
                self.note(f"no {name} written: {one_line(error)}")
                self._folders[name] = None
        return self._folders[name]

    # ------------------------------------------------------------------------------------------------ draw
    def draw(self, evaluations: dict, low_level=None) -> None:
        """Figures and videos of every evaluation (``(setting, task) -> (stage, TaskEvaluation)``), then the latent
        map; stale ones removed; ``outputs.json`` written."""
        from hierloco.pipeline import report
        from hierloco.pipeline.config import make_task_from_spec, task_specs

        specs = task_specs(self.cfg)
        steps = int(self.cfg.steps_per_action)
        videos = set(self.cfg.eval.videos or [])
        figures = self._folder("figures") if self.cfg.eval.figures else None
        for (setting, name), (stage, evaluation) in evaluations.items():
            task = make_task_from_spec(name, specs[name])
            if figures is not None:
                try:
                    drawn = report.task_figures(evaluation, task, self.robot, figures, method=self.method,
                                                setting=setting, steps_per_action=steps)
                except Exception as error:  # noqa: BLE001  (an optional output)
                    self.warn(f"the figures of {setting}/{name}", error)
                    drawn = []
                if not drawn and "com_paths" not in evaluation.recording:
                    self.warnings.append(f"no figures of {setting}/{name}: its evaluation kept no recording")
                for path in drawn:
                    self.made[self._relative(path)] = stage.digest
                    self._log(lambda: self.logger.log_image(f"figures/{path.stem}", path), f"logging {path.name}")
            if name in videos:
                self._video(setting, name, stage, evaluation, task)
        if low_level is not None and figures is not None:
            try:
                path = report.latent_map(low_level, self.robot, figures / "latent_map.png", method=self.method,
                                         seed=self.cfg.seed)
            except Exception as error:  # noqa: BLE001
                self.warn("the latent map", error)
                path = None
            if path is not None:
                self.made[self._relative(path)] = "run"
                self._log(lambda: self.logger.log_image("figures/latent_map", path), "logging the latent map")
        self._remove_stale()
        write_text(self.out / OUTPUTS, json.dumps({"files": self.made}, indent=1, sort_keys=True))

    def _video(self, setting: str, name: str, stage, evaluation, task) -> None:
        from hierloco.envs.faults import fault_legs
        from hierloco.loggers import metric_component
        from hierloco.pipeline import report

        folder = self._folder("videos")
        if folder is None:
            return
        path = folder / f"{setting}_{name}.mp4"
        relative = self._relative(path)
        if path.exists() and self.before.get(relative) == stage.digest:
            self.made[relative] = stage.digest  # drawn from this very evaluation: kept
            return
        why = _rendering_available()
        if why is not None:
            self.warnings.append(f"no video of {setting}/{name}: {why}")
            return
        try:
            from hierloco.pipeline.config import world

            frames = report.task_video(evaluation, task, self.robot, path,
                                       disabled_legs=fault_legs(self.robot, setting)[0],
                                       terrain=world(self.cfg, "evaluation", name).terrain)
        except Exception as error:  # noqa: BLE001  (rendering is optional)
            self.warn(f"the video of {setting}/{name}", error)
            return
        if frames is None:
            self.warnings.append(f"no video of {setting}/{name}: its evaluation kept no joint positions")
            return
        self.made[relative] = stage.digest
        self._log(lambda: self.logger.log_video(f"eval/{setting}/{metric_component(name)}/video", frames,
                                                fps=report.VIDEO_FPS), f"logging the video of {setting}/{name}")

    def _remove_stale(self) -> None:
        """Removes what an earlier finish made (listed in its ``outputs.json``, a figure or video of its folders:
        :meth:`_managed`) and this one did not; only plain files, never through a link."""
        for relative in sorted(set(self.before) - set(self.made)):
            try:
                path = inside(self.out, relative)  # checked again now: nothing may have become a link since
                if stat.S_ISREG(os.lstat(path).st_mode):
                    path.unlink()
            except FileNotFoundError:
                pass
            except (OSError, UnsafePathError) as error:
                self.warn(f"removing the stale {relative}", error)

    # ------------------------------------------------------------------------------------------------ log
    def _log(self, call, what: str) -> None:
        try:
            call()
        except Exception as error:  # noqa: BLE001  (a tracker: the results are written)
            self.warn(what, error)

    def log(self, evaluations: dict, rows: list[dict], headline: float, stage_seconds: dict, timings: dict) -> None:
        """The evaluations' metrics, the stage wall-clocks, the results table and the summary, to the trackers;
        then closes them."""
        from hierloco.loggers import metric_component
        from hierloco.pipeline import report

        for (setting, name), (_, evaluation) in evaluations.items():
            self._log(lambda: report.log_evaluation(self.logger, evaluation, setting, name),
                      f"logging {setting}/{name}")
        for stage, seconds in stage_seconds.items():
            self._log(lambda: self.logger.log_scalar(f"time/{stage}", seconds), "logging the wall-clock")
            plan = timings.get(stage, {}).get("metrics", {}).get("plan_seconds")
            if plan is not None:  # one planner call, in s
                self._log(lambda: self.logger.log_scalar(f"time/{stage}/plan_seconds", plan), "logging the wall-clock")
        if rows:
            self._log(lambda: self.logger.log_table("eval/results", rows), "logging the results table")
        summary = {"headline_normalized_cost": headline,
                   **{f"eval/{s}/{metric_component(n)}/normalized_cost": e.metrics["normalized_cost"]
                      for (s, n), (_, e) in evaluations.items()}}
        self._log(lambda: self.logger.summary(summary), "the tracker's summary")
        self._log(self.logger.close, "closing the trackers")

    def log_checkpoints(self, stages, run_path: Path) -> None:
        """The trained run as one tracker artifact of type ``hierloco-run`` (its ``run.json``, every trained
        network ``*.pt`` and the expert library, each stage's key digest as metadata), which
        ``hierloco.load_run("wandb:<entity>/<project>/<name>:<version>")`` opens again; wandb offline keeps it for
        ``wandb sync``."""
        files = [run_path / "run.json"] + [run_path / stage.filename for stage in stages
                                           if stage.filename.endswith((".pt", "experts.npz"))]
        files = [path for path in files if path.is_file()]
        digests = {stage.name: stage.digest for stage in stages}
        self._log(lambda: self.logger.log_artifact(files, f"{run_path.name}-run", "hierloco-run", digests),
                  "logging the run's checkpoints")


def environment_threads() -> list[str]:
    """Problems with the thread variables of the environment (``OMP_NUM_THREADS=abc``): each one line."""
    problems = []
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        value = os.environ.get(name)
        if value is not None and not (value.strip().isdigit() and int(value) >= 1):
            problems.append(f"{name}={value!r} must be a whole number of threads >= 1 (or unset)")
    return problems


__all__ = ["OUTPUTS", "Outputs", "environment_threads"]
