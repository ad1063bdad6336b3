"""The CoM dynamics model: a delta model in the robot's local frame over one latent action (Li et al., RA-L 2021,
Sec. III-C).

The CoM state is ``(x, y, yaw, vx, vy)`` in the world frame (m, rad, m/s). Over one action ``a`` (a latent z, an
expert index as a float or a velocity command: any ``A``-vector) the model predicts

    ``(dx, dy, dyaw, vx', vy') = f(vx, vy, a)``

with every quantity in the local frame of the robot at the START of the action: ``(vx, vy)`` the current velocity,
``(dx, dy)`` the displacement, ``dyaw`` the yaw change wrapped to (-pi, pi] (so one action turns by less than half
a turn), and ``(vx', vy')`` the next velocity, still in the start frame. The prediction does not depend on the
position or heading, which makes it the same everywhere in the world. :func:`local_transition` turns world-frame
state pairs into training pairs and :func:`apply_delta` turns a prediction back into a world-frame next state.

The network is a :class:`torchrl.modules.MLP` with 2 hidden layers of 512 ReLU units on standardised inputs
predicting standardised outputs; the statistics are buffers, so the module maps physical units to physical units.
:func:`train_com_model` fits it by MSE on the standardised outputs with Adam, holds out a seeded random 10 % and
stops early on the held-out loss.

Models are a registry, :data:`MODELS` (``dynamics_model``): the MLP above is ``mlp``, the probabilistic ensemble of
:mod:`hierloco.components.com_ensemble` (PETS, Chua et al., NeurIPS 2018) is ``ensemble``. Every model derives from
:class:`CoMModel`, which states the contract: a new model is one subclass writing ``standardised_delta(x)``,
with ``predict(com_state, action)``, the normalisation buffers and the training hooks inherited. A model's options
are its constructor's keyword arguments (``MODELS.options("ensemble")``); :func:`train_com_model` trains any model by
name (``model="ensemble", members=5``); the options a model is built with are recorded as it is built
(:attr:`CoMModel.options`), its checkpoint holds its name and options, and :meth:`TrainedCoMModel.load` rebuilds
it with them. :func:`com_model_module` wraps any of them as a TensorDict module.

Example:
    >>> import torch
    >>> model = CoMDynamicsModel(action_dim=3, hidden=64)
    >>> com_state = torch.zeros(4, 1, 5)  # B x 1 x 5: B robots at the origin, at rest
    >>> model.predict(com_state, torch.rand(4, 8000, 3)).shape  # B x S next states for S sampled actions
    torch.Size([4, 8000, 5])
"""

from __future__ import annotations

import functools
import inspect
import json
import math
import os
import time
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torchrl.modules import MLP
from tqdm.auto import tqdm

from hierloco.envs.frames import local_to_world, world_to_local, wrap_angle
from hierloco.io import ArtifactError, load_checkpoint, save_checkpoint
from hierloco.registry import Registry, is_import_path

CHECKPOINT_FORMAT = 1
CHECKPOINT_KIND = "com_model"
OUTPUT_NAMES = ("dx", "dy", "dyaw", "vx_next", "vy_next")
MIN_TRANSITIONS = 10

MODELS = Registry("dynamics_model", context=("action_dim", "input_mean", "input_std", "output_mean", "output_std"),
                  modules=("hierloco.components.com_ensemble",))
"""The CoM dynamics models by name (``mlp``, ``ensemble``); options are their constructors' keyword arguments."""


def _as_float_tensor(x) -> torch.Tensor:
    tensor = x if isinstance(x, torch.Tensor) else torch.as_tensor(x, device="cpu")
    return tensor if tensor.is_floating_point() else tensor.to(torch.get_default_dtype())


def _check_last_dim(name: str, tensor: torch.Tensor, size: int) -> None:
    if tensor.ndim == 0 or tensor.shape[-1] != size:
        raise ValueError(f"{name} must have a last dimension of {size}, got shape {tuple(tensor.shape)}")


def _five_vectors(**arrays) -> list[torch.Tensor]:
    """The named ``... x 5`` arrays as float tensors of one common dtype (a bad shape names the argument)."""
    tensors = []
    for name, value in arrays.items():
        tensor = _as_float_tensor(value)
        _check_last_dim(name, tensor, 5)
        tensors.append(tensor)
    dtype = torch.promote_types(tensors[0].dtype, tensors[1].dtype)
    return [t.to(dtype) for t in tensors]


