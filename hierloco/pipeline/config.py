"""Config checks of the recipes: the whole config is read and checked before any work, task options included.

:func:`prepare` normalises what users type (``settings=normal`` is the one-item list ``[normal]``) and collects every
problem into one :class:`ConfigError`; recipes add their own checks through ``extra``. Only recipe code reads the
config: the library takes keyword arguments.

The import paths a config names (``planner.name=my_pkg.planning:MyPlanner``, a task's ``task: my_pkg.tasks:Patrol``,
``dynamics.model=...``; :func:`import_paths`) are imported by the check (:func:`check_import_paths`), each refused in
one line unless it is a class of its kind; nothing else imports them. The config checked is the user's own:
``recipes/evaluate.py`` first refuses the import paths of a received run's ``config.yaml`` that its command line does
not give again (``docs/pipeline.md``).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Iterable

from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict

from hierloco.envs.faults import SETTINGS, physical_setting  # normal, the fault models, the hardware robot
from hierloco.pipeline.errors import ConfigError
from hierloco.registry import is_import_path

LIST_OPTIONS = ("settings", "eval.videos", "logger.backends")


def section(cfg: DictConfig, name: str) -> dict:
    return OmegaConf.to_container(cfg[name], resolve=True)


def get(cfg: DictConfig, dotted: str, default: Any = None) -> Any:
    return OmegaConf.select(cfg, dotted, default=default)


def as_lists(cfg: DictConfig, options: Iterable[str]) -> None:
    """A list option given a scalar (``settings=normal``) becomes a one-item list; ``null`` stays ``null``."""
    with open_dict(cfg):
        for dotted in options:
            value = OmegaConf.select(cfg, dotted)
            if value is not None and not isinstance(value, ListConfig):
                OmegaConf.update(cfg, dotted, [value], merge=False)


# ---------------------------------------------------------------------------------------------------- values
def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class Checker:
    """Collects problems about config values, each naming its key."""

    def __init__(self, cfg: DictConfig):
        self.cfg = cfg
        self.problems: list[str] = []

    def fail(self, message: str) -> None:
        self.problems.append(message)

    def integer(self, dotted: str, minimum: int = 1) -> None:
        value = get(self.cfg, dotted)
        if not (_is_int(value) and value >= minimum):
            self.fail(f"{dotted} must be an integer >= {minimum}, got {value!r}")

    def positive(self, dotted: str) -> None:
        value = get(self.cfg, dotted)
        if not (_is_number(value) and value > 0):
            self.fail(f"{dotted} must be a positive number, got {value!r}")

    def fraction(self, dotted: str) -> None:
        value = get(self.cfg, dotted)
        if not (_is_number(value) and 0 < value < 1):
            self.fail(f"{dotted} must be a number in (0, 1), got {value!r}")

    def choice(self, dotted: str, choices: Iterable[str], what: str) -> None:
        value = get(self.cfg, dotted)
        choices = tuple(choices)
        if value not in choices:
            self.fail(f"unknown {what} {value!r} ({dotted}: choose from {', '.join(choices)})")

    def raise_if_any(self) -> None:
        if self.problems:
            raise ConfigError("bad config: " + "; ".join(self.problems))


# ---------------------------------------------------------------------------------------------------- tasks
def task_specs(cfg) -> dict:
    """Task name -> its spec (``task`` type and options): the main tasks (``eval.tasks``), then the generalisation
    ones (``eval.generalization``)."""
    specs = {}
    for group in ("tasks", "generalization"):
        entries = cfg.eval.get(group)
        for name, spec in (OmegaConf.to_container(entries, resolve=True) if entries is not None else {}).items():
            specs[name] = dict(spec or {})
    return specs


def make_task_from_spec(name: str, spec: dict):
    """The task ``name`` of the ``eval`` section: ``spec`` holds its type (``task``: a name in the task registry
    :data:`hierloco.envs.tasks.TASKS`, or ``package.module:Class``; default the name) and options; ``split: train``
    gives its training split instead (:meth:`hierloco.envs.tasks.Task.training_split`: the half of the targets a
    baseline is trained or tuned on), named ``<name>_train``. The world the task is evaluated in (its own
    ``terrain``, ``pushes``, ``randomization``: :data:`WORLD_KEYS`) is not the task's: :func:`world` reads it.

    Unknown options and bad values raise :class:`ConfigError` naming the task, the option and the valid ones."""
    from hierloco.envs.tasks import make_task

    options = {key: value for key, value in (spec or {}).items() if key not in WORLD_KEYS}  # the world: world()
    kind = options.pop("task", name)
    split = options.pop("split", "all")
    if split not in ("all", "train"):
        raise ConfigError(f"bad config: eval task {name!r}: split must be all or train, got {split!r}")
    try:
        task = make_task(kind, **{"name": name, **options})
    except (TypeError, ValueError) as error:
        raise ConfigError(f"bad config: eval task {name!r}: {error}") from None
    return task.training_split() if split == "train" else task


# ---------------------------------------------------------------------------------------------------- the world
# The ground, pushes on the trunk and randomised dynamics (docs/terrain.md). ``terrain`` and ``randomization`` (config
# groups: recipes/conf/terrain, recipes/conf/randomization) are the world of the whole run: its dynamics data, its
# SAC training and its evaluations. ``eval.terrain``, ``eval.pushes`` and ``eval.randomization`` set the evaluations'
# world alone (what ``hierloco evaluate`` may change), and an evaluation task's own ``terrain``, ``pushes`` and
# ``randomization`` (options beside its type) set its own. Flat ground, no pushes and nominal dynamics are keyed as
# nothing: every stage key is then what it was before the world had options.
WORLD_KEYS = ("terrain", "pushes", "randomization")
WORLD_PARTS = ("data", "training", "evaluation")  # dynamics data, SAC training (high and low level), evaluations
# The "hardware" robot's own world (``hardware_world.terrain``, ``hardware_world.randomization``): the ground it walks
# on and how its dynamics vary, for the settings that simulate it (``hardware``, ``hardware_unadapted``: its dynamics
# data and its evaluations) and for no other, so that the nominal robot stays in the simulation's world while the
# "hardware" one meets what a lab floor adds (Li et al., Sec. IV-D; docs/terrain.md, "The hardware gap").
HARDWARE_WORLD_KEYS = ("terrain", "randomization")


def _plain(value):
    return OmegaConf.to_container(value, resolve=True) if isinstance(value, (DictConfig, ListConfig)) else value


def world_spec(cfg, part: str, task: dict | None = None, setting: str | None = None) -> dict:
    """What the config gives for the world of ``part`` (one of :data:`WORLD_PARTS`; for ``evaluation``, of the task
    whose spec is ``task``; in ``setting``, where it is given): ``{"terrain": ..., "pushes": ..., "randomization":
    ...}`` as typed (``None``: the default). Pushes are an evaluation's only. In a setting that simulates the
    "hardware" robot, ``hardware_world.*`` (:data:`HARDWARE_WORLD_KEYS`) comes last: the ground under that robot is
    its own. A config without these sections (a run made before them) is flat, without pushes, with nominal
    dynamics."""
    if part not in WORLD_PARTS:
        raise ValueError(f"part must be one of {WORLD_PARTS}, got {part!r}")
    spec = {"terrain": _plain(get(cfg, "terrain")), "pushes": None,
            "randomization": _plain(get(cfg, "randomization"))}
    if part == "evaluation":
        for key in WORLD_KEYS:
            for source in (get(cfg, f"eval.{key}"), (task or {}).get(key)):
                if source is not None:
                    spec[key] = _plain(source)
    if setting is not None and physical_setting(setting) == "hardware":
        for key in HARDWARE_WORLD_KEYS:
            if get(cfg, f"hardware_world.{key}") is not None:
                spec[key] = _plain(get(cfg, f"hardware_world.{key}"))
    return spec


class World:
    """The world a simulation runs in: a built :class:`~hierloco.envs.terrain.Terrain`,
    :class:`~hierloco.envs.terrain.Pushes` and :class:`~hierloco.envs.terrain.DynamicsRandomization`
    (:func:`make_world`). ``params()`` is what a stage key holds of it (``{}`` for the default world); ``options()``
    the keyword arguments of the simulators (``BatchedSimulator``, ``LatentActionEnv``)."""

    def __init__(self, terrain, pushes, randomization):
        self.terrain, self.pushes, self.randomization = terrain, pushes, randomization

    def params(self) -> dict:
        keys = {"terrain": self.terrain.key(), "pushes": self.pushes.key(), "randomization": self.randomization.key()}
        return {name: key for name, key in keys.items() if key}

    def options(self) -> dict:
        return {"terrain": self.terrain, "pushes": self.pushes, "randomization": self.randomization}

    @property
    def is_default(self) -> bool:
        return not self.params()

    def describe(self) -> str:
        """One line: ``"rough (difficulty=0.5, seed=1); pushes 0.5 m/s; randomised dynamics"``."""
        parts = [self.terrain.describe()]
        if self.pushes.active:
            parts.append(f"pushes {self.pushes.magnitude_mps:g} m/s every {self.pushes.interval_s[0]:g}-"
                         f"{self.pushes.interval_s[1]:g} s")
        if self.randomization.active:
            parts.append("randomised dynamics (" + ", ".join(self.randomization.key()) + ")")
        return "; ".join(parts)


def make_world(spec: dict) -> World:
    """The :class:`World` of a :func:`world_spec`; a bad option or terrain file raises
    :class:`hierloco.envs.terrain.TerrainError` (one line)."""
    from hierloco.envs.terrain import make_pushes, make_randomization, make_terrain

    return World(make_terrain(spec.get("terrain")), make_pushes(spec.get("pushes")),
                 make_randomization(spec.get("randomization")))


def world(cfg, part: str, task_name: str | None = None, setting: str | None = None) -> World:
    """The :class:`World` of ``part`` in ``cfg`` (for ``evaluation``, of the evaluation task ``task_name``; in
    ``setting``: :func:`world_spec`); a bad one is a :class:`ConfigError` (checked before any work by
    :func:`check_world`)."""
    from hierloco.envs.terrain import TerrainError

    task = task_specs(cfg).get(task_name) if task_name is not None else None
    try:
        return make_world(world_spec(cfg, part, task, setting))
    except TerrainError as error:
        raise ConfigError(f"bad config: {error}") from None


def check_world(c: Checker) -> None:
    """``terrain``, ``randomization``, ``eval.terrain``, ``eval.pushes``, ``eval.randomization`` and every
    evaluation task's own: each built once (a terrain file read and parsed), each problem one line naming where."""
    from hierloco.envs.terrain import TerrainError, make_pushes, make_randomization, make_terrain

    makers = {"terrain": make_terrain, "pushes": make_pushes, "randomization": make_randomization}
    given = [("", key, get(c.cfg, key)) for key in ("terrain", "randomization")]
    given += [("eval.", key, get(c.cfg, f"eval.{key}")) for key in WORLD_KEYS]
    given += [("hardware_world.", key, get(c.cfg, f"hardware_world.{key}")) for key in HARDWARE_WORLD_KEYS]
    try:
        specs = task_specs(c.cfg)
    except Exception:  # noqa: BLE001  (a malformed eval section: check_eval says why)
        specs = {}
    given += [(f"eval task {name!r}: ", key, spec[key]) for name, spec in specs.items() if isinstance(spec, dict)
              for key in WORLD_KEYS if spec.get(key) is not None]
    for where, key, value in given:
        if value is None:
            continue
        try:
            makers[key](_plain(value))
        except TerrainError as error:
            text = str(error)
            if where.endswith("."):  # "eval.terrain 'rough': ...", "eval.pushes: ..."
                c.fail(f"{where}{text}" if text.startswith(key) else f"{where}{key}: {text}")
            else:
                c.fail(f"{where}{text}" if where or text.startswith(key) else f"{key}: {text}")


