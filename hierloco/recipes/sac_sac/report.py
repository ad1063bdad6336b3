"""SAC-SAC's low level reported on its own (Li et al., RA-L 2021, Sec. IV-B): its learning curve, the budget the
curve suggests, and its velocity-tracking error per command.

    python recipes/sac_sac/report.py outputs/sac_sac/paper/a1_seed0 results/sac_sac_low_level/a1_seed0

Reads the run's ``sac_low_level.pt`` (its metadata holds the learning curve) and ``sac_low_level_tracking.json``;
writes ``report.md`` and ``learning_curve.png`` in the output directory. The tracking stage of the recipe writes
the same report into the run directory as it is built (``sac_low_level_report.md``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def tracking_markdown(report: dict) -> str:
    """Commanded against achieved velocity per command, then the means (the tracking stage's ``rows`` and
    ``summary``, see :func:`hierloco.components.sac_low_level.evaluate_velocity_tracking`)."""
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


def learning_curve_markdown(curve: list[dict]) -> str:
    """The curve as a table; with a wall-clock column when its points have one (a run directory's artifacts keep
    no wall-clock, see ``hierloco/pipeline/run.py``)."""
    timed = all("seconds" in p for p in curve)
    lines = ["| frames |" + (" wall-clock s |" if timed else "") + " updates | reward/step | tracking error m/s | "
             "falls per 1000 frames |", "|---|---|---|---|---|" + ("---|" if timed else "")]
    for p in curve:
        lines.append(f"| {p['frames']} |" + (f" {p['seconds']:.0f} |" if timed else "") + f" {p['updates']} | "
                     f"{p['reward']:.3f} | {p['tracking_error']:.3f} | {p['falls_per_1000_frames']:.2f} |")
    return "\n".join(lines)


def budget_from_curve(curve: list[dict], *, window: int = 5, tolerance: float = 0.1) -> dict:
    """What the learning curve says of the budget: the frames from which the tracking error (a moving mean over
    ``window`` log points) stays within ``tolerance`` (relative) of its final level (the mean of the last fifth of
    the curve), and whether it was still falling at the end (the last fifth's moving mean below the one before it by
    more than ``tolerance``).

    Returns ``{"final_error", "plateau_frames", "still_improving", "frames"}``; ``plateau_frames`` is ``None`` for a
    curve too short to judge (fewer than ``2 * window`` points).

    >>> curve = [{"frames": 1000 * i, "tracking_error": max(0.1, 1.0 - 0.1 * i)} for i in range(1, 31)]
    >>> budget_from_curve(curve)["plateau_frames"], budget_from_curve(curve)["still_improving"]
    (9000, False)
    """
    frames = np.array([p["frames"] for p in curve])
    error = np.array([p["tracking_error"] for p in curve], dtype=float)
    if len(error) < 2 * window:
        return {"final_error": float(error[-1]) if len(error) else float("nan"), "plateau_frames": None,
                "still_improving": None, "frames": int(frames[-1]) if len(frames) else 0}
    smooth = np.convolve(error, np.ones(window) / window, mode="valid")  # smooth[i]: points i .. i + window - 1
    fifth = max(1, len(error) // 5)
    final = float(error[-fifth:].mean())
    within = smooth <= final * (1 + tolerance)
    # the first point after which the moving mean never leaves the band again
    outside = np.flatnonzero(~within)
    first = 0 if len(outside) == 0 else outside[-1] + 1
    plateau = int(frames[min(first, len(frames) - 1)])  # where the first window wholly in the band starts
    before = float(error[-2 * fifth:-fifth].mean())
    return {"final_error": final, "plateau_frames": plateau, "still_improving": bool(final < before * (1 - tolerance)),
            "frames": int(frames[-1])}


def budget_sentence(budget: dict) -> str:
    if budget["plateau_frames"] is None:
        return f"{budget['frames']} frames: too few log points to judge the budget."
    verdict = ("still improving at the end: a larger budget would lower the error further"
               if budget["still_improving"] else
               f"flat from about {budget['plateau_frames']:,} frames (within 10 % of its final "
               f"{budget['final_error']:.3f} m/s): the {budget['frames']:,} frames used are "
               + ("enough" if budget["plateau_frames"] < budget["frames"] else "just enough"))
    return f"Tracking error of the exploring policy {verdict}."


def plot_learning_curve(curve: list[dict], path: Path, *, title: str = "SAC-SAC low level: learning curve") -> None:
    """Tracking error and reward per step against frames (exploring policy, as collected)."""
    from hierloco.plots import plt, save_figure

    frames = [p["frames"] / 1e3 for p in curve]
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.2))
    left.plot(frames, [p["tracking_error"] for p in curve])
    left.set(xlabel="frames (thousands)", ylabel="tracking error (m/s)", ylim=(0, None))
    right.plot(frames, [p["reward"] for p in curve])
    right.set(xlabel="frames (thousands)", ylabel="reward per step")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path)


ACTORS = {"stochastic": "samples of the policy (how the high level runs it)",
          "deterministic": "the deterministic actor (the policy's squashed mean)"}


def low_level_markdown(robot: str, metadata: dict, tracking: dict, settings: dict,
                       train_seconds: float | None = None, actor: str = "stochastic") -> str:
    """The whole report: budget used, the curve's verdict on it, the curve, the tracking table. ``train_seconds``:
    the training's wall-clock (a run's ``builds.json``), if known; ``actor``: how the tracking was measured
    (``"stochastic"`` or ``"deterministic"``, the recipe's ``low_level_actor``)."""
    if actor not in ACTORS:
        raise ValueError(f"actor must be one of {sorted(ACTORS)}, got {actor!r}")
    curve = metadata["learning_curve"]
    took = f", {train_seconds / 60:.1f} min of training" if train_seconds is not None else ""
    return (f"# SAC-SAC low level, {robot}\n\n{metadata['frames']:,} frames, {metadata['updates']:,} updates"
            f"{took}; settings {json.dumps(settings, sort_keys=True)}\n\n"
            f"{budget_sentence(budget_from_curve(curve))}\n\n"
            "The learning curve is measured on the exploring (stochastic) policy; the tracking table acts with "
            f"{ACTORS[actor]}, each command held from standing, the first action left out of the means; fallen "
            "robots are left out of the error means and counted in the fall rate.\n\n"
            f"## Learning curve\n\n{learning_curve_markdown(curve)}\n\n"
            f"## Tracking per command ({actor} actor)\n\n{tracking_markdown(tracking)}\n")


def write_low_level_report(out: Path, robot: str, metadata: dict, tracking: dict, settings: dict, *,
                           train_seconds: float | None = None, name: str = "report.md",
                           actor: str = "stochastic") -> Path:
    from hierloco.io import write_text

    out.mkdir(parents=True, exist_ok=True)
    write_text(out / name, low_level_markdown(robot, metadata, tracking, settings, train_seconds, actor))
    plot_learning_curve(metadata["learning_curve"], out / "learning_curve.png",
                        title=f"SAC-SAC low level ({robot}): learning curve")
    return out / name


def main(argv=None) -> None:
    from hierloco.components.sac_low_level import TrainedSACLowLevel
    from hierloco.pipeline.rundir import RunDirectory

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("error: usage: python recipes/sac_sac/report.py RUN_DIR OUT_DIR", file=sys.stderr)
        sys.exit(2)
    run_dir, out = Path(argv[0]), Path(argv[1])
    missing = [n for n in ("sac_low_level.pt", "sac_low_level_tracking.json") if not (run_dir / n).exists()]
    if missing:
        print(f"error: {run_dir} has no finished SAC-SAC low level: missing {', '.join(missing)}", file=sys.stderr)
        sys.exit(2)
    trained = TrainedSACLowLevel.load(run_dir / "sac_low_level.pt")
    tracking = json.loads((run_dir / "sac_low_level_tracking.json").read_text())
    params = json.loads((run_dir / "sac_low_level.pt.key.json").read_text())["params"]
    robot = json.loads((run_dir / "run.json").read_text())["robot"]
    seconds = RunDirectory(run_dir, readonly=True).builds().get("sac_low_level", {}).get("seconds")
    actor = json.loads((run_dir / "sac_low_level_tracking.json.key.json").read_text())["params"]["actor"]
    print(write_low_level_report(out, robot, trained.metadata, tracking, params, train_seconds=seconds, actor=actor))


if __name__ == "__main__":
    main()
