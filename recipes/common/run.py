"""One recipe run: its checked config, robot, plan of stages, locked run directory, loggers, and its reports.

:func:`open_run` does everything that can refuse a run before any work: it checks the whole config, plans every
stage (their keys), checks each against the run directory, and only then locks the directory and opens the loggers,
so a refused run writes nothing. :meth:`Run.stage` then loads or builds one stage; :meth:`Run.finish` writes the
results tables, figures, videos and report, and returns the headline cost.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Callable, Iterable

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from hierloco.envs.faults import fault_legs, is_unadapted
from hierloco.envs.robots import get_robot
from hierloco.io import write_text
from hierloco.loggers import NullLogger, RunLogger, metric_component
from hierloco.results import TaskEvaluation, write_results
from hierloco.runs import RunDirectory, normalized
from hierloco.trained import MANIFEST
from recipes.common import report
from recipes.common.entry import findings, one_line
from recipes.common.records import FAILED
from recipes.common.config import ConfigError, make_task_from_spec, section
from recipes.common.stages import Stage, task_specs

CURRENT: dict = {}  # the run directory and stage of this process's run, for the interrupt message
EVALUATE: dict = {}  # set by recipes/common/evaluate.py: {"out": folder}: training stages must be finished


def is_training(name: str) -> bool:
    """Every stage but the evaluations trains something (evaluate.py never builds one)."""
    return not name.startswith("evaluation_")


WALL_CLOCK_KEYS = ("train_seconds", "seconds", "plan_seconds")


def strip_wall_clock(value):
    """``value`` (metadata: dicts and lists) without its wall-clock entries, and those entries: artifacts hold only
    what the same command reproduces byte for byte; timings go to ``report.json``."""
    if isinstance(value, dict):
        kept, removed = {}, {}
        for key, item in value.items():
            if key in WALL_CLOCK_KEYS:
                removed[key] = item
            else:
                kept[key], inner = strip_wall_clock(item)
                if inner:
                    removed[key] = inner
        return kept, removed
    if isinstance(value, list) and any(isinstance(item, dict) for item in value):
        pairs = [strip_wall_clock(item) for item in value]
        return [kept for kept, _ in pairs], ([removed for _, removed in pairs] if any(r for _, r in pairs) else {})
    return value, {}


def _save_without_wall_clock(artifact, path, timings: dict) -> None:
    for field in ("metadata", "metrics"):
        if isinstance(getattr(artifact, field, None), dict):
            kept, removed = strip_wall_clock(getattr(artifact, field))
            setattr(artifact, field, kept)
            if removed:
                timings[field] = removed
    artifact.save(path)


def default_threads() -> int:
    """The cores this process may use (its CPU affinity), the default number of simulation threads."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def resolve_run_dir(cfg, method: str, robot) -> Path:
    """``run_dir``, or by default ``outputs/<method>/<preset>/<robot>_seed<seed>``; in a Hydra multirun the
    job's overrides are appended, so the jobs of a sweep never share a directory."""
    if cfg.run_dir is not None:
        return Path(str(cfg.run_dir))
    profile = cfg.get("robot_profile", "own")
    name = robot.name if profile == "own" else f"{robot.name}-{profile}"
    path = Path("outputs") / method / str(cfg.get("preset_name", "custom")) / f"{name}_seed{cfg.seed}"
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        hydra_cfg = HydraConfig.get()
        if hydra_cfg.mode == RunMode.MULTIRUN and hydra_cfg.job.override_dirname:
            path = path / hydra_cfg.job.override_dirname.replace("/", "_")
    except (ImportError, ValueError):  # not under Hydra
        pass
    return path