# ---------------------------------------------------------------------------------------------------- recipes
QUALITY_BARS = {"min_expert_reach": (False, "(0, 1]"), "min_reproduced_fraction": (True, "[0, 1]")}  # zero allowed?


def check_quality_bars(c: Checker) -> None:
    """The ``checks.*`` bars (``recipes/conf/checks``), if the recipe has them: fractions, ``0`` allowed
    only where it means "report, do not stop"."""
    for key, (zero, interval) in QUALITY_BARS.items():
        value = get(c.cfg, f"checks.{key}", None)
        if value is None:
            continue
        if not (_is_number(value) and (0 <= value if zero else 0 < value) and value <= 1):
            c.fail(f"checks.{key} must be a number in {interval}, got {value!r}")


def check_common(c: Checker, robot_checks: bool = True) -> Any:
    """Seed, device, threads, settings, robot; returns the robot description (or ``None`` when it is bad)."""
    from hierloco.devices import device_problem
    from hierloco.envs.robots import get_robot

    cfg = c.cfg
    c.integer("seed", minimum=0)
    problem = device_problem(get(cfg, "device"))
    if problem is not None:
        c.fail(problem)
    if get(cfg, "nthread") is not None:
        c.integer("nthread")
    settings = list(get(cfg, "settings") or [])
    if not settings:
        c.fail("settings is empty (give normal and/or legs_disabled)")
    for setting in settings:
        if setting not in SETTINGS:
            c.fail(f"unknown setting {setting!r} (settings: {', '.join(SETTINGS)})")
    if len(set(settings)) != len(settings):
        c.fail(f"settings {settings} lists a setting twice")
    check_quality_bars(c)
    robot = None
    if robot_checks:
        from hierloco.envs.robots.profiles import with_profile

        try:
            robot = with_profile(get_robot(cfg.robot), get(cfg, "robot_profile", "own"))
        except (ValueError, FileNotFoundError, OSError) as error:
            c.fail(str(error))
    hardware = get(cfg, "hardware")
    if hardware is not None and not isinstance(hardware, DictConfig):
        c.fail(f"hardware must map perturbation options to values (e.g. hardware.servo_latency=0.03), got {hardware!r}")
    elif any(s in SETTINGS and physical_setting(s) == "hardware" for s in settings):
        from hierloco.envs.faults import setting_robot

        try:
            options = OmegaConf.to_container(hardware, resolve=True) if hardware is not None else {}
            if robot is not None:
                setting_robot(robot, "hardware", options)
            else:
                from hierloco.envs.robots import hardware_options

                hardware_options(**options)
        except (ValueError, TypeError) as error:
            c.fail(f"hardware: {error}")
    elif hardware is not None and len(hardware):
        c.fail("hardware.* options are given but no setting simulates the hardware robot (settings=[...,hardware])")
    hardware_world = get(cfg, "hardware_world")
    if hardware_world is not None and not isinstance(hardware_world, DictConfig):
        c.fail(f"hardware_world must map {' and '.join(HARDWARE_WORLD_KEYS)} to a world, got {hardware_world!r}")
    elif hardware_world is not None:
        unknown = sorted(set(hardware_world) - set(HARDWARE_WORLD_KEYS))
        if unknown:
            c.fail(f"hardware_world: unknown option(s) {', '.join(map(repr, unknown))} (options: "
                   f"{', '.join(HARDWARE_WORLD_KEYS)})")
        if any(hardware_world.get(k) is not None for k in HARDWARE_WORLD_KEYS) and not any(
                s in SETTINGS and physical_setting(s) == "hardware" for s in settings):
            c.fail("hardware_world.* is given but no setting simulates the hardware robot (settings=[...,hardware])")
    check_world(c)
    return robot