def local_transition(com_state, next_com_state) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame CoM state pairs -> the model's input velocity and target delta.

    Args:
        com_state: ``... x 5`` states ``(x, y, yaw, vx, vy)`` at the start of an action, world frame (m, rad, m/s).
        next_com_state: ``... x 5`` states at its end, same frame and units. NumPy arrays are accepted.

    Returns:
        ``velocity_local`` ``... x 2``, the current velocity in the current local frame (m/s), and ``delta``
        ``... x 5`` = ``(dx, dy, dyaw, vx', vy')``: displacement (m) and next velocity (m/s) in the current local
        frame, and the yaw change wrapped to (-pi, pi] (rad).

    Example:
        >>> import numpy as np
        >>> s = np.array([1.0, 2.0, np.pi / 2, 0.0, 1.0])   # facing +y, walking forward at 1 m/s
        >>> s2 = np.array([1.0, 3.0, np.pi / 2 + 0.1, -0.5, 1.0])
        >>> v, delta = local_transition(s, s2)  # float64 torch tensors
        >>> (v.round(decimals=4) + 0).tolist(), (delta.round(decimals=4) + 0).tolist()
        ([1.0, 0.0], [1.0, 0.0, 0.1, 1.0, 0.5])
    """
    state, next_state = _five_vectors(com_state=com_state, next_com_state=next_com_state)
    yaw = state[..., 2]
    velocity_local = world_to_local(state[..., 3:5], yaw)
    displacement = world_to_local(next_state[..., :2] - state[..., :2], yaw)
    dyaw = wrap_angle(next_state[..., 2] - yaw)
    next_velocity = world_to_local(next_state[..., 3:5], yaw)
    return velocity_local, torch.cat([displacement, dyaw[..., None], next_velocity], -1)


def apply_delta(com_state, delta) -> torch.Tensor:
    """The world-frame next state from a world-frame state ``... x 5`` and a local-frame ``delta`` ``... x 5``.

    The inverse of :func:`local_transition`: ``apply_delta(s, local_transition(s, s2)[1])`` is ``s2`` with its yaw
    wrapped to (-pi, pi]. Leading dimensions broadcast (a ``B x 1 x 5`` state with ``B x S x 5`` deltas gives
    ``B x S x 5``).
    """
    state, delta = _five_vectors(com_state=com_state, delta=delta)
    yaw = state[..., 2]
    position = state[..., :2] + local_to_world(delta[..., :2], yaw)
    next_yaw = wrap_angle(yaw + delta[..., 2])
    velocity = local_to_world(delta[..., 3:5], yaw)
    return torch.cat([position, next_yaw[..., None], velocity], -1)


def _nonzero_std(std: torch.Tensor) -> torch.Tensor:
    """A constant feature or target keeps a scale of 1 rather than blowing up."""
    return torch.where(std > 1e-6, std, torch.ones_like(std))


# What a dynamics config section and train_com_model use themselves: a model's option may not be named like one
# (``hidden`` is both: the width every model takes). tests/components/test_custom_model.py checks that this list
# agrees with train_com_model's arguments and the pipeline's dynamics keys.
RESERVED_OPTIONS = ("com_state", "action", "next_com_state", "model", "lr", "batch_size", "holdout", "max_epochs",
                    "patience", "duration", "seed", "device", "progress", "num_transitions", "num_robots",
                    "episode_length", "body_state")


def _recorded_options(signature: inspect.Signature, args: tuple, kwargs: dict) -> dict:
    """The options a constructor with ``signature`` was called with: every named argument (defaults filled in) and
    every extra keyword argument, but the registry's context (``action_dim``, the statistics)."""
    bound = signature.bind(*args, **kwargs)
    bound.apply_defaults()
    options = {}
    for index, (name, value) in enumerate(bound.arguments.items()):
        kind = signature.parameters[name].kind
        if index == 0 or kind == inspect.Parameter.VAR_POSITIONAL:  # self; positional extras have no names
            continue
        extra = value if kind == inspect.Parameter.VAR_KEYWORD else {name: value}
        options.update({key: item for key, item in extra.items() if key not in MODELS.context})
    return options


