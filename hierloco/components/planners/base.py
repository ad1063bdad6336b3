"""What every hierloco planner shares: candidate scoring on a world model env, the action box, warm starts.

A planner subclass writes only ``planning(tensordict) -> action``; it proposes ``B x S x H x A`` candidate action
sequences and calls :meth:`BoxPlannerBase.score`, which rolls them out on the (not batch-locked) world model env and
sums the rewards over the horizon (Li et al., RA-L 2021, Sec. III-A.2, Eq. 1). Every planner is a
:class:`hierloco.components.policies.TaskPolicy`: :meth:`BoxPlannerBase.begin_task` re-targets the world model to a
task and forgets the warm start.

The planner runs on its world model's device: a call moves the measured state there (one transfer) and returns the
action on the device of the state it was given, so a planner on CUDA drives robots simulated on the CPU.
:meth:`BoxPlannerBase.set_scoring` compiles the scoring (``torch.compile``, CUDA graphs on a GPU) and sets its
matrix-product precision (``fp32``, ``tf32``, ``bf16``; ``docs/gpu.md``).

Warm starts are kept per batch row (per robot): a row starts from its own previous plan only while its episode goes
on. A call to the planner (``planner(tensordict)``, as ``env.rollout`` and TorchRL collectors make it) reads, when
present, ``is_init`` (TorchRL's :class:`~torchrl.envs.transforms.InitTracker`: true on the first step of an
episode), ``_reset``, the task step counter ``task_step`` (a row whose counter went back has started a new episode)
and ``task_episode`` (a row pursuing another target set); a row flagged by any of them starts cold, the others keep
their warm start. So a robot reset by a collector never inherits its previous episode's plan, nor another robot's.

A state without the task keys (from an env that runs no task: a bare
:class:`~hierloco.envs.latent_env.LatentActionEnv` in a TorchRL ``Collector``, with no transform) is planned as the
task state that :func:`hierloco.envs.transforms.task_transforms` would have written: row ``b`` pursues episode
``b % num_episodes`` of the world model's task (:func:`hierloco.envs.world_model.default_episodes`), at the task step
the planner counts itself, its plans for that row since the row's episode started (``is_init``, which
:class:`~hierloco.envs.latent_env.LatentActionEnv` writes at a reset, ``_reset``, or :meth:`BoxPlannerBase.reset`).
Keys the state holds are read as they are.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Categorical
from torchrl.modules.planners import MPCPlannerBase

from hierloco.components.policies import TaskPolicy
from hierloco.devices import check_precision, compile_mode, precision_context
from hierloco.envs.world_model import default_episodes
from hierloco.registry import Registry

# The planners by name (``planner.name``): a new planner is one subclass of :class:`BoxPlannerBase` decorated with
# ``@PLANNERS.register("name")``; its options are its constructor's keyword arguments (``docs/extending.md``).
PLANNERS = Registry("planner", context=("env", "planning_horizon", "seed", "choices", "init_key", "step_key",
                                             "episode_key"))


class BoxPlannerBase(MPCPlannerBase, TaskPolicy):
    """MPC over a box (or finite set) of actions with a learned world model.

    A TensorDict module: it reads the world model's state keys (``in_keys``: ``com_state`` ``B x 5``,
    ``task_episode`` and ``task_step`` ``B x 1`` for :class:`~hierloco.envs.world_model.CoMWorldModelEnv`; the task
    keys made by the planner when a state lacks them, see the module doc) and writes ``action`` (``B x A``); ``B`` may
    be absent (one state).

    Args:
        env: a world model env, e.g. :class:`hierloco.envs.world_model.CoMWorldModelEnv` (to plan a task with
            :meth:`begin_task`, it needs ``set_task(task)``).
        planning_horizon: H, high-level actions looked ahead.
        num_candidates: S, action sequences scored per call and per robot.
        seed: seeds the planner's own random generator.
        init_key, step_key, episode_key: the keys that say a row's episode has (re)started (see the module doc).

    Attributes:
        warm_rows: ``B`` bool, the rows whose last plan started from their previous plan (``None`` before a call).
        compile, precision: how candidates are scored (:meth:`set_scoring`; default eager, ``fp32``).
    """

    ACTION_SPACES = ("box",)  # what it plans over: "box" (a continuous box), "finite" (a set of choices)

    def __init__(self, env, planning_horizon: int = 1, num_candidates: int = 8000, seed: int = 0, *,
                 init_key: str = "is_init", step_key: str = "task_step", episode_key: str = "task_episode"):
        super().__init__(env)
        measured = getattr(env, "measured_keys", None)
        if measured is not None:  # what a measured state holds (a world model may carry more, e.g. particles)
            self.in_keys = list(measured)
        if int(planning_horizon) < 1 or int(num_candidates) < 1:
            raise ValueError(f"need planning_horizon >= 1 and num_candidates >= 1, got {planning_horizon}, "
                             f"{num_candidates}")
        self.planning_horizon = int(planning_horizon)
        self.num_candidates = int(num_candidates)
        self.discrete = isinstance(env.action_spec, Categorical)
        if self.discrete:
            self.register_buffer("low", torch.zeros(1, device=env.device))
            self.register_buffer("high", torch.full((1,), float(env.action_spec.n - 1), device=env.device))
        else:
            self.register_buffer("low", env.action_spec.space.low.clone().float())
            self.register_buffer("high", env.action_spec.space.high.clone().float())
        self.generator = torch.Generator(device=self.low.device).manual_seed(seed)
        self._previous = None  # B x H x A, the last plan (for warm starts)
        self.init_key, self.step_key, self.episode_key = init_key, step_key, episode_key
        self._marks: dict[str, torch.Tensor] = {}  # B, the step and episode of each row's last plan
        self._keep = None  # B bool while a call plans: the rows whose warm start is still theirs
        self._moved_on = None  # B bool while a call plans: the rows whose task step moved on since their last plan
        self.warm_rows = None
        self.compile, self.precision, self._imagined_return = False, "fp32", None

    def set_scoring(self, *, compile: bool = False, precision: str = "fp32") -> "BoxPlannerBase":
        """How candidates are scored from now on (``planner.compile``, ``planner.precision``).

        Args:
            compile: score through the world model's tensor function (``imagined_return``, when it has one) compiled
                with ``torch.compile``: with CUDA graphs on a GPU (``mode="reduce-overhead"``), plain on the CPU.
                Each batch shape compiles once (a one-off cost). ``False``: the TorchRL env steps, as always.
            precision: ``fp32``; ``tf32`` (TensorFloat-32 matrix products on CUDA); ``bf16`` (the model's matrix
                products autocast to bfloat16). Costs are summed in float32 either way.
        """
        if not isinstance(compile, bool):
            raise ValueError(f"compile must be true or false, got {compile!r}")
        self.compile, self.precision = compile, check_precision(precision)
        self._imagined_return = None
        return self

    @property
    def action_dim(self) -> int:
        return self.low.shape[-1]

    def reset(self) -> None:
        """Forgets the previous plan of every row (a row whose episode restarts is forgotten on its own)."""
        self._previous = None
        self._marks = {}

    def forward(self, tensordict: TensorDictBase, tensordict_out: TensorDictBase | None = None,
                **kwargs) -> TensorDictBase:
        """Plans from the states in ``tensordict`` and writes ``action`` (on the device of ``tensordict``); each row
        keeps its warm start only while its episode goes on (see the module doc)."""
        if "params" in kwargs or "vmap" in kwargs:
            raise ValueError("planners do not support functional calls")
        device = self.low.device
        source = _device_of(tensordict, self.in_keys)
        here = tensordict
        if source != device:  # the measured state, once, to the planner's device
            here = tensordict.select(*self.in_keys, self.init_key, "_reset", strict=False).to(device)
        here = self._with_task_state(here)
        td = self._flat(here)
        self._keep = self.continuing_rows(td)
        self._moved_on = self.moved_on_rows(td)
        self.warm_rows = torch.zeros_like(self._keep)  # planners without warm starts leave it so
        try:
            action = self.action_spec.project(self.planning(here))
        finally:
            self._keep = self._moved_on = None
        self._marks = {key: td.get(key).reshape(td.batch_size[0], -1)[:, 0].clone()
                       for key in (self.step_key, self.episode_key) if key in td.keys()}
        return self._write_to_tensordict(tensordict, (action.to(source),), tensordict_out)

    def continuing_rows(self, tensordict: TensorDictBase) -> torch.Tensor:
        """``B`` bool: the rows of a ``B``-batch of states that go on with the episode of their previous plan.

        False for every row when there is no previous plan of that batch size; else false where ``is_init`` or
        ``_reset`` is set, where the step counter is below the one of the row's last plan, or where the episode
        index changed.
        """
        batch = tensordict.batch_size[0]
        device = self.low.device
        if self._previous is None or self._previous.shape[0] != batch:
            return torch.zeros(batch, dtype=torch.bool, device=device)
        keep = ~self._flagged_rows(tensordict)
        keys = tensordict.keys()
        for key, started_over in ((self.step_key, torch.lt), (self.episode_key, torch.ne)):
            previous = self._marks.get(key)
            if key in keys and previous is not None:
                now = tensordict.get(key).reshape(batch, -1)[:, 0]
                keep &= ~started_over(now, previous).to(device)
        return keep

    def moved_on_rows(self, tensordict: TensorDictBase) -> torch.Tensor:
        """``B`` bool: the rows whose task step moved on since their last plan (true where it cannot be told). A row
        still in the same task step re-plans within an action (``eval.replan_steps``, ``docs/terrain.md``): its
        previous plan's first action is still the one under way, so its warm start is that plan unshifted."""
        batch = tensordict.batch_size[0]
        moved = torch.ones(batch, dtype=torch.bool, device=self.low.device)
        previous = self._marks.get(self.step_key)
        if self.step_key in tensordict.keys() and previous is not None and previous.shape[0] == batch:
            now = tensordict.get(self.step_key).reshape(batch, -1)[:, 0]
            moved = (now != previous).to(moved.device)
        return moved

    def _flagged_rows(self, tensordict: TensorDictBase) -> torch.Tensor:
        """``B`` bool: the rows of a ``B``-batch whose ``is_init`` or ``_reset`` is set."""
        batch = tensordict.batch_size[0]
        flagged = torch.zeros(batch, dtype=torch.bool, device=self.low.device)
        for flag in (self.init_key, "_reset"):
            if flag in tensordict.keys():
                flagged |= tensordict.get(flag).reshape(batch, -1).any(-1).to(flagged.device)
        return flagged

    def _with_task_state(self, tensordict: TensorDictBase) -> TensorDictBase:
        """``tensordict`` with the task keys it lacks (see the module doc), in a shallow copy: the caller's is not
        written."""
        missing = [key for key in (self.episode_key, self.step_key) if key not in tensordict.keys()]
        if not missing:
            return tensordict
        flat = self._flat(tensordict)
        rows, device = flat.batch_size[0], self.low.device
        shape = (*tensordict.batch_size, 1)
        out = tensordict.copy()
        if self.episode_key in missing:
            out.set(self.episode_key, default_episodes(getattr(self.env, "task", None), rows, device).reshape(shape))
        if self.step_key in missing:
            previous = self._marks.get(self.step_key)
            if previous is None or previous.shape[0] != rows:
                steps = torch.zeros(rows, dtype=torch.int64, device=device)
            else:
                steps = torch.where(self._flagged_rows(flat), 0, previous.to(device) + 1)
            out.set(self.step_key, steps.reshape(shape))
        return out

    def begin_task(self, task) -> None:
        """Scores plans with ``task``'s cost from now on (the world model's ``set_task``) and forgets the previous
        plan."""
        self.env.set_task(task)
        self.reset()

    def sample_uniform(self, batch: int, count: int) -> torch.Tensor:
        """``batch x count x H x A`` action sequences uniform in the box."""
        shape = (batch, count, self.planning_horizon, self.action_dim)
        unit = torch.rand(shape, generator=self.generator, device=self.generator.device)
        return self.low + (self.high - self.low) * unit

    def sample_normal(self, shape) -> torch.Tensor:
        """Standard normal draws of ``shape`` from the planner's generator, on its device."""
        return torch.randn(shape, generator=self.generator, device=self.generator.device)

    def clip(self, actions: torch.Tensor) -> torch.Tensor:
        return torch.maximum(torch.minimum(actions, self.high), self.low)

    @torch.no_grad()
    def score(self, tensordict: TensorDictBase, actions: torch.Tensor) -> torch.Tensor:
        """Summed rewards ``B x S`` of the ``B x S x H x A`` action sequences from the states in ``tensordict``, in
        the scoring's precision; compiled (:meth:`set_scoring`), through the world model's ``imagined_return``."""
        with precision_context(self.precision, actions.device):
            if self.compile and hasattr(self.env, "imagined_return"):
                return self._compiled_return()(
                    tensordict.get("com_state"), tensordict.get(self.episode_key), tensordict.get(self.step_key),
                    actions.round().long() if self.discrete else actions,
                    *(tensordict.get(key) for key in getattr(self.env, "context", ())))
            batch, count = actions.shape[:2]
            td = tensordict.select(*self.in_keys).unsqueeze(-1).expand(batch, count).clone()
            total = torch.zeros(batch, count, device=actions.device)
            for h in range(actions.shape[2]):
                action = actions[:, :, h]
                if self.discrete:
                    action = action.round().long()
                td.set("action", action)
                td = self.env.step(td)
                total += td.get(("next", "reward")).reshape(batch, count)
                td = td.get("next")
            return total

    def _compiled_return(self):
        if self._imagined_return is None:
            self._imagined_return = torch.compile(self.env.imagined_return, mode=compile_mode(self.low.device),
                                                  dynamic=False)
        return self._imagined_return

    def initial_mean(self, batch: int) -> torch.Tensor:
        """``batch x H x A``: per row, its warm start while its episode goes on (:meth:`continuing_rows`), else the
        centre of the box. Sets :attr:`warm_rows`."""
        centre = ((self.low + self.high) / 2).expand(batch, self.planning_horizon, -1)
        warm = self.warm_start(batch)
        if warm is None:
            self.warm_rows = torch.zeros(batch, dtype=torch.bool, device=centre.device)
            return centre
        keep = self._keep if self._keep is not None else torch.ones(batch, dtype=torch.bool, device=centre.device)
        self.warm_rows = keep.clone()
        return torch.where(keep[:, None, None], warm, centre)

    def warm_start(self, batch: int) -> torch.Tensor | None:
        """The previous plan shifted by one action (its last action repeated), ``batch x H x A``, or ``None``; a row
        re-planning within the same task step (:meth:`moved_on_rows`) keeps it unshifted."""
        previous = self._previous
        if previous is None or previous.shape[0] != batch:
            return None
        shifted = torch.cat([previous[:, 1:], previous[:, -1:]], 1)
        moved = self._moved_on
        if moved is None or moved.shape[0] != batch:
            return shifted
        return torch.where(moved.to(previous.device)[:, None, None], shifted, previous)

    def _flat(self, tensordict: TensorDictBase) -> TensorDictBase:
        if tensordict.batch_dims > 1:
            raise ValueError(f"planners take a 0- or 1-D batch of states, got batch size {tensordict.batch_size}")
        return tensordict.unsqueeze(0) if tensordict.batch_dims == 0 else tensordict

    def _output(self, tensordict: TensorDictBase, action: torch.Tensor) -> torch.Tensor:
        if self.discrete:
            action = action.round().long()
        return action[0] if tensordict.batch_dims == 0 else action


def _device_of(tensordict: TensorDictBase, keys) -> torch.device:
    """The device of ``tensordict`` (of its first key among ``keys`` when it has none of its own)."""
    if tensordict.device is not None:
        return tensordict.device
    for key in keys:
        if key in tensordict.keys():
            return tensordict.get(key).device
    return torch.device("cpu")
