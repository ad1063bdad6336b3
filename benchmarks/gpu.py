"""hierloco on a GPU (``docs/gpu.md``; targets in ``docs/index.md``, Performance): the hot loops against their bare
references, LAT end to end at paper scale, one SAC task at paper scale, and how far CUDA's numbers are from the CPU's.

    python benchmarks/gpu.py                                  # on a GPU machine: every section, results/bench/gpu.md
    python benchmarks/gpu.py --cpu-reference                  # + the same LAT run on the CPU beside it (tolerance)
    python benchmarks/gpu.py --device cpu --small --out /tmp/gpu.md   # the script's own check on a CPU machine

Without a GPU (and ``--device cuda``, the default) it prints one line and exits 0.

Sections:

- MPC call: one call of the paper's planner (random shooting, 8000 candidates, horizon 1, a 2 x 512 CoM model,
  goal-reaching cost) for 8 and 64 robots, the state coming from the CPU as in closed-loop evaluation, eager and
  compiled (``planner.compile``: CUDA graphs), in fp32, tf32 and bf16 (``planner.precision``), against the bare
  batched model forward on the same number of inputs, already on the device (eager fp32). Median of timed calls after
  a warm-up (compilation included there), synchronised.
- SAC update: one update of 2 x 512 networks on a batch of 512 (observation 48, action 12), eager, compiled
  (``torch.compile``) and graphed (``mode="reduce-overhead"``: CUDA graphs, what ``sac.compile=true`` does on a GPU),
  against a plain update of the same three networks (forward, MSE, backward, fused Adam).
- LAT end to end: ``recipes/lat/train.py`` at paper scale on A1 with ``device`` (a fresh run directory), its
  wall-clock and its stages'.
- SAC task: goal-conditioned SAC over z at paper scale (10,000 frames on 16 robots, batch 512, 2 x 512) on the LAT
  run's gait policy, goal reaching's training half.
- Numerics: the LAT run's CoM model on the device against the CPU (largest difference of its predictions), and the
  paper's planner on the device in fp32, tf32 and bf16 against the CPU in fp32 on the same candidates: how much more
  the picked actions cost, in units of the standing-still cost (the normalised metric's scale).
- With ``--cpu-reference``: the same LAT recipe with ``device=cpu`` runs at the same time on the other half of the
  cores (each run gets half), and the two runs' normalised costs per task are compared: the cpu/cuda tolerance of a
  whole run, where every stage differs by rounding (``docs/gpu.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hierloco.devices import is_cuda, synchronize  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda", help="cuda (default; without a GPU: skipped) or cpu")
    parser.add_argument("--out", help="the Markdown report (default results/bench/gpu.md on CUDA, none on the CPU)")
    parser.add_argument("--work", default="outputs/bench_gpu", help="run directories of the end-to-end sections")
    parser.add_argument("--repeats", type=int, default=50, help="timed calls of each micro-benchmark")
    parser.add_argument("--small", action="store_true",
                        help="small sizes and the tiny preset: checks the script itself, measures nothing")
    parser.add_argument("--skip", nargs="*", default=[], choices=["mpc", "sac_update", "lat", "sac_task", "numerics"],
                        help="sections to leave out")
    parser.add_argument("--cpu-reference", action="store_true",
                        help="run LAT with device=cpu beside the GPU run (half the cores each) and compare")
    return parser.parse_args(argv)


# ---------------------------------------------------------------------------------------------------- timing
def median_ms(fn, device, repeats: int, warmup: int = 5) -> float:
    """Median wall-clock of ``fn()`` in ms over ``repeats`` synchronised calls after ``warmup`` calls."""
    for _ in range(warmup):
        fn()
    synchronize(device)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        synchronize(device)
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------- MPC
def com_model(hidden: int, action_dim: int = 3):
    from hierloco.components.com_model import CoMDynamicsModel

    torch.manual_seed(0)
    return CoMDynamicsModel(action_dim=action_dim, hidden=hidden).eval()


def mpc_section(device, repeats: int, small: bool) -> str:
    """One MPC call against the bare forward (see the module doc)."""
    from hierloco.components.planners import make_planner
    from hierloco.envs.tasks import GoalReaching
    from hierloco.envs.world_model import CoMWorldModelEnv

    candidates, hidden = (500, 64) if small else (8000, 512)
    model = com_model(hidden).to(device)
    rows = []
    variants = [(False, "fp32"), (True, "fp32"), (True, "tf32"), (True, "bf16"), (False, "bf16")]
    for robots in (8, 64):
        inputs = robots * candidates
        velocity = torch.randn(inputs, 2, device=device)
        action = torch.rand(inputs, 3, device=device) * 2 - 1

        @torch.no_grad()
        def forward():
            model(velocity, action)

        bare = median_ms(forward, device, repeats)
        env = CoMWorldModelEnv(model, action_low=[-1.0] * 3, action_high=[1.0] * 3, task=GoalReaching(),
                               device=device)
        state = env.initial_state(episode=torch.arange(robots, device=device) % 8).cpu()  # as the robots give it
        for compiled, precision in variants:
            if robots == 64 and precision != "fp32":
                continue
            planner = make_planner(env, name="random_shooting", num_candidates=candidates, compile=compiled,
                                   precision=precision)
            start = time.perf_counter()
            planner(state.clone())
            synchronize(device)
            first = time.perf_counter() - start
            plan = median_ms(lambda: planner(state.clone()), device, repeats)
            rows.append([robots, candidates, "compiled" if compiled else "eager", precision, plan, bare, plan / bare,
                         first])
    return ("## MPC call (random shooting, horizon 1, 2 x 512 model, goal reaching; state from the CPU)\n\n"
            + table(["robots", "candidates", "scoring", "precision", "call ms", "bare forward ms (fp32)",
                     "ratio", "first call s"], rows)
            + "\n\ntargets (docs/index.md): 8 robots x 8000 <= 1.5 ms and <= 1.2x the bare forward\n")


# ---------------------------------------------------------------------------------------------------- SAC update
def sac_update_section(device, repeats: int, small: bool) -> str:
    from benchmarks.bench_sac import ACTION_DIM, OBSERVATION_DIM, _batch, reference_update
    from hierloco.components.sac import SACAgent

    hidden, size = (64, 64) if small else (512, 512)
    batch = _batch(size, torch.Generator().manual_seed(0)).to(device)
    reference = median_ms(reference_update(hidden, batch, device), device, repeats)
    rows = []
    modes = [("eager", False), ("compiled", "default"),
             ("graphed", "reduce-overhead" if is_cuda(device) else None)]
    for name, mode in modes:
        if mode is None:
            rows.append([name, "CUDA only", "", ""])
            continue
        agent = SACAgent.build(OBSERVATION_DIM, [-1.0] * ACTION_DIM, [1.0] * ACTION_DIM, hidden=hidden,
                               observation_key="observation", compile_update=mode, device=device)
        start = time.perf_counter()
        agent.update(batch, as_floats=False)
        synchronize(device)
        first = time.perf_counter() - start
        ms = median_ms(lambda: agent.update(batch, as_floats=False), device, repeats)
        rows.append([name, ms, ms / reference, first])
    return (f"## SAC update ({hidden} x {hidden}, batch {size}, observation {OBSERVATION_DIM}, action {ACTION_DIM})"
            f"\n\nplain update of the same networks: {reference:.3f} ms\n\n"
            + table(["update", "ms", "/ plain", "first call s"], rows)
            + "\n\ntarget (docs/index.md): one SAC update (2 x 512, batch 512) <= 1 ms\n")


# ---------------------------------------------------------------------------------------------------- end to end
def lat_command(run_dir: Path, device: str, threads: int, small: bool) -> list[str]:
    return [sys.executable, str(ROOT / "recipes" / "lat" / "train.py"), f"run_dir={run_dir}", f"device={device}",
            f"nthread={threads}", "progress=false", "logger.backends=[csv]", "eval.videos=[]", "eval.figures=false",
            *(["preset=tiny"] if small else [])]


def start_lat(run_dir: Path, device: str, threads: int, cores: list[int] | None, small: bool) -> subprocess.Popen:
    """A LAT run in a fresh run directory, on ``cores`` (all when ``None``), its log beside it."""
    import shutil

    shutil.rmtree(run_dir, ignore_errors=True)
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    log = open(run_dir.parent / f"{run_dir.name}.log", "w")
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "PYTHONPATH": f"{ROOT}:{os.environ.get('PYTHONPATH', '')}"}
    preexec = (lambda: os.sched_setaffinity(0, cores)) if cores else None
    return subprocess.Popen(lat_command(run_dir, device, threads, small), cwd=ROOT, stdout=log,
                            stderr=subprocess.STDOUT, env=env, preexec_fn=preexec)


def finished_lat(process: subprocess.Popen, run_dir: Path, start: float) -> dict:
    code = process.wait()
    seconds = time.perf_counter() - start
    if code != 0:
        tail = (run_dir.parent / f"{run_dir.name}.log").read_text().strip().splitlines()[-5:]
        raise RuntimeError(f"LAT run into {run_dir} failed (exit {code}): " + " | ".join(tail))
    report = json.loads((run_dir / "report.json").read_text())
    return {"seconds": seconds, "stages": report.get("stage_seconds", {}), "run_dir": run_dir}


def lat_section(result: dict, device: str, threads: int) -> str:
    stages = ", ".join(f"{name} {value:.1f}" for name, value in result["stages"].items())
    return (f"## LAT end to end (A1, device={device}, {threads} simulation thread{'s' if threads != 1 else ''})\n\n"
            f"wall-clock {result['seconds']:.1f} s (the process: start-up, every stage, the tables)\n\n"
            f"stages (s): {stages}\n\ntarget (docs/index.md): <= 60 s on one H200 with 16 cores\n")


def sac_task_section(lat_dir: Path, device, threads: int, small: bool) -> str:
    """Goal-conditioned SAC over z at paper scale on the LAT run's gait policy (the SAC recipe's stage)."""
    from hierloco.components.gait_policy import TrainedGaitPolicy
    from hierloco.components.low_level import LatentLowLevel
    from hierloco.components.sac import SACAgent, train_sac
    from hierloco.envs.tasks import GoalReaching
    from hierloco.envs.transforms import GoalObservation
    from hierloco.recipes.sac.utils import task_env

    frames, robots, hidden, batch = (64, 8, 32, 32) if small else (10_000, 16, 512, 512)
    trained = TrainedGaitPolicy.load(lat_dir / "gait_policy.pt")
    low_level = LatentLowLevel(trained, "a1", device=str(device))
    rows = []
    for name, mode in (("eager", False), ("graphed" if is_cuda(device) else "compiled", True)):
        env = task_env(low_level, GoalReaching().training_split(), robots, 0, nthread=threads)
        agent = SACAgent.build(GoalObservation.SIZE, low_level.action_low, low_level.action_high, hidden=hidden,
                               seed=0, device=device, compile_update=mode)
        start = time.perf_counter()
        report = train_sac(env, agent, total_frames=frames, init_random_frames=min(1000, frames // 2),
                           batch_size=batch, buffer_size=frames, progress=False, torch_threads_during=None)
        synchronize(device)
        seconds = time.perf_counter() - start
        env.close()
        rows.append([name, seconds, report["seconds"]["collection"], report["seconds"]["update"], report["updates"],
                     1000 * report["seconds"]["update"] / max(1, report["updates"])])
    return (f"## SAC task (goal reaching's training half, {frames} frames on {robots} robots, {hidden} x {hidden}, "
            f"batch {batch}, device={device})\n\n"
            + table(["update", "total s", "collection s", "updates s", "updates", "ms per update"], rows)
            + "\n\n(a compiled or graphed update's time includes its compilation, at the first update)\n")


def numerics_section(lat_dir: Path, device, small: bool) -> str:
    """The run's CoM model on the device against the CPU, and the planner's picks (see the module doc)."""
    from hierloco.envs.tasks import GoalReaching
    from hierloco.trained import load_run

    run = load_run(lat_dir)
    model_cpu = run.com_model().model
    model_dev = run.com_model(device=str(device)).model
    generator = torch.Generator().manual_seed(0)
    low, high = run.low_level().action_low, run.low_level().action_high
    action_dim = len(low)
    inputs = 10_000
    states = torch.randn(inputs, 5, generator=generator, device="cpu") * torch.tensor([1.0, 1.0, 1.0, 0.2, 0.2],
                                                                                    device="cpu")
    actions = torch.as_tensor(low, dtype=torch.float32, device="cpu") + torch.rand(
        inputs, action_dim, generator=generator, device="cpu") * torch.as_tensor(high - low, dtype=torch.float32,
                                                                                 device="cpu")
    with torch.no_grad():
        reference = model_cpu.predict(states, actions)
        difference = (model_dev.predict(states.to(device), actions.to(device)).cpu() - reference).abs().max()
    task = GoalReaching()
    episodes = torch.arange(8, device="cpu")
    start = task.start_state().repeat(8, 1)
    count = 500 if small else 8000
    box_low = torch.as_tensor(low, dtype=torch.float32, device="cpu")
    box_high = torch.as_tensor(high, dtype=torch.float32, device="cpu")
    candidates = box_low + (box_high - box_low) * torch.rand(8, count, 1, action_dim, generator=generator,
                                                             device="cpu")  # the same for every device

    def picked(device, precision: str) -> torch.Tensor:
        planner = run.planner(task, device=str(device), precision=precision)
        state = planner.env.initial_state(start.to(device), episode=episodes.to(device))
        best = planner.score(state, candidates.to(device)).argmax(1).cpu()
        return candidates[torch.arange(8, device="cpu"), best, 0]

    def cost(action):
        with torch.no_grad():
            following = model_cpu.predict(start, run.low_level().action_features(action))
        return task.cost(start, following, episodes, 0)

    reference_cost, standing = cost(picked("cpu", "fp32")), task.cost(start, start, episodes, 0)
    rows = []
    for precision in ("fp32", "tf32", "bf16"):
        excess = (cost(picked(device, precision)) - reference_cost) / standing
        rows.append([precision, float(excess.max()), float(excess.mean())])
    return (f"## Numerics: device={device} against the CPU\n\n"
            f"CoM model predictions on {inputs} random inputs: largest difference {float(difference):.2e} "
            "(m, rad, m/s)\n\n"
            f"The planner's picks (goal reaching, the 8 starts, the same {count} candidates), their cost under the "
            "CPU model minus the CPU pick's, in units of the standing-still cost:\n\n"
            + table(["precision on the device", "largest excess", "mean excess"], rows)
            + "\n\n(the precision test's bound: 0.01, tests/components/test_planner_scoring.py)\n")


def comparison_section(cpu: dict, gpu: dict, device: str) -> str:
    """The two LAT runs' normalised costs per setting and task."""
    import csv

    def costs(run_dir: Path) -> dict:
        values: dict = {}
        with open(run_dir / "results.csv") as handle:
            for row in csv.DictReader(handle):
                values.setdefault((row["setting"], row["task"]), []).append(float(row["normalized_cost"]))
        return {key: sum(v) / len(v) for key, v in values.items()}

    a, b = costs(cpu["run_dir"]), costs(gpu["run_dir"])
    rows = [[setting, task, a[(setting, task)], b[(setting, task)], b[(setting, task)] - a[(setting, task)]]
            for setting, task in sorted(a) if (setting, task) in b]
    return (f"## LAT: device=cpu against device={device} (the whole run, every stage on its device)"
            f"\n\ncpu run: {cpu['seconds']:.0f} s beside the GPU run on the other half of the cores\n\n"
            + table(["setting", "task", "normalised cost (cpu)", f"({device})", "difference"], rows)
            + "\n\nEvery stage's rounding differs, and closed-loop runs diverge from there: the difference is that "
              "of two runs, not of one number (docs/gpu.md)\n")


