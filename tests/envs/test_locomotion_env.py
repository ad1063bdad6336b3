"""The TorchRL locomotion env (``make_env``): specs, seeding, termination, truncation and disabled legs."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from hierloco.envs import get_robot, make_env
from hierloco.envs.robots import CONTROL_TIMESTEP
from tests.envs.toy_robot import make_toy_robot

ROBOTS = ("a1", "daisy")
DISABLED_LEG_AMPLITUDE = 0.3  # rad, sinusoid of the legs that still work
DISABLED_LEG_TOLERANCE = 0.05  # rad


def _sinusoid_policy(robot, amplitude=0.1, frequency=2.0):
    """A deterministic open-loop policy: the standing pose plus a per-joint phase-shifted sinusoid (rad)."""
    standing = torch.as_tensor(robot.standing_pose, dtype=torch.float32)
    phase = torch.arange(robot.num_joints, dtype=torch.float32)
    step = itertools.count()

    def policy(td):
        t = next(step) * CONTROL_TIMESTEP
        return td.set("action", standing + amplitude * torch.sin(2 * math.pi * frequency * t + phase))

    return policy


def _constant_policy(action):
    action = torch.as_tensor(action, dtype=torch.float32)
    return lambda td: td.set("action", action.clone())


# ---------------------------------------------------------------- specs
@pytest.mark.parametrize("disabled", [False, True], ids=["all_legs", "rear_legs_disabled"])
@pytest.mark.parametrize("name", ROBOTS)
def test_check_env_specs(name, disabled):
    robot = get_robot(name)
    env = make_env(name, disabled_legs=robot.rear_legs if disabled else (), seed=0)
    check_env_specs(env)
    td = env.reset()
    assert td["joint_positions"].shape == (robot.num_joints,)
    assert td["foot_contacts"].shape == (len(robot.legs),)
    assert env.action_spec.shape == (robot.num_joints,)
    # the episode starts at the origin, facing +y; com_state is (x, y, yaw, vx, vy) in the world frame
    assert td["com_state"][:2].abs().max() < 1e-6
    assert td["com_state"][2].item() == pytest.approx(math.pi / 2, abs=1e-5)
    torch.testing.assert_close(td["com_state"][3:], td["com_velocity"][:2])


# ---------------------------------------------------------------- seeding
@pytest.mark.parametrize("name", ROBOTS)
def test_same_seed_same_rollout_different_seed_different_rollout(name):
    robot = get_robot(name)
    rollouts = [make_env(name, seed=seed).rollout(40, policy=_sinusoid_policy(robot)) for seed in (3, 3, 4)]
    same, again, other = rollouts
    assert same.shape == again.shape == other.shape == (40,)
    for key in ("joint_positions", "joint_velocities", "com_state", "orientation"):
        torch.testing.assert_close(same["next", key], again["next", key], rtol=0, atol=0)
    torch.testing.assert_close(same["action"], other["action"])  # the policy does not depend on the state
    # so the difference comes from the seeded initial state alone
    assert (same["joint_positions"][0] - other["joint_positions"][0]).abs().max() > 1e-3
    assert (same["next", "joint_positions"][-1] - other["next", "joint_positions"][-1]).abs().max() > 1e-4


# ---------------------------------------------------------------- episode ends
@pytest.mark.parametrize("name", ROBOTS)
def test_fall_sets_terminated_not_truncated(name):
    robot = get_robot(name)
    env = make_env(name, seed=0)
    td = env.rollout(500, policy=_constant_policy(torch.zeros(robot.num_joints)))  # all-zero targets: collapse
    assert len(td) < 500
    assert td["next", "terminated"][-1].item() and td["next", "done"][-1].item()
    assert not td["next", "truncated"].any()
    assert not td["next", "done"][:-1].any()
    roll, pitch, _ = td["next", "orientation"][-1].tolist()
    height = td["next", "com_position"][-1, 2].item()
    assert abs(roll) > robot.max_roll or abs(pitch) > robot.max_pitch or height < robot.min_height


@pytest.mark.parametrize("name", ROBOTS)
def test_time_limit_sets_truncated_not_terminated(name):
    robot = get_robot(name)
    env = make_env(name, time_limit=0.3, seed=0)
    td = env.rollout(500, policy=_constant_policy(robot.standing_pose))
    assert len(td) == round(0.3 / CONTROL_TIMESTEP)
    assert td["next", "truncated"][-1].item() and td["next", "done"][-1].item()
    assert not td["next", "terminated"].any()
    assert not td["next", "done"][:-1].any()


def test_physics_blow_up_sets_terminated_and_warns():
    robot = get_robot("a1")
    env = make_env("a1", seed=0)
    td = env.reset()
    physics = env.base_env.physics  # the dm_control Physics under the TorchRL wrapper
    physics.data.qvel[8] = 1e11  # beyond MuJoCo's limit: it warns and resets the data
    td.set("action", torch.as_tensor(robot.standing_pose, dtype=torch.float32))
    with pytest.warns(RuntimeWarning, match="physics became unstable"):
        td = env.step(td)
    assert td["next", "terminated"].item() and not td["next", "truncated"].item()
    # the next episode starts clean
    td = env.rollout(20, policy=_constant_policy(robot.standing_pose))
    assert len(td) == 20 and not td["next", "done"].any()


@pytest.mark.parametrize("name", ROBOTS)
def test_stands_10_s_in_the_env(name):
    robot = get_robot(name)
    env = make_env(name, time_limit=10.0, seed=0)
    td = env.rollout(2000, policy=_constant_policy(robot.standing_pose))
    assert len(td) == 1000  # the whole episode: no fall
    assert not td["next", "terminated"].any() and td["next", "truncated"][-1].item()
    assert (td["next", "reward"] == 1).all()
    height = td["next", "com_position"][50:, 2]  # after 0.5 s of settling
    assert (height.max() - height.min()).item() < 0.02
    assert td["next", "foot_contacts"][-1].all()


# ---------------------------------------------------------------- disabled legs
@pytest.mark.parametrize("name", ROBOTS)
def test_disabled_legs_hold_their_standing_angles(name):
    robot = get_robot(name)
    disabled = robot.leg_joint_indices(robot.rear_legs)
    working = robot.leg_joint_indices([leg for leg in robot.leg_names if leg not in robot.rear_legs])
    env = make_env(name, disabled_legs=robot.rear_legs, seed=0)
    lows, highs = env.action_spec.space.low, env.action_spec.space.high
    generator = torch.Generator().manual_seed(0)
    sinusoid = _sinusoid_policy(robot, amplitude=DISABLED_LEG_AMPLITUDE)

    def policy(td):
        action = sinusoid(td)["action"]
        random = lows + (highs - lows) * torch.rand(robot.num_joints, generator=generator)
        action[disabled] = random[disabled]  # the disabled legs are asked to go anywhere
        return td.set("action", action)

    td = env.rollout(100, policy=policy)
    assert len(td) == 100 and not td["next", "done"].any()
    assert (td["action"][:, disabled] - torch.as_tensor(robot.standing_pose)[disabled]).abs().max() > 0.5
    joints = torch.cat([td["joint_positions"][:1], td["next", "joint_positions"]])  # from the reset on
    standing = torch.as_tensor(robot.standing_pose, dtype=joints.dtype)
    assert (joints[:, disabled] - standing[disabled]).abs().max() < DISABLED_LEG_TOLERANCE
    swing = joints[:, working].max(0).values - joints[:, working].min(0).values
    assert swing.min() > DISABLED_LEG_AMPLITUDE  # every working joint moves (peak to peak ~0.6 rad)


# ---------------------------------------------------------------- a user's MJCF robot
@pytest.mark.parametrize("feet", ["site", "body"])
def test_user_mjcf_robot_env(feet):
    robot = make_toy_robot(feet)
    env = make_env(robot, seed=0)
    check_env_specs(env)
    td = env.rollout(200, policy=_sinusoid_policy(robot, amplitude=0.05))
    assert len(td) == 200 and not td["next", "terminated"].any()
    assert (td["next", "com_position"][:, 2] > robot.min_height).all()
    assert td["next", "foot_contacts"][-1].sum() >= 3
    assert np.isfinite(td["next", "joint_positions"].numpy()).all()


def test_user_mjcf_robot_env_with_disabled_legs():
    robot = make_toy_robot("body")
    env = make_env(robot, disabled_legs=("RR", "RL"), seed=0)
    check_env_specs(env)


# ---------------------------------------------------------------- bad input
def test_unknown_robot_is_an_error():
    with pytest.raises(ValueError, match="unknown robot 'spot'"):
        make_env("spot")


def test_unknown_disabled_leg_is_an_error():
    with pytest.raises(ValueError, match=r"no legs \['XX'\]"):
        make_env("a1", disabled_legs=("RR", "XX"))


@pytest.mark.parametrize("time_limit", [0.0, -1.0, float("nan")])
def test_non_positive_time_limit_is_an_error(time_limit):
    with pytest.raises(ValueError, match="time_limit must be positive"):
        make_env("a1", time_limit=time_limit)


# ---------------------------------------------------------------- NaN, inf and out-of-range actions
@pytest.mark.parametrize("name", ROBOTS)
def test_nan_action_terminates_the_step_with_zero_reward(name):
    robot = get_robot(name)
    env = make_env(name, seed=0)
    td = env.reset()
    action = torch.as_tensor(robot.standing_pose, dtype=torch.float32).clone()
    action[2] = float("nan")
    with pytest.warns(RuntimeWarning, match="NaN joint targets"):
        td = env.step(td.set("action", action))
    out = td["next"]
    assert out["terminated"].item() and out["done"].item() and not out["truncated"].item()
    assert out["reward"].item() == 0.0  # not the reward of a robot standing
    for key in ("com_state", "joint_positions", "joint_velocities"):
        assert torch.isfinite(out[key]).all()
    # the next episode starts clean and earns its reward again
    td = env.rollout(5, policy=_constant_policy(robot.standing_pose))
    assert len(td) == 5 and not td["next", "done"].any() and (td["next", "reward"] == 1).all()


@pytest.mark.parametrize("bad", [float("inf"), float("-inf")])
def test_infinite_action_is_refused(bad):
    robot = get_robot("a1")
    env = make_env("a1", seed=0)
    td = env.reset()
    action = torch.as_tensor(robot.standing_pose, dtype=torch.float32).clone()
    action[4] = bad
    with pytest.raises(ValueError, match=r"joint targets contain inf \(joints \[4\]\)"):
        env.step(td.set("action", action))


@pytest.mark.parametrize("name", ROBOTS)
def test_huge_action_is_clamped_to_the_joint_range_as_in_the_batched_simulator(name):
    """A 1e12 rad target acts as the joint limit (the model's control range, the one BatchedSimulator clamps to)."""
    from hierloco.envs.batched_sim import BatchedSimulator

    robot = get_robot(name)
    low, high = BatchedSimulator(name, 1).model.actuator_ctrlrange.T
    huge = torch.as_tensor(robot.standing_pose, dtype=torch.float32).clone()
    beyond = huge.clone()
    huge[0], huge[1] = 1e12, -1e12
    beyond[0], beyond[1] = float(high[0]) + 0.5, float(low[1]) - 0.5
    envs = [make_env(name, seed=0) for _ in range(2)]
    rollouts = [env.rollout(30, policy=_constant_policy(a)) for env, a in zip(envs, (huge, beyond))]
    torch.testing.assert_close(rollouts[0]["next", "joint_positions"], rollouts[1]["next", "joint_positions"],
                               rtol=0, atol=0)
    ctrl = envs[0].base_env.physics.data.ctrl
    assert ctrl[0] == high[0] and ctrl[1] == low[1]  # exactly the limits, in float64
    assert rollouts[0]["next", "joint_positions"][-1, 0] > robot.standing_pose[0] + 0.05  # pushed towards it
