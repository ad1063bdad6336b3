"""The perturbed "hardware" robot: heavier, weaker, less friction, late servos, a noisy state estimate
(``hierloco.envs.robots.hardware``), and the settings that simulate it (``hierloco.envs.faults``)."""

import numpy as np
import pytest
import torch

from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.faults import fault_legs, is_unadapted, physical_setting, setting_robot
from hierloco.envs.robots import A1, HARDWARE, compile_model, get_robot, perturbed, robot_fingerprint


def test_the_default_perturbation_changes_mass_motors_and_friction():
    robot = perturbed(A1)
    nominal, heavy = compile_model(A1), compile_model(robot)
    assert heavy.body_mass.sum() == pytest.approx(HARDWARE["mass_scale"] * nominal.body_mass.sum())
    assert np.allclose(heavy.body_inertia, HARDWARE["mass_scale"] * nominal.body_inertia)
    assert robot.kp == tuple(0.8 * k for k in A1.kp) and robot.torque_limit == tuple(0.8 * t for t in A1.torque_limit)
    assert robot.foot_friction == 0.5 and robot.servo_latency == 0.02 and robot.com_noise == (0.02, 0.03, 0.05)
    assert robot.name == "a1_hardware" and robot.joint_names == A1.joint_names
    with pytest.raises(ValueError, match="unknown hardware option"):
        perturbed(A1, latency=0.1)
    with pytest.raises(ValueError, match="servo_latency must be"):
        perturbed(A1, servo_latency=-0.01)


def test_the_new_fields_leave_every_nominal_robot_s_fingerprint_as_it_was():
    # runs cached before these fields existed stay valid: at their defaults they are not fingerprinted
    same = A1.replace(mass_scale=1.0, servo_latency=0.0, com_noise=(0.0, 0.0, 0.0))
    assert robot_fingerprint(same) == robot_fingerprint(A1)
    for change in ({"mass_scale": 1.1}, {"servo_latency": 0.01}, {"com_noise": (0.0, 0.0, 0.01)}):
        assert robot_fingerprint(A1.replace(**change)) != robot_fingerprint(A1), change


def test_servo_latency_delays_every_target_by_whole_physics_steps():
    late_robot = A1.replace(servo_latency=0.02)  # 10 physics steps = 2 control steps
    rng = np.random.default_rng(0)
    standing = np.asarray(A1.standing_pose)
    first = standing + 0.2 * rng.uniform(-1, 1, (2, 30, A1.num_joints))
    second = standing + 0.2 * rng.uniform(-1, 1, (2, 30, A1.num_joints))
    late, prompt = BatchedSimulator(late_robot, 2, nthread=1), BatchedSimulator(A1, 2, nthread=1)
    assert late.latency_steps == 10
    hold = np.tile(standing, (2, 2, 1))
    a, b = late.run(first), prompt.run(np.concatenate([hold, first[:, :-2]], 1))
    assert np.array_equal(a.qpos, b.qpos), "the late robot is the prompt one two control steps behind"
    # the next call starts with the two targets still in flight from the first
    a, b = late.run(second), prompt.run(np.concatenate([first[:, -2:], second[:, :-2]], 1))
    assert np.array_equal(a.qpos, b.qpos)
    # a reset robot has nothing in flight: it holds the standing pose first
    late.reset(np.array([True, False]))
    prompt.reset(np.array([True, False]))
    a = late.run(first)
    b = prompt.run(np.concatenate([np.concatenate([hold[:1], first[:1, :-2]], 1),
                                   np.concatenate([second[1:, -2:], first[1:, :-2]], 1)]))
    assert np.array_equal(a.qpos, b.qpos)


def test_the_measured_com_state_is_noisy_and_the_true_one_is_kept():
    from hierloco.components.expert_library import build_expert_library
    from hierloco.components.low_level import ExpertReplayLowLevel
    from hierloco.envs.latent_env import LatentActionEnv

    low = ExpertReplayLowLevel(build_expert_library("a1", 3, progress=False))
    noisy = A1.replace(com_noise=(0.02, 0.03, 0.05))
    env = LatentActionEnv(low, num_robots=400, robot=noisy, seed=0, nthread=1)
    td = env.reset()
    error = (td["com_state"] - td["com_state_true"]).numpy()
    assert np.allclose(error.std(0), [0.02, 0.02, 0.03, 0.05, 0.05], rtol=0.15), error.std(0)
    assert np.allclose(error.mean(0), 0, atol=0.01)
    td = env.step(td.set("action", torch.zeros(400, 1, dtype=torch.int64)))["next"]
    error = (td["com_state"] - td["com_state_true"]).numpy()
    assert np.allclose(error.std(0), [0.02, 0.02, 0.03, 0.05, 0.05], rtol=0.15), error.std(0)
    env.close()
    plain = LatentActionEnv(low, num_robots=2, seed=0, nthread=1)
    assert "com_state_true" not in plain.reset().keys()
    plain.close()
    with pytest.raises(ValueError, match="joints"):
        LatentActionEnv(low, num_robots=1, robot=get_robot("daisy"))


def test_the_hardware_settings():
    assert physical_setting("hardware_unadapted") == "hardware" and is_unadapted("legs_disabled_unadapted")
    assert not is_unadapted("hardware") and fault_legs(A1, "legs_disabled_unadapted") == (("RR", "RL"), ())
    assert setting_robot(A1, "legs_disabled") is A1
    assert setting_robot(A1, "hardware", {"servo_latency": 0.0}).servo_latency == 0.0
    with pytest.raises(ValueError, match="unknown setting 'normal_unadapted'"):
        is_unadapted("normal_unadapted")