class CoMModel(nn.Module):
    """The contract of a CoM dynamics model: ``f(v_local, a)``, velocity ``... x 2`` (m/s) and action ``... x A`` ->
    local-frame delta ``... x 5`` (see the module doc), learned on standardised inputs and outputs.

    A model is one subclass that writes :meth:`standardised_delta` (``b x (2 + A)`` standardised inputs ->
    ``b x 5`` standardised delta); the rest has defaults: :meth:`forward` (physical units), :meth:`predict` (world
    frame), and the training hooks :func:`train_com_model` calls (:meth:`training_rows`, :meth:`epoch_order`,
    :meth:`training_loss`: the MSE, :meth:`heldout_loss`, :meth:`heldout_report`), which a model may override (the
    ensemble does).

    Its constructor is called ``Model(action_dim, hidden=..., **options, **statistics)``:

    - ``action_dim`` (A) and ``hidden`` (a width, ``dynamics.hidden``) come from the pipeline; pass both on to
      ``super().__init__``;
    - its *options* are its other keyword arguments with defaults (``+dynamics.<option>=...`` in a recipe, checked
      against them before any work); their values are recorded as the model is built (:attr:`options`), saved in
      its checkpoint and given back to the constructor when the checkpoint is loaded (by ``load_run``, ``evaluate``,
      the exporter), so a model never writes a method to keep them. An option may not be named like a training
      setting (:data:`RESERVED_OPTIONS`: ``lr``, ``seed``, ...): such a class is refused when it is defined;
    - ``**statistics``, the keyword-only ``input_mean``, ``input_std`` (``2 + A``, of ``(vx, vy, a)``) and
      ``output_mean``, ``output_std`` (``5``, of the delta), go on to ``super().__init__``, which keeps them as
      buffers (``None``: zeros and ones).

    Example (a residual network; ``docs/extending.md``, example 5, trains one in a recipe):
        >>> class ResMLP(CoMModel):
        ...     def __init__(self, action_dim, hidden=64, *, skip_scale: float = 1.0, **statistics):
        ...         super().__init__(action_dim, hidden, **statistics)
        ...         self.skip_scale = skip_scale
        ...         self.inner = nn.Sequential(nn.Linear(self.num_inputs, hidden), nn.ReLU(), nn.Linear(hidden, 5))
        ...         self.skip = nn.Linear(self.num_inputs, 5)
        ...
        ...     def standardised_delta(self, x):
        ...         return self.inner(x) + self.skip_scale * self.skip(x)
        >>> model = ResMLP(action_dim=3, skip_scale=0.5)
        >>> model.options
        {'hidden': 64, 'skip_scale': 0.5}
        >>> model.predict(torch.zeros(4, 5), torch.rand(4, 3)).shape
        torch.Size([4, 5])
    """

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get("__init__")
        if init is None:  # the base's constructor, already recording
            return
        signature = inspect.signature(init)
        reserved = [name for name in list(signature.parameters)[1:] if name in RESERVED_OPTIONS]
        if reserved:
            raise TypeError(f"{cls.__qualname__}: option{'s' if len(reserved) > 1 else ''} {', '.join(reserved)} "
                            f"named like train_com_model's own settings ({', '.join(RESERVED_OPTIONS)}): "
                            "rename it")

        @functools.wraps(init)
        def init_recording_options(self, *args, **kwargs):
            init(self, *args, **kwargs)
            if type(self).__init__ is init_recording_options:  # the class built, not a base it calls
                self._options = _recorded_options(signature, (self, *args), kwargs)

        cls.__init__ = init_recording_options

    def __init__(self, action_dim: int, hidden: int = 512, *, input_mean: torch.Tensor | None = None,
                 input_std: torch.Tensor | None = None, output_mean: torch.Tensor | None = None,
                 output_std: torch.Tensor | None = None):
        super().__init__()
        for name, value in [("action_dim", action_dim), ("hidden", hidden)]:
            if isinstance(value, bool) or int(value) != value or int(value) < 1:
                raise ValueError(f"{name} must be a whole number >= 1, got {value!r}")
        self.action_dim, self.hidden = int(action_dim), int(hidden)
        self.num_inputs = 2 + self.action_dim
        self._options = {"hidden": self.hidden}
        for name, value, size, default in [("input_mean", input_mean, self.num_inputs, 0.0),
                                           ("input_std", input_std, self.num_inputs, 1.0),
                                           ("output_mean", output_mean, 5, 0.0),
                                           ("output_std", output_std, 5, 1.0)]:
            buffer = (torch.full((size,), default, device="cpu") if value is None
                      else torch.as_tensor(value, device="cpu").float().clone())
            if buffer.shape != (size,):
                raise ValueError(f"{name} must have shape ({size},), got {tuple(buffer.shape)}")
            self.register_buffer(name, buffer)

    @property
    def options(self) -> dict:
        """The options the model was built with (its constructor's arguments but ``action_dim`` and the
        statistics): what its checkpoint records and gives back to the constructor."""
        return dict(self._options)

    def config(self) -> dict:
        """The constructor's arguments a checkpoint records: ``action_dim`` and :attr:`options`."""
        return {"action_dim": self.action_dim, **self.options}

    # ------------------------------------------------------------------------------------------ what a model writes
    def standardised_delta(self, x: torch.Tensor) -> torch.Tensor:
        """``... x (2 + A)`` standardised ``(vx, vy, a)`` -> ``... x 5`` standardised delta: the network."""
        raise NotImplementedError(f"{type(self).__name__} must write standardised_delta(x) (CoMModel)")

    # ------------------------------------------------------------------------------------------ predictions
    def _inputs(self, velocity_local, action) -> torch.Tensor:
        """``... x (2 + A)`` raw inputs, leading dimensions broadcast, in the model's dtype and device."""
        dtype, device = self.input_mean.dtype, self.input_mean.device
        velocity = torch.as_tensor(velocity_local, dtype=dtype, device=device)
        action = torch.as_tensor(action, dtype=dtype, device=device)
        _check_last_dim("velocity_local", velocity, 2)
        _check_last_dim("action", action, self.action_dim)
        batch = torch.broadcast_shapes(velocity.shape[:-1], action.shape[:-1])
        return torch.cat([velocity.expand(*batch, 2), action.expand(*batch, self.action_dim)], -1)

    def standardised_inputs(self, velocity_local, action) -> torch.Tensor:
        """``... x 2`` local velocity (m/s), ``... x A`` action -> the standardised ``... x (2 + A)`` inputs."""
        return (self._inputs(velocity_local, action) - self.input_mean) / self.input_std

    def normalized(self, velocity_local, action) -> torch.Tensor:
        """The standardised delta ``... x 5`` (what the training loss is computed on)."""
        return self.standardised_delta(self.standardised_inputs(velocity_local, action))

    def forward(self, velocity_local, action) -> torch.Tensor:
        """``... x 2`` local velocity (m/s), ``... x A`` action -> ``... x 5`` delta in physical units."""
        return self.normalized(velocity_local, action) * self.output_std + self.output_mean

    def predict(self, com_state, action) -> torch.Tensor:
        """``... x 5`` world state, ``... x A`` action -> ``... x 5`` world state after one action."""
        state = _as_float_tensor(com_state)
        _check_last_dim("com_state", state, 5)
        velocity_local = world_to_local(state[..., 3:5], state[..., 2])
        return apply_delta(state.to(self.input_mean.device), self(velocity_local, action))

    # ---------------------------------------------------------------- training hooks (see train_com_model)
    def training_rows(self, num_train: int, generator: torch.Generator) -> torch.Tensor | None:
        """The rows each part of the model learns from: all of them (``None``, nothing drawn)."""
        return None

    def epoch_order(self, rows, num_train: int, generator: torch.Generator) -> torch.Tensor:
        """``num_train``: the training rows in a new random order for one epoch."""
        return torch.randperm(num_train, generator=generator, device="cpu")

    def training_loss(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The MSE of the standardised delta on ``b x (2 + A)`` standardised inputs and ``b x 5`` targets."""
        return ((self.standardised_delta(x) - y) ** 2).mean()

    @torch.no_grad()
    def heldout_loss(self, x: torch.Tensor, y: torch.Tensor) -> float:
        """The standardised MSE on held-out rows (what early stopping watches)."""
        return float(((self.standardised_delta(x) - y) ** 2).mean())

    def heldout_report(self, x: torch.Tensor, y: torch.Tensor) -> dict:
        """Entries of the training report beyond the RMSE: none for a point model."""
        return {}


@MODELS.register("mlp")
class CoMDynamicsModel(CoMModel):
    """The paper's model: a :class:`torchrl.modules.MLP` with 2 hidden layers of ``hidden`` ReLU units
    (:class:`CoMModel`: ``f(v_local, a)``, velocity ``... x 2`` (m/s) and action ``... x A`` -> delta ``... x 5``).

    Args:
        action_dim: A, the size of the action vector.
        hidden: width of the 2 hidden ReLU layers.
        statistics: ``input_mean``, ``input_std`` (``2 + A``, of ``(vx, vy, a)``), ``output_mean``, ``output_std``
            (``5``, of the delta): see :class:`CoMModel`.

    Leading dimensions of the velocity and the action broadcast against each other.

    Example:
        >>> import torch
        >>> model = CoMDynamicsModel(action_dim=2, hidden=32)
        >>> model(torch.zeros(10, 2), torch.zeros(10, 2)).shape
        torch.Size([10, 5])
    """

    def __init__(self, action_dim: int, hidden: int = 512, **statistics):
        super().__init__(action_dim, hidden, **statistics)
        self.net = MLP(in_features=self.num_inputs, out_features=5, num_cells=[self.hidden, self.hidden],
                       activation_class=nn.ReLU)

    def standardised_delta(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def model_name(model: nn.Module) -> str:
    """The registry name of a CoM model (``mlp`` for :class:`CoMDynamicsModel`)."""
    name = getattr(type(model), "registry_name", None)
    if name is None or name not in MODELS or MODELS[name] is not type(model):
        raise ValueError(f"{type(model).__name__} is not a registered dynamics model ({', '.join(MODELS.names())})")
    return name


class _PredictWithSpread(nn.Module):
    """``(com_state, action)`` -> the mean next state and, for a model with members, their spread and predictions."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model
        self.has_members = hasattr(model, "predict_members")

    def forward(self, com_state: torch.Tensor, action: torch.Tensor):
        if not self.has_members:
            return self.model.predict(com_state, action)
        from hierloco.envs.world_model import particle_moments

        members = self.model.predict_members(com_state, action)
        _, spread = particle_moments(members)
        return self.model.predict(com_state, action), spread, members


def com_model_module(model: nn.Module, *, state_key="com_state", action_key="action",
                     out_key=("next", "com_state")):
    """A CoM model as a :class:`tensordict.nn.TensorDictModule`: reads ``com_state`` (``B x 5``, world frame) and
    ``action`` (``B x A``, the model's action features), writes the predicted ``("next", "com_state")`` (``B x 5``);
    a model with members (the ensemble) also writes ``("next", "com_state_std")`` (``B x 5``, the spread of the
    members' predictions, yaw about its circular mean) and ``("next", "com_state_members")`` (``B x M x 5``).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> module = com_model_module(CoMDynamicsModel(action_dim=3, hidden=16))
        >>> td = module(TensorDict({"com_state": torch.zeros(4, 5), "action": torch.zeros(4, 3)}, [4]))
        >>> td["next", "com_state"].shape
        torch.Size([4, 5])
    """
    from tensordict.nn import TensorDictModule

    def sibling(name):
        return (*out_key[:-1], name) if isinstance(out_key, tuple) else name

    out_keys = [out_key]
    if hasattr(model, "predict_members"):
        out_keys += [sibling("com_state_std"), sibling("com_state_members")]
    return TensorDictModule(_PredictWithSpread(model), in_keys=[state_key, action_key], out_keys=out_keys)


@dataclass
class TrainedCoMModel:
    """A trained CoM dynamics model and its training report (see :func:`train_com_model`)."""

    model: nn.Module
    metadata: dict

    @property
    def name(self) -> str:
        """The model's registry name (``mlp``, ``ensemble``, ...)."""
        return model_name(self.model)

    def save(self, path: str | os.PathLike) -> None:
        """Writes a checkpoint (the model's registry name, its constructor's arguments :meth:`CoMModel.config`,
        weights and statistics, metadata) to ``path`` atomically; an option that JSON cannot hold (an object) is a
        ``ValueError`` before anything is written."""
        config = self.model.config()
        try:
            json.dumps(config)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{type(self.model).__name__}: its options must be numbers, strings, booleans, lists or "
                             f"dicts of them to be saved, got {config!r} ({error})") from None
        save_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, {"model": self.name, "config": config,
                        "state_dict": self.model.state_dict(), "metadata": self.metadata})

    @classmethod
    def load(cls, path: str | os.PathLike, map_location="cpu", *, trust_imports=()) -> "TrainedCoMModel":
        """Reads a checkpoint written by :meth:`save` (a checkpoint without a model name is an ``mlp``), building the
        model from :data:`MODELS` with the options it was trained with; raises :class:`ArtifactError` naming the file
        if it is bad. A checkpoint is data: a model it names by import path (``pkg.module:Class``) is imported only
        when ``trust_imports`` lists that path (or it is imported already: the config named it)."""
        payload = load_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, map_location)
        name = payload.get("model", "mlp")
        if is_import_path(name) and name not in MODELS:
            if name not in ({trust_imports} if isinstance(trust_imports, str) else set(trust_imports)):
                raise ArtifactError(f"{path}: its model {name!r} is an import path read from the file, which is never "
                                    f"run as code; if you trust it, name it yourself: trust_imports=[{name!r}]")
            try:
                MODELS.import_path(name, base=CoMModel)
            except ValueError as error:
                raise ArtifactError(f"{path}: {error}") from None
        try:
            if name not in MODELS:
                raise ValueError(f"unknown dynamics model {name!r} ({', '.join(MODELS.names())})")
            model = MODELS[name](**payload["config"])
            model.load_state_dict(payload["state_dict"])
        except (KeyError, TypeError, ValueError, RuntimeError) as error:
            raise ArtifactError(f"corrupted CoM model checkpoint {path}: {error}") from error
        model.eval()
        return cls(model, payload["metadata"])


