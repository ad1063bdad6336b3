"""Fault models and actuator/contact profiles, in the real simulation."""

import mujoco
import numpy as np
import pytest

from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.faults import FAULTS, fault_legs
from hierloco.envs.robots import compile_model, get_robot, robot_fingerprint
from hierloco.envs.robots.profiles import with_profile


def hold_standing(robot, seconds=1.0, **faults):
    sim = BatchedSimulator(robot, 1, **faults)
    steps = int(seconds * 100)
    out = sim.run(np.tile(np.asarray(robot.standing_pose), (1, steps, 1)))
    sim.close()
    return out


@pytest.mark.parametrize("name", ["a1", "daisy"])
def test_every_fault_names_legs_of_the_robot(name):
    robot = get_robot(name)
    for setting in FAULTS:
        locked, limp = fault_legs(robot, setting)
        robot.leg_joint_indices(locked + limp)  # valid names
        assert not set(locked) & set(limp)
    assert fault_legs(robot, "legs_disabled") == (tuple(robot.rear_legs), ())
    with pytest.raises(ValueError, match="unknown setting 'broken'"):
        fault_legs(robot, "broken")


def test_limp_legs_carry_no_torque_and_sag():
    robot = get_robot("a1")
    rear = robot.leg_joint_indices(robot.rear_legs)
    normal = hold_standing(robot)
    limp = hold_standing(robot, limp_legs=robot.rear_legs)
    sag = np.abs(limp.joint_positions[0, -1, rear] - np.asarray(robot.standing_pose)[rear]).max()
    held = np.abs(normal.joint_positions[0, -1, rear] - np.asarray(robot.standing_pose)[rear]).max()
    assert held < 0.1 and sag > 5 * held, (held, sag)  # servos droop a little under load; unpowered legs fold
    model = compile_model(robot, limp_legs=robot.rear_legs)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    data.ctrl[:] = 1.0  # any target
    mujoco.mj_forward(model, data)
    assert np.allclose(data.actuator_force[rear], 0.0) and not np.allclose(data.actuator_force, 0.0)


def test_one_locked_leg_stays_at_its_standing_angles():
    robot = get_robot("a1")
    locked = robot.leg_joint_indices(("RR",))
    out = hold_standing(robot, disabled_legs=("RR",))
    servo = hold_standing(robot)
    standing = np.asarray(robot.standing_pose)[locked]
    locked_error = np.abs(out.joint_positions[0][:, locked] - standing).max()
    servo_error = np.abs(servo.joint_positions[0][:, locked] - standing).max()
    # a joint equality is a (stiff) soft constraint: it gives a little under the body's weight, less than a servo
    assert locked_error < 0.03 and locked_error < 0.5 * servo_error, (locked_error, servo_error)


def test_a_leg_cannot_be_locked_and_limp():
    with pytest.raises(ValueError, match="both locked and limp"):
        compile_model(get_robot("a1"), disabled_legs=("RR",), limp_legs=("RR",))


def test_the_stiff_profile_has_stiffer_servos_and_low_friction_contacts():
    a1 = get_robot("a1")
    stiff = with_profile(a1, "stiff")
    assert robot_fingerprint(stiff) != robot_fingerprint(a1)
    model = compile_model(stiff)
    assert np.allclose(model.actuator_gainprm[:, 0], 3 * np.asarray(a1.kp))
    assert np.allclose(model.actuator_forcerange[:, 1], 3 * np.asarray(a1.torque_limit))
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    from hierloco.envs.robots import standing_qpos

    data.qpos[:] = standing_qpos(model, stiff)
    data.ctrl[:] = stiff.standing_pose
    for _ in range(200):
        mujoco.mj_step(model, data)
    feet = [c for c in data.contact[: data.ncon]]
    assert feet and all(abs(c.friction[0] - 0.4) < 1e-9 for c in feet), [c.friction[0] for c in feet]
    with pytest.raises(ValueError, match="unknown robot profile 'soft'"):
        with_profile(a1, "soft")


def test_the_stiff_servos_profile_changes_the_servos_only():
    a1 = get_robot("a1")
    servos, stiff = with_profile(a1, "stiff_servos"), with_profile(a1, "stiff")
    assert servos.kp == stiff.kp and servos.torque_limit == stiff.torque_limit
    assert servos.foot_friction == a1.foot_friction != stiff.foot_friction
    assert len({robot_fingerprint(r) for r in (a1, servos, stiff)}) == 3
