"""The rules every simulator shares: the fall test, the reset noise, the joint-target clamp, periods per action,
and where the low-level interface lives."""

from __future__ import annotations

import numpy as np
import pytest

from hierloco.envs import LowLevel, get_robot
from hierloco.envs.locomotion import (
    LocomotionPhysics,
    clamp_joint_targets,
    joint_target_limits,
    periods_per_action,
    reset_joint_noise,
    robot_has_fallen,
)
from hierloco.envs.robots import compile_model


@pytest.mark.parametrize("name", ["a1", "daisy"])
def test_fall_test_on_floats_and_arrays(name):
    robot = get_robot(name)
    rng = np.random.default_rng(0)
    roll, pitch = rng.uniform(-1, 1, (2, 50, 4))
    height = rng.uniform(0, 0.4, (50, 4))
    expected = (np.abs(roll) > robot.max_roll) | (np.abs(pitch) > robot.max_pitch) | (height < robot.min_height)
    assert 0 < expected.sum() < expected.size
    np.testing.assert_array_equal(robot_has_fallen(robot, roll, pitch, height), expected)
    for i in range(10):  # the scalar form, as LocomotionPhysics.has_fallen uses it
        assert bool(robot_has_fallen(robot, float(roll[i, 0]), float(pitch[i, 0]), float(height[i, 0]))) == \
            expected[i, 0]


def test_physics_fall_test_is_the_shared_one():
    robot = get_robot("a1")
    physics = LocomotionPhysics.from_robot(robot)
    physics.data.qpos[2] = 0.3
    physics.data.qpos[3:7] = [1, 0, 0, 0]
    physics.forward()
    assert not physics.has_fallen()
    physics.data.qpos[2] = robot.min_height - 0.01
    assert physics.has_fallen()
    physics.data.qpos[2] = 0.3
    angle = robot.max_roll + 0.05  # rolled about x
    physics.data.qpos[3:7] = [np.cos(angle / 2), np.sin(angle / 2), 0, 0]
    assert physics.has_fallen()


def test_reset_noise_draws():
    locked = [1, 4]
    noise = reset_joint_noise(np.random.default_rng(7), 0.05, 3, 6, locked)
    direct = np.random.default_rng(7).uniform(-0.05, 0.05, (3, 6))
    direct[:, locked] = 0.0
    np.testing.assert_array_equal(noise, direct)
    # dm_control's RandomState: one robot's draws, as the 1-D draws of the same generator
    single = reset_joint_noise(np.random.RandomState(3), 0.02, 1, 6)
    np.testing.assert_array_equal(single[0], np.random.RandomState(3).uniform(-0.02, 0.02, 6))
    assert np.abs(noise).max() <= 0.05 and np.abs(noise[:, [0, 2, 3, 5]]).min() > 0
    # no noise draws nothing
    rng = np.random.default_rng(1)
    assert not reset_joint_noise(rng, 0.0, 2, 6).any()
    assert rng.uniform() == np.random.default_rng(1).uniform()
    for bad in (-0.1, float("nan"), float("inf"), "0.1", True):
        with pytest.raises(ValueError, match="init_joint_noise"):
            reset_joint_noise(np.random.default_rng(0), bad, 1, 6)


def test_joint_target_limits_are_the_joint_ranges():
    robot = get_robot("a1")
    low, high = joint_target_limits(compile_model(robot))
    assert low.shape == high.shape == (robot.num_joints,)
    np.testing.assert_allclose(low[:3], [-0.8029, -1.0472, -2.6965])
    np.testing.assert_allclose(high[:3], [0.8029, 4.1888, -0.9163])
    targets = np.array([[1e12, -1e12, -1.5], [np.nan, 0.0, 0.0]])
    clamped = clamp_joint_targets(targets, low[:3], high[:3])
    np.testing.assert_array_equal(clamped[0], [high[0], low[1], -1.5])  # in-range values are untouched
    assert np.isnan(clamped[1, 0])


def test_periods_per_action():
    assert periods_per_action("a1", 100) == 5  # 0.2 s trot
    assert periods_per_action("daisy", 100) == 1  # 1 s tripod
    assert periods_per_action(get_robot("a1"), 40) == 2
    with pytest.raises(ValueError, match=r"steps_per_action=150 \(1.50 s\) must hold a whole number of daisy's"):
        periods_per_action("daisy", 150)
    for bad in (0, -100, 30):
        with pytest.raises(ValueError, match="must hold a whole number of a1's 0.2 s gait periods"):
            periods_per_action("a1", bad)
    for bad in (100.0, "100", True):
        with pytest.raises(ValueError, match="whole number of control steps"):
            periods_per_action("a1", bad)


def test_low_level_lives_beside_the_latent_env_and_components_re_export_it():
    from hierloco.components import low_level
    from hierloco.envs import low_level as env_low_level

    assert low_level.LowLevel is env_low_level.LowLevel is LowLevel
    assert all(issubclass(cls, LowLevel) for cls in (low_level.LatentLowLevel, low_level.ExpertReplayLowLevel,
                                                      low_level.CommandLowLevel))
