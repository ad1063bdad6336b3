"""Is SAC-SAC's low-level training reproducible? The paper preset's first frames, trained twice on this machine
with the same seed, compared number for number and weight for weight, and against learning curves recorded on other
machines.

    PYTHONPATH=. .venv/bin/python benchmarks/sac_reproducibility.py --robot a1 --frames 34016 \\
        --against results/sac_sac_low_level/a1_seed0/report.md results/sac_sac_low_level/a1_seed0_rerun/report.md

Each run trains :func:`hierloco.components.sac_low_level.train_sac_low_level` with the settings of
``recipes/sac_sac/low_level/paper.yaml`` (one torch thread, one simulation thread) for ``--frames`` frames, logging
the learning curve every ``--log-every`` frames as the recipe does at paper scale (850,000 // 50). Prints whether the
two runs' curves and final weights are identical, this machine's CPU and library versions, and each ``--against``
report's learning-curve rows at the same frames (the ``report.md`` of a recipe run,
``python recipes/sac_sac/report.py``). Identical runs here with curves that differ from another machine's rows mean
the training is deterministic on one machine and its floating-point results differ between machines.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import mujoco
import torch
import yaml

from hierloco.components.sac_low_level import train_sac_low_level
from hierloco.pipeline.rundir import cpu_description

PAPER = Path(__file__).resolve().parents[1] / "recipes" / "sac_sac" / "low_level" / "paper.yaml"
CURVE_ROW = re.compile(r"^\| (\d+) \| (\d+) \| ([-\d.]+) \| ([-\d.]+) \| ([-\d.]+) \|$")


def train(robot: str, frames: int, log_every: int, seed: int):
    settings = {**yaml.safe_load(PAPER.read_text()), "total_frames": frames, "seed": seed}
    trained = train_sac_low_level(robot, log_every=log_every, nthread=1, progress=False, **settings)
    curve = [(p["frames"], round(p["reward"], 3), round(p["tracking_error"], 3))
             for p in trained.metadata["learning_curve"]]
    weights = torch.cat([p.detach().flatten() for p in trained.agent.actor.parameters()])
    return curve, weights


def recorded_curve(report: Path) -> dict[int, tuple[float, float]]:
    """frames -> (reward per step, tracking error) from a ``report.md``'s learning-curve table."""
    rows = (CURVE_ROW.match(line.strip()) for line in report.read_text().splitlines())
    return {int(m[1]): (float(m[3]), float(m[4])) for m in rows if m}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="a1")
    parser.add_argument("--frames", type=int, default=34016)
    parser.add_argument("--log-every", type=int, default=17000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--against", nargs="*", type=Path, default=[])
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"machine: {cpu_description()}; torch {torch.__version__}, mujoco {mujoco.__version__}")
    (first, first_weights), (second, second_weights) = (train(args.robot, args.frames, args.log_every, args.seed)
                                                        for _ in range(2))
    same = first == second and torch.equal(first_weights, second_weights)
    print(f"two runs here, seed {args.seed}, {args.frames} frames: "
          + ("identical (learning curve and actor weights)" if same else "DIFFERENT"))
    print("| frames | run 1 reward/step | run 1 tracking m/s | run 2 reward/step | run 2 tracking m/s |"
          + "".join(f" {r.parent.name} reward/step | {r.parent.name} tracking m/s |" for r in args.against))
    print("|---|---|---|---|---|" + "---|---|" * len(args.against))
    recorded = [recorded_curve(r) for r in args.against]
    for (frames, reward, error), (_, reward2, error2) in zip(first, second):
        cells = [f"{reward:.3f} | {error:.3f} | {reward2:.3f} | {error2:.3f}"]
        cells += [" | ".join(f"{v:.3f}" for v in rows[frames]) if frames in rows else "- | -" for rows in recorded]
        print(f"| {frames} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
