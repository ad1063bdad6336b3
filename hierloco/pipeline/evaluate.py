"""Evaluate a trained run on any tasks or planners: ``hierloco evaluate run_dir=... [overrides]``.

One entry point serves every method: the run's ``run.json`` names its method (the method registry,
:mod:`hierloco.pipeline.methods`, finds its recipe). The run's own config (``<run_dir>/config.yaml``) is the base;
the overrides may change only what evaluation depends on (the ``eval`` and ``planner`` sections, ``settings``,
threads, device, progress, logging) and use Hydra's override grammar (``+eval.tasks.goal_reaching_5m={task:
goal_reaching, radius: 5}``, ``planner.name=cem``). ``-m`` (or ``--multirun``) sweeps: ``planner.num_candidates=
1000,2000,4000`` evaluates the same trained run once per value, never training anything. The recipe runs with every
training stage loaded (a missing one is an error) and each evaluation cached per task and planner; tables, figures
and videos go to ``<run_dir>/evaluations/<name>/`` (``name=`` a plain name; default a digest of the evaluation
config).

A run directory may come from someone else: its ``config.yaml`` and ``run.json`` are data. An import path in its
config (``planner.name: some.module:Class``, a task's ``task:``, ``dynamics.model``;
:func:`hierloco.pipeline.config.import_paths`) is imported only when the command line names it too, in an override
(``planner.name=some.module:Class``) or in ``trust_imports=some.module:Class[,...]``; a registered name is used as it
is (``docs/pipeline.md``).

Example:
    hierloco train lat preset=small run_dir=runs/a1
    hierloco evaluate run_dir=runs/a1 '+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5}'
    hierloco evaluate -m run_dir=runs/a1 planner.name=random_shooting,cem
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

from hierloco.pipeline.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, ConfigError, one_line

EVALUATION_KEYS = ("eval", "planner", "settings", "nthread", "device", "progress", "logger")
USAGE = ("usage: hierloco evaluate [-m] run_dir=<trained run> [name=<label>] [trust_imports=<pkg.mod:Class>,"
         "...] [eval/planner overrides]")
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.=,-]*")
IMPORT_PATH = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_][\w.]*")  # package.module:Class, as typed in an override


def split_arguments(arguments: list[str]) -> tuple[str | None, str | None, bool, list[str], list[str]]:
    """``(run_dir, name, multirun, overrides, trust_imports)`` of the command line; ``trust_imports=a:B,c:D`` (or
    ``[a:B,c:D]``) lists import paths the run's own files may name."""
    run_dir = name = None
    multirun = False
    overrides, trusted = [], []
    for argument in arguments:
        if argument in ("-m", "--multirun"):
            multirun = True
        elif argument.startswith("run_dir="):
            run_dir = argument.split("=", 1)[1]
        elif argument.startswith("name="):
            name = argument.split("=", 1)[1]
        elif argument.startswith("trust_imports="):
            trusted += [item.strip() for item in argument.split("=", 1)[1].strip("[]").split(",") if item.strip()]
        else:
            overrides.append(argument)
    return run_dir, name, multirun, overrides, trusted


def check_name(name: str) -> str:
    """``name`` as a folder name under ``evaluations/``: a plain name, never a path."""
    if not NAME.fullmatch(name) or name in (".", ".."):
        raise ConfigError(f"name={name!r} must be a plain name (letters, digits, _ . - =), not a path: the "
                          "evaluation goes to <run_dir>/evaluations/<name>/")
    return name


def _key_of(override: str) -> str:
    return override.split("=", 1)[0].lstrip("+~").split(".")[0]