def check_experts(c: Checker, robot, *, library: bool = True) -> None:
    if library:
        c.integer("experts.num_experts")
        c.positive("experts.settle_time")
        if not isinstance(get(c.cfg, "experts.tune", False), bool):
            c.fail(f"experts.tune must be true or false, got {get(c.cfg, 'experts.tune')!r}")
        if get(c.cfg, "experts.tune_budget") is not None:
            c.positive("experts.tune_budget")
        swing = get(c.cfg, "experts.swing_height_m")
        if swing is not None and not (_is_number(swing) and 0 < swing < (robot.standing_height if robot else 1.0)):
            c.fail(f"experts.swing_height_m must be a foot lift in m, above 0 and below the robot's standing height "
                   f"{robot.standing_height if robot else 1.0:g} m, or null (the robot's), got {swing!r}")
        failed = get(c.cfg, "experts.max_failed_experts")
        if failed is not None and not (_is_int(failed) and failed >= 0):
            c.fail(f"experts.max_failed_experts must be an integer >= 0 or null, got {failed!r}")
        gaits = get(c.cfg, "experts.gaits")
        if gaits is not None:
            if not isinstance(gaits, DictConfig):
                c.fail(f"experts.gaits must map gait names to gait groups (e.g. {{trot: [[FR, RL], [FL, RR]], pace: "
                       f"[[FR, RR], [FL, RL]]}}), got {gaits!r}")
            elif robot is not None:
                from hierloco.components.gaits import check_gaits

                for problem in check_gaits(robot, OmegaConf.to_container(gaits, resolve=True)):
                    c.fail(f"experts.gaits: {problem}")
        boxes = get(c.cfg, "experts.gait_boxes")
        if boxes is not None:
            if not isinstance(gaits, DictConfig):
                c.fail("experts.gait_boxes gives gaits of experts.gaits boxes of their own: set experts.gaits too")
            elif robot is not None:
                from hierloco.components.gaits import check_gait_boxes

                boxes = OmegaConf.to_container(boxes, resolve=True) if isinstance(boxes, DictConfig) else boxes
                for problem in check_gait_boxes(robot, OmegaConf.to_container(gaits, resolve=True), boxes):
                    c.fail(f"experts.{problem}")
            if get(c.cfg, "experts.tune", False):
                c.fail("experts.tune searches the robot's own gait's parameters: it does not combine with experts.gaits")
        box = {k: get(c.cfg, f"experts.{k}") for k in ("command_low", "command_high")}
        if robot is not None and any(v is not None for v in box.values()):
            from hierloco.components.expert_library import command_box

            try:
                command_box(robot, *(OmegaConf.to_container(v) if isinstance(v, ListConfig) else v
                                     for v in box.values()))
            except ValueError as error:
                c.fail(f"experts: {error}")
    c.integer("steps_per_action")
    steps = get(c.cfg, "steps_per_action")
    if robot is not None and _is_int(steps) and steps >= 1:
        from hierloco.envs.locomotion import periods_per_action

        try:
            periods_per_action(robot, steps)
        except ValueError as error:
            c.fail(str(error))


