"""The Raibert expert controller walks at the commanded velocity on both robots, without falling."""

import numpy as np
import pytest

from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import get_robot

SETTLE_STEPS, MEASURE_STEPS = 200, 500  # 2 s of settling, then 5 s of measurement at 100 Hz


def _commands(robot):
    """(+-0.2, 0), (0, +-0.2) m/s, turns in place both ways, and two corners of the command box."""
    hi, lo = np.asarray(robot.command_high), np.asarray(robot.command_low)
    yaw = 0.8 * hi[2]
    return np.array([
        [0.2, 0.0, 0.0], [-0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, -0.2, 0.0],
        [0.0, 0.0, yaw], [0.0, 0.0, -yaw],
        [0.9 * hi[0], 0.9 * hi[1], 0.9 * hi[2]], [0.9 * lo[0], 0.9 * hi[1], 0.9 * lo[2]],
    ])


@pytest.mark.parametrize("robot_name", ["a1", "daisy"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_expert_tracks_command(robot_name, seed):
    robot = get_robot(robot_name)
    commands = _commands(robot)
    sim = BatchedSimulator(robot, len(commands), init_joint_noise=0.05, seed=seed)
    out = run_closed_loop(sim, RaibertController(robot, len(commands)), commands, SETTLE_STEPS + MEASURE_STEPS,
                          ramp_steps=100)
    assert not out.failed.any(), f"fell or blew up: commands {commands[out.failed[:, -1]]}"
    velocity = out.com_velocity_local[:, SETTLE_STEPS:].mean(1)
    yaw_rate = out.yaw_rate[:, SETTLE_STEPS:].mean(1)
    achieved = np.concatenate([velocity, yaw_rate[:, None]], -1)
    tolerance = np.maximum(0.05, 0.25 * np.abs(commands))
    bad = np.abs(achieved - commands) > tolerance
    assert not bad.any(), "\n".join(f"command {c} achieved {a.round(3)}" for c, a in zip(commands[bad.any(1)],
                                                                                          achieved[bad.any(1)]))


def test_gait_groups_alternate():
    """A trot: diagonal pairs are in swing in turn, never together."""
    ctrl = RaibertController("a1", 1)
    legs = list(ctrl.robot.leg_names)
    for step in range(ctrl.steps_per_period):
        swinging = {legs[i] for i in np.flatnonzero(ctrl.swing_progress(step) > 0)}
        assert swinging in ({"FR", "RL"}, {"FL", "RR"})


def test_gait_period_must_fit_control_steps():
    with pytest.raises(ValueError, match="gait_period"):
        RaibertController("a1", 1, gait_period=0.123)
