"""The learned CoM dynamics as a TorchRL world model (``ModelBasedEnvBase``), scored by a cost.

One step of this env is one high-level action: the dynamics model predicts the next world-frame CoM state from
the current one and the action; the reward is ``-cost`` of that imagined transition at the current task step, which
the env then advances. It is not batch-locked, so TorchRL planners (and hierloco's) roll it out on ``B x S``
candidate actions at once.

The cost is any callable ``cost(com_state, next_com_state, action, info) -> ...`` over tensors batched on leading
dimensions ``...`` (states ``... x 5``, world frame, m, rad, m/s; ``action`` ``... x A``); ``info`` is a dict of
tensors that broadcast against ``...``: ``task_episode`` and ``task_step`` (int64), and for a model with members (the
ensemble, :mod:`hierloco.components.com_ensemble`) ``next_com_state_mean`` and ``next_com_state_std`` (``... x 5``:
the mean and spread of the model's particles after the action). A :class:`~hierloco.envs.tasks.Task` is such a
callable and is the default cost (``task=``); ``cost=`` replaces it without a subclass.

With a model that carries particles (``model.num_particles``, ``model.predict_particles``: the ensemble), the env
carries ``P`` particles per state (``com_state_particles``, ``P x 5``) over the horizon and calls the cost on every
particle (``...`` then ends with ``P``); ``com_state`` is their mean. The reward aggregates the particles' costs by
``risk``: ``"none"`` (their mean), ``"mean_std"`` (mean + ``beta`` x standard deviation) or ``"pessimistic"`` (the
worst particle), applied to each particle's cost summed since the state the planner started from
(``cost_particles``, ``P``): a planner summing the rewards over the horizon scores a plan by the risk of its whole
cost.

State keys: ``com_state`` (``5``, world ``(x, y, yaw, vx, vy)``), ``task_episode`` and ``task_step`` (``1``, int64),
which a measured state holds (``measured_keys``: what planners read); with particles also ``com_state_particles``
and ``cost_particles``, made from ``com_state`` when absent.

With a task, a step that ends the task's last step (``task_step`` reaching ``task.num_steps``) sets ``done`` and
``terminated`` (``1``, bool; ``truncated`` stays false): the task step is part of this env's state and the task
defines no cost after its end, so its end is terminal here, as ``env.rollout`` and value targets expect. The reward
of a step past the end is still the task's cost (a planner near the end of an episode scores its whole horizon as
before). Without a task the env never ends.

Example:
    >>> import torch
    >>> from hierloco.envs.tasks import GoalReaching
    >>> class Drift(torch.nn.Module):  # a stand-in model: moves by the action, in the world frame
    ...     def predict(self, com_state, action):
    ...         return torch.cat([com_state[..., :2] + action, com_state[..., 2:]], -1)
    >>> env = CoMWorldModelEnv(Drift(), action_low=[-1, -1], action_high=[1, 1], task=GoalReaching())
    >>> td = env.reset(env.initial_state(episode=torch.tensor([0, 2])))
    >>> td = env.step(td.set("action", torch.tensor([[0.5, 0.0], [0.0, 0.5]])))
    >>> td["next", "com_state"][:, :2].tolist(), td["next", "task_step"].squeeze(-1).tolist()
    ([[0.5, 0.0], [0.0, 0.5]], [1, 1])

    The task's end (goal reaching: 30 steps) is terminal:

    >>> td = env.step(env.initial_state(episode=torch.tensor([0, 0]), step=torch.tensor([28, 29])).set(
    ...     "action", torch.zeros(2, 2)))
    >>> td["next", "terminated"].squeeze(-1).tolist(), td["next", "done"].squeeze(-1).tolist()
    ([False, True], [False, True])

    A cost of one's own, here "reach (1, 0) and keep out of a disc of 0.3 m around (0.5, 0)":

    >>> def avoid_disc(com_state, next_com_state, action, info):
    ...     distance = (next_com_state[..., :2] - torch.tensor([1.0, 0.0])).norm(dim=-1)
    ...     inside = (0.3 - (next_com_state[..., :2] - torch.tensor([0.5, 0.0])).norm(dim=-1)).clamp_min(0)
    ...     return distance + 10 * inside
    >>> env = CoMWorldModelEnv(Drift(), action_low=[-1, -1], action_high=[1, 1], cost=avoid_disc)
    >>> td = env.step(env.reset().set("action", torch.tensor([0.5, 0.0])))
    >>> round(-td["next", "reward"].item(), 2)  # 0.5 m from the goal, 0.3 m inside the disc
    3.5
"""