def machine(device) -> str:
    name = torch.cuda.get_device_name(torch.device(device)) if is_cuda(device) else platform.processor() or "CPU"
    return (f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {name}; {len(os.sched_getaffinity(0))} cores; "
            f"torch {torch.__version__}" + (f", CUDA {torch.version.cuda}" if is_cuda(device) else ""))


def main(argv=None) -> int:
    args = parse_args(argv)
    if is_cuda(args.device) and not torch.cuda.is_available():
        print("benchmarks/gpu.py: no GPU here (torch.cuda.is_available() is False): skipped")
        return 0
    device = torch.device(args.device)
    out = Path(args.out) if args.out else (ROOT / "results" / "bench" / "gpu.md" if is_cuda(device) else None)
    work = Path(args.work).resolve()
    cores = sorted(os.sched_getaffinity(0))
    mine, theirs = (cores[: len(cores) // 2], cores[len(cores) // 2:]) if args.cpu_reference else (cores, [])
    if theirs:
        os.sched_setaffinity(0, mine)
    threads = len(mine)
    torch.set_num_threads(threads)
    sections = [f"# hierloco on a GPU (`python benchmarks/gpu.py`)\n\n{machine(device)}\n"]

    def say(text: str) -> None:
        sections.append(text)
        print(text, flush=True)

    reference = None
    if theirs:  # the CPU run starts first, on the other half of the cores, and runs beside everything else
        reference = (start_lat(work / "lat_cpu", "cpu", len(theirs), theirs, args.small), time.perf_counter())
    if "mpc" not in args.skip:
        say(mpc_section(device, args.repeats, args.small))
    if "sac_update" not in args.skip:
        say(sac_update_section(device, args.repeats, args.small))
    lat = None
    if {"lat", "sac_task", "numerics"} - set(args.skip):
        start = time.perf_counter()
        lat = finished_lat(start_lat(work / f"lat_{device.type}", str(device), threads, None, args.small),
                           work / f"lat_{device.type}", start)
        if "lat" not in args.skip:
            say(lat_section(lat, str(device), threads))
    if lat is not None and "sac_task" not in args.skip:
        say(sac_task_section(lat["run_dir"], device, threads, args.small))
    if lat is not None and "numerics" not in args.skip:
        say(numerics_section(lat["run_dir"], device, args.small))
    if reference is not None:
        cpu = finished_lat(reference[0], work / "lat_cpu", reference[1])
        if lat is not None:
            say(comparison_section(cpu, lat, str(device)))
    if out is not None:
        from hierloco.io import write_text

        out.parent.mkdir(parents=True, exist_ok=True)
        write_text(out, "\n".join(sections))
        print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