def check_policy(c: Checker) -> None:
    for key in ("policy.hidden", "policy.epochs", "policy.batch_size", "policy.num_harmonics"):
        c.integer(key)
    for key in ("policy.lr", "policy.latent_lr"):
        c.positive(key)
    decay = get(c.cfg, "policy.latent_weight_decay")
    if not (_is_number(decay) and decay >= 0):
        c.fail(f"policy.latent_weight_decay must be a number >= 0, got {decay!r}")
    dim = get(c.cfg, "policy.latent_dim")
    if not (_is_int(dim) and 1 <= dim <= 4):
        c.fail(f"policy.latent_dim must be 2, 3 or 4 (1 also works), got {dim!r}")
    if not isinstance(get(c.cfg, "policy.adaptive", False), bool):
        c.fail(f"policy.adaptive must be true or false, got {get(c.cfg, 'policy.adaptive')!r}")
    if get(c.cfg, "policy.budget_epochs") is not None:
        c.integer("policy.budget_epochs")


DYNAMICS_KEYS = ("num_transitions", "num_robots", "episode_length", "hidden", "lr", "batch_size", "holdout",
                 "patience", "max_epochs", "model", "body_state")


def check_dynamics(c: Checker) -> None:
    from hierloco.components.com_model import MIN_TRANSITIONS, MODELS

    name = get(c.cfg, "dynamics.model", "mlp")
    if is_import_path(name) and name not in MODELS:
        pass  # an import path that could not be imported: check_import_paths said why
    elif name not in MODELS:
        c.fail(f"unknown dynamics model {name!r} (dynamics.model: choose from {', '.join(MODELS.names())})")
    else:
        try:
            own = {k: v for k, v in section(c.cfg, "dynamics").items() if k not in DYNAMICS_KEYS}
            for problem in MODELS.check_options(name, own):
                c.fail(f"dynamics: {problem}")
        except ValueError as error:
            c.fail(f"dynamics: {error}")

    if not isinstance(get(c.cfg, "dynamics.body_state", False), bool):
        c.fail(f"dynamics.body_state must be true or false, got {get(c.cfg, 'dynamics.body_state')!r}")
    c.integer("dynamics.num_transitions", minimum=MIN_TRANSITIONS)
    for key in ("dynamics.num_robots", "dynamics.episode_length", "dynamics.hidden", "dynamics.batch_size",
                "dynamics.patience", "dynamics.max_epochs"):
        c.integer(key)
    c.positive("dynamics.lr")
    c.fraction("dynamics.holdout")


