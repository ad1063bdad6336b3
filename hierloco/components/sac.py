"""SAC parts for a goal-conditioned high level: actor, Q networks, loss and one training update (SPEC 7).

The actor maps a goal observation (:class:`hierloco.envs.transforms.GoalObservation`) to an action in a box (a
latent z for the SAC baseline, a velocity command for SAC-SAC's high level) through a tanh-squashed Gaussian; two
Q networks score (observation, action). The loss is TorchRL's :class:`~torchrl.objectives.SACLoss` with a learned
temperature and soft-updated target Q networks.

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> agent = SACAgent.build(observation_dim=7, action_low=[-1.0, -1.0], action_high=[1.0, 1.0], hidden=32)
    >>> td = agent.actor(TensorDict({"goal_observation": torch.zeros(4, 7)}, batch_size=[4]))
    >>> td["action"].shape
    torch.Size([4, 2])
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.data import Bounded
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate

from hierloco.io import load_checkpoint, save_checkpoint

CHECKPOINT_KIND, CHECKPOINT_FORMAT = "sac_agent", 1


@dataclass
class SACAgent:
    """The actor, the Q networks, the SAC loss, its optimisers and the target-network updater."""

    actor: ProbabilisticActor
    qvalue: ValueOperator
    loss: SACLoss
    optimizer: torch.optim.Optimizer
    target_updater: SoftUpdate
    config: dict
    metadata: dict = field(default_factory=dict)

    @classmethod
    def build(cls, observation_dim: int, action_low: Sequence[float], action_high: Sequence[float], *,
              hidden: int = 256, lr: float = 3e-4, gamma: float = 0.95, tau: float = 0.005,
              observation_key: str = "goal_observation", seed: int = 0) -> "SACAgent":
        """Networks with 2 hidden layers of ``hidden`` ReLU units; actions in ``[action_low, action_high]``."""
        config = {"observation_dim": int(observation_dim), "action_low": [float(v) for v in action_low],
                  "action_high": [float(v) for v in action_high], "hidden": int(hidden), "lr": float(lr),
                  "gamma": float(gamma), "tau": float(tau), "observation_key": observation_key, "seed": int(seed)}
        low = torch.as_tensor(config["action_low"])
        high = torch.as_tensor(config["action_high"])
        if low.ndim != 1 or low.shape != high.shape or not torch.all(low < high):
            raise ValueError(f"bad action box: low {action_low}, high {action_high}")
        dim = len(low)
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            net = nn.Sequential(MLP(in_features=observation_dim, out_features=2 * dim, num_cells=[hidden, hidden],
                                    activation_class=nn.ReLU), NormalParamExtractor())
            actor = ProbabilisticActor(
                TensorDictModule(net, in_keys=[observation_key], out_keys=["loc", "scale"]),
                spec=Bounded(low, high, (dim,)), in_keys=["loc", "scale"], distribution_class=TanhNormal,
                distribution_kwargs={"low": low, "high": high}, return_log_prob=False)
            qvalue = ValueOperator(MLP(in_features=observation_dim + dim, out_features=1, num_cells=[hidden, hidden],
                                       activation_class=nn.ReLU), in_keys=[observation_key, "action"])
        loss = SACLoss(actor, qvalue, num_qvalue_nets=2, loss_function="l2", alpha_init=1.0)
        loss.make_value_estimator(gamma=gamma)
        optimizer = torch.optim.Adam(loss.parameters(), lr=lr)
        return cls(actor, qvalue, loss, optimizer, SoftUpdate(loss, tau=tau), config)

    def update(self, batch: TensorDictBase) -> dict:
        """One gradient step on a replay batch; returns the detached loss terms and the temperature."""
        out = self.loss(batch)
        total = out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]
        self.optimizer.zero_grad(set_to_none=True)
        total.backward()
        self.optimizer.step()
        self.target_updater.step()
        return {key: float(out[key].detach()) for key in ("loss_actor", "loss_qvalue", "loss_alpha", "alpha")}

    def save(self, path: str | os.PathLike) -> None:
        """Writes a checkpoint (config, networks, temperature, targets, metadata) to ``path`` atomically."""
        save_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, {
            "config": self.config, "loss_state": self.loss.state_dict(), "metadata": dict(self.metadata)})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SACAgent":
        """The agent (actor, Q networks, temperature, targets) with the metadata saved with it."""
        payload = load_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT)
        agent = cls.build(**payload["config"])
        agent.loss.load_state_dict(payload["loss_state"])
        agent.metadata = payload["metadata"]
        return agent
