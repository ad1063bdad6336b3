"""Exhaustive MPC over a finite action set (LIB's experts): every sequence of H choices is scored."""

from __future__ import annotations

import itertools

import torch
from tensordict import TensorDictBase

from hierloco.components.planners.base import PLANNERS, BoxPlannerBase


@PLANNERS.register("exhaustive")
class ExhaustivePlanner(BoxPlannerBase):
    """Scores all ``G ** H`` sequences over a finite action set and returns the first action of the best.

    Works on a world model env whose action spec is ``Categorical(G)``, or on a box with an explicit ``choices``
    tensor (``G x A``) of actions to enumerate.
    """

    ACTION_SPACES = ("finite",)

    def __init__(self, env, planning_horizon: int = 1, choices: torch.Tensor | None = None, max_sequences=100_000):
        super().__init__(env, planning_horizon, num_candidates=1)
        device = self.low.device
        if choices is None:
            if not self.discrete:
                raise ValueError("ExhaustivePlanner needs a Categorical action spec or explicit choices")
            choices = torch.arange(env.action_spec.n, dtype=torch.float32, device=device)[:, None]
        choices = torch.as_tensor(choices, dtype=torch.float32, device=device)
        if choices.ndim != 2 or choices.shape[1] != self.action_dim:
            raise ValueError(f"choices must be G x {self.action_dim}, got {tuple(choices.shape)}")
        count = len(choices) ** self.planning_horizon
        if count > max_sequences:
            raise ValueError(f"{len(choices)} choices over horizon {self.planning_horizon} make {count} sequences, "
                             f"more than max_sequences={max_sequences}")
        index = torch.tensor(list(itertools.product(range(len(choices)), repeat=self.planning_horizon)), device=device)
        self.register_buffer("sequences", choices[index])  # G^H x H x A
        self.num_candidates = count

    @torch.no_grad()
    def planning(self, tensordict: TensorDictBase) -> torch.Tensor:
        td = self._flat(tensordict)
        batch = td.batch_size[0]
        candidates = self.sequences.expand(batch, *self.sequences.shape)
        best = self.score(td, candidates).argmax(1)
        plan = candidates[torch.arange(batch, device=best.device), best]
        self._previous = plan
        return self._output(tensordict, plan[:, 0])