def holdout_split(num: int, holdout: float, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The seeded random split of ``num`` transitions used by :func:`train_com_model`: ``(train, heldout)`` indices.

    ``round(holdout * num)`` transitions are held out, at least 1 and at most ``num - 1``.
    """
    num_heldout = min(max(1, round(holdout * num)), num - 1)
    order = torch.randperm(num, generator=torch.Generator().manual_seed(seed), device="cpu")
    return order[num_heldout:], order[:num_heldout]


def _check_training_inputs(com_state, action, next_com_state, holdout) -> tuple[torch.Tensor, ...]:
    tensors = {}
    for name, value in [("com_state", com_state), ("action", action), ("next_com_state", next_com_state)]:
        try:
            tensors[name] = (value.cpu() if isinstance(value, torch.Tensor)
                             else torch.as_tensor(np.asarray(value, float), device="cpu"))
        except (TypeError, ValueError, RuntimeError) as error:
            raise ValueError(f"{name} is not a numeric array: {error}") from error
    state, act, next_state = (tensors[k].double() for k in ("com_state", "action", "next_com_state"))
    for name, tensor, width in [("com_state", state, 5), ("next_com_state", next_state, 5)]:
        if tensor.ndim != 2 or tensor.shape[1] != width:
            raise ValueError(f"{name} must be M x 5 (x, y, yaw, vx, vy), got shape {tuple(tensor.shape)}")
    if act.ndim != 2 or act.shape[1] < 1:
        raise ValueError(f"action must be M x A (use action[:, None] for a scalar action), got shape "
                         f"{tuple(act.shape)}")
    lengths = {"com_state": len(state), "action": len(act), "next_com_state": len(next_state)}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"com_state, action and next_com_state must have the same length M, got {lengths}")
    for name, tensor in [("com_state", state), ("action", act), ("next_com_state", next_state)]:
        bad = ~torch.isfinite(tensor).all(1)
        if bad.any():
            raise ValueError(f"{name} has NaN or inf in {int(bad.sum())} transition(s), first at index "
                             f"{int(bad.nonzero()[0])}")
    if len(state) < MIN_TRANSITIONS:
        raise ValueError(f"need at least {MIN_TRANSITIONS} transitions to train and hold out, got {len(state)}")
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"holdout must be a fraction in (0, 1), got {holdout}")
    return state, act, next_state


def train_com_model(
    com_state,
    action,
    next_com_state,
    *,
    model: str = "mlp",
    hidden: int = 512,
    lr: float = 1e-3,
    batch_size: int = 512,
    holdout: float = 0.1,
    max_epochs: int = 500,
    patience: int = 20,
    duration: float = 1.0,
    seed: int = 0,
    device: str = "cpu",
    progress: bool = False,
    **model_options,
) -> TrainedCoMModel:
    """Fits a CoM dynamics model (by registry name, :data:`MODELS`) to M world-frame transitions
    ``com_state -> next_com_state`` under ``action``.

    Args:
        com_state, next_com_state: ``M x 5`` world-frame states ``(x, y, yaw, vx, vy)`` (m, rad, m/s), NumPy or
            torch.
        action: ``M x A`` actions held over each transition.
        model: the model's registry name: ``mlp`` (:class:`CoMDynamicsModel`, the paper's; trained exactly as
            before the registry existed), ``ensemble``
            (:class:`~hierloco.components.com_ensemble.CoMEnsembleModel`) or any registered :class:`CoMModel`;
            ``model_options`` are its other options (``members``, ``head``, ``propagation``, ``member_data`` for the
            ensemble).
        hidden: width of the 2 hidden layers. lr, batch_size: Adam step size and minibatch size (per member for an
            ensemble).
        holdout: fraction of the transitions held out (seeded random split, see :func:`holdout_split`).
        max_epochs: upper bound on the epochs. patience: stop once the held-out loss has not improved for this many
            epochs; the weights of the best epoch are kept.
        duration: length of one action in s, used by the constant-velocity baseline.
        seed: seeds the split, the initial weights and the minibatch order (the global RNG is left untouched).
        device: where the network trains; the returned model is on the CPU.

    Returns:
        The model (eval mode) and a report in ``metadata``: ``heldout_rmse`` and ``constant_velocity_rmse`` (5 each,
        physical units, order dx, dy, dyaw, vx', vy'; the baseline predicts ``(dx, dy) = v * duration``,
        ``dyaw = 0``, ``v' = v``), ``heldout_loss`` (best standardised MSE) with its ``heldout_loss_history`` (and ``train_loss_history``) per
        epoch, ``epochs``, ``best_epoch`` (1-based), ``train_seconds``, ``num_train``, ``num_heldout``, ``seed``.

    Raises:
        ValueError: for mismatched lengths, wrong trailing dimensions, NaN/inf, fewer than ``MIN_TRANSITIONS``
            transitions, an unknown model or option, or a bad hyperparameter, before training starts.

    Example:
        >>> import numpy as np
        >>> rng = np.random.default_rng(0)
        >>> state, action = rng.normal(size=(200, 5)), rng.uniform(-1, 1, size=(200, 2))
        >>> next_state = state + 0.1 * rng.normal(size=(200, 5))
        >>> trained = train_com_model(state, action, next_state, hidden=16, max_epochs=3, progress=False)
        >>> trained.metadata["num_train"], trained.metadata["num_heldout"], len(trained.metadata["heldout_rmse"])
        (180, 20, 5)
    """
    state, act, next_state = _check_training_inputs(com_state, action, next_com_state, holdout)
    if model not in MODELS:
        raise ValueError(f"unknown dynamics model {model!r} (dynamics models: {', '.join(MODELS.names())})")
    if not (isinstance(MODELS[model], type) and issubclass(MODELS[model], CoMModel)):
        raise ValueError(f"dynamics model {model!r} is not a CoMModel subclass (hierloco.components.com_model)")
    problems = MODELS.check_options(model, {"hidden": hidden, **model_options})
    if problems:
        raise ValueError("; ".join(problems))
    for name, value in [("hidden", hidden), ("batch_size", batch_size), ("max_epochs", max_epochs),
                        ("patience", patience)]:
        if int(value) < 1:
            raise ValueError(f"{name} must be at least 1, got {value}")
    for name, value in [("lr", lr), ("duration", duration)]:
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value}")

    velocity_local, delta = local_transition(state, next_state)
    inputs = torch.cat([velocity_local, act], -1)
    train_idx, heldout_idx = holdout_split(len(inputs), holdout, seed)
    input_mean, input_std = inputs[train_idx].mean(0), _nonzero_std(inputs[train_idx].std(0, correction=0))
    output_mean, output_std = delta[train_idx].mean(0), _nonzero_std(delta[train_idx].std(0, correction=0))
    name = model
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = MODELS[name](act.shape[1], hidden=hidden, input_mean=input_mean, input_std=input_std,
                             output_mean=output_mean, output_std=output_std, **model_options)
    model.to(device)
    generator = torch.Generator().manual_seed(seed)

    def standardised(index):  # through the model's own float32 statistics, as in CoMDynamicsModel.normalized
        x = (inputs[index].float() - model.input_mean.cpu()) / model.input_std.cpu()
        y = (delta[index].float() - model.output_mean.cpu()) / model.output_std.cpu()
        return x.to(device), y.to(device)

    train_x, train_y = standardised(train_idx)
    heldout_x, heldout_y = standardised(heldout_idx)
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)

    def heldout_loss() -> float:
        model.eval()
        with torch.no_grad():
            loss = model.heldout_loss(heldout_x, heldout_y)
        model.train()
        return loss

    rows = model.training_rows(len(train_x), generator)  # None: every row (the MLP); M x num_train: per member
    history, best_loss, best_epoch = [], math.inf, 0
    best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
    start = time.perf_counter()
    bar = tqdm(range(1, int(max_epochs) + 1), desc="CoM model", disable=not progress)
    model.train()
    train_history = []  # the mean training loss of each epoch (over its batches)
    for epoch in bar:
        order = model.epoch_order(rows, len(train_x), generator).to(device)
        losses = []
        for begin in range(0, order.shape[-1], batch_size):
            idx = order[..., begin:begin + batch_size]
            loss = model.training_loss(train_x[idx], train_y[idx])
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            losses.append(loss.detach())
        train_history.append(float(torch.stack(losses).mean()))
        history.append(heldout_loss())
        if history[-1] < best_loss:
            best_loss, best_epoch = history[-1], epoch
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        bar.set_postfix(heldout=f"{history[-1]:.4f}", best=f"{best_loss:.4f}")
        if epoch - best_epoch >= patience:
            break
    bar.close()
    train_seconds = time.perf_counter() - start
    model.load_state_dict(best_state)
    model.cpu().eval()

    with torch.no_grad():
        prediction = model(velocity_local[heldout_idx], act[heldout_idx]).double()
    target = delta[heldout_idx]
    v = velocity_local[heldout_idx]
    baseline = torch.cat([v * duration, torch.zeros_like(v[:, :1]), v], -1)
    metadata = {
        "heldout_rmse": ((prediction - target) ** 2).mean(0).sqrt().tolist(),
        "constant_velocity_rmse": ((baseline - target) ** 2).mean(0).sqrt().tolist(),
        "output_names": list(OUTPUT_NAMES),
        "heldout_loss": best_loss, "heldout_loss_history": history, "train_loss_history": train_history,
        "epochs": len(history), "best_epoch": best_epoch, "train_seconds": train_seconds,
        "num_train": len(train_idx), "num_heldout": len(heldout_idx), "seed": int(seed),
        "action_dim": int(act.shape[1]), "hidden": int(hidden), "lr": float(lr), "batch_size": int(batch_size),
        "holdout": float(holdout), "max_epochs": int(max_epochs), "patience": int(patience),
        "duration": float(duration), "model": name,
        "model_options": model.options,
        **model.heldout_report(heldout_x.cpu(), heldout_y.cpu()),
    }
    return TrainedCoMModel(model, metadata)


def prediction_errors(model: CoMModel, com_states, actions) -> torch.Tensor:
    """How wrong ``model`` was about the actions that were taken: predicted minus actual delta, ``E x T x 5``.

    Args:
        model: the CoM model (its inputs are the actions' features: a latent z as it is, an expert index one-hot,
            :meth:`hierloco.envs.low_level.LowLevel.action_features`).
        com_states: ``E x (T + 1) x 5`` world CoM states at the start of each action and after the last, e.g.
            ``rollout.result.com_states`` of an MPC episode (:func:`hierloco.components.evaluation.run_task`).
        actions: ``E x T x A`` the features of the actions taken between them.

    Returns:
        ``(dx, dy, dyaw, vx', vy')`` errors in each action's start frame (m, rad wrapped to (-pi, pi], m/s): on a
        planner's chosen actions, compare them with the held-out errors on random actions (``heldout_rmse`` in
        the model's metadata) to see whether the plans exploit what the model gets wrong.

    Example:
        >>> model = CoMDynamicsModel(action_dim=2, hidden=8)
        >>> prediction_errors(model, torch.zeros(3, 5, 5), torch.zeros(3, 4, 2)).shape
        torch.Size([3, 4, 5])
    """
    states = _as_float_tensor(com_states)
    _check_last_dim("com_states", states, 5)
    actions = _as_float_tensor(actions)
    if states.dim() != 3 or actions.dim() != 3 or actions.shape[:2] != (states.shape[0], states.shape[1] - 1):
        raise ValueError(f"com_states must be E x (T + 1) x 5 and actions E x T x A, got {tuple(states.shape)} and "
                         f"{tuple(actions.shape)}")
    velocity_local, actual = local_transition(states[:, :-1], states[:, 1:])
    with torch.no_grad():
        predicted = model(velocity_local, actions).to(actual.device, actual.dtype)  # from the model's device
    error = predicted - actual
    error[..., 2] = wrap_angle(error[..., 2])
    return error


__all__ = ["MODELS", "RESERVED_OPTIONS", "CoMDynamicsModel", "CoMModel", "TrainedCoMModel", "apply_delta",
           "com_model_module", "holdout_split", "local_transition", "model_name", "prediction_errors",
           "train_com_model"]

