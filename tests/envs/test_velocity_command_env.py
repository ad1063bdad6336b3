"""The velocity-command env (SAC-SAC's low level): TorchRL contracts, reward terms on hand-made states, falls and
time limits, command resampling, the action-to-target map; the simulator's joint and angular velocities."""

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from hierloco.envs.batched_sim import BatchedSimulator, SimulationResult
from hierloco.envs.robots import CONTROL_TIMESTEP
from hierloco.envs.velocity_command_env import (
    DEFAULT_REWARD_WEIGHTS,
    LINEAR_VELOCITY_SCALE,
    REWARD_TERMS,
    VelocityCommandEnv,
    VelocityCommandInterface,
    reward_terms,
)


def _step(env, td, action=None):
    td.set("action", torch.zeros(env.action_spec.shape) if action is None else action)
    return env.step(td)


@pytest.mark.parametrize("robot", ["a1", "daisy"])
def test_check_env_specs(robot):
    env = VelocityCommandEnv(robot, num_robots=3, seed=0)
    check_env_specs(env)
    j = env.robot.num_joints
    assert env.action_spec.shape == (3, j)
    assert env.observation_spec["observation"].shape == (3, 3 * j + 12) == (3, env.interface.observation_size)
    env.close()


def test_reward_terms_oracle():
    """Exact values on hand-made states: perfect tracking gives 1, an error of sqrt(sigma) gives exp(-1)."""
    motion = {"com_velocity_local": np.array([[0.2, 0.0], [0.0, 0.0]]), "yaw_rate": np.array([0.1, 0.0]),
              "roll_pitch": np.array([[0.0, 0.0], [0.3, -0.4]])}
    command = np.array([[0.2, 0.0, 0.1], [0.2, 0.0, np.sqrt(0.1)]])
    torques = np.array([[0.0, 0.0], [10.0, -20.0]])
    limit = np.array([20.0, 20.0])
    action = np.array([[0.5, 0.5], [1.0, -1.0]])
    last = np.array([[0.5, 0.5], [0.0, 0.0]])
    terms = reward_terms(motion, command, torques, limit, action, last, np.array([False, True]),
                         linear_sigma=0.04, yaw_sigma=0.1)
    np.testing.assert_allclose(terms["tracking_linear"], [1.0, np.exp(-1.0)])
    np.testing.assert_allclose(terms["tracking_yaw"], [1.0, np.exp(-1.0)])
    np.testing.assert_allclose(terms["alive"], [1.0, 0.0])
    np.testing.assert_allclose(terms["torque"], [0.0, -(0.25 + 1.0) / 2])
    np.testing.assert_allclose(terms["action_rate"], [0.0, -1.0])
    np.testing.assert_allclose(terms["orientation"], [0.0, -0.25])
    assert set(terms) == set(REWARD_TERMS)


def test_standing_on_a_zero_command_is_rewarded_as_specified():
    """Holding the standing pose with the command (0, 0, 0): near-perfect tracking, no action change, upright; the
    weighted terms sum to the reward."""
    env = VelocityCommandEnv("a1", num_robots=2, command_low=(0, 0, 0), command_high=(0, 0, 0), seed=0)
    td = env.reset()
    for _ in range(30):
        td = _step(env, td)["next"]
    terms = td["reward_terms"]
    assert torch.all(terms["tracking_linear"] > 0.95 * DEFAULT_REWARD_WEIGHTS["tracking_linear"])
    assert torch.all(terms["alive"] == DEFAULT_REWARD_WEIGHTS["alive"])
    assert torch.all(terms["action_rate"] == 0)
    assert torch.all(terms["orientation"] > -1e-3) and torch.all(terms["torque"] < 0)
    torch.testing.assert_close(sum(terms[t] for t in REWARD_TERMS), td["reward"])
    assert torch.all(td["tracking_error"] < 0.05) and not td["done"].any()


def test_a_fall_terminates_and_only_that_robot_resets():
    env = VelocityCommandEnv("a1", num_robots=2, seed=0)
    td = env.reset()
    for _ in range(3):
        td = _step(env, td)["next"]
    state = env.sim.state.copy()
    roll = 1.0  # rad, beyond A1's 0.5 rad limit
    state[0, 1 + 3:1 + 7] = [np.cos(roll / 2), np.sin(roll / 2), 0.0, 0.0]
    env.sim.set_state(state)
    td.set("action", torch.zeros(env.action_spec.shape))
    step, td = env.step_and_maybe_reset(td)
    nxt = step["next"]
    assert nxt["terminated"][:, 0].tolist() == [True, False] and nxt["done"][:, 0].tolist() == [True, False]
    assert not nxt["truncated"].any()
    torch.testing.assert_close(nxt["reward_terms", "alive"][:, 0], torch.tensor([0.0, DEFAULT_REWARD_WEIGHTS["alive"]]))
    assert env._step_count.tolist() == [0, 4]  # robot 0 was reset, robot 1 walks on
    np.testing.assert_allclose(env.sim.qpos[0, 3:7], env.sim._standing_state[1 + 3:1 + 7])
    assert env.failures == 1


