"""One SAC update (TorchRL ``SACLoss``) against a plain MLP update of the same size (target: within 3x).

    .venv/bin/python benchmarks/bench_sac.py                    # 256 x 256 and the paper's 512 x 512, batch = hidden
    .venv/bin/python benchmarks/bench_sac.py --compile          # also the torch.compile'd update (about 1 min each)
    .venv/bin/python benchmarks/bench_sac.py --high-level-frames 10000   # + SAC high-level training time on A1

"Same size" means the same three networks (the actor, ``obs -> hidden -> hidden -> 2A``, and two Q networks,
``obs + A -> hidden -> hidden -> 1``, ReLU), the same batch, the same fused Adam: the reference is one forward pass
of all three on the batch, an MSE loss on their outputs, one backward pass and one Adam step. A SAC update is
``SACAgent.update``: the SAC loss (actor on the batch and on the next observations, both Q nets on three inputs,
target Q nets, temperature), its backward pass, the Adam step and the soft target update; its arithmetic is about
1.8x the reference's, so the ratio cannot fall much below that. Workloads are timed interleaved, fastest of
``--repeats``, with one torch thread (what the training loops use; timed in the thread's CPU time, which a busy
shared machine does not inflate by preempting the call) and with the process's default threads (wall-clock);
"before" is the update as it was built before (the two Q nets vmapped, Adam's per-parameter loop) at the same
threads. Observation 48, action 12 (the SAC-SAC low
level on A1).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import torch
from tensordict import TensorDict
from torch import nn

from torchrl.objectives import SACLoss, SoftUpdate

from hierloco.components.sac import SACAgent, torch_threads

OBSERVATION_DIM, ACTION_DIM = 48, 12
TARGET_RATIO = 3.0


def _batch(size: int, generator: torch.Generator) -> TensorDict:
    done = torch.zeros(size, 1, dtype=torch.bool)
    return TensorDict({"observation": torch.randn(size, OBSERVATION_DIM, generator=generator),
                       "action": torch.rand(size, ACTION_DIM, generator=generator) * 2 - 1,
                       "next": {"observation": torch.randn(size, OBSERVATION_DIM, generator=generator),
                                "reward": torch.randn(size, 1, generator=generator), "done": done,
                                "terminated": done.clone()}}, batch_size=[size])


def _mlp(inputs: int, outputs: int, hidden: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(),
                         nn.Linear(hidden, outputs))


def reference_update(hidden: int, batch: TensorDict, device: str | torch.device = "cpu"):
    """The plain update of the same three networks on ``device`` (where ``batch`` is): forward, MSE, backward, fused
    Adam step (the reference of a SAC update here and in ``benchmarks/gpu.py``)."""
    nets = nn.ModuleList([_mlp(OBSERVATION_DIM, 2 * ACTION_DIM, hidden),
                          _mlp(OBSERVATION_DIM + ACTION_DIM, 1, hidden),
                          _mlp(OBSERVATION_DIM + ACTION_DIM, 1, hidden)]).to(device)
    optimizer = torch.optim.Adam(nets.parameters(), lr=1e-3, fused=True)
    obs, action, target = batch["observation"], batch["action"], batch["next", "reward"]
    obs_action = torch.cat([obs, action], -1)

    def update():
        loss = (nets[0](obs).pow(2).mean() + (nets[1](obs_action) - target).pow(2).mean()
                + (nets[2](obs_action) - target).pow(2).mean())
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()

    return update


def sac_agent(hidden: int, *, compile_update: bool = False, before: bool = False,
              observation_dim: int = OBSERVATION_DIM, action_low=None, action_high=None,
              observation_key: str = "observation", seed: int = 0) -> SACAgent:
    """The agent as built now, or (``before``) as it was built before this benchmark: the two Q nets vmapped and
    Adam's per-parameter loop."""
    low = [-1.0] * ACTION_DIM if action_low is None else action_low
    high = [1.0] * ACTION_DIM if action_high is None else action_high
    agent = SACAgent.build(observation_dim, low, high, hidden=hidden, observation_key=observation_key,
                           compile_update=compile_update, seed=seed)
    if before:
        loss = SACLoss(agent.actor, agent.qvalue, num_qvalue_nets=2, loss_function="l2",
                       alpha_init=agent.config["alpha_init"])
        loss.make_value_estimator(gamma=agent.config["gamma"])
        agent = SACAgent(agent.actor, agent.qvalue, loss, torch.optim.Adam(loss.parameters(), lr=agent.config["lr"]),
                         SoftUpdate(loss, tau=agent.config["tau"]), agent.config)
    return agent


def _fastest(workloads: dict, repeats: int, clock=time.perf_counter) -> dict:
    """Fastest of ``repeats`` interleaved calls of each workload, in ms of ``clock``."""
    for fn in workloads.values():  # warm-up
        fn(), fn()
    best = {name: float("inf") for name in workloads}
    for _ in range(repeats):
        for name, fn in workloads.items():
            start = clock()
            fn()
            best[name] = min(best[name], clock() - start)
    return {name: 1000 * value for name, value in best.items()}


