"""The cross-entropy method over a box, with a warm start from the previous plan."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

from hierloco.components.planners.base import PLANNERS, BoxPlannerBase


@PLANNERS.register("cem")
class BoxCEMPlanner(BoxPlannerBase):
    """CEM: Gaussian sampling around a mean plan, refit to the ``top_k`` best sequences, ``optim_steps`` times.

    The first mean is the previous plan shifted by one action when there is one (warm start), else the box centre;
    the first standard deviation is half the box width. Samples are clipped to the box. Returns the first action of
    the best sequence seen.

    Args:
        optim_steps: refits per call. top_k: elites per refit. num_candidates: samples per refit.
    """

    def __init__(self, env, planning_horizon: int = 1, num_candidates: int = 1000, optim_steps: int = 5,
                 top_k: int = 50, seed: int = 0):
        super().__init__(env, planning_horizon, num_candidates, seed)
        if not 1 <= top_k <= num_candidates or optim_steps < 1:
            raise ValueError(f"need 1 <= top_k <= num_candidates and optim_steps >= 1, got {top_k}, {optim_steps}")
        self.optim_steps, self.top_k = int(optim_steps), int(top_k)

    @torch.no_grad()
    def planning(self, tensordict: TensorDictBase) -> torch.Tensor:
        td = self._flat(tensordict)
        batch = td.batch_size[0]
        mean = self.initial_mean(batch)
        std = ((self.high - self.low) / 2).expand_as(mean)
        best_score = torch.full((batch,), -torch.inf, device=mean.device)
        best_plan = mean.clone()
        rows = torch.arange(batch, device=mean.device)
        for _ in range(self.optim_steps):
            noise = self.sample_normal((batch, self.num_candidates, *mean.shape[1:]))
            candidates = self.clip(mean[:, None] + std[:, None] * noise)
            scores = self.score(td, candidates)
            top_scores, top = scores.topk(self.top_k, dim=1)
            improved = top_scores[:, 0] > best_score
            best_plan[improved] = candidates[rows, top[:, 0]][improved]
            best_score = torch.maximum(best_score, top_scores[:, 0])
            elites = candidates[rows[:, None], top]  # B x K x H x A
            mean, std = elites.mean(1), elites.std(1).clamp_min(1e-6)
        self._previous = best_plan
        return self._output(tensordict, best_plan[:, 0])