def test_time_limit_truncates():
    env = VelocityCommandEnv("a1", num_robots=2, episode_length=0.05, seed=0)
    td = env.reset()
    flags = []
    for _ in range(5):
        out = _step(env, td)
        flags.append((bool(out["next", "truncated"].all()), bool(out["next", "terminated"].any())))
        td = out["next"]
    assert flags == [(False, False)] * 4 + [(True, False)]


def test_commands_resample_on_schedule_inside_the_box():
    env = VelocityCommandEnv("a1", num_robots=16, command_interval=0.03, seed=0)
    td = env.reset()
    commands = [td["command"].clone()]
    for _ in range(7):
        td = _step(env, td)["next"]
        commands.append(td["command"].clone())
    changed = [not torch.equal(a, b) for a, b in zip(commands, commands[1:])]
    assert changed == [False, False, True, False, False, True, False]  # after steps 3 and 6
    all_commands = torch.stack(commands).reshape(-1, 3)
    low, high = torch.tensor(env.robot.command_low), torch.tensor(env.robot.command_high)
    assert torch.all(all_commands >= low) and torch.all(all_commands <= high)
    assert all_commands.std(0).min() > 0.1  # spread over the box, not a constant


def test_observation_at_reset():
    env = VelocityCommandEnv("a1", num_robots=3, init_joint_noise=0.0, seed=0)
    td = env.reset()
    obs = td["observation"].numpy()
    j = env.robot.num_joints
    np.testing.assert_allclose(obs[:, :2 * j + 7], 0.0, atol=1e-6)  # standing still, upright, joints at the pose
    np.testing.assert_allclose(obs[:, 2 * j + 7:2 * j + 9], LINEAR_VELOCITY_SCALE * td["command"][:, :2].numpy(),
                               rtol=1e-6)
    np.testing.assert_allclose(obs[:, 2 * j + 9], td["command"][:, 2].numpy(), rtol=1e-6)
    np.testing.assert_allclose(obs[:, 2 * j + 10:2 * j + 12], [[0.0, 1.0]] * 3, atol=1e-7)  # phase clock at t = 0
    np.testing.assert_allclose(obs[:, 2 * j + 12:], 0.0)  # no previous action


def test_same_seed_same_rollout():
    def run(seed):
        env = VelocityCommandEnv("a1", num_robots=2, seed=seed)
        torch.manual_seed(0)
        return env.rollout(20, break_when_any_done=False)

    a, b, c = run(1), run(1), run(2)
    torch.testing.assert_close(a["next", "observation"], b["next", "observation"])
    assert not torch.equal(a["command"], c["command"])


def test_actions_map_into_the_joint_range():
    interface = VelocityCommandInterface.for_robot("a1", action_scale=5.0)
    j = interface.num_joints
    np.testing.assert_allclose(interface.joint_targets(np.ones((1, j))), interface.joint_high[None])
    np.testing.assert_allclose(interface.joint_targets(-np.ones((1, j))), interface.joint_low[None])
    small = VelocityCommandInterface.for_robot("a1", action_scale=0.1)
    np.testing.assert_allclose(small.joint_targets(np.full((1, j), 0.5)),
                               np.asarray(small.robot.standing_pose)[None] + 0.05)


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="unknown reward terms"):
        VelocityCommandEnv("a1", reward_weights={"speed": 1.0})
    with pytest.raises(ValueError, match="command box"):
        VelocityCommandEnv("a1", command_low=(0.1, 0, 0), command_high=(0, 0, 0))
    with pytest.raises(ValueError, match="num_robots"):
        VelocityCommandEnv("a1", num_robots=0)
    with pytest.raises(ValueError, match="positive"):
        VelocityCommandInterface.for_robot("a1", action_scale=0.0)


def test_simulation_result_joint_and_angular_velocities():
    """The new result fields agree with the state, with finite differences of the joint angles, and with the
    yaw rate of a robot turning upright; results concatenate along time."""
    sim = BatchedSimulator("a1", 2, seed=0)
    pose = np.asarray(sim.robot.standing_pose)
    t = np.arange(50) * CONTROL_TIMESTEP
    wave = pose + 0.2 * np.sin(2 * np.pi * 2.0 * t)[:, None] * np.eye(12)[1]  # one hip pitch swings at 2 Hz
    first = sim.run(np.tile(wave[None], (2, 1, 1)))
    np.testing.assert_allclose(first.joint_velocities[:, -1], sim.qvel[:, sim._joint_qvel])
    np.testing.assert_allclose(first.angular_velocity_local[:, -1], sim.qvel[:, 3:6])
    finite = np.diff(first.joint_positions[:, :, 1], axis=1) / CONTROL_TIMESTEP
    middle = 0.5 * (first.joint_velocities[:, 1:, 1] + first.joint_velocities[:, :-1, 1])
    assert np.corrcoef(finite.ravel(), middle.ravel())[0, 1] > 0.98  # another joint's velocity would not match
    upright = np.abs(first.roll_pitch).max() < 0.05
    assert upright
    np.testing.assert_allclose(first.angular_velocity_local[..., 2], first.yaw_rate, atol=0.02)
    second = sim.run(np.tile(pose, (2, 10, 1)))
    merged = SimulationResult.concatenate([first, second])
    assert merged.joint_velocities.shape == (2, 60, 12) and merged.com_state.shape == (2, 60, 5)
    np.testing.assert_array_equal(merged.angular_velocity_local[:, 50:], second.angular_velocity_local)