def check_planner(c: Checker, action_space: str = "box") -> None:
    """``planner.name`` from the planner registry (:data:`hierloco.components.planners.PLANNERS`) for this
    ``action_space`` (``box``: LAT's latents, IK's commands; ``finite``: LIB's experts), ``planner.horizon``, and
    every other key of the section an option of some registered planner, with a value like its default; the
    selected planner is built on a stand-in world model, so it checks its own values."""
    from hierloco.components.planners import PLANNERS, check_planner_options

    name = get(c.cfg, "planner.name")
    suitable = [n for n in PLANNERS.names() if action_space in PLANNERS[n].ACTION_SPACES]
    if is_import_path(name) and name not in PLANNERS:
        return  # an import path that could not be imported: check_import_paths said why
    if name not in suitable and not (name in PLANNERS and action_space in PLANNERS[name].ACTION_SPACES):
        c.fail(f"unknown planner {name!r} (planner.name: choose from {', '.join(suitable)})")
        return
    c.integer("planner.horizon")
    for problem in check_planner_options(name, section(c.cfg, "planner"), action_space=action_space):
        c.fail(problem)
    from hierloco.envs.world_model import RISKS

    risk = get(c.cfg, "planner.risk", "none")
    if risk not in RISKS:
        c.fail(f"unknown risk {risk!r} (planner.risk: choose from {', '.join(RISKS)})")
    elif risk != "none" and get(c.cfg, "dynamics.model", "mlp") == "mlp":
        c.fail(f"planner.risk={risk} weighs the disagreement of a model's members: it needs dynamics.model=ensemble")
    beta = get(c.cfg, "planner.beta", 1.0)
    if not (_is_number(beta) and beta >= 0):
        c.fail(f"planner.beta must be a number >= 0, got {beta!r}")


