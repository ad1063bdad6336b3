"""A demo of the foundation: each robot stands, then walks expert gaits in the batched simulator.

Run with ``python -m hierloco.demo [--robots a1 daisy] [--out outputs/demo]``. Prints a table of what happened
and writes a gait diagram per robot.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import ROBOTS, get_robot
from hierloco.plots import plot_gait_diagram

COMMANDS = np.array([[0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [-0.15, -0.15, 0.0], [0.0, 0.0, 0.3]])  # m/s, m/s, rad/s


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--robots", nargs="+", default=["a1", "daisy"], choices=sorted(ROBOTS))
    parser.add_argument("--out", default="outputs/demo")
    parser.add_argument("--seconds", type=float, default=6.0, help="walking time per command")
    args = parser.parse_args(argv)
    out_dir = Path(args.out)
    rows = []
    for name in args.robots:
        robot = get_robot(name)
        start = time.perf_counter()
        sim = BatchedSimulator(robot, 1)
        stand = sim.run(np.tile(np.asarray(robot.standing_pose), (1, 500, 1)))
        drift = np.ptp(stand.height[0, 50:])
        rows.append((name, "stand 5 s", "-", f"height drift {100 * drift:.1f} cm",
                     "yes" if stand.failed.any() else "no"))
        steps = int(args.seconds * 100)
        sim = BatchedSimulator(robot, len(COMMANDS))
        out = run_closed_loop(sim, RaibertController(robot, len(COMMANDS)), COMMANDS, steps, ramp_steps=100)
        velocity = out.com_velocity_local[:, 200:].mean(1)
        yaw_rate = out.yaw_rate[:, 200:].mean(1)
        for i, command in enumerate(COMMANDS):
            rows.append((name, "walk", _fmt(command), _fmt(np.r_[velocity[i], yaw_rate[i]]),
                         "yes" if out.failed[i].any() else "no"))
        plot_gait_diagram(out.foot_contacts[0, -200:], robot.leg_names, out_dir / f"gait_{name}.png",
                          title=f"{name}: expert gait at command {_fmt(COMMANDS[0])}")
        print(f"{name}: simulated in {time.perf_counter() - start:.1f} s")
    header = ("robot", "what", "command (vx, vy, wz)", "achieved (vx, vy, wz)", "fell")
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    line = " | ".join(h.ljust(w) for h, w in zip(header, widths))
    print("\n" + line + "\n" + "-" * len(line))
    for row in rows:
        print(" | ".join(str(c).ljust(w) for c, w in zip(row, widths)))
    print(f"\ngait diagrams in {out_dir}/")


def _fmt(values) -> str:
    return "(" + ", ".join(f"{v:+.2f}" for v in values) + ")"


if __name__ == "__main__":
    main()
