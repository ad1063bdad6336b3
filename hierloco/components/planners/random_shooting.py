"""Random shooting: the paper's planner (8000 uniform samples, horizon 1 by default)."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

from hierloco.components.planners.base import PLANNERS, BoxPlannerBase


@PLANNERS.register("random_shooting")
class RandomShootingPlanner(BoxPlannerBase):
    """Samples ``num_candidates`` action sequences uniformly in the box and returns the first action of the best.

    Example:
        >>> import torch
        >>> from hierloco.envs.world_model import CoMWorldModelEnv
        >>> from hierloco.envs.tasks import GoalReaching
        >>> class Drift(torch.nn.Module):
        ...     def predict(self, s, a):
        ...         return torch.cat([s[..., :2] + a, s[..., 2:]], -1)
        >>> env = CoMWorldModelEnv(Drift(), action_low=[-0.3, -0.3], action_high=[0.3, 0.3], task=GoalReaching())
        >>> planner = RandomShootingPlanner(env, num_candidates=2000)
        >>> action = planner(env.initial_state(episode=torch.tensor([0])))["action"]  # goal 0 is at (2, 0)
        >>> bool(action[0, 0] > 0.25 and action[0, 1].abs() < 0.05)
        True
    """

    @torch.no_grad()
    def planning(self, tensordict: TensorDictBase) -> torch.Tensor:
        td = self._flat(tensordict)
        candidates = self.sample_uniform(td.batch_size[0], self.num_candidates)
        best = self.score(td, candidates).argmax(1)
        plan = candidates[torch.arange(len(best), device=best.device), best]  # B x H x A
        self._previous = plan
        return self._output(tensordict, plan[:, 0])
