"""The policy protocol of closed-loop task evaluation (:func:`hierloco.components.evaluation.run_task`).

A :class:`TaskPolicy` is told which task it is about to act on before the first step (:meth:`TaskPolicy.begin_task`):
an MPC planner re-targets its world model to the task's cost and forgets its warm start (Li et al., RA-L 2021,
Sec. III-A.2); a learned goal-conditioned policy reads its goal from its observation and needs nothing, so
:class:`ActorPolicy` wraps any TensorDict policy (e.g. a SAC actor, acting with the mode of its distribution).

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> from tensordict.nn import TensorDictModule
    >>> actor = TensorDictModule(torch.nn.Linear(7, 2), in_keys=["goal_observation"], out_keys=["action"])
    >>> policy = ActorPolicy(actor)
    >>> policy.begin_task(None)  # nothing to re-target
    >>> policy(TensorDict({"goal_observation": torch.zeros(3, 7)}, batch_size=[3]))["action"].shape
    torch.Size([3, 2])
"""

from __future__ import annotations

import abc

import torch
from tensordict import TensorDictBase
from tensordict.nn import InteractionType, TensorDictModuleBase, set_interaction_type


class TaskPolicy(abc.ABC):
    """What :func:`hierloco.components.evaluation.run_task` needs of a policy besides ``policy(tensordict)``:
    ``begin_task(task)``, called once before the task's episodes start."""

    @abc.abstractmethod
    def begin_task(self, task) -> None:
        """Prepares for the episodes of ``task`` (a :class:`hierloco.envs.tasks.Task`)."""


class ActorPolicy(TensorDictModuleBase, TaskPolicy):
    """A TensorDict policy that does not depend on the task beyond its observation, e.g. a trained SAC actor.

    Args:
        actor: reads ``actor.in_keys`` and writes ``actor.out_keys`` (the action).
        deterministic: act with the mode of the action distribution (no exploration), as for evaluation.

    It acts without gradients (``torch.no_grad``), on the actor's device: the observation is moved there and the
    action back to the device of the tensordict it was given (robots simulated on the CPU, an actor on a GPU).
    """

    def __init__(self, actor, *, deterministic: bool = True):
        super().__init__()
        self.actor = actor
        self.in_keys = list(getattr(actor, "in_keys", []))
        self.out_keys = list(getattr(actor, "out_keys", ["action"]))
        self.interaction = InteractionType.DETERMINISTIC if deterministic else InteractionType.RANDOM

    def begin_task(self, task) -> None:
        """Nothing to prepare: the goal comes with the observation."""

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        device = next((p.device for p in self.actor.parameters()), None) if isinstance(self.actor, torch.nn.Module) \
            else None
        with set_interaction_type(self.interaction):
            if device is None or tensordict.device in (None, device):
                return self.actor(tensordict)
            acted = self.actor(tensordict.select(*self.in_keys).to(device))
            return tensordict.update({key: acted.get(key).to(tensordict.device) for key in self.out_keys})


__all__ = ["ActorPolicy", "TaskPolicy"]