class Run:
    """A recipe run in progress. ``stage(name, *inputs)`` gives a stage's artifact (loaded or built)."""

    def __init__(self, cfg: DictConfig, method: str, robot, stages: Iterable[Stage], directory: RunDirectory,
                 logger: RunLogger | None):
        self.cfg, self.method, self.robot = cfg, method, robot
        self.plan = {stage.name: stage for stage in stages}
        self.dir = directory
        self.out = Path(EVALUATE["out"]) if EVALUATE else directory.path  # where tables, figures and videos go
        self.logger = logger if logger is not None else NullLogger()
        self.nthread = int(cfg.nthread) if cfg.get("nthread") is not None else default_threads()
        self.progress = bool(cfg.progress)
        self.reports: dict = {}
        self.evaluations: dict[tuple[str, str], TaskEvaluation] = {}
        self.start = time.perf_counter()

    @property
    def path(self) -> Path:
        return self.dir.path

    @property
    def current(self) -> str | None:
        return self.dir.current

    @property
    def settings(self) -> list[str]:
        return list(self.cfg.settings)

    @property
    def dynamics_settings(self) -> list[str]:
        """The settings whose CoM dynamics are learned: every setting but the ``<setting>_unadapted`` ones, which
        plan with the normal setting's model (``normal`` is then learned first even when not evaluated)."""
        return [name.removeprefix("dynamics_model_") for name in self.plan if name.startswith("dynamics_model_")]

    def stage(self, name: str, *inputs, build: Callable | None = None):
        """Stage ``name`` of the plan: loaded when finished with the same key, else built from ``inputs`` (by
        ``build(run, params, *inputs)`` when given, else by the stage's own builder)."""
        stage = self.plan[name]
        build = build or stage.build
        if EVALUATE and is_training(name) and not self.dir.check(name, stage.key, stage.filename):
            raise ConfigError(f"stage {name!r} is not finished in {self.path}: train the run first (train.py)")
        CURRENT["stage"] = name
        timings: dict = {}
        try:
            artifact = self.dir.stage(name, stage.key, lambda: build(self, stage.params, *inputs),
                                      lambda a, path: _save_without_wall_clock(a, path, timings),
                                      stage.artifact.load, stage.filename)
        except findings() as error:  # a finding about the setting: kept, so a study need not run it again
            if not self.dir.readonly:
                write_text(self.path / FAILED, json.dumps({"stage": name, "key": normalized(stage.key),
                                                           "error": one_line(error)}, indent=2))
            raise
        if timings:
            self.reports.setdefault("timings", {})[name] = timings
        if stage.check is not None:
            stage.check(self, artifact)
        if isinstance(artifact, TaskEvaluation):
            self.evaluations[(stage.params["setting"], stage.params["task_name"])] = artifact
        else:
            summary = getattr(artifact, "summary", None)  # what the artifact says of itself, else its metadata
            self.reports[name] = summary() if callable(summary) else dict(getattr(artifact, "metadata", artifact))
        CURRENT["stage"] = None
        return artifact

    def dependents(self, name: str) -> list[str]:
        """The planned stages that depend directly on stage ``name``, in plan order."""
        key = self.plan[name].digest
        return [other for other, stage in self.plan.items() if key in stage.after.values()]

    def evaluate(self, setting: str, *inputs) -> None:
        """Every evaluation stage of ``setting`` (one per task), with the same ``inputs`` (its CoM model among them),
        and, for ``normal``, those of the ``<setting>_unadapted`` settings, which plan with the normal model."""
        for name, stage in self.plan.items():
            evaluated = stage.params.get("setting") if name.startswith("evaluation_") else None
            if evaluated == setting or (setting == "normal" and evaluated is not None and is_unadapted(evaluated)):
                self.stage(name, *inputs)

    # ------------------------------------------------------------------------------------------------ finish
    def finish(self, low_level=None) -> float:
        """Writes ``results.csv``, ``episodes.csv``, ``results.md``, figures, videos, ``report.json`` and
        ``config.yaml`` (nothing when read-only), prints the table and returns the headline cost: the mean
        normalised cost over the main tasks of the first setting."""
        missing = [name for name in self.plan if name not in self.dir.timings]
        if missing:
            raise RuntimeError(f"the recipe planned stages it did not run: {missing}")
        rows = [row for evaluation in self.evaluations.values() for row in evaluation.rows]
        main_tasks = list(self.cfg.eval.tasks)
        first = self.settings[0]
        costs = [e.metrics["normalized_cost"] for (s, n), e in self.evaluations.items() if s == first and n in main_tasks]
        headline = float(np.mean(costs)) if costs else float("nan")
        if self.dir.readonly:
            from hierloco.results import markdown_table

            table = markdown_table(rows)
            print(f"\n{self.method.upper()} on {self.robot.name} (seed {self.cfg.seed}), read-only run directory "
                  f"{self.path}\n\n{table}")
            return headline
        for (setting, name), evaluation in self.evaluations.items():
            report.log_evaluation(self.logger, evaluation, setting, name)
        self._figures_and_videos(low_level)
        self.reports["stage_seconds"] = self.dir.timings
        self.reports["reused_stages"] = self.dir.reused
        self.reports["build_seconds"] = self.dir.build_seconds  # what each stage took when it was built
        self.reports["total_seconds"] = time.perf_counter() - self.start
        write_text(self.out / "report.json", json.dumps(self.reports, indent=2, default=float))
        table = write_results(self.out, rows)
        write_text(self.out / "config.yaml", OmegaConf.to_yaml(self.cfg, resolve=True))
        for stage, seconds in self.dir.timings.items():
            self.logger.log_scalar(f"time/{stage}", seconds)
            plan = self.reports.get("timings", {}).get(stage, {}).get("metrics", {}).get("plan_seconds")
            if plan is not None:  # one planner call, in s
                self.logger.log_scalar(f"time/{stage}/plan_seconds", plan)
        if rows:
            self.logger.log_table("eval/results", rows)
        self.logger.summary({"headline_normalized_cost": headline,
                             **{f"eval/{s}/{metric_component(n)}/normalized_cost": e.metrics["normalized_cost"]
                                for (s, n), e in self.evaluations.items()}})
        self.logger.close()
        print(f"\n{self.method.upper()} on {self.robot.name} (seed {self.cfg.seed}), run directory {self.path}"
              + (f", evaluation in {self.out}" if self.out != self.path else "") + "\n")
        print(table)
        print("stage wall-clock (s): " + ", ".join(f"{k} {v:.1f}" + (" (cached)" if self.dir.reused[k] else "")
                                                  for k, v in self.dir.timings.items()))
        print(f"figures in {self.out / 'figures'}/, results in {self.out / 'results.csv'}")
        return headline

    def _figures_and_videos(self, low_level) -> None:
        figures = self.out / "figures"
        specs = task_specs(self.cfg)
        steps = int(self.cfg.steps_per_action)
        for (setting, name), evaluation in self.evaluations.items():
            task = make_task_from_spec(name, specs[name])
            if self.cfg.eval.figures:
                for path in report.task_figures(evaluation, task, self.robot, figures, method=self.method,
                                                setting=setting, steps_per_action=steps):
                    self.logger.log_image(f"figures/{path.stem}", path)
            video = self.out / "videos" / f"{setting}_{name}.mp4"
            if name in (self.cfg.eval.videos or []) and not video.exists():
                frames = report.task_video(evaluation, task, self.robot, video,
                                           disabled_legs=fault_legs(self.robot, setting)[0])
                if frames is None:
                    print(f"no video of {setting}/{name}: its evaluation kept no joint positions")
                else:
                    self.logger.log_video(f"eval/{setting}/{metric_component(name)}/video", frames,
                                          fps=report.VIDEO_FPS)
        if low_level is not None and self.cfg.eval.figures:
            path = report.latent_map(low_level, self.robot, figures / "latent_map.png", method=self.method,
                                     seed=self.cfg.seed)
            if path is not None:
                self.logger.log_image("figures/latent_map", path)


