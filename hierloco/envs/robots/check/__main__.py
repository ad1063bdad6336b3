"""``hierloco-robot-check ROBOT`` (``python -m hierloco.envs.robots.check``): the description's problems in
milliseconds (:mod:`hierloco.envs.robots.check`), then the search of the expert controller's parameters
(:func:`hierloco.components.expert_tuning.tune_expert_parameters`), what made the difference, and the lines to
paste: YAML lines for the robot's file, recipe overrides for the command line (``docs/robots.md``). A robot whose
file and description give some joints no torque limit is read with provisional ones
(:func:`hierloco.envs.robots.check.robot_for_check`) and the search finds the smallest that walks, printed as a
``torque_limit:`` line: the motors' peak torque the gait needs, to check against the robot's motors.
"""

from __future__ import annotations

import math

from hierloco.envs.robots.check import (
    EXIT_FOUND,
    EXIT_NOT_FOUND,
    description_problems,
    description_summary,
    provisional_torque_text,
    robot_for_check,
)


def tracking_table(axes) -> list[str]:
    """A Markdown table of :class:`hierloco.components.expert_library.AxisTracking` rows."""
    lines = ["| axis | commanded | achieved | achieved ~ slope x command + offset | reach towards low / high edge |"
             " ok |", "|---|---|---|---|---|---|"]
    for a in axes:
        lines.append(f"| {a.axis} ({a.unit}) | {a.command_low:+.2f} .. {a.command_high:+.2f} | {a.achieved_low:+.2f} .."
                     f" {a.achieved_high:+.2f} | {a.slope:.2f} x command {a.offset:+.3f} | {a.reach_low:.0%} / "
                     f"{a.reach_high:.0%} (need {a.min_reach:.0%}) | {'yes' if a.ok else 'no'} |")
    return lines


def main(argv=None) -> int:
    """``hierloco-robot-check ROBOT``: the description's problems in milliseconds, then the search (see the module
    docstring). Returns the exit status: 0 found, 2 not found or bad input."""
    import argparse
    import sys
    import time

    parser = argparse.ArgumentParser(
        prog="hierloco-robot-check",
        description="Check a robot description and search the expert controller's parameters for experts that walk "
                    "as commanded and a gait policy that reproduces them (docs/robots.md).")
    parser.add_argument("robot", help="path/to/robot.yaml (or a registered robot name)")
    parser.add_argument("--budget", type=float, default=300.0, help="s of search and verification (default 300): "
                        "no stage or verification starts after it; the one running finishes")
    parser.add_argument("--experts", type=int, default=30, help="experts in the verified library (default 30, the "
                        "small preset's)")
    parser.add_argument("--settle-time", type=float, default=3.0, help="s each verified expert walks before it is "
                        "recorded (default 3)")
    parser.add_argument("--epochs", type=int, default=150, help="gait-policy epochs (default 150, the small preset's)")
    parser.add_argument("--hidden", type=int, default=512, help="gait-policy hidden units (default 512)")
    parser.add_argument("--latent-dim", type=int, default=3, help="latent dimension (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--description-only", action="store_true", help="check the description and stop")
    parser.add_argument("--no-verify", action="store_true", help="screen only: no expert library nor gait policy")
    args = parser.parse_args(argv)

    def fail(message: str) -> int:
        print(f"error: {' '.join(str(message).split())}", file=sys.stderr)
        return EXIT_NOT_FOUND

    for name in ("budget", "settle_time"):
        if not (math.isfinite(getattr(args, name)) and getattr(args, name) > 0):
            return fail(f"--{name.replace('_', '-')} must be a positive number of s, got {getattr(args, name)}")
    for name in ("experts", "epochs", "hidden"):
        if getattr(args, name) < 1:
            return fail(f"--{name} must be a positive whole number, got {getattr(args, name)}")
    start = time.perf_counter()
    try:
        robot = robot_for_check(args.robot)
        problems = description_problems(robot)
    except (ValueError, OSError) as error:
        return fail(error)
    where = robot.reference
    print(f"robot {robot.name} ({where}): {len(robot.legs)} legs, gait groups "
          f"{[list(g) for g in robot.gait_groups]}; now gait_period {robot.gait_period:g} s, standing_height "
          f"{robot.standing_height:.3f} m, swing_height {robot.swing_height:g} m")
    if robot.provisional_torque_joints:
        print(provisional_torque_text(robot))
    elapsed = time.perf_counter() - start
    if problems:
        print(f"description: {len(problems)} problem{'s' if len(problems) > 1 else ''} ({elapsed:.2f} s):")
        for line in problems:
            print(f"  - {line}")
        return EXIT_NOT_FOUND
    print(f"description: ok ({elapsed:.2f} s): {description_summary(robot)}")
    if args.description_only:
        return EXIT_FOUND
    from hierloco.components.expert_tuning import tune_expert_parameters

    print(f"search (budget {args.budget:g} s):", flush=True)
    result = tune_expert_parameters(
        robot, budget_seconds=args.budget, num_experts=args.experts, settle_time=args.settle_time,
        policy={"epochs": args.epochs, "hidden": args.hidden, "latent_dim": args.latent_dim},
        verify=not args.no_verify, seed=args.seed, log=lambda line: print(line, flush=True))
    print("\n".join(report_lines(result, where=where, epochs=args.epochs, hidden=args.hidden)))
    return EXIT_FOUND if result.found else EXIT_NOT_FOUND


