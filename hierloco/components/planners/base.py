"""What every hierloco planner shares: candidate scoring on a world model env, the action box, warm starts.

A planner subclass writes only ``planning(tensordict) -> action``; it proposes ``B x S x H x A`` candidate action
sequences and calls :meth:`BoxPlannerBase.score`, which rolls them out on the (not batch-locked) world model env and
sums the rewards over the horizon (Li et al., RA-L 2021, Sec. III-A.2, Eq. 1). Every planner is a
:class:`hierloco.components.policies.TaskPolicy`: :meth:`BoxPlannerBase.begin_task` re-targets the world model to a
task and forgets the warm start.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Categorical
from torchrl.modules.planners import MPCPlannerBase

from hierloco.components.policies import TaskPolicy
from hierloco.registry import Registry

# The planners by name (``planner.name``): a new planner is one subclass of :class:`BoxPlannerBase` decorated with
# ``@PLANNERS.register("name")``; its options are its constructor's keyword arguments (``docs/extending.md``).
PLANNERS = Registry("planner", context=("env", "planning_horizon", "seed", "choices"))


class BoxPlannerBase(MPCPlannerBase, TaskPolicy):
    """MPC over a box (or finite set) of actions with a learned world model.

    Args:
        env: a world model env, e.g. :class:`hierloco.envs.world_model.CoMWorldModelEnv` (to plan a task with
            :meth:`begin_task`, it needs ``set_task(task)``).
        planning_horizon: H, high-level actions looked ahead.
        num_candidates: S, action sequences scored per call and per robot.
        seed: seeds the planner's own random generator.
    """

    ACTION_SPACES = ("box",)  # what it plans over: "box" (a continuous box), "finite" (a set of choices)

    def __init__(self, env, planning_horizon: int = 1, num_candidates: int = 8000, seed: int = 0):
        super().__init__(env)
        if int(planning_horizon) < 1 or int(num_candidates) < 1:
            raise ValueError(f"need planning_horizon >= 1 and num_candidates >= 1, got {planning_horizon}, "
                             f"{num_candidates}")
        self.planning_horizon = int(planning_horizon)
        self.num_candidates = int(num_candidates)
        self.discrete = isinstance(env.action_spec, Categorical)
        if self.discrete:
            self.register_buffer("low", torch.zeros(1))
            self.register_buffer("high", torch.full((1,), float(env.action_spec.n - 1)))
        else:
            self.register_buffer("low", env.action_spec.space.low.clone().float())
            self.register_buffer("high", env.action_spec.space.high.clone().float())
        self.generator = torch.Generator(device=self.low.device).manual_seed(seed)
        self._previous = None  # B x H x A, the last plan (for warm starts)

    @property
    def action_dim(self) -> int:
        return self.low.shape[-1]

    def reset(self) -> None:
        """Forgets the previous plan (call between episodes)."""
        self._previous = None

    def begin_task(self, task) -> None:
        """Scores plans with ``task``'s cost from now on (the world model's ``set_task``) and forgets the previous
        plan."""
        self.env.set_task(task)
        self.reset()

    def sample_uniform(self, batch: int, count: int) -> torch.Tensor:
        """``batch x count x H x A`` action sequences uniform in the box."""
        shape = (batch, count, self.planning_horizon, self.action_dim)
        unit = torch.rand(shape, generator=self.generator, device=self.low.device)
        return self.low + (self.high - self.low) * unit

    def clip(self, actions: torch.Tensor) -> torch.Tensor:
        return torch.maximum(torch.minimum(actions, self.high), self.low)

    @torch.no_grad()
    def score(self, tensordict: TensorDictBase, actions: torch.Tensor) -> torch.Tensor:
        """Summed rewards ``B x S`` of the ``B x S x H x A`` action sequences from the states in ``tensordict``."""
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

    def initial_mean(self, batch: int) -> torch.Tensor:
        """``batch x H x A``: the warm start when there is one, else the centre of the box."""
        mean = self.warm_start(batch)
        if mean is None:
            mean = ((self.low + self.high) / 2).expand(batch, self.planning_horizon, -1)
        return mean

    def warm_start(self, batch: int) -> torch.Tensor | None:
        """The previous plan shifted by one action (its last action repeated), ``batch x H x A``, or ``None``."""
        previous = self._previous
        if previous is None or previous.shape[0] != batch:
            return None
        return torch.cat([previous[:, 1:], previous[:, -1:]], 1)

    def _flat(self, tensordict: TensorDictBase) -> TensorDictBase:
        if tensordict.batch_dims > 1:
            raise ValueError(f"planners take a 0- or 1-D batch of states, got batch size {tensordict.batch_size}")
        return tensordict.unsqueeze(0) if tensordict.batch_dims == 0 else tensordict

    def _output(self, tensordict: TensorDictBase, action: torch.Tensor) -> torch.Tensor:
        if self.discrete:
            action = action.round().long()
        return action[0] if tensordict.batch_dims == 0 else action
