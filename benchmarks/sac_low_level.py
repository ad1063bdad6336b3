"""SAC-SAC's low level on its own: train the 100 Hz velocity-tracking SAC policy, then measure it on a grid of
commands against the IK expert controller (the same commands, the same measurement).

    .venv/bin/python benchmarks/sac_low_level.py --robot a1 --total-frames 1000000 --out results/sac_low_level_a1

Training checkpoints to ``<out>/training.pt`` every ``--checkpoint-every`` frames: run the same command again after
a kill and it resumes (with a smaller ``--total-frames`` than already done it just evaluates). Writes
``<out>/sac_low_level.pt`` (the artifact), ``<out>/report.json`` (settings, wall-clock, learning curve, tracking
per command for SAC and IK), ``<out>/report.md`` (the same as tables) and ``<out>/learning_curve.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from hierloco.components.low_level import CommandLowLevel
from hierloco.components.sac_low_level import (
    SACLowLevel,
    command_grid,
    evaluate_velocity_tracking,
    train_sac_low_level,
)
from hierloco.io import write_text
from hierloco.recipes.sac_sac.report import learning_curve_markdown, plot_learning_curve, tracking_markdown


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="a1")
    parser.add_argument("--total-frames", type=int, default=1_000_000)
    parser.add_argument("--num-robots", type=int, default=32)
    parser.add_argument("--hidden", type=int, default=256)
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--updates-per-frame", type=float, default=1 / 32)
    parser.add_argument("--init-random-frames", type=int, default=10_000)
    parser.add_argument("--log-every", type=int, default=20_000)
    parser.add_argument("--checkpoint-every", type=int, default=50_000)
    parser.add_argument("--compile", action="store_true", help="compile the SAC update")
    parser.add_argument("--grid", type=int, default=3, help="commands per axis of the evaluation grid")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/sac_low_level_a1")
    return parser.parse_args(argv)


def main(argv=None) -> None:
    args = parse_args(argv)
    out = Path(args.out)
    start = time.perf_counter()
    trained = train_sac_low_level(
        args.robot, total_frames=args.total_frames, num_robots=args.num_robots, hidden=args.hidden,
        batch_size=args.batch_size, lr=args.lr, updates_per_frame=args.updates_per_frame,
        init_random_frames=args.init_random_frames, log_every=args.log_every,
        checkpoint_path=out / "training.pt", checkpoint_every=args.checkpoint_every, compile_update=args.compile,
        seed=args.seed)
    trained.save(out / "sac_low_level.pt")
    train_seconds = time.perf_counter() - start
    commands = command_grid(args.robot, args.grid)
    sac = evaluate_velocity_tracking(SACLowLevel(trained), commands, seed=args.seed)
    ik = evaluate_velocity_tracking(CommandLowLevel(args.robot, len(commands)), commands, seed=args.seed)
    meta = trained.metadata
    given = sys.argv[1:] if argv is None else list(argv)
    report = {"command": "python benchmarks/sac_low_level.py " + " ".join(given), "args": vars(args),
              "frames": meta["frames"], "updates": meta["updates"], "train_seconds_total": meta["train_seconds"],
              "seconds_this_run": meta["seconds"], "learning_curve": meta["learning_curve"],
              "tracking_sac": sac, "tracking_ik": ik, "wall_clock_this_invocation": time.perf_counter() - start,
              "train_wall_clock_this_invocation": train_seconds}
    write_text(out / "report.json", json.dumps(report, indent=1))
    text = (f"# SAC-SAC low level, {args.robot}\n\n{meta['frames']} frames, {meta['updates']} updates, "
            f"{meta['train_seconds'] / 60:.1f} min of training (all runs), settings {json.dumps(vars(args))}\n\n"
            f"## Learning curve\n\n" + learning_curve_markdown(meta["learning_curve"]) +
            f"\n\n## Tracking, SAC low level (deterministic actor)\n\n{tracking_markdown(sac)}\n\n"
            f"## Tracking, IK expert controller (reference)\n\n{tracking_markdown(ik)}\n")
    write_text(out / "report.md", text)
    plot_learning_curve(meta["learning_curve"], out / "learning_curve.png")
    print(text)
    print(f"mean SAC tracking error {np.mean([r['linear_error'] for r in sac['rows']]):.3f} m/s")


if __name__ == "__main__":
    main()