def open_run(cfg: DictConfig, method: str, plan: Callable, checks: Callable | None = None,
             manifest: Callable | None = None) -> Run:
    """Checks ``cfg`` (common checks, then ``checks(checker, robot)``), plans the stages (``plan(cfg, robot)``),
    checks each against the run directory, locks it, writes the run manifest and opens the loggers."""
    from recipes.common.config import prepare

    robot = prepare(cfg, checks)
    stages = list(plan(cfg, robot))
    directory = RunDirectory(resolve_run_dir(cfg, method, robot))
    CURRENT.update(run_dir=str(directory.path), stage=None)
    specs = [stage.spec for stage in stages]
    directory.check_free()  # another process's run is named first: its stages may not match ours yet
    done = directory.verify(specs)  # before anything is written
    unfinished = [name for name, finished in done.items() if is_training(name) and not finished]
    if EVALUATE and unfinished:
        raise ConfigError(f"{directory.path} has unfinished training stages ({', '.join(unfinished)}): run "
                          f"recipes/{method}/train.py into it first")
    directory.acquire()
    directory.verify(specs)  # again, now that no other process can write it
    if not directory.readonly:
        (directory.path / FAILED).unlink(missing_ok=True)  # an earlier run's finding: this run finds again
    logger = None
    if not directory.readonly and not EVALUATE:
        info = {"method": method, "robot": get_robot(cfg.robot).reference,
                "robot_profile": cfg.get("robot_profile", "own"), "seed": int(cfg.seed), "settings": list(cfg.settings),
                "planner": section(cfg, "planner") if "planner" in cfg else {},
                **(manifest(cfg, robot) if manifest is not None else {})}
        write_text(directory.path / MANIFEST, json.dumps(info, indent=2))
    if not directory.readonly:
        preset = cfg.get("preset_name", "custom")
        logger = RunLogger(robot.name, directory.path / "logs", prefix=method, backends=cfg.logger.backends,
                           project=cfg.logger.project, wandb_mode=cfg.logger.wandb_mode,
                           group=f"{method}/{robot.name}/{preset}", tags=[method, robot.name, str(preset)],
                           config=OmegaConf.to_container(cfg, resolve=True))
    torch.manual_seed(cfg.seed)
    return Run(cfg, method, robot, stages, directory, logger)