def check_eval(c: Checker, replan_period: int | None = None) -> dict:
    """Builds every evaluation task (so a misspelt option is caught now); returns name -> task. ``eval.replan_steps``
    (re-planning within an action, ``docs/terrain.md``) is checked against ``replan_period``, the control steps
    after which the recipe's low level may cut an action (``None``: whole actions only)."""
    from hierloco.envs.low_level import replan_problem
    from hierloco.envs.tasks import TASKS

    replan_steps = get(c.cfg, "eval.replan_steps")
    if replan_steps is not None:
        problem = replan_problem(replan_steps, get(c.cfg, "steps_per_action", 100), replan_period)
        if problem is not None:
            c.fail(f"eval.{problem}")

    tasks = {}
    try:
        specs = task_specs(c.cfg)
    except Exception as error:  # e.g. a scalar where a mapping belongs
        c.fail(f"eval.tasks / eval.generalization must map task names to options: {error}")
        return tasks
    if not get(c.cfg, "eval.tasks"):
        c.fail("eval.tasks is empty")
    for name, spec in specs.items():
        if not isinstance(spec, dict):
            c.fail(f"eval task {name!r} must be a mapping of options, got {spec!r}")
            continue
        if is_import_path(spec.get("task")) and spec["task"] not in TASKS:
            continue  # an import path that could not be imported: check_import_paths said why
        try:
            tasks[name] = make_task_from_spec(name, spec)
        except ConfigError as error:
            c.fail(str(error).removeprefix("bad config: "))
    for name in get(c.cfg, "eval.videos") or []:
        if name not in specs:
            c.fail(f"eval.videos names {name!r}, which is not an evaluated task ({', '.join(specs)})")
    continuity = get(c.cfg, "eval.latent_continuity")
    if continuity is not None:
        if not hasattr(continuity, "keys") or set(continuity) - {"grid", "num_actions"}:
            c.fail(f"eval.latent_continuity must be null or a mapping of grid and num_actions, got {continuity!r}")
        else:
            for name, least in (("grid", 2), ("num_actions", 2)):
                value = continuity.get(name, least)
                if not (isinstance(value, int) and not isinstance(value, bool) and value >= least):
                    c.fail(f"eval.latent_continuity.{name} must be an integer >= {least}, got {value!r}")
    if not isinstance(get(c.cfg, "eval.figures"), bool):
        c.fail(f"eval.figures must be true or false, got {get(c.cfg, 'eval.figures')!r}")
    return tasks


def check_logger(c: Checker) -> None:
    from hierloco.loggers import BACKENDS

    for backend in get(c.cfg, "logger.backends") or []:
        if backend not in BACKENDS:
            c.fail(f"unknown logger backend {backend!r} (backends: {', '.join(BACKENDS)})")
    c.choice("logger.wandb_mode", ("offline", "online"), "wandb mode")


