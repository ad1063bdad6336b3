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
from hierloco.plots import plt, save_figure


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


def _table(report: dict) -> str:
    lines = ["| command (vx, vy, wz) | achieved | linear error m/s | yaw-rate error rad/s | fell |",
             "|---|---|---|---|---|"]
    for row in report["rows"]:
        c, a = row["command"], row["achieved"]
        lines.append(f"| ({c[0]:+.2f}, {c[1]:+.2f}, {c[2]:+.2f}) | ({a[0]:+.3f}, {a[1]:+.3f}, {a[2]:+.3f}) | "
                     f"{row['linear_error']:.3f} | {row['yaw_rate_error']:.3f} | {'yes' if row['fell'] else ''} |")
    s = report["summary"]
    lines.append(f"\nmean linear error {s['linear_error_mean']:.3f} m/s "
                 f"(standing still: {s['linear_error_standing']:.3f}), "
                 f"mean yaw-rate error {s['yaw_rate_error_mean']:.3f} rad/s (standing still: "
                 f"{s['yaw_rate_error_standing']:.3f}), fall rate {s['fall_rate']:.2f}")
    return "\n".join(lines)


def plot_learning_curve(curve: list[dict], path: Path) -> None:
    """Tracking error and reward per step against frames (exploring policy, as collected)."""
    frames = [p["frames"] / 1e3 for p in curve]
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.2))
    left.plot(frames, [p["tracking_error"] for p in curve])
    left.set(xlabel="frames (thousands)", ylabel="tracking error (m/s)", ylim=(0, None))
    right.plot(frames, [p["reward"] for p in curve])
    right.set(xlabel="frames (thousands)", ylabel="reward per step")
    fig.suptitle("SAC-SAC low level: learning curve")
    fig.tight_layout()
    save_figure(fig, path)


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
    curve = ["| frames | wall-clock s | updates | reward/step | tracking error m/s | falls per 1000 frames |",
             "|---|---|---|---|---|---|"]
    for p in meta["learning_curve"]:
        curve.append(f"| {p['frames']} | {p['seconds']:.0f} | {p['updates']} | {p['reward']:.3f} | "
                     f"{p['tracking_error']:.3f} | {p['falls_per_1000_frames']:.2f} |")
    text = (f"# SAC-SAC low level, {args.robot}\n\n{meta['frames']} frames, {meta['updates']} updates, "
            f"{meta['train_seconds'] / 60:.1f} min of training (all runs), settings {json.dumps(vars(args))}\n\n"
            f"## Learning curve\n\n" + "\n".join(curve) +
            f"\n\n## Tracking, SAC low level (deterministic actor)\n\n{_table(sac)}\n\n"
            f"## Tracking, IK expert controller (reference)\n\n{_table(ik)}\n")
    write_text(out / "report.md", text)
    plot_learning_curve(meta["learning_curve"], out / "learning_curve.png")
    print(text)
    print(f"mean SAC tracking error {np.mean([r['linear_error'] for r in sac['rows']]):.3f} m/s")


if __name__ == "__main__":
    main()