@dataclass
class UpdateRow:
    hidden: int
    batch: int
    threads: int
    reference_ms: float
    sac_ms: float
    before_ms: float | None = None
    compiled_ms: float | None = None

    @property
    def ratio(self) -> float:
        return self.sac_ms / self.reference_ms


def benchmark_update(hidden: int, batch_size: int, threads: int, *, repeats: int = 20, compile_update: bool = False,
                     before: bool = False) -> UpdateRow:
    batch = _batch(batch_size, torch.Generator().manual_seed(0))
    with torch_threads(threads):
        workloads = {"reference": reference_update(hidden, batch)}
        agent = sac_agent(hidden)
        workloads["sac"] = lambda: agent.update(batch)
        if before:
            old = sac_agent(hidden, before=True)
            workloads["before"] = lambda: old.update(batch)
        if compile_update:
            compiled = sac_agent(hidden, compile_update=True)
            workloads["compiled"] = lambda: compiled.update(batch)
        # one thread: the calling thread's CPU time (a preempted call on a shared machine still counts only its
        # own work); more threads: wall-clock (the helper threads' work and waits are the point)
        best = _fastest(workloads, repeats, time.thread_time if threads == 1 else time.perf_counter)
    return UpdateRow(hidden, batch_size, threads, best["reference"], best["sac"], best.get("before"),
                     best.get("compiled"))


def compile_check(hidden: int = 256, batch_size: int = 256) -> dict:
    """Compile time of the update and its agreement with the eager update (same weights, batch and random draws:
    inductor's ``fallback_random``) over three updates."""
    import torch._inductor.config as inductor_config

    batch = _batch(batch_size, torch.Generator().manual_seed(1))
    eager, compiled = sac_agent(hidden), sac_agent(hidden, compile_update=True)
    worst = 0.0
    with torch_threads(1), inductor_config.patch(fallback_random=True):
        start = time.perf_counter()
        torch.manual_seed(0)
        first = compiled.update(batch.clone())
        compile_seconds = time.perf_counter() - start
        torch.manual_seed(0)
        reference = eager.update(batch.clone())
        worst = max(abs(first[k] - reference[k]) / max(1.0, abs(reference[k])) for k in reference)
        for step in range(2):
            outs = []
            for agent in (eager, compiled):
                torch.manual_seed(step + 1)
                outs.append(agent.update(batch.clone()))
            worst = max(worst, *(abs(outs[0][k] - outs[1][k]) / max(1.0, abs(outs[0][k])) for k in outs[0]))
    return {"compile_seconds": compile_seconds, "max_relative_difference": worst}


def batch_scaling(hidden: int = 512, batches=(256, 512, 1024), repeats: int = 10) -> list[tuple[int, float]]:
    """(batch, ms per update) for one agent: larger batches cost less per transition (fewer, larger updates)."""
    agent = sac_agent(hidden)
    with torch_threads(1):
        workloads = {b: (lambda td: (lambda: agent.update(td)))(_batch(b, torch.Generator().manual_seed(b)))
                     for b in batches}
        best = _fastest(workloads, repeats, time.thread_time)
    return [(b, best[b]) for b in batches]


def format_updates(rows: list[UpdateRow]) -> str:
    header = (f"{'hidden':>7}{'batch':>7}{'threads':>8}{'plain ms':>10}{'SAC ms':>9}{'ratio':>7}"
              f"{'before ms':>11}{'compiled ms':>13}{'ratio':>7}")
    lines = [header, "-" * len(header)]
    for r in rows:
        before = f"{r.before_ms:>11.1f}" if r.before_ms is not None else f"{'':>11}"
        compiled = (f"{r.compiled_ms:>13.1f}{r.compiled_ms / r.reference_ms:>7.2f}" if r.compiled_ms is not None
                    else "")
        flag = "ok" if r.ratio <= TARGET_RATIO else "MISSED"
        lines.append(f"{r.hidden:>7}{r.batch:>7}{r.threads:>8}{r.reference_ms:>10.1f}{r.sac_ms:>9.1f}"
                     f"{r.ratio:>7.2f}{before}{compiled}  {flag}")
    lines.append(f"target: one SAC update within {TARGET_RATIO:.0f}x a plain update of the same three networks "
                 "(forward + MSE + backward + Adam, same batch); 'before': vmapped Q nets, non-fused Adam, same "
                 "threads;\n"
                 "one thread: CPU time of the thread; more threads: wall-clock")
    return "\n".join(lines)