from __future__ import annotations

from typing import Callable, Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import nn
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase

from hierloco.envs.frames import wrap_angle
from hierloco.envs.tasks import Task

RISKS = ("none", "mean_std", "pessimistic")
MEASURED_KEYS = ("com_state", "task_episode", "task_step")
DONE_KEYS = ("done", "terminated", "truncated")
Cost = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, dict], torch.Tensor]


def default_episodes(task: Task | None, count: int, device="cpu") -> torch.Tensor:
    """``count`` episode indices (int64) when none are given: row ``b`` pursues episode ``b % task.num_episodes``
    (episode 0 without a task). What :class:`hierloco.envs.transforms.TaskEpisode` writes and a planner assumes for
    a state without ``task_episode``.

        >>> from hierloco.envs.tasks import GoalReaching
        >>> default_episodes(GoalReaching(num_goals=3), 5).tolist()
        [0, 1, 2, 0, 1]
    """
    episodes = torch.arange(int(count), device=device)
    return episodes % task.num_episodes if task is not None else torch.zeros_like(episodes)


def risk_of(costs: torch.Tensor, risk: str, beta: float) -> torch.Tensor:
    """``...``: the risk of ``... x P`` particle costs: their mean (``none``), mean + ``beta`` x standard deviation
    (``mean_std``, population std) or maximum (``pessimistic``)."""
    if risk == "none":
        return costs.mean(-1)
    if risk == "mean_std":
        return costs.mean(-1) + beta * costs.std(-1, correction=0)
    if risk == "pessimistic":
        return costs.amax(-1)
    raise ValueError(f"risk must be one of {', '.join(RISKS)}, got {risk!r}")