def override_value(value) -> str:
    """``value`` (nested dicts, lists, numbers, plain words) as a Hydra override's value, in the order given:
    ``{trot: [[FR, RL], [FL, RR]]}``, ``[[0, 0.05], [0, 0.3]]``. What a study writes into its jobs' overrides.

        >>> override_value({"speed": {"task": "velocity_tracking", "velocities": [[0, 0.05]], "rounds": 1}})
        '{speed: {task: velocity_tracking, velocities: [[0, 0.05]], rounds: 1}}'
    """
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key}: {override_value(item)}" for key, item in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(override_value(item) for item in value) + "]"
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def compose_recipe(method: str, overrides: Iterable[str]) -> DictConfig:
    """``recipes/<method>/config.yaml`` with ``overrides``, composed as its ``train.py`` would compose it; callable
    inside another Hydra app (the study drivers): Hydra's global state is restored afterwards."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from hierloco.pipeline.methods import METHODS

    directory = METHODS[method].folder
    outer = GlobalHydra.instance().hydra if GlobalHydra.instance().is_initialized() else None
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(directory), version_base=None):
            return compose(config_name="config", overrides=list(overrides))
    finally:
        GlobalHydra.instance().clear()
        if outer is not None:
            GlobalHydra.instance().initialize(outer)


# ---------------------------------------------------------------------------------------------------- import paths
def import_paths(cfg) -> dict[str, str]:
    """Every import path (``package.module:Class``) that selects a part in ``cfg``: ``planner.name``,
    ``dynamics.model`` and the ``task`` of each evaluation task (``eval.tasks.<name>.task``,
    ``eval.generalization.<name>.task``), as dotted key -> path. Registered names are not listed."""
    found = {}
    for dotted in ("planner.name", "dynamics.model"):
        value = get(cfg, dotted)
        if is_import_path(value):
            found[dotted] = value
    for group in ("tasks", "generalization"):
        entries = get(cfg, f"eval.{group}")
        if isinstance(entries, DictConfig):
            for name, spec in entries.items():
                value = spec.get("task") if isinstance(spec, DictConfig) else None
                if is_import_path(value):
                    found[f"eval.{group}.{name}.task"] = value
    return found


def _registry_of(dotted: str):
    """The registry an import path at ``dotted`` (a key of :func:`import_paths`) selects from, and the class its
    parts derive from."""
    if dotted == "planner.name":
        from hierloco.components.planners import PLANNERS, BoxPlannerBase

        return PLANNERS, BoxPlannerBase
    if dotted == "dynamics.model":
        from hierloco.components.com_model import MODELS, CoMModel

        return MODELS, CoMModel
    from hierloco.envs.tasks import TASKS, Task

    return TASKS, Task


def check_import_paths(c: Checker) -> None:
    """Imports every import path of the config (:func:`import_paths`): each must name a class of its kind (a
    ``BoxPlannerBase`` subclass for ``planner.name``, a ``CoMModel`` for ``dynamics.model``, a ``Task`` for a task),
    or it is one problem naming the key (``planner.name=os:getcwd`` names a function, ``json:JSONDecoder`` a class
    that plans nothing). Once imported, the registries know them under their paths for the rest of the run."""
    for dotted, reference in import_paths(c.cfg).items():
        registry, base = _registry_of(dotted)
        try:
            registry.import_path(reference, base=base)
        except ValueError as error:
            c.fail(f"{dotted}: {error}")


def prepare(cfg: DictConfig, checks: Callable[[Checker, Any], None] | None = None, *,
            list_options: Iterable[str] = LIST_OPTIONS) -> Any:
    """Normalises ``cfg`` in place and checks it all (common parts, the import paths it names, then the recipe's
    ``checks(checker, robot)``); raises one :class:`ConfigError` naming every problem. Returns the robot
    description."""
    as_lists(cfg, list_options)
    c = Checker(cfg)
    robot = check_common(c)
    check_import_paths(c)
    if checks is not None:
        checks(c, robot)
    c.raise_if_any()
    resolve_devices(cfg)
    return robot


def resolve_devices(cfg: DictConfig) -> None:
    """``device=auto`` becomes the device it names here (``cuda`` with a GPU, else ``cpu``: what stage keys record,
    so a CPU machine's keys hold ``"cpu"`` as they always did; :func:`hierloco.devices.resolve_device`)."""
    from hierloco.devices import resolve_device

    if get(cfg, "device") is not None:
        with open_dict(cfg):
            cfg.device = resolve_device(cfg.device)