def high_level_training(frames: int, *, num_robots: int = 16, hidden: int = 512, batch_size: int = 512,
                        updates_per_frame: float = 1.0, before: bool = False, seed: int = 0) -> dict:
    """Wall-clock of goal-conditioned SAC over z on A1 (the SAC baseline's high level): ``frames`` latent actions on
    ``num_robots`` robots per collector step, goal reaching on half the goals. The LAT low level is a quick one (10
    experts, 100 epochs): its quality does not change the cost of a step. ``before``: the agent as it was built
    before (vmapped Q nets, non-fused Adam) on the default torch threads, as the SAC recipe ran."""
    from hierloco.components.expert_library import build_expert_library
    from hierloco.components.gait_policy import train_gait_policy
    from hierloco.components.low_level import LatentLowLevel
    from hierloco.components.sac import train_sac
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.envs.tasks import GoalReaching
    from hierloco.envs.transforms import GoalObservation, TaskTransform
    from torchrl.envs import Compose, TransformedEnv

    library = build_expert_library("a1", 10, seed=seed, progress=False)
    low = LatentLowLevel(train_gait_policy(library.joint_targets, periods_per_action=5, epochs=100, seed=seed,
                                           progress=False), "a1")
    full = GoalReaching()
    task = GoalReaching(goals=full.goals[::2].numpy(), num_steps=full.num_steps)
    env = TransformedEnv(LatentActionEnv(low, num_robots=num_robots, seed=seed),
                         Compose(TaskTransform(task, torch.arange(num_robots) % task.num_episodes),
                                 GoalObservation(task)))
    agent = sac_agent(hidden, before=before, observation_dim=GoalObservation.SIZE, action_low=low.action_low,
                      action_high=low.action_high, observation_key="goal_observation", seed=seed)
    report = train_sac(env, agent, total_frames=frames, init_random_frames=min(1000, frames // 2),
                       updates_per_frame=updates_per_frame, batch_size=batch_size, buffer_size=10_000,
                       log_every=max(1, frames // 4), torch_threads_during=None if before else 1, seed=seed,
                       progress=False, tag="sac_high_level")
    env.close()
    return {"frames": report["frames"], "updates": report["updates"], "seconds": report["train_seconds"],
            "collection_seconds": report["seconds"]["collection"], "update_seconds": report["seconds"]["update"],
            "reward_first": report["learning_curve"][0]["reward"],
            "reward_last": report["learning_curve"][-1]["reward"]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", type=int, default=[256, 512], help="hidden units (= batch size)")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--compile", action="store_true", help="also time the compiled update (and check it)")
    parser.add_argument("--high-level-frames", type=int, default=0,
                        help="also time SAC high-level training on A1 for this many frames, after and before")
    parser.add_argument("--before-frames", type=int, default=None,
                        help="frames of the 'before' high-level run (default: --high-level-frames)")
    parser.add_argument("--check", action="store_true", help="exit 1 when the one-thread ratio misses the target")
    args = parser.parse_args(argv)
    default_threads = torch.get_num_threads()
    rows = []
    for size in args.sizes:
        print(f"benchmarking SAC update, hidden {size}, batch {size} ...", flush=True)
        rows.append(benchmark_update(size, size, 1, repeats=args.repeats, compile_update=args.compile, before=True))
        if default_threads > 1:
            rows.append(benchmark_update(size, size, default_threads, repeats=max(3, args.repeats // 4), before=True))
    print()
    print(format_updates(rows))
    print("\nper-transition cost, hidden 512, one thread:")
    for batch, ms in batch_scaling():
        print(f"  batch {batch:>5}: {ms:7.1f} ms per update, {1000 * ms / batch:6.1f} us per transition")
    if args.compile:
        check = compile_check()
        print(f"\ncompiled update: first call (compile) {check['compile_seconds']:.0f} s; max relative difference to "
              f"the eager update over 3 updates {check['max_relative_difference']:.1e}")
    if args.high_level_frames:
        after = None
        for before in (False, True):
            frames = args.high_level_frames if not before or args.before_frames is None else args.before_frames
            label = ("before (default threads, vmapped Q nets, non-fused Adam)" if before
                     else "after (one thread, looped Q nets, fused Adam)")
            print(f"\nSAC high level on A1, {frames} frames, 2 x 512, batch 512, 16 robots per step: {label} ...",
                  flush=True)
            r = high_level_training(frames, before=before)
            print(f"  {r['seconds']:.0f} s: {r['update_seconds']:.0f} s in {r['updates']} updates "
                  f"({1000 * r['update_seconds'] / max(1, r['updates']):.0f} ms each), {r['collection_seconds']:.0f} s "
                  f"collecting; reward {r['reward_first']:.3f} -> {r['reward_last']:.3f}")
            if after is None:
                after = r
            elif r["frames"] != after["frames"]:  # the same run's cost at the 'after' run's length
                estimate = (r["collection_seconds"] / r["frames"] * after["frames"]
                            + r["update_seconds"] / max(1, r["updates"]) * after["updates"])
                print(f"  estimated for {after['frames']} frames ({after['updates']} updates): {estimate:.0f} s")
    if args.check and any(r.ratio > TARGET_RATIO for r in rows if r.threads == 1):
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
