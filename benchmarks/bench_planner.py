"""One MPC call against the bare batched model forward pass it is built on (target: within 2x,
``docs/index.md``, Performance).

The planner (random shooting, 8000 samples, horizon 1, a 2 x 512 CoM model, goal-reaching cost) samples the
candidates, rolls them through the TorchRL world model env, scores them with the task and picks the best; the
reference is only ``model(velocity, action)`` on the same 8000 inputs. Both are timed interleaved, fastest of N.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch

from hierloco.components.com_model import CoMDynamicsModel
from hierloco.components.planners import PLANNERS
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.world_model import CoMWorldModelEnv


@dataclass
class PlannerRow:
    planner: str
    num_candidates: int
    horizon: int
    robots: int
    plan_ms: float
    forward_ms: float

    @property
    def ratio(self) -> float:
        return self.plan_ms / self.forward_ms


def benchmark_planner(name: str = "random_shooting", num_candidates: int = 8000, horizon: int = 1,
                      robots: int = 1, latent_dim: int = 3, repeats: int = 20) -> PlannerRow:
    torch.manual_seed(0)
    model = CoMDynamicsModel(action_dim=latent_dim, hidden=512).eval()
    low, high = [-1.0] * latent_dim, [1.0] * latent_dim
    env = CoMWorldModelEnv(model, action_low=low, action_high=high, task=GoalReaching())
    planner = PLANNERS[name](env, planning_horizon=horizon, num_candidates=num_candidates)
    state = env.initial_state(episode=torch.arange(robots) % 8)
    velocity = torch.randn(robots * num_candidates * horizon, 2)
    action = torch.rand(robots * num_candidates * horizon, latent_dim) * 2 - 1

    def plan():
        planner(state.clone())

    @torch.no_grad()
    def forward():
        model(velocity, action)

    plan(), forward()
    best = {"plan": float("inf"), "forward": float("inf")}
    for _ in range(repeats):
        for key, fn in (("plan", plan), ("forward", forward)):
            start = time.perf_counter()
            fn()
            best[key] = min(best[key], time.perf_counter() - start)
    return PlannerRow(name, num_candidates, horizon, robots, 1000 * best["plan"], 1000 * best["forward"])


def format_table(rows: list[PlannerRow]) -> str:
    header = f"{'planner':<16}{'samples':>8}{'H':>3}{'robots':>7}{'plan ms':>10}{'forward ms':>12}{'ratio':>8}"
    lines = [header, "-" * len(header)]
    for r in rows:
        flag = "ok" if r.ratio <= 2.0 else "MISSED"
        lines.append(f"{r.planner:<16}{r.num_candidates:>8}{r.horizon:>3}{r.robots:>7}{r.plan_ms:>10.1f}"
                     f"{r.forward_ms:>12.1f}{r.ratio:>6.2f} {flag}")
    lines.append("target: one MPC call (8000 samples, 2 x 512 model) within 2x of the bare forward pass")
    return "\n".join(lines)


if __name__ == "__main__":
    print(format_table([benchmark_planner(), benchmark_planner(robots=8)]))
