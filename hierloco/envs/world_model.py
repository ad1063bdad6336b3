"""The learned CoM dynamics as a TorchRL world model (``ModelBasedEnvBase``), scored by a task.

One step of this env is one high-level action: the dynamics model predicts the next world-frame CoM state from
the current one and the action; the reward is ``-cost`` of the task for that imagined transition at the current
task step, which the env then advances. It is not batch-locked, so TorchRL planners (and hierloco's) roll it out on
``B x S`` candidate actions at once.

State keys: ``com_state`` (``5``, world ``(x, y, yaw, vx, vy)``), ``task_episode`` and ``task_step`` (``1``, int64).

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
"""

from __future__ import annotations

from typing import Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase

from hierloco.envs.tasks import Task


class _CoMStep(nn.Module):
    """``(com_state, action, task_episode, task_step) -> (next com_state, reward, next task_step)``."""

    def __init__(self, model: nn.Module, task: Task | None, action_features=None):
        super().__init__()
        self.model = model
        self.task = task
        self.action_features = action_features

    def forward(self, com_state, action, episode, step):
        features = action if self.action_features is None else self.action_features(action)
        next_state = self.model.predict(com_state, features.to(com_state.dtype))
        if self.task is None:
            reward = torch.zeros_like(next_state[..., :1])
        else:
            cost = self.task.cost(com_state, next_state, episode.squeeze(-1), step.squeeze(-1))
            reward = -cost.unsqueeze(-1).to(next_state.dtype)
        return next_state, reward, step + 1


class CoMWorldModelEnv(ModelBasedEnvBase):
    """A world model env over a learned CoM dynamics model (anything with ``predict(com_state, action)``).

    Args:
        model: the dynamics model, e.g. :class:`hierloco.components.com_model.CoMDynamicsModel`.
        action_low, action_high: the action box (``A``); with ``num_choices`` the action is an index in
            ``[0, num_choices)`` (LIB's experts), passed to the model as a float.
        task: scores transitions (reward ``-cost``); ``None`` gives zero reward.
        action_features: maps actions to the model's input features (e.g. expert indices to one-hot vectors,
            :meth:`hierloco.components.low_level.LowLevel.action_features`); default: the actions themselves.
    """

    def __init__(self, model: nn.Module, *, action_low: Sequence[float] | None = None,
                 action_high: Sequence[float] | None = None, num_choices: int | None = None,
                 task: Task | None = None, action_features=None, device: str = "cpu"):
        step = TensorDictModule(_CoMStep(model, task, action_features),
                                in_keys=["com_state", "action", "task_episode", "task_step"],
                                out_keys=["com_state", "reward", "task_step"])
        super().__init__(step, device=device)
        self.model = model
        self.task = task
        self.observation_spec = Composite(
            com_state=Unbounded((5,), device=self.device),
            task_episode=Unbounded((1,), dtype=torch.int64, device=self.device),
            task_step=Unbounded((1,), dtype=torch.int64, device=self.device),
            device=self.device,
        )
        if num_choices is not None:
            if int(num_choices) < 1:
                raise ValueError(f"num_choices must be at least 1, got {num_choices}")
            self.action_spec = Categorical(int(num_choices), (1,), dtype=torch.int64, device=self.device)
        else:
            if action_low is None or action_high is None:
                raise ValueError("give the action box (action_low and action_high) or num_choices")
            low = torch.as_tensor(action_low, dtype=torch.float32)
            high = torch.as_tensor(action_high, dtype=torch.float32)
            if low.shape != high.shape or low.ndim != 1 or not torch.all(low <= high):
                raise ValueError(f"bad action box: low {action_low}, high {action_high}")
            self.action_spec = Bounded(low, high, low.shape, device=self.device)
        self.reward_spec = Unbounded((1,), device=self.device)

    def set_task(self, task: Task | None) -> None:
        """Scores with ``task`` from now on (the model is kept)."""
        self.task = task
        self.world_model.module.task = task

    def initial_state(self, com_state: torch.Tensor | None = None, episode=0, step=0) -> TensorDict:
        """A state TensorDict: ``com_state`` (default: the task's start) at ``task_episode``/``task_step``."""
        episode = torch.as_tensor(episode, dtype=torch.int64, device=self.device)
        step = torch.as_tensor(step, dtype=torch.int64, device=self.device)
        if com_state is None:
            start = self.task.start_state() if self.task is not None else torch.zeros(5)
            com_state = start.to(self.device).expand(*torch.broadcast_shapes(episode.shape, step.shape), 5)
        com_state = torch.as_tensor(com_state, dtype=torch.float32, device=self.device)
        batch = com_state.shape[:-1]
        return TensorDict({"com_state": com_state, "task_episode": episode.expand(batch).unsqueeze(-1).clone(),
                           "task_step": step.expand(batch).unsqueeze(-1).clone()}, batch_size=batch,
                          device=self.device)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        if tensordict is not None and "com_state" in tensordict.keys():
            out = tensordict.select("com_state", "task_episode", "task_step", strict=False).clone()
            if "task_episode" not in out.keys():
                out.update(self.initial_state(out["com_state"]).exclude("com_state"))
            return out
        batch = tensordict.batch_size if tensordict is not None else torch.Size([])
        return self.initial_state(episode=torch.zeros(batch, dtype=torch.int64))
