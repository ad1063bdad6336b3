"""Evaluate a trained run on any tasks or planners: ``hierloco evaluate run_dir=... [overrides]``, a Hydra app.

One entry point serves every method: the run's ``run.json`` names its method (the method registry,
:mod:`hierloco.pipeline.methods`, finds its recipe). The app's config is ``hierloco/recipes/conf/evaluate.yaml``: the
run's own config (``<run_dir>/config.yaml``, read safely and given to Hydra as the config group option
``trained_run/run``) is its base, the config groups ``planner`` (``planner=cem``) and ``planner_scale`` may be chosen
over it, and the overrides may change only what evaluation depends on (:data:`EVALUATION_KEYS`: the ``eval`` and
``planner`` sections, ``settings``, threads, device, progress, logging), in Hydra's override grammar
(``+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5}``, ``planner.name=cem``). Hydra answers ``--help``,
``--cfg job`` and ``--info``; ``-m`` (or ``--multirun``) sweeps through Hydra's sweeper and launcher
(``hydra/launcher=joblib`` runs the jobs in parallel): ``planner.num_candidates=1000,2000,4000`` evaluates the same
trained run once per value, never training anything. The recipe runs with every training stage loaded (a missing
one is an error) and each evaluation cached per task and planner; tables, figures and videos go to
``<run_dir>/evaluations/<name>/``: ``name=`` a plain name; by default a digest of the evaluation config, and in a
sweep the job's Hydra override dirname, which leaves out the settings that change no result (``progress``,
``nthread``, logger settings: ``hydra.job.config.override_dirname.exclude_keys``).

A run directory may come from someone else: its ``config.yaml`` and ``run.json`` are data. Its ``config.yaml`` is
read with :func:`hierloco.io.load_yaml` first (a YAML bomb is refused before Hydra sees it) and may configure neither
Hydra nor this command. An import path in it (``planner.name: some.module:Class``, a task's ``task:``,
``dynamics.model``; :func:`hierloco.pipeline.config.import_paths`) is imported only when the command line names it
too, in an override (``planner.name=some.module:Class``) or in ``trust_imports=some.module:Class`` (several:
``trust_imports=[a.b:C,d.e:F]``); a registered name is used as it is (``docs/pipeline.md``).

Example:
    hierloco train lat preset=small run_dir=runs/a1
    hierloco evaluate run_dir=runs/a1 '+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5}'
    hierloco evaluate -m run_dir=runs/a1 planner=random_shooting,cem hydra/launcher=joblib
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
from collections.abc import Mapping
from pathlib import Path

from hierloco.pipeline.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, ConfigError, one_line

EVALUATION_KEYS = ("eval", "planner", "settings", "nthread", "device", "progress", "logger")
EVALUATION_GROUPS = ("planner", "planner_scale")  # config groups of hierloco/recipes/conf an evaluation may choose
COMMAND_KEYS = ("run_dir", "name", "trust_imports")  # this command's own keys, never the run's
CONFIG_NAME = "evaluate"  # hierloco/recipes/conf/evaluate.yaml
TRAINED_GROUP = "trained_run"  # the config group option (in Hydra's ConfigStore) holding the run's config.yaml
FOLDER_RESOLVER = "hierloco.evaluation_folder"  # names a sweep job's folder (evaluate.yaml: hydra.sweep.subdir)
USAGE = ("usage: hierloco evaluate [-m] run_dir=<trained run> [name=<label>] [trust_imports=<pkg.mod:Class>] "
         "[planner=<type>] [eval/planner/... overrides]")
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.=,-]*")
IMPORT_PATH = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_][\w.]*")  # package.module:Class, as typed in an override


def check_name(name: str) -> str:
    """``name`` as a folder name under ``evaluations/``: a plain name, never a path."""
    if not NAME.fullmatch(name) or name in (".", ".."):
        raise ConfigError(f"name={name!r} must be a plain name (letters, digits, _ . - =), not a path: the "
                          "evaluation goes to <run_dir>/evaluations/<name>/")
    return name


def evaluation_folder(name, override_dirname) -> str:
    """The folder under ``<run_dir>/evaluations/`` of a job of a sweep: ``name`` when given, else the job's Hydra
    override dirname (its overrides but those of ``hydra.job.config.override_dirname.exclude_keys``), each character
    other than letters, digits and ``_ . = , -`` replaced by ``_`` (a long one shortened by a digest); ``default``
    for a job without overrides. Hydra's ``hydra.sweep.subdir`` (``evaluate.yaml``).

        >>> evaluation_folder(None, "planner.num_candidates=1000,planner=cem")
        'planner.num_candidates=1000,planner=cem'
        >>> evaluation_folder(None, "+eval.tasks.far={task: goal_reaching}")
        'eval.tasks.far=_task__goal_reaching_'
        >>> evaluation_folder("mine", "planner=cem"), evaluation_folder(None, "")
        ('mine', 'default')
    """
    if name is not None:
        return str(name)
    folder = re.sub(r"[^A-Za-z0-9_.=,-]", "_", str(override_dirname or "")).lstrip("_.=,-")
    if len(folder) > 200:  # a file system's names end at 255 bytes
        folder = f"{folder[:180]}-{hashlib.sha256(folder.encode()).hexdigest()[:12]}"
    return folder or "default"


def _register_folder_resolver() -> None:
    """Registers :func:`evaluation_folder` with OmegaConf (at import: a launcher's worker process imports this module
    with the job's function, before Hydra resolves the job's folder)."""
    from omegaconf import OmegaConf

    if not OmegaConf.has_resolver(FOLDER_RESOLVER):
        OmegaConf.register_new_resolver(FOLDER_RESOLVER, evaluation_folder)


_register_folder_resolver()


def conf_folder() -> Path:
    """``hierloco/recipes/conf``: the shared config groups and ``evaluate.yaml``."""
    from hierloco.recipes import conf

    return Path(next(iter(conf.__path__))).resolve()


def read_command_line(arguments: list[str]) -> tuple[list[str], str | None, str | None]:
    """``(arguments, run_dir, name)`` of the command line, checked before Hydra runs it: every override (Hydra's
    grammar, parsed by Hydra's parser) changes an evaluation key (:data:`EVALUATION_KEYS`), chooses an evaluation
    config group (:data:`EVALUATION_GROUPS`), sets this command's keys or Hydra's own settings
    (``hydra/launcher=joblib``); ``run_dir`` and ``name`` take one value and ``name`` is a plain name, given to a
    sweep of one job only; ``trust_imports=a:B,c:D`` is passed on as the list ``trust_imports=[a:B,c:D]``."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    arguments = list(arguments)
    positions = [i for i, argument in enumerate(arguments) if "=" in argument and not argument.startswith("-")]
    parsed = OverridesParser.create().parse_overrides([arguments[i] for i in positions])
    values: dict = {}
    bad, sweeps = [], []
    for position, override in zip(positions, parsed):
        key = override.key_or_group
        if override.is_hydra_override():
            continue
        if key in COMMAND_KEYS:
            if override.is_sweep_override():
                if key != "trust_imports":
                    why = "one trained run per command" if key == "run_dir" else "a sweep names each by its overrides"
                    raise ConfigError(f"{key}= takes one value, got {override.input_line!r} ({why})")
                listed = ",".join(override.sweep_string_iterator())
                arguments[position] = f"{override.get_key_element()}=[{listed}]"
            values[key] = override.value()
        elif re.split(r"[./@]", key)[0] not in (*EVALUATION_KEYS, *EVALUATION_GROUPS):
            bad.append(override.input_line)
        elif override.is_sweep_override():
            sweeps.append(override.input_line)
    if bad:
        raise ConfigError(f"evaluate.py changes only {', '.join(EVALUATION_KEYS)} (and the config groups "
                          f"{', '.join(EVALUATION_GROUPS)}); got {', '.join(bad)} (a training change needs hierloco "
                          "train and another run_dir)")
    run_dir, name = (None if values.get(key) is None else str(values[key]) for key in ("run_dir", "name"))
    if name is not None:
        check_name(name)
        if sweeps:
            raise ConfigError(f"name= names one evaluation; a sweep ({', '.join(sweeps)}) names each by its "
                              "overrides")
    return arguments, run_dir, name


def trained_config(run_dir: str):
    """The trained run's ``config.yaml`` (a :class:`~omegaconf.DictConfig`), read as a received file: safely first
    (:func:`hierloco.io.load_yaml`: no YAML bomb reaches OmegaConf or Hydra), a mapping of settings that configures
    neither Hydra (its ``hydra`` section would name code to run) nor this command."""
    from omegaconf import OmegaConf

    from hierloco.io import load_yaml

    config = Path(run_dir) / "config.yaml"
    if not config.is_file():
        raise ConfigError(f"{run_dir} has no config.yaml: it is not a finished training run (run hierloco train "
                          "first)")
    value = load_yaml(config)  # an ArtifactError naming the file: one line
    if not isinstance(value, dict):
        raise ConfigError(f"{config}: a run's config is a mapping of settings, not {type(value).__name__}")
    foreign = [key for key in ("hydra", "defaults", "name", "trust_imports") if key in value]
    if foreign:
        raise ConfigError(f"{config} sets {', '.join(foreign)}: a run's config configures neither Hydra nor "
                          "hierloco evaluate")
    try:
        return OmegaConf.load(config)  # Hydra's own reading of the same (checked) text, as recipes save it
    except Exception as error:  # noqa: BLE001  (what the safe reading let through but OmegaConf refuses): one line
        raise ConfigError(f"{config}: {one_line(error)}") from None


def store_trained_config(run_dir: str | None) -> None:
    """Gives Hydra the run's config as the option ``run`` of the config group ``trained_run`` (``evaluate.yaml``'s
    first default); empty without a run (``hierloco evaluate --cfg job``)."""
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    node = trained_config(run_dir) if run_dir is not None else OmegaConf.create({})
    ConfigStore.instance().store(group=TRAINED_GROUP, name="run", node=node)


def check_import_paths_given(cfg, overrides: list[str], run_dir: str, trusted=()) -> None:
    """Refuses, in one line, the import paths of the evaluation config ``cfg`` that come from the run's own
    ``config.yaml``, not from the command line (its ``overrides`` or ``trusted``, its ``trust_imports=``): a
    received file never names code to import."""
    from hierloco.pipeline.config import import_paths

    bad = [item for item in trusted if not IMPORT_PATH.fullmatch(item)]
    if bad:
        raise ConfigError(f"trust_imports lists {', '.join(bad)}: give import paths (package.module:Class)")
    unescaped = [re.sub(r"\\(.)", r"\1", override) for override in overrides]  # a sweep's job: os\:getcwd
    typed = {match.group(0) for override in unescaped for match in IMPORT_PATH.finditer(override)} | set(trusted)
    received = {dotted: path for dotted, path in import_paths(cfg).items() if path not in typed}
    if received:
        listed = " ".join(f"{dotted}={path}" for dotted, path in received.items())
        paths = ",".join(dict.fromkeys(received.values()))
        them = "them" if len(received) > 1 else "it"
        raise ConfigError(f"{Path(run_dir) / 'config.yaml'} names the import path{'s' if len(received) > 1 else ''} "
                          f"{listed}: code named by a run directory's files is never imported; if you trust {them}, "
                          f"add trust_imports={paths} to the command line, or choose a registered name")


def terrain_files(value, trail: str = "") -> dict[str, str]:
    """The terrain files a config names, ``dotted key -> path``: every ``terrain`` (the run's, ``eval.terrain``, a
    task's own) that is a file (``ground.png``, ``scene.xml``) or a mapping with a ``path``.

        >>> terrain_files({"terrain": {"name": "heightmap", "path": "g.png"}, "eval": {"terrain": "s.xml"}})
        {'terrain.path': 'g.png', 'eval.terrain': 's.xml'}
    """
    found = {}
    if isinstance(value, Mapping):
        for key, item in value.items():
            dotted = f"{trail}.{key}" if trail else str(key)
            if key == "terrain" and isinstance(item, str) and os.path.splitext(item)[1].lower() in (".png", ".xml"):
                found[dotted] = item
            elif key == "terrain" and isinstance(item, Mapping) and isinstance(item.get("path"), str):
                found[f"{dotted}.path"] = item["path"]
            else:
                found.update(terrain_files(item, dotted))
    return found


def check_terrain_files_given(cfg, overrides: list[str], run_dir: str) -> None:
    """Refuses, in one line, a terrain file that the run's own ``config.yaml`` names outside the run directory and
    the command line does not name again: a received run directory reads no file of this machine on its own word
    (a file inside the run directory, which came with it, is read)."""
    from omegaconf import OmegaConf

    typed = " ".join(overrides)
    root = Path(run_dir).resolve()
    received = {}
    for dotted, path in terrain_files(OmegaConf.to_container(cfg, resolve=False)).items():
        if path in typed:
            continue
        resolved = Path(os.path.expanduser(path)).resolve()
        if resolved != root and root not in resolved.parents:
            received[dotted] = path
    if received:
        listed = " ".join(f"{dotted}={path}" for dotted, path in received.items())
        raise ConfigError(f"{Path(run_dir) / 'config.yaml'} names the terrain file{'s' if len(received) > 1 else ''} "
                          f"{listed} outside the run directory: a run directory's files never name a file of this "
                          "machine to read; give it on the command line (the same override), or put the file in the "
                          "run directory")


def method_of(run_dir: str):
    """The :class:`hierloco.pipeline.methods.Method` that made ``run_dir`` (its ``run.json``)."""
    import json

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


def _trusted(value) -> list[str]:
    """``trust_imports`` as a list of strings (one path, or a list of them)."""
    from omegaconf import ListConfig

    if value is None:
        return []
    return [str(item) for item in (value if isinstance(value, (list, tuple, ListConfig)) else [value])]


def evaluate(cfg, overrides: list[str], folder: str | None = None) -> float:
    """Evaluates the trained run of the composed evaluation config ``cfg`` (the run's config with ``overrides``, the
    command line's, and this command's keys ``run_dir``, ``name``, ``trust_imports``) into
    ``<run_dir>/evaluations/<folder>/`` (``folder``: the job's name; default a digest of the evaluation config);
    returns the headline cost."""
    from omegaconf import OmegaConf, open_dict

    from hierloco.io import inside
    from hierloco.pipeline.rundir import digest

    run_dir = str(cfg.run_dir)
    trusted = _trusted(cfg.get("trust_imports"))
    with open_dict(cfg):  # the run's config as the recipe reads it: without this command's keys
        for key in COMMAND_KEYS[1:]:
            cfg.pop(key, None)
        cfg.run_dir = run_dir
    method = method_of(run_dir)
    check_import_paths_given(cfg, overrides, run_dir, trusted)
    check_terrain_files_given(cfg, overrides, run_dir)
    trained = trained_config(run_dir).get("device", "cpu")
    with open_dict(cfg):
        if str(cfg.get("device")) != str(trained):  # evaluated elsewhere: the trained stages keep their keys
            cfg.trained_device = trained
    label = check_name(folder) if folder is not None else digest(OmegaConf.to_container(cfg, resolve=True))[:8]
    return method.main().run(cfg, evaluation_out=inside(run_dir, f"evaluations/{label}"))


def evaluation_job(cfg) -> float:
    """One evaluation, a Hydra job (a sweep's jobs may run in a launcher's worker processes): a single run goes to
    ``evaluations/<name or digest>/``, a sweep's job to ``evaluations/<its override dirname>/``
    (:func:`evaluation_folder`, the folder Hydra made for the job). A user's error is one line and exit status 2."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from hierloco.pipeline.entry import one_line_errors

    hydra_cfg = HydraConfig.get()
    folder = None if cfg.get("name") is None else str(cfg.name)
    if hydra_cfg.mode == RunMode.MULTIRUN:
        folder = evaluation_folder(folder, hydra_cfg.job.override_dirname)
    with one_line_errors():
        return evaluate(cfg, list(hydra_cfg.overrides.task), folder)


def help_text() -> str:
    """``hierloco evaluate --help``: what it does (``evaluate.yaml``'s opening comment), how to call it, the config
    groups an evaluation may choose and the keys it may change."""
    from hierloco.pipeline.entry import config_groups

    lines = (conf_folder() / f"{CONFIG_NAME}.yaml").read_text().splitlines()
    about = [line.lstrip("# ").rstrip() for line in lines[:next(i for i, line in enumerate(lines)
                                                                 if not line.startswith("#"))]]
    groups = {group: options for group, options in config_groups(conf_folder()).items() if group in EVALUATION_GROUPS}
    text = [f"hierloco evaluate: {about[0]}", *about[1:], "", USAGE,
            "  (Hydra's override grammar; -m sweeps over comma-separated values, each job's folder named by its "
            "overrides;", "   hydra/launcher=joblib runs them in parallel; --cfg job prints the composed config, "
            "--info how it was composed)", "", f"keys it may change: {', '.join(EVALUATION_KEYS)}", "",
            "config groups (group=option):", *[f"  {group}: {', '.join(options)}" for group, options in groups.items()]]
    return "\n".join(text) + "\n\nconfig (key=value overrides any of it):\n"


def run_app(arguments: list[str]) -> None:
    """Runs the Hydra app (``evaluate.yaml`` over the stored run config, :func:`evaluation_job`) on ``arguments``."""
    import hydra

    app = hydra.main(config_path=str(conf_folder()), config_name=CONFIG_NAME, version_base=None)(evaluation_job)
    saved = sys.argv
    sys.argv = [saved[0] if saved else "hierloco evaluate", *arguments]
    try:
        app()
    finally:
        sys.argv = saved


def evaluate_main(arguments: list[str] | None = None) -> None:
    """The command line of ``hierloco evaluate`` (and ``recipes/evaluate.py``); exits 2 on a user error, printing
    one line, before any work."""
    from hydra.errors import HydraException

    from hierloco.io import inside
    from hierloco.pipeline.entry import information_only, one_line_errors, report_error, sigterm_as_interrupt

    os.environ.setdefault("HYDRA_FULL_ERROR", "1")  # Hydra raises its own errors; they are reported here
    sigterm_as_interrupt()
    arguments = list(sys.argv[1:] if arguments is None else arguments)
    try:
        with one_line_errors():
            arguments, run_dir, _ = read_command_line(arguments)
            if "--help" in arguments or "-h" in arguments:
                print(help_text(), end="")
                arguments = ["--cfg", "job", *[a for a in arguments if a not in ("--help", "-h")]]
            elif not information_only(arguments):
                if run_dir is None:
                    raise ConfigError(f"give the trained run: run_dir=... ({USAGE})")
                method_of(run_dir)
                inside(run_dir, "evaluations/multirun.yaml")  # where a sweep writes: never through a link
            store_trained_config(run_dir)
            run_app(arguments)
    except KeyboardInterrupt:
        print("interrupted: finished evaluations are kept; run the same command again to resume", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    except HydraException as error:  # a bad override, an unknown config group option
        report_error(error)
        sys.exit(EXIT_USER_ERROR)


__all__ = ["EVALUATION_GROUPS", "EVALUATION_KEYS", "evaluate", "evaluate_main", "evaluation_folder", "evaluation_job",
           "trained_config"]