def report_lines(result, *, where: str, epochs: int, hidden: int) -> list[str]:
    """What the check prints after its search (:class:`hierloco.components.expert_tuning.TuningResult`): the
    tracking table of the candidate the result is about (verified numbers under "verified", the screening's under
    "screened"), then either what was found (which change made the difference, for a torque limit the file lacks
    a line saying it is the motors' peak torque the gait needs, the YAML lines to paste, the recipe overrides to
    paste) or what limits it, labelled verified or screened, and its parameters."""
    import numpy as np

    from hierloco.components.expert_tuning import per_joint_text, torque_limit_levels

    params = result.params
    if params is None:
        return [f"not found in {result.seconds:.0f} s:", *(f"  - {line}" for line in result.limits)]
    lines = []
    shown = result.shown  # the verification the parameters are from, when one ran
    label = shown.candidate.label if shown is not None else result.best.candidate.label
    if shown is not None and shown.report is not None:
        lines += ["", f"verified: tracking of the {shown.report.num_experts} experts of the experts stage ({label}):",
                  *tracking_table(shown.report.axes),
                  f"verified: the experts' own targets replayed open loop: {shown.replayed_fraction:.0%} within "
                  "0.05 m/s"]
        if shown.reproduced_fraction is not None:
            lines.append(f"verified: the gait policy reproduces {shown.reproduced_fraction:.0%} of the experts within "
                         f"0.05 m/s in simulation (need {result.min_reproduced_fraction:.0%})")
    elif result.best is not None and result.best.axes:
        lines += ["", f"screened (not verified): tracking of the {result.best.num_commands} screened experts "
                      f"({result.best.candidate.label}):", *tracking_table(result.best.axes),
                  f"screened (not verified): the experts' own targets replayed open loop: "
                  f"{result.best.replayed_fraction:.0%} within 0.05 m/s"]
    changed = params.changed(result.reference)
    yaml_lines = params.yaml_lines(result.robot, only=changed)
    if not result.found:
        what = "verified" if shown is not None else "screened"
        lines += ["", f"not found in {result.seconds:.0f} s; the candidate {what}: {label}", "what limits it:",
                  *(f"  - {line}" for line in result.limits), "its parameters:", *yaml_lines]
        return lines
    what = "verified" if result.verified is not None else "screened only (--no-verify)"
    same = "" if changed else "; the description's own parameters walk, these lines pin the derived values"
    lines += ["", f"found in {result.seconds:.0f} s ({what}{same})"]
    if result.differences:
        needed = [d.name for d in result.differences if d.needed]
        margin = [d.name for d in result.differences if d.margin]
        lines.append("what made the difference (screened, each change undone alone, the others kept): "
                     + (", ".join(needed) if needed else "no single change")
                     + (f"; more margin: {', '.join(margin)}" if margin else ""))
        lines += [f"  - {d.describe()}" for d in result.differences]
    if params.torque_limit is not None and "torque_limit" in changed:
        factor = next((f for limit, f in torque_limit_levels(result.robot)
                       if np.allclose(limit, params.torque_limit)), None)
        times = f", {factor:g} x the largest torque standing" if factor is not None else ""
        lines.append(f"torque_limit {per_joint_text(result.robot, params.torque_limit)} N m{times}: the motors' peak "
                     "torque the gait needs (the smallest level that walks; the file and the description give none): "
                     "check it against your motors' peak torque before you paste it")
    lines += [f"paste into {where} (replacing these keys):", *yaml_lines]
    overrides = result.override_lines()
    if overrides:
        fits = result.verified.policy_attempts
        first, last = fits[0]["reproduced_fraction"], fits[-1]["reproduced_fraction"]
        lines += [f"and train the gait policy with these overrides on the recipe's command line (experts.tune=true "
                  f"applies them): the configured {epochs} epochs of {hidden} units reproduce {first:.0%} of the "
                  f"experts, this fit {last:.0%}", *overrides]
    return lines


__all__ = ["main", "report_lines", "tracking_table"]


if __name__ == "__main__":
    raise SystemExit(main())