def particle_moments(particles: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and standard deviation ``... x 5`` over the particle dimension of ``... x P x 5`` world CoM states.

    The yaw's mean is circular (``atan2`` of the mean sine and cosine) and its spread is that of the yaw differences
    to it, wrapped to (-pi, pi]; the other dimensions have plain (population) moments.
    """
    yaw = particles[..., 2]
    mean_yaw = torch.atan2(torch.sin(yaw).mean(-1), torch.cos(yaw).mean(-1))
    planar = particles[..., [0, 1, 3, 4]]
    centre = planar.mean(-2)
    spread = (planar - centre.unsqueeze(-2)).pow(2).mean(-2).sqrt()
    yaw_spread = wrap_angle(yaw - mean_yaw.unsqueeze(-1)).pow(2).mean(-1).sqrt()
    mean = torch.cat([centre[..., :2], mean_yaw.unsqueeze(-1), centre[..., 2:]], -1)
    std = torch.cat([spread[..., :2], yaw_spread.unsqueeze(-1), spread[..., 2:]], -1)
    return mean, std


class _CoMStep(nn.Module):
    """One imagined action on tensors: the model, the scoring (``cost``, else ``task``), the risk over particles."""

    def __init__(self, model: nn.Module, task: Task | None, cost: Cost | None, action_features=None, *,
                 risk: str = "none", beta: float = 1.0, generator: torch.Generator | None = None):
        super().__init__()
        self.model = model
        self.task, self.cost = task, cost
        self.action_features = action_features
        self.risk, self.beta, self.generator = risk, float(beta), generator
        self.particles = int(getattr(model, "num_particles", 0)) if hasattr(model, "predict_particles") else 0

    @property
    def scoring(self) -> Cost | None:
        return self.cost if self.cost is not None else self.task

    def features(self, action, context, dtype) -> torch.Tensor:
        """The model's input beside the state: the action's features, then each context tensor (``... x C``, held
        over the horizon), leading dimensions broadcast."""
        features = (action if self.action_features is None else self.action_features(action)).to(dtype)
        if not context:
            return features
        parts = [features, *(c.to(dtype) for c in context)]
        batch = torch.broadcast_shapes(*(part.shape[:-1] for part in parts))
        return torch.cat([part.expand(*batch, part.shape[-1]) for part in parts], -1)

    def forward(self, com_state, action, episode, step, *context):
        """``... x 5``, ``... x A``, ``... x 1``, ``... x 1`` (then the context tensors ``... x C``) -> next
        ``com_state``, ``reward`` ``... x 1``, next ``task_step``."""
        features = self.features(action, context, com_state.dtype)
        next_state = self.model.predict(com_state, features)
        if self.scoring is None:
            return next_state, torch.zeros_like(next_state[..., :1]), step + 1
        info = {"task_episode": episode.squeeze(-1), "task_step": step.squeeze(-1)}
        cost = self.scoring(com_state, next_state, action, info)
        return next_state, -cost.unsqueeze(-1).to(next_state.dtype), step + 1

    def particles_forward(self, com_state, action, episode, step, particles, spent, *context):
        """As :meth:`forward` with ``P`` particles ``... x P x 5`` and their costs so far ``... x P``; also returns
        the next particles and their costs."""
        features = self.features(action, context, com_state.dtype)
        next_particles = self.model.predict_particles(particles, features.unsqueeze(-2), self.generator)
        next_state, spread = particle_moments(next_particles)
        total = spent
        if self.scoring is not None:
            info = {"task_episode": episode, "task_step": step, "next_com_state_mean": next_state.unsqueeze(-2),
                    "next_com_state_std": spread.unsqueeze(-2)}
            total = spent + self.scoring(particles, next_particles, action.unsqueeze(-2), info).to(spent.dtype)
        reward = -(risk_of(total, self.risk, self.beta) - risk_of(spent, self.risk, self.beta)).unsqueeze(-1)
        return next_state, reward, step + 1, next_particles, total


class _StepModule(TensorDictModuleBase):
    """:class:`_CoMStep` on TensorDicts; the particle keys are made from ``com_state`` when a state lacks them; the
    done flags are set at the task's end."""

    def __init__(self, module: _CoMStep, context_keys: Sequence[str] = ()):
        super().__init__()
        self.module = module
        self.context_keys = list(context_keys)
        self.in_keys = ["com_state", "action", "task_episode", "task_step", *self.context_keys]
        self.out_keys = ["com_state", "reward", "task_step"]
        if module.particles:
            self.in_keys += ["com_state_particles", "cost_particles"]
            self.out_keys += ["com_state_particles", "cost_particles"]
        self.out_keys += list(DONE_KEYS)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        inputs = [tensordict.get(key) for key in ("com_state", "action", "task_episode", "task_step")]
        missing = [key for key in self.context_keys if key not in tensordict.keys()]
        if missing:
            raise KeyError(f"the world model's dynamics model also reads {', '.join(missing)} (held over the horizon "
                           "from the measured state): give it in the state")
        context = [tensordict.get(key) for key in self.context_keys]
        if not self.module.particles:
            outputs = self.module(*inputs, *context)
        else:
            com_state = inputs[0]
            count, batch = self.module.particles, com_state.shape[:-1]
            particles = tensordict.get("com_state_particles", None)
            if particles is None:
                particles = com_state.unsqueeze(-2).expand(*batch, count, 5)
            spent = tensordict.get("cost_particles", None)
            if spent is None:
                spent = torch.zeros(*batch, count, dtype=com_state.dtype, device=com_state.device)
            outputs = self.module.particles_forward(*inputs, particles, spent, *context)
        next_step = outputs[2]
        task = self.module.task
        ended = (next_step >= task.num_steps if task is not None
                 else torch.zeros(next_step.shape, dtype=torch.bool, device=next_step.device))
        flags = (ended, ended.clone(), torch.zeros_like(ended))
        return tensordict.update(dict(zip(self.out_keys, (*outputs, *flags))))


def _check_risk(model: nn.Module, risk: str, beta: float) -> None:
    if risk not in RISKS:
        raise ValueError(f"risk must be one of {', '.join(RISKS)}, got {risk!r}")
    if isinstance(beta, bool) or not isinstance(beta, (int, float)) or beta != beta or abs(beta) == float("inf"):
        raise ValueError(f"beta must be a finite number, got {beta!r}")
    if risk != "none" and not hasattr(model, "predict_particles"):
        raise ValueError(f"risk {risk!r} needs a model with members (e.g. the ensemble); {type(model).__name__} "
                         "predicts one state")


class CoMWorldModelEnv(ModelBasedEnvBase):
    """A world model env over a learned CoM dynamics model (anything with ``predict(com_state, action)``).

    Args:
        model: the dynamics model, e.g. :class:`hierloco.components.com_model.CoMDynamicsModel` or the ensemble
            :class:`hierloco.components.com_ensemble.CoMEnsembleModel` (then particles, see the module doc).
        action_low, action_high: the action box (``A``); with ``num_choices`` the action is an index in
            ``[0, num_choices)`` (LIB's experts), passed to the model as a float.
        task: the task: its episodes' start state and, unless ``cost`` is given, the cost (reward ``-cost``);
            ``None`` with no ``cost`` gives zero reward.
        cost: a cost callable ``(com_state, next_com_state, action, info) -> ...`` (see the module doc) used instead
            of the task's.
        action_features: maps actions to the model's input features (e.g. expert indices to one-hot vectors,
            :meth:`hierloco.components.low_level.LowLevel.action_features`); default: the actions themselves.
        risk: ``"none"``, ``"mean_std"`` or ``"pessimistic"``: how the particles' costs make the reward (a model with
            particles only). beta: the weight of the standard deviation in ``mean_std``.
        seed: seeds the draws of a model that samples its particles (trajectory sampling, moment matching).
        context: state keys the model also reads, name -> size ``C`` (e.g. ``{"body_state": 3}``: roll, pitch and
            height, :class:`~hierloco.envs.latent_env.LatentActionEnv`): taken from the measured state, held over
            the horizon and appended to the action's features (a model trained on them, ``dynamics.body_state``,
            ``docs/terrain.md``); they join :attr:`measured_keys`.
    """

    def __init__(self, model: nn.Module, *, action_low: Sequence[float] | None = None,
                 action_high: Sequence[float] | None = None, num_choices: int | None = None,
                 task: Task | None = None, action_features=None, device: str = "cpu", cost: Cost | None = None,
                 risk: str = "none", beta: float = 1.0, seed: int = 0, context: dict | None = None):
        _check_risk(model, risk, beta)
        if cost is not None and not callable(cost):
            raise ValueError(f"cost must be a callable (com_state, next_com_state, action, info), got {cost!r}")
        self.generator = torch.Generator(device=device).manual_seed(int(seed))
        step = _CoMStep(model, task, cost, action_features, risk=risk, beta=beta, generator=self.generator)
        self.context = {str(key): int(size) for key, size in (context or {}).items()}
        bad = [key for key, size in self.context.items() if size < 1 or key in MEASURED_KEYS]
        if bad:
            raise ValueError(f"context: {', '.join(bad)} must be other keys than {', '.join(MEASURED_KEYS)}, each of "
                             "size >= 1")
        super().__init__(_StepModule(step, list(self.context)), device=device)
        self.model = model
        self.task = task
        if task is not None and hasattr(task, "to_device"):
            task.to_device(self.device)
        self.cost = cost
        self.risk, self.beta = risk, float(beta)
        self.num_particles = step.particles
        self.measured_keys = [*MEASURED_KEYS, *self.context]
        observation = dict(
            com_state=Unbounded((5,), device=self.device),
            task_episode=Unbounded((1,), dtype=torch.int64, device=self.device),
            task_step=Unbounded((1,), dtype=torch.int64, device=self.device),
            **{key: Unbounded((size,), device=self.device) for key, size in self.context.items()},
        )
        if self.num_particles:
            observation["com_state_particles"] = Unbounded((self.num_particles, 5), device=self.device)
            observation["cost_particles"] = Unbounded((self.num_particles,), device=self.device)
        self.observation_spec = Composite(observation, device=self.device)
        if num_choices is not None:
            if int(num_choices) < 1:
                raise ValueError(f"num_choices must be at least 1, got {num_choices}")
            self.action_spec = Categorical(int(num_choices), (1,), dtype=torch.int64, device=self.device)
        else:
            if action_low is None or action_high is None:
                raise ValueError("give the action box (action_low and action_high) or num_choices")
            low = torch.as_tensor(action_low, dtype=torch.float32, device=self.device)
            high = torch.as_tensor(action_high, dtype=torch.float32, device=self.device)
            if low.shape != high.shape or low.ndim != 1 or not torch.all(low <= high):
                raise ValueError(f"bad action box: low {action_low}, high {action_high}")
            self.action_spec = Bounded(low, high, low.shape, device=self.device)
        self.reward_spec = Unbounded((1,), device=self.device)
        flag = Categorical(2, (1,), dtype=torch.bool, device=self.device)
        self.done_spec = Composite({key: flag.clone() for key in DONE_KEYS}, device=self.device)

    def set_task(self, task: Task | None) -> None:
        """Pursues ``task`` from now on (the model is kept): its cost scores transitions unless a ``cost`` was
        given (:meth:`set_cost`)."""
        self.task = task
        self.world_model.module.task = task
        if task is not None and hasattr(task, "to_device"):
            task.to_device(self.device)  # its targets, once, where the costs are computed

    def set_cost(self, cost: Cost | None) -> None:
        """Scores transitions with ``cost`` from now on (``None``: the task's cost again)."""
        if cost is not None and not callable(cost):
            raise ValueError(f"cost must be a callable (com_state, next_com_state, action, info), got {cost!r}")
        self.cost = cost
        self.world_model.module.cost = cost

    def set_risk(self, risk: str = "none", beta: float = 1.0) -> None:
        """Aggregates the particles' costs by ``risk`` (``none``, ``mean_std`` with ``beta``, ``pessimistic``) from
        now on."""
        _check_risk(self.model, risk, beta)
        self.risk, self.beta = risk, float(beta)
        self.world_model.module.risk, self.world_model.module.beta = risk, float(beta)

    def imagined_return(self, com_state: torch.Tensor, episode: torch.Tensor, step: torch.Tensor,
                        actions: torch.Tensor, *context: torch.Tensor) -> torch.Tensor:
        """``B x S`` summed rewards of ``B x S x H x A`` action sequences from ``B`` measured states (``com_state``
        ``B x 5``, ``episode`` and ``step`` ``B x 1``): what :meth:`step` gives over the horizon, summed, on tensors
        alone (no TensorDict), so that ``torch.compile`` captures a planner's whole scoring in one graph
        (:meth:`hierloco.components.planners.BoxPlannerBase.set_scoring`). Particles start at ``com_state``;
        ``context``: the :attr:`context` tensors ``B x C`` in its order."""
        module = self.world_model.module
        batch, count, horizon = actions.shape[:3]
        state = com_state.unsqueeze(1).expand(batch, count, com_state.shape[-1])
        episode = episode.unsqueeze(1).expand(batch, count, episode.shape[-1])
        step = step.unsqueeze(1).expand(batch, count, step.shape[-1])
        context = [c.unsqueeze(1).expand(batch, count, c.shape[-1]) for c in context]
        total = com_state.new_zeros(batch, count)
        if module.particles:
            particles = state.unsqueeze(-2).expand(batch, count, module.particles, state.shape[-1])
            spent = com_state.new_zeros(batch, count, module.particles)
        for h in range(horizon):
            if module.particles:
                state, reward, step, particles, spent = module.particles_forward(state, actions[:, :, h], episode,
                                                                                 step, particles, spent, *context)
            else:
                state, reward, step = module(state, actions[:, :, h], episode, step, *context)
            total = total + reward.squeeze(-1)
        return total

    def initial_state(self, com_state: torch.Tensor | None = None, episode=0, step=0) -> TensorDict:
        """A state TensorDict: ``com_state`` (default: the task's start) at ``task_episode``/``task_step``."""
        episode = torch.as_tensor(episode, dtype=torch.int64, device=self.device)
        step = torch.as_tensor(step, dtype=torch.int64, device=self.device)
        if com_state is None:
            start = self.task.start_state() if self.task is not None else torch.zeros(5, device=self.device)
            com_state = start.to(self.device).expand(*torch.broadcast_shapes(episode.shape, step.shape), 5)
        com_state = torch.as_tensor(com_state, dtype=torch.float32, device=self.device)
        batch = com_state.shape[:-1]
        state = {"com_state": com_state, "task_episode": episode.expand(batch).unsqueeze(-1).clone(),
                 "task_step": step.expand(batch).unsqueeze(-1).clone()}
        if self.num_particles:
            state["com_state_particles"] = com_state.unsqueeze(-2).expand(*batch, self.num_particles, 5).clone()
            state["cost_particles"] = torch.zeros(*batch, self.num_particles, device=self.device)
        return TensorDict(state, batch_size=batch, device=self.device)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        if tensordict is not None and "com_state" in tensordict.keys():
            out = tensordict.select("com_state", "task_episode", "task_step", *self.context, strict=False).clone()
            if "task_episode" not in out.keys():
                out.update(self.initial_state(out["com_state"]).exclude("com_state"))
            if self.num_particles:  # a measured state: every particle starts there, nothing spent yet
                out.update(self.initial_state(out["com_state"]).select("com_state_particles", "cost_particles"))
            return out
        batch = tensordict.batch_size if tensordict is not None else torch.Size([])
        return self.initial_state(episode=torch.zeros(batch, dtype=torch.int64, device=self.device))
