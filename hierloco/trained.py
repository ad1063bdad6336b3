"""Trained runs: assemble the parts of the hierarchy (low level, world model, planner) from a run's artifacts.

:func:`load_run` opens a run directory written by a recipe (``recipes/<method>/train.py``) and gives, for new
research code, the trained low level, the learned CoM world model of a setting and an MPC planner over it, without
running any recipe code. :func:`make_world_model` is the factory the recipes use too.

Example:
    >>> from hierloco.envs import GoalReaching
    >>> run = load_run("outputs/lat/paper/a1_seed0")   # a trained run's folder
    >>> low_level = run.low_level()                    # pi(., z), for any number of robots
    >>> planner = run.planner(GoalReaching())          # random shooting over z with the learned model

A run trained on any device loads on any other (checkpoints are read onto the CPU, then moved):
``load_run(path, device="cuda")`` gives parts whose networks and planning run on the GPU (``docs/gpu.md``).

A run directory may come from someone else, so its files are data: every artifact is read from inside it
(:func:`hierloco.io.inside`), and a part its ``run.json`` or checkpoints select is a registered name. An import path
there (``low_level.kind: "pkg.module:Class"``) is imported only when the caller names it too:
``load_run(path, trust_imports=["pkg.module:Class"])`` (``docs/pipeline.md``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hierloco.io import ArtifactError, check_schema, inside
from hierloco.registry import is_import_path

MANIFEST = "run.json"
BODY_CONTEXT = {"body_state": 3}  # roll, pitch (rad), height above the ground (m): LatentActionEnv's body_state


def make_world_model(model, low_level, *, task=None, device: str = "cpu"):
    """The :class:`~hierloco.envs.world_model.CoMWorldModelEnv` of a trained CoM ``model`` (a
    :class:`~hierloco.components.com_model.TrainedCoMModel`, or its :class:`~hierloco.components.com_model.CoMModel`)
    over ``low_level``'s action space (a box, or a finite set of choices with the low level's action features); a
    model trained on state keys beside the action (its metadata's ``context``, e.g. ``body_state``) reads them."""
    from hierloco.envs.world_model import CoMWorldModelEnv

    context = dict(getattr(model, "metadata", {}).get("context") or {})
    if any(BODY_CONTEXT.get(key) != size for key, size in context.items()):  # a checkpoint is data: read, not trusted
        raise ArtifactError(f"its CoM model reads {context} beside the action: not a state the latent-action env "
                            f"reports ({BODY_CONTEXT})")
    net = getattr(model, "model", model).to(device).eval()
    if low_level.num_choices is not None:
        return CoMWorldModelEnv(net, num_choices=low_level.num_choices, action_features=low_level.action_features,
                                task=task, device=device, context=context)
    return CoMWorldModelEnv(net, action_low=low_level.action_low, action_high=low_level.action_high,
                            action_features=low_level.action_features, task=task, device=device, context=context)


@dataclass
class TrainedRun:
    """The trained parts of a run directory. Build them with :meth:`low_level`, :meth:`world_model`,
    :meth:`planner`; ``manifest`` is what the recipe recorded (method, robot, settings, planner, ...); ``device``
    is where their networks run unless a call names another."""

    path: Path
    manifest: dict
    _cache: dict = field(default_factory=dict, repr=False)
    device: str = "cpu"
    trust_imports: frozenset = frozenset()

    def _part(self, registry, name, field: str, base: type):
        """The class ``registry`` holds under ``name``, read from the run's ``field``: a registered name, or an import
        path the caller trusts (:func:`load_run`'s ``trust_imports``); anything else is an :class:`ArtifactError`."""
        if is_import_path(name) and name not in registry:
            if name not in self.trust_imports:
                raise ArtifactError(f"{self.path / MANIFEST}: {field} {name!r} is an import path read from the run's "
                                    f"own files, which are never run as code; if you trust it, name it yourself: "
                                    f"load_run(..., trust_imports=[{name!r}])")
            try:
                return registry.import_path(name, base=base)
            except ValueError as error:
                raise ArtifactError(f"{self.path / MANIFEST}: {field}: {error}") from None
        try:
            return registry[name]
        except ValueError as error:
            raise ArtifactError(f"{self.path / MANIFEST}: {error}") from None

    def _device(self, device) -> str:
        from hierloco.devices import resolve_device

        return resolve_device(self.device if device is None else device)

    @property
    def method(self) -> str:
        return self.manifest["method"]

    @property
    def robot(self):
        from hierloco.envs.robots import get_robot
        from hierloco.envs.robots.profiles import with_profile

        return with_profile(get_robot(self.manifest["robot"]), self.manifest.get("robot_profile", "own"))

    @property
    def settings(self) -> list[str]:
        return list(self.manifest["settings"])

    def artifact(self, name: str) -> Path:
        """The path of the run's artifact ``name`` (e.g. ``gait_policy.pt``); raises when the run lacks it."""
        path = inside(self.path, name)
        if not path.exists():
            raise ArtifactError(f"{self.path} has no {name}: the {self.method} run did not finish that stage")
        return path

    def low_level(self, num_robots: int = 1, device: str | None = None):
        """The trained low level (LAT and SAC: ``pi(., z)``; LIB: expert replay; IK: the expert controller for
        ``num_robots`` robots; SAC-SAC: the SAC velocity policy), rebuilt by its class in the low-level registry
        (:data:`hierloco.envs.low_level.LOW_LEVELS`) from the options the run recorded."""
        from hierloco.envs.low_level import LOW_LEVELS, LowLevel

        spec = self.manifest["low_level"]
        cls = self._part(LOW_LEVELS, spec["kind"], "low_level.kind", LowLevel)
        return cls.from_run(self, num_robots=num_robots, device=self._device(device), **spec.get("options", {}))

    def com_model(self, setting: str = "normal", device: str | None = None):
        """The trained :class:`~hierloco.components.com_model.TrainedCoMModel` of ``setting``, its model on
        ``device`` (default the run's): the class its checkpoint names (a model named by import path only when
        ``trust_imports`` lists it), built with the options it was trained with."""
        from hierloco.components.com_model import TrainedCoMModel

        if setting not in self.settings:
            raise ValueError(f"{self.path} was trained for settings {self.settings}, not {setting!r}")
        trained = TrainedCoMModel.load(self.artifact(f"dynamics_model_{setting}.pt"), trust_imports=self.trust_imports)
        trained.model.to(self._device(device))
        return trained

    def world_model(self, setting: str = "normal", task=None, device: str | None = None):
        """The learned CoM world model env of ``setting``, scoring with ``task`` (a :class:`hierloco.envs.Task`)."""
        device = self._device(device)
        return make_world_model(self.com_model(setting), self.low_level(device=device), task=task, device=device)

    def dynamics_data(self, setting: str = "normal"):
        """The CoM dynamics data of ``setting`` (a :class:`~hierloco.components.dynamics_data.TransitionData`:
        ``com_state``, ``action``, ``next_com_state``, ``M x 5`` / ``M x A`` / ``M x 5``), e.g. to train another
        model on it: ``train_com_model(d.com_state, run.low_level().action_features(d.action), d.next_com_state,
        model="ensemble")``."""
        from hierloco.components.dynamics_data import TransitionData

        if setting not in self.settings:
            raise ValueError(f"{self.path} was trained for settings {self.settings}, not {setting!r}")
        return TransitionData.load(self.artifact(f"dynamics_data_{setting}.npz"))

    def planner(self, task=None, setting: str = "normal", device: str | None = None, *, model=None, cost=None,
                risk: str | None = None, beta: float | None = None, **overrides):
        """The run's MPC planner (its recorded settings, changed by ``overrides``) over :meth:`world_model`.

        Args:
            task: the task planned for (its cost, unless ``cost`` is given; :meth:`begin_task` changes it).
            model: plan with this CoM model instead of the run's (a :class:`~hierloco.components.com_model.
                TrainedCoMModel` or a model with ``predict``, e.g. an ensemble trained on :meth:`dynamics_data`).
            cost: a cost callable ``(com_state, next_com_state, action, info)`` used instead of the task's
                (:class:`~hierloco.envs.world_model.CoMWorldModelEnv`).
            risk, beta: how a model with members scores a plan (``none``, ``mean_std`` with ``beta``,
                ``pessimistic``); default the run's ``planner.risk`` and ``planner.beta``, else ``none``.
        """
        from hierloco.components.planners import PLANNERS, BoxPlannerBase, make_planner

        device = self._device(device)
        options = {**self.manifest["planner"], **overrides}
        name = options.get("name", "random_shooting")
        if "name" in overrides and is_import_path(name):  # named by the caller's own code
            PLANNERS.import_path(name, base=BoxPlannerBase)
        elif "name" not in overrides:
            self._part(PLANNERS, name, "planner.name", BoxPlannerBase)
        risk = options.pop("risk", "none") if risk is None else risk
        beta = options.pop("beta", 1.0) if beta is None else beta
        model = self.com_model(setting) if model is None else model
        world_model = make_world_model(model, self.low_level(device=device), task=task,
                                       device=device)
        world_model.set_cost(cost)
        world_model.set_risk(risk, beta)
        return make_planner(world_model, seed=self.manifest["seed"], **options)


def fetch_wandb_run(reference: str) -> Path:
    """Downloads the ``hierloco-run`` artifact ``wandb:<entity>/<project>/<name>:<version>`` (logged by every
    recipe run with the wandb backend) and returns its folder; needs wandb and its server."""
    try:
        import wandb
    except ImportError:
        raise ArtifactError(f"{reference}: loading a run from wandb needs wandb installed") from None
    name = reference.removeprefix("wandb:")
    try:
        artifact = wandb.Api(timeout=10).artifact(name, type="hierloco-run")
        return Path(artifact.download())
    except Exception as error:  # noqa: BLE001  (no network, no login, no such artifact: one line)
        raise ArtifactError(f"cannot fetch the wandb artifact {name}: {' '.join(str(error).split())[:200]}") from None


def load_run(run_dir: str | os.PathLike, device: str = "cpu", *, trust_imports=()) -> TrainedRun:
    """Opens the run directory of a finished (or partly finished) model-based recipe run (LAT, LIB, IK), or a run
    logged to wandb (``"wandb:<entity>/<project>/<run>-run:<version>"``: its checkpoints artifact). Its parts run on
    ``device`` (``cpu``, ``cuda``, ``auto``: :func:`hierloco.devices.resolve_device`), whatever it was trained on.

    The run's files select its parts by registered name; ``trust_imports`` lists the import paths
    (``"pkg.module:Class"``) they may name instead, which are then imported (a class of the right kind, or an
    :class:`ArtifactError`). Any other import path in them is refused: a run directory may come from someone else."""
    from hierloco.devices import resolve_device

    device = resolve_device(device)  # a device that cannot be used here: ValueError, before any file is read
    if isinstance(trust_imports, str) or not all(is_import_path(item) for item in trust_imports):
        raise ValueError(f"trust_imports must list import paths ('pkg.module:Class'), got {trust_imports!r}")
    if isinstance(run_dir, str) and run_dir.startswith("wandb:"):
        run_dir = fetch_wandb_run(run_dir)
    path = Path(run_dir)
    manifest_path = inside(path, MANIFEST)
    if not manifest_path.exists():
        raise ArtifactError(f"{path} is not a hierloco run directory (no {MANIFEST}); run a recipe into it first")
    try:
        manifest: Any = json.loads(manifest_path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ArtifactError(f"corrupted run manifest {manifest_path}: {error}") from error
    check_schema(manifest, {"method": str, "robot": str, "seed": int, "settings": list, "planner": dict,
                            "low_level": {"kind": str}}, f"corrupted run manifest {manifest_path}")
    return TrainedRun(path, manifest, device=device, trust_imports=frozenset(trust_imports))