def evaluation_config(run_dir: str, overrides: list[str]):
    """The trained run's config with the evaluation ``overrides`` applied (refusing any other key)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from hierloco.io import load_yaml

    config = Path(run_dir) / "config.yaml"
    if not config.is_file():
        raise ConfigError(f"{run_dir} has no config.yaml: it is not a finished training run (run train.py first)")
    bad = [o for o in overrides if _key_of(o) not in EVALUATION_KEYS]
    if bad:
        raise ConfigError(f"evaluate.py changes only {', '.join(EVALUATION_KEYS)}; got {', '.join(bad)} (a "
                          "training change needs train.py and another run_dir)")
    load_yaml(config)  # a received file, read safely first: no YAML bomb reaches Hydra (ArtifactError: one line)
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(config.parent.resolve()), version_base=None):
            return compose(config_name="config", overrides=overrides)
    except Exception as error:  # noqa: BLE001  (an unparsable config.yaml, a bad override): one line
        from omegaconf.errors import OmegaConfBaseException
        from hydra.errors import HydraException

        if isinstance(error, (HydraException, OmegaConfBaseException, ValueError)) or "yaml" in type(error).__module__:
            raise ConfigError(f"{config}: {one_line(error)}") from None
        raise
    finally:
        GlobalHydra.instance().clear()


def check_import_paths_given(cfg, overrides: list[str], run_dir: str, trusted=()) -> None:
    """Refuses, in one line, the import paths of the evaluation config ``cfg`` that come from the run's own
    ``config.yaml``, not from the command line (its ``overrides`` or ``trusted``, its ``trust_imports=``): a
    received file never names code to import."""
    from hierloco.pipeline.config import import_paths

    bad = [item for item in trusted if not IMPORT_PATH.fullmatch(item)]
    if bad:
        raise ConfigError(f"trust_imports lists {', '.join(bad)}: give import paths (package.module:Class)")
    typed = {match.group(0) for override in overrides for match in IMPORT_PATH.finditer(override)} | set(trusted)
    received = {dotted: path for dotted, path in import_paths(cfg).items() if path not in typed}
    if received:
        listed = " ".join(f"{dotted}={path}" for dotted, path in received.items())
        paths = ",".join(dict.fromkeys(received.values()))
        them = "them" if len(received) > 1 else "it"
        raise ConfigError(f"{Path(run_dir) / 'config.yaml'} names the import path{'s' if len(received) > 1 else ''} "
                          f"{listed}: code named by a run directory's files is never imported; if you trust {them}, "
                          f"add trust_imports={paths} to the command line, or choose a registered name")


def method_of(run_dir: str):
    """The :class:`hierloco.pipeline.methods.Method` that made ``run_dir`` (its ``run.json``)."""
    from hierloco.pipeline.methods import METHODS
    from hierloco.trained import MANIFEST

    manifest = Path(run_dir) / MANIFEST
    try:
        method = json.loads(manifest.read_text())["method"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ConfigError(f"{run_dir} is not a hierloco run directory ({MANIFEST}: {one_line(error)})") from None
    try:
        return METHODS[method]
    except ValueError as error:
        raise ConfigError(f"{manifest}: {error}") from None


def sweep(overrides: list[str]) -> list[list[str]]:
    """The jobs of a sweep over ``overrides`` (Hydra's grammar: ``a=1,2 b=x,y`` gives four)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(overrides)
    return [job for batch in BasicSweeper.split_arguments(parsed, max_batch_size=None) for job in batch]


def evaluate(run_dir: str, overrides: list[str], name: str | None = None, trust_imports=()) -> float:
    """Evaluates the trained run in ``run_dir`` with ``overrides`` (``trust_imports``: import paths its config may
    name, :func:`check_import_paths_given`); returns the headline cost."""
    from omegaconf import OmegaConf, open_dict

    from hierloco.pipeline.rundir import digest

    from hierloco.io import inside

    method = method_of(run_dir)
    cfg = evaluation_config(run_dir, overrides)
    check_import_paths_given(cfg, overrides, run_dir, trust_imports)
    trained = OmegaConf.load(Path(run_dir) / "config.yaml").get("device", "cpu")
    with open_dict(cfg):
        cfg.run_dir = run_dir
        if str(cfg.get("device")) != str(trained):  # evaluated elsewhere: the trained stages keep their keys
            cfg.trained_device = trained
    label = check_name(name) if name is not None else digest(OmegaConf.to_container(cfg, resolve=True))[:8]
    return method.main().run(cfg, evaluation_out=inside(run_dir, f"evaluations/{label}"))


def evaluate_main(arguments: list[str] | None = None) -> None:
    """The command line of ``recipes/evaluate.py``; exits 2 on a user error, printing one line."""
    from hydra.errors import HydraException

    from hierloco.pipeline.entry import one_line_errors, report_error, sigterm_as_interrupt

    os.environ.setdefault("HYDRA_FULL_ERROR", "1")
    sigterm_as_interrupt()
    run_dir, name, multirun, overrides, trusted = split_arguments(sys.argv[1:] if arguments is None else arguments)
    try:
        with one_line_errors():
            if run_dir is None:
                raise ConfigError(f"give the trained run: run_dir=... ({USAGE})")
            jobs = sweep(overrides) if multirun else [overrides]
            if multirun and name is not None and len(jobs) > 1:
                raise ConfigError("name= names one evaluation; a sweep names each by its overrides")
            for job in jobs:
                label = name
                if multirun and name is None:
                    label = re.sub(r"[^A-Za-z0-9_.=,-]", "_", ",".join(job)) or "default"
                    print(f"evaluation {label}: {' '.join(job) or '(the run config)'}", flush=True)
                evaluate(run_dir, job, label, trusted)
    except KeyboardInterrupt:
        print("interrupted: finished evaluations are kept; run the same command again to resume", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    except HydraException as error:
        report_error(error)
        sys.exit(EXIT_USER_ERROR)


__all__ = ["EVALUATION_KEYS", "evaluate", "evaluate_main", "evaluation_config"]
