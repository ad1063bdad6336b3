"""MPPI over a box: reward-weighted averaging of sampled plans, with a warm start from the previous plan."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

from hierloco.components.planners.base import PLANNERS, BoxPlannerBase


@PLANNERS.register("mppi")
class BoxMPPIPlanner(BoxPlannerBase):
    """MPPI: samples around a mean plan, weights them by ``softmax(return / temperature)``, averages; repeats.

    The first mean is the previous plan shifted by one action (warm start) or the box centre; the sampling standard
    deviation is ``noise_scale`` times the box half-width. Returns the first action of the final mean plan.

    Args:
        temperature: in units of the summed reward (task cost). optim_steps: refinements per call.
    """

    def __init__(self, env, planning_horizon: int = 1, num_candidates: int = 1000, optim_steps: int = 5,
                 temperature: float = 0.05, noise_scale: float = 0.5, seed: int = 0):
        super().__init__(env, planning_horizon, num_candidates, seed)
        if not temperature > 0 or not noise_scale > 0 or optim_steps < 1:
            raise ValueError("need temperature > 0, noise_scale > 0 and optim_steps >= 1")
        self.temperature, self.noise_scale, self.optim_steps = float(temperature), float(noise_scale), int(optim_steps)

    @torch.no_grad()
    def planning(self, tensordict: TensorDictBase) -> torch.Tensor:
        td = self._flat(tensordict)
        batch = td.batch_size[0]
        mean = self.initial_mean(batch)
        std = self.noise_scale * (self.high - self.low) / 2
        for _ in range(self.optim_steps):
            noise = self.sample_normal((batch, self.num_candidates, *mean.shape[1:]))
            candidates = self.clip(mean[:, None] + std * noise)
            scores = self.score(td, candidates)
            weights = torch.softmax((scores - scores.max(1, keepdim=True).values) / self.temperature, dim=1)
            mean = (weights[..., None, None] * candidates).sum(1)
        self._previous = mean
        return self._output(tensordict, mean[:, 0])
