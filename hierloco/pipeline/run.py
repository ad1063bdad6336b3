"""One recipe run: its checked config, robot, plan of stages, locked run directory, loggers and outputs.

:func:`open_run` does everything that can refuse a run before any work: it checks the whole config, plans every
stage (their keys), checks the run directory (whose it is, and each stage's key), and only then locks the directory
and opens the loggers, so a refused run writes nothing. :meth:`Run.stage` loads or builds one stage;
:meth:`Run.finish` writes the results tables from the evaluations the plan names, then the optional outputs
(trackers, figures, videos), and returns the headline cost. A run is a context manager: leaving it releases the
run directory's lock (``docs/pipeline.md``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable, Iterable

import numpy as np
from omegaconf import DictConfig, OmegaConf

from hierloco.io import temporaries_in, write_text
from hierloco.pipeline.budget import check_budget
from hierloco.pipeline.config import ConfigError, make_task_from_spec, section, task_specs
from hierloco.pipeline.errors import findings, one_line
from hierloco.pipeline.outputs import Outputs
from hierloco.pipeline.plan import Plan, Stage
from hierloco.pipeline.records import FAILED
from hierloco.pipeline.rundir import RunDirectory, RunDirectoryError, check_run_dir, normalized
from hierloco.pipeline.validate import validate
from hierloco.results import TaskEvaluation, markdown_table, write_results
from hierloco.trained import MANIFEST

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
    from hierloco.envs.batched_sim import available_cores

    return available_cores()


# Keys whose value changes no artifact: left out of a multirun job's directory name.
NOT_IN_RUN_DIR_NAME = ("progress", "nthread", "logger", "eval.videos", "eval.figures", "dry_run", "records")


def resolve_run_dir(cfg, method: str, robot) -> Path:
    """``run_dir``, or by default ``outputs/<method>/<preset>/<robot>_seed<seed>``; in a Hydra multirun the
    job's overrides that change an artifact are appended (not ``progress``, ``nthread`` or logger settings), so
    the jobs of a sweep never share a directory unless they share every artifact."""
    if cfg.run_dir is not None:
        return check_run_dir(cfg.run_dir)
    profile = cfg.get("robot_profile", "own")
    name = robot.name if profile == "own" else f"{robot.name}-{profile}"
    path = Path("outputs") / method / str(cfg.get("preset_name", "custom")) / f"{name}_seed{cfg.seed}"
    overrides = multirun_overrides()
    if overrides:
        path = path / ",".join(overrides).replace("/", "_")
    return check_run_dir(path)


def multirun_overrides() -> list[str]:
    """The overrides of this Hydra multirun job that change artifacts (``[]`` outside a multirun)."""
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        hydra_cfg = HydraConfig.get()
    except (ImportError, ValueError):  # not under Hydra
        return []
    if hydra_cfg.mode != RunMode.MULTIRUN:
        return []
    kept = []
    for override in hydra_cfg.overrides.task:
        key = override.split("=", 1)[0].lstrip("+~")
        if key in ("run_dir", "seed", "robot", "preset") or any(key == k or key.startswith(f"{k}.")
                                                                for k in NOT_IN_RUN_DIR_NAME):
            continue
        kept.append(override)
    return sorted(kept)


def in_multirun() -> bool:
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        return HydraConfig.get().mode == RunMode.MULTIRUN
    except (ImportError, ValueError):
        return False


class Run:
    """A recipe run in progress: ``run.plan`` holds the stages as named handles; ``run.stage(handle, *inputs)``
    gives a stage's artifact (loaded or built).

    Args:
        cfg: the checked config. method: the recipe's name. robot: the robot description.
        plan: the recipe's :class:`Plan`. directory: the locked :class:`RunDirectory`. logger: a ``RunLogger``.
        evaluation_out: in evaluation mode (``recipes/evaluate.py``), where its tables, figures and videos go;
            every training stage must then be finished.
    """

    def __init__(self, cfg: DictConfig, method: str, robot, plan: Plan, directory: RunDirectory, logger,
                 evaluation_out: Path | None = None):
        from hierloco.loggers import NullLogger

        self.cfg, self.method, self.robot = cfg, method, robot
        self.plan = plan
        self.dir = directory
        self.evaluating = evaluation_out is not None
        self.out = Path(evaluation_out) if evaluation_out is not None else directory.path
        self.logger = logger if logger is not None else NullLogger()
        self.nthread = int(cfg.nthread) if cfg.get("nthread") is not None else default_threads()
        self.progress = bool(cfg.progress)
        self.reports: dict = {}
        self.evaluations: dict[tuple[str, str], tuple[Stage, TaskEvaluation]] = {}
        self.start = time.perf_counter()
        self._robot_checked = False

    @property
    def path(self) -> Path:
        return self.dir.path

    @property
    def current(self) -> str | None:
        """The stage being built or loaded now."""
        return self.dir.current

    def where(self) -> str:
        """Where the run is, for an interruption message."""
        return f" in stage {self.current!r} of {self.path}" if self.current else f" in {self.path}"

    def stage(self, stage: Stage, *inputs, build: Callable | None = None):
        """The artifact of ``stage`` (a handle of :attr:`plan`): loaded when finished with the same key, else built
        from ``inputs`` (by ``build(run, params, *inputs)`` when given, else by the stage's own builder)."""
        if not isinstance(stage, Stage) or self.plan_stage(stage.name) is not stage:
            raise RuntimeError(f"run.stage takes a stage of the run's plan, got {stage!r}")
        build = build or stage.build
        if self.evaluating and stage.trains and not self.dir.check(stage.name, stage.key, stage.filename):
            raise ConfigError(f"stage {stage.name!r} is not finished in {self.path}: train the run first (train.py)")
        if stage.trains and not self._robot_checked and not self.dir.check(stage.name, stage.key, stage.filename):
            build = self._checking_the_robot_first(build)
        build = self._announced(stage, build)
        timings: dict = {}
        try:
            with temporaries_in(self.path):
                artifact = self.dir.stage(stage.name, stage.key, lambda: build(self, stage.params, *inputs),
                                          lambda a, path: _save_without_wall_clock(a, path, timings),
                                          stage.artifact_class.load, stage.filename)
            if self.dir.reused.get(stage.name):
                self._announce(stage, "cached")
        except findings() as error:  # a finding about the setting: kept, so a study need not run it again
            if not self.dir.readonly:
                with temporaries_in(self.path):
                    write_text(self.path / FAILED, json.dumps({"stage": stage.name, "key": normalized(stage.key),
                                                               "error": one_line(error)}, indent=2))
            raise
        validate(stage, artifact, self.robot, self.path / stage.filename)  # shapes, finite values: or one line
        if timings:
            self.reports.setdefault("timings", {})[stage.name] = timings
        if stage.check is not None:
            stage.check(self, artifact)
        if isinstance(artifact, TaskEvaluation):
            self.evaluations[(stage.params["setting"], stage.params["task_name"])] = (stage, artifact)
        else:
            summary = getattr(artifact, "summary", None)  # what the artifact says of itself, else its metadata
            self.reports[stage.name] = summary() if callable(summary) else dict(getattr(artifact, "metadata", artifact))
        return artifact

    def _announce(self, stage: Stage, what: str) -> None:
        """One line per stage, whatever ``progress`` says (its bars are the only other sign of life)."""
        print(f"[{time.perf_counter() - self.start:5.0f} s] stage {stage.name}: {what}", flush=True)

    def _announced(self, stage: Stage, build: Callable) -> Callable:
        """``build``, after the stage's line."""
        def announced(*args):
            self._announce(stage, "building")
            return build(*args)

        return announced

    def _checking_the_robot_first(self, build: Callable) -> Callable:
        """``build``, preceded (once per run) by the robot description's checks, which take milliseconds: a robot
        that cannot stand (pose outside its joint limits, feet that do not reach the floor, motors too weak for its
        weight) is a finding of the first stage that would simulate it (``hierloco.envs.robots.check``)."""
        def checked(*args):
            from hierloco.envs.robots.check import RobotDescriptionError, description_problems

            self._robot_checked = True
            problems = description_problems(self.robot)
            if problems:
                raise RobotDescriptionError(f"robot {self.robot.name!r} cannot walk as described: "
                                            + "; ".join(problems))
            return build(*args)

        return checked

    def plan_stage(self, name: str) -> Stage | None:
        return next((stage for stage in self.plan.stages() if stage.name == name), None)

    def evaluate(self, evaluations: Iterable[Stage], *inputs) -> None:
        """Every evaluation stage of ``evaluations`` (e.g. ``setting.evaluations``), with the same ``inputs``."""
        for stage in evaluations:
            self.stage(stage, *inputs)

    # ------------------------------------------------------------------------------------------------ finish
    def finish(self, low_level=None) -> float:
        """Writes ``results.csv``, ``episodes.csv``, ``results.md``, ``config.yaml`` and ``report.json`` from the
        evaluations of the plan, then the optional outputs (tracker, figures, videos; each failure is one warning
        line and a ``warnings`` entry of ``report.json``, never a failed run); prints the table and returns the
        headline cost: the mean normalised cost over the main tasks of the first setting."""
        missing = [stage.name for stage in self.plan.stages() if stage.name not in self.dir.timings]
        if missing:
            raise RuntimeError(f"the recipe planned stages it did not run: {missing}")
        rows = [row for _, evaluation in self.evaluations.values() for row in evaluation.rows]
        main_tasks = list(self.cfg.eval.tasks)
        first = list(self.cfg.settings)[0]
        costs = [e.metrics["normalized_cost"] for (s, n), (_, e) in self.evaluations.items()
                 if s == first and n in main_tasks]
        headline = float(np.mean(costs)) if costs else float("nan")
        if self.dir.readonly:
            print(f"\n{self.method.upper()} on {self.robot.name} (seed {self.cfg.seed}), read-only run directory "
                  f"{self.path}\n\n{markdown_table(rows)}")
            return headline
        with temporaries_in(self.path):
            table = write_results(self.out, rows)  # the results first: nothing after this can lose them
            write_text(self.out / "config.yaml", OmegaConf.to_yaml(self.cfg, resolve=True))
            self.reports["stage_seconds"] = self.dir.timings
            self.reports["reused_stages"] = self.dir.reused
            self.reports["build_seconds"] = self.dir.build_seconds  # what each stage took when it was built
            self._write_report()
            outputs = Outputs(self.out, self.cfg, self.robot, self.method, self.logger)
            outputs.draw(self.evaluations, low_level)
            if not self.evaluating:
                outputs.log_checkpoints(self.plan.stages(), self.path)
            outputs.log(self.evaluations, rows, headline, self.dir.timings, self.reports.get("timings", {}))
            self.reports["total_seconds"] = time.perf_counter() - self.start
            if outputs.warnings:
                self.reports["warnings"] = outputs.warnings
            self._write_report()
        print(f"\n{self.method.upper()} on {self.robot.name} (seed {self.cfg.seed}), run directory {self.path}"
              + (f", evaluation in {self.out}" if self.out != self.path else "") + "\n")
        print(table)
        print("stage wall-clock (s): " + ", ".join(f"{k} {v:.1f}" + (" (cached)" if self.dir.reused[k] else "")
                                                  for k, v in self.dir.timings.items()))
        print(f"figures in {self.out / 'figures'}/, results in {self.out / 'results.csv'}")
        return headline

    def _write_report(self) -> None:
        write_text(self.out / "report.json", json.dumps(self.reports, indent=2, default=float))

    # ------------------------------------------------------------------------------------------------ life
    def close(self) -> None:
        """Releases the run directory (and closes the loggers if :meth:`finish` did not)."""
        try:
            self.logger.close()
        except Exception as error:  # noqa: BLE001  (an optional tracker: the run's results are written)
            print(f"warning: closing the loggers failed: {one_line(error)}")
        self.dir.release()

    def __enter__(self) -> "Run":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def check_owner(directory: RunDirectory, method: str, cfg, robot, filenames: Iterable[str] = ()) -> None:
    """Refuses a run directory made by another method, or for another robot or seed (its ``run.json``); without a
    ``run.json``, one holding files that the plan (its stages' ``filenames``) does not make: whose they are cannot be
    established (:meth:`RunDirectory.foreign_artifacts`)."""
    manifest = directory.path / MANIFEST
    if not manifest.is_file():
        foreign = directory.foreign_artifacts(filenames)
        if foreign:
            listed = ", ".join(foreign[:4]) + (", ..." if len(foreign) > 4 else "")
            raise RunDirectoryError(f"run directory {directory.path} has no {MANIFEST} (which names the method that "
                                    f"made it) yet holds files {method}'s plan does not make ({listed}): another "
                                    f"run's, which {method} would overwrite; restore its {MANIFEST} or choose another "
                                    "run_dir")
        return
    try:
        made = json.loads(manifest.read_text())
    except (OSError, ValueError) as error:
        raise RunDirectoryError(f"corrupted run manifest {manifest}: {error}") from None
    if not isinstance(made, dict):
        raise RunDirectoryError(f"corrupted run manifest {manifest}: not a JSON object")
    if made.get("method") != method:
        raise RunDirectoryError(f"run directory {directory.path} belongs to method {made.get('method')!r} (its "
                                f"{MANIFEST}); {method} needs a run directory of its own (run_dir=...)")
    if made.get("seed") != int(cfg.seed):
        raise RunDirectoryError(f"run directory {directory.path} was made with seed {made.get('seed')}, not "
                                f"{cfg.seed}: choose another run_dir")


def open_run(cfg: DictConfig, method: str, plan: Callable, checks: Callable | None = None,
             manifest: Callable | None = None, *, evaluation_out: Path | None = None) -> Run:
    """Checks ``cfg`` (common checks, then ``checks(checker, robot)``), plans the stages (``plan(cfg, robot)``),
    checks the run directory (its owner, each stage's key) before any work, then locks it (in a Hydra multirun it
    waits for another job of the sweep that holds it), writes the run manifest and opens the loggers."""
    import torch

    from hierloco.envs.robots import get_robot
    from hierloco.pipeline.config import prepare

    robot = prepare(cfg, checks)
    directory = RunDirectory(resolve_run_dir(cfg, method, robot))
    multirun = in_multirun()
    tuning = None
    if cfg.get("experts") is not None and cfg.experts.get("tune"):  # the robot's expert parameters searched first
        robot, tuning = tune_first(cfg, method, robot, directory, multirun)
    planned = plan(cfg, robot)
    if not isinstance(planned, Plan):
        planned = Plan(stages=list(planned))
    specs = [stage.spec for stage in planned.stages()]
    if not multirun:
        directory.check_free()  # another process's run is named first: its stages may not match ours yet
    from hierloco.pipeline.tuning import FILENAME as TUNING_FILE

    owned = [spec.filename for spec in specs] + ([TUNING_FILE] if tuning is not None else [])  # what it makes
    check_owner(directory, method, cfg, robot, owned)
    done = directory.verify(specs)  # before anything is written
    unfinished = [stage.name for stage in planned.stages() if stage.trains and not done[stage.name]]
    if evaluation_out is not None and unfinished:
        raise ConfigError(f"{directory.path} has unfinished training stages ({', '.join(unfinished)}): run "
                          f"recipes/{method}/train.py into it first")
    threads = int(cfg.nthread) if cfg.get("nthread") is not None else default_threads()
    check_budget([stage for stage in planned.stages() if not done[stage.name]], threads=threads,
                 confirmed=bool(cfg.get("confirm_long", False)))
    directory.acquire(wait=multirun)
    try:
        check_owner(directory, method, cfg, robot, owned)
        directory.verify(specs)  # again, now that no other process can write it
        logger = None
        if not directory.readonly:
            (directory.path / FAILED).unlink(missing_ok=True)  # an earlier run's finding: this run finds again
            if evaluation_out is None:
                info = {"method": method, "robot": get_robot(cfg.robot).reference,
                        "robot_profile": cfg.get("robot_profile", "own"), "seed": int(cfg.seed),
                        "settings": list(cfg.settings),
                        "planner": section(cfg, "planner") if "planner" in cfg else {},
                        **(manifest(cfg, robot) if manifest is not None else {}),
                        **({"expert_tuning": {key: tuning[key] for key in ("parameters", "changed", "yaml",
                                                                            "tuned_fingerprint", "policy_overrides")}}
                           if tuning is not None else {})}
                with temporaries_in(directory.path):
                    write_text(directory.path / MANIFEST, json.dumps(info, indent=2))
            logger = open_logger(cfg, method, robot, directory.path)
            if evaluation_out is None and logger.wandb_run is not None:  # where this run's tracker is
                manifest_path = directory.path / MANIFEST
                info = {**json.loads(manifest_path.read_text()), "wandb": logger.wandb_run}
                with temporaries_in(directory.path):
                    write_text(manifest_path, json.dumps(info, indent=2))
    except BaseException:
        directory.release()
        raise
    torch.manual_seed(cfg.seed)
    return Run(cfg, method, robot, planned, directory, logger, evaluation_out=evaluation_out)


def tune_first(cfg, method: str, robot, directory: RunDirectory, multirun: bool):
    """``experts.tune=true``: the cached search of the robot's expert parameters (:mod:`hierloco.pipeline.tuning`),
    run under the run directory's lock before anything else is planned; returns the tuned robot and the report,
    and applies the gait-policy overrides the search verified with to ``cfg.policy``."""
    from omegaconf import open_dict

    from hierloco.pipeline.tuning import tuned_robot, tuning_stage

    stage = tuning_stage(cfg, robot)
    if not multirun:
        directory.check_free()
    check_owner(directory, method, cfg, robot, [stage.filename])
    directory.verify([stage.spec])
    directory.acquire(wait=multirun)
    try:
        report = Run(cfg, method, robot, Plan(tuning=stage), directory, None).stage(stage)
    except BaseException:
        directory.release()
        raise
    with open_dict(cfg):
        for key, value in report["policy_overrides"].items():
            cfg.policy[key] = value
    return tuned_robot(robot, report), dict(report)


def open_logger(cfg, method: str, robot, run_path: Path):
    """The run's ``RunLogger`` (CSV, wandb offline unless asked, TensorBoard on request); a tracker that cannot
    start (an unwritable home for wandb's files, ...) is one warning line, and the run goes on with CSV."""
    from hierloco.loggers import RunLogger

    preset = cfg.get("preset_name", "custom")
    options = dict(prefix=method, project=cfg.logger.project, wandb_mode=cfg.logger.wandb_mode,
                   group=f"{method}/{robot.name}/{preset}", tags=[method, robot.name, str(preset)],
                   config=OmegaConf.to_container(cfg, resolve=True))
    try:
        return RunLogger(robot.name, run_path / "logs", backends=cfg.logger.backends, **options)
    except Exception as error:  # noqa: BLE001  (a tracker: the run's own results do not depend on it)
        print(f"warning: the loggers {list(cfg.logger.backends)} could not start ({one_line(error)}); logging to "
              "CSV only")
        return RunLogger(robot.name, run_path / "logs", backends=("csv",), **options)


__all__ = ["Run", "default_threads", "open_run", "resolve_run_dir", "strip_wall_clock"]
