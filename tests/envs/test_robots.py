"""Robots: the compiled models of A1, Daisy and a user's MJCF robot match their published facts and stand still."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from hierloco.envs.frames import quat_to_roll_pitch_yaw
from hierloco.envs.robots import (
    A1,
    DAISY,
    PHYSICS_STEPS_PER_CONTROL,
    PHYSICS_TIMESTEP,
    ROBOTS,
    compile_model,
    get_robot,
    joint_qpos_indices,
    robot_from_mjcf,
    standing_qpos,
)
from tests.envs.test_user_robots import FIXTURE_YAML
from tests.envs.toy_robot import TOY_FOOT_RADIUS, TOY_QUADRUPED_XML, TOY_STANDING_HEIGHT, make_toy_robot

STANDING_DURATION = 10.0  # s
SETTLING_TIME = 0.5  # s
MAX_HEIGHT_DRIFT = 0.02  # m


def _forward(robot, qpos=None):
    model = compile_model(robot)
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, robot) if qpos is None else qpos
    mujoco.mj_forward(model, data)
    return model, data


# ---------------------------------------------------------------- every robot: the compiled model's contract
@pytest.mark.parametrize("name", sorted(ROBOTS) + [str(FIXTURE_YAML)], ids=lambda n: Path(n).stem)
def test_compiled_model_contract(name):
    robot = get_robot(name)
    model = compile_model(robot)
    assert model.opt.timestep == PHYSICS_TIMESTEP
    assert model.nu == robot.num_joints
    # one position servo per leg joint, in joint order
    actuated = [model.joint(model.actuator_trnid[i, 0]).name for i in range(model.nu)]
    assert actuated == list(robot.joint_names)
    np.testing.assert_allclose(model.actuator_biasprm[:, 1], -model.actuator_gainprm[:, 0])
    assert np.all(model.actuator_gainprm[:, 0] > 0)
    # one free joint, first in qpos; one touch sensor per foot; a floor
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert sum(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE) == 1
    assert model.nsensor == len(robot.legs)
    assert any(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
    # the standing pose is inside the joint limits
    ranges = model.jnt_range[[model.joint(j).id for j in robot.joint_names]]
    assert np.all((ranges[:, 0] <= robot.standing_pose) & (np.asarray(robot.standing_pose) <= ranges[:, 1]))


def test_registry_holds_a1_and_daisy():
    assert get_robot("a1") is A1 and get_robot("daisy") is DAISY
    assert get_robot(A1) is A1
    assert A1.source == DAISY.source == "builtin" and A1.reference == "a1"


# ---------------------------------------------------------------- A1
def test_a1_total_mass():
    model = compile_model(A1)
    assert model.body_mass.sum() == pytest.approx(12.45, rel=0.02)


def test_a1_thigh_and_calf_are_20_cm():
    """Measured in the world between the compiled model's joint anchors and foot sites, leg by leg."""
    _, data = _forward(A1)
    for leg in A1.legs:
        _, thigh_joint, knee_joint = leg.joints
        thigh = data.joint(thigh_joint).xanchor
        knee = data.joint(knee_joint).xanchor
        foot = data.site(leg.foot_site).xpos
        assert np.linalg.norm(knee - thigh) == pytest.approx(0.2, abs=1e-6), leg.name
        assert np.linalg.norm(foot - knee) == pytest.approx(0.2, abs=1e-6), leg.name


def test_a1_standing_feet_touch_the_floor():
    _, data = _forward(A1)
    feet_z = np.array([data.site(leg.foot_site).xpos[2] for leg in A1.legs])
    np.testing.assert_allclose(feet_z, 0.02, atol=0.01)  # foot sphere radius 0.02 m


# ---------------------------------------------------------------- Daisy
def test_daisy_standing_feet_on_a_055_m_circle():
    _, data = _forward(DAISY)
    centre = data.body(DAISY.base_body).xpos
    feet = np.array([data.site(leg.foot_site).xpos for leg in DAISY.legs])
    radii = np.linalg.norm(feet[:, :2] - centre[:2], axis=1)
    np.testing.assert_allclose(radii, 0.55, atol=0.03)
    # body about 0.21 m above the feet, and the feet on the floor
    np.testing.assert_allclose(centre[2] - feet[:, 2], 0.21, atol=0.02)
    np.testing.assert_allclose(feet[:, 2], 0.02, atol=0.01)
    # six legs spread around the body: feet 60 deg apart
    angles = np.sort(np.arctan2(feet[:, 1] - centre[1], feet[:, 0] - centre[0]))
    np.testing.assert_allclose(np.diff(angles), np.pi / 3, atol=0.05)


# ---------------------------------------------------------------- standing, every robot and a user's MJCF robot
def _stand(robot):
    """Simulates ``robot`` from its standing pose with the standing pose as targets; per control step arrays."""
    model = compile_model(robot)
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, robot)
    data.ctrl[:] = robot.standing_pose
    num_control = int(round(STANDING_DURATION / (PHYSICS_TIMESTEP * PHYSICS_STEPS_PER_CONTROL)))
    base = np.empty((num_control, 7))
    for t in range(num_control):
        mujoco.mj_step(model, data, nstep=PHYSICS_STEPS_PER_CONTROL)
        base[t] = data.qpos[:7]
    return base, data.warning


@pytest.mark.parametrize("robot", [A1, DAISY, make_toy_robot("site"), get_robot(str(FIXTURE_YAML))],
                         ids=lambda r: r.name)
def test_stands_10_s_from_the_standing_pose(robot):
    """Also the 20 kg fixture, whose standing height is derived, not given."""
    base, warnings = _stand(robot)
    assert all(w.number == 0 for w in warnings), "MuJoCo warned during a standing simulation"
    assert np.all(np.isfinite(base))
    roll_pitch = quat_to_roll_pitch_yaw(base[:, 3:7])[:, :2]
    height = base[:, 2]
    assert np.all(np.abs(roll_pitch[:, 0]) < robot.max_roll)
    assert np.all(np.abs(roll_pitch[:, 1]) < robot.max_pitch)
    assert np.all(height > robot.min_height)
    settled = height[int(SETTLING_TIME / (PHYSICS_TIMESTEP * PHYSICS_STEPS_PER_CONTROL)):]
    assert settled.max() - settled.min() < MAX_HEIGHT_DRIFT
    assert abs(settled.mean() - robot.standing_height) < 0.05
    # it stands in place
    assert np.linalg.norm(base[-1, :2]) < 0.05


# ---------------------------------------------------------------- a user's MJCF robot
@pytest.mark.parametrize("feet", ["site", "body"])
def test_user_mjcf_robot_gets_servos_free_joint_floor_and_feet(feet):
    robot = make_toy_robot(feet)
    model = compile_model(robot)
    assert model.opt.timestep == PHYSICS_TIMESTEP  # the file's own 0.005 s is replaced
    assert model.nu == 12 and model.nq == 7 + 12
    np.testing.assert_allclose(model.actuator_gainprm[:, 0], 40.0)  # motors became servos with the given kp
    np.testing.assert_allclose(model.actuator_biasprm[:, 1], -40.0)
    np.testing.assert_allclose(model.actuator_forcerange, [[-15.0, 15.0]] * 12)  # the motors' torque range
    assert model.actuator_gear[:, 0].tolist() == [1.0] * 12
    # foot sites sit at the foot spheres, which touch the floor in the standing pose
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, robot)
    mujoco.mj_forward(model, data)
    for leg in robot.legs:
        np.testing.assert_allclose(data.site(leg.foot_site).xpos, data.geom(f"{leg.name}_foot").xpos, atol=1e-9)
        assert data.site(leg.foot_site).xpos[2] == pytest.approx(TOY_FOOT_RADIUS, abs=1e-6)
    assert data.qpos[2] == pytest.approx(TOY_STANDING_HEIGHT)
    assert joint_qpos_indices(model, robot).tolist() == list(range(7, 19))


# ---------------------------------------------------------------- bad input
def test_unknown_robot_name_is_an_error():
    with pytest.raises(ValueError, match="unknown robot 'cheetah'"):
        get_robot("cheetah")


def test_unknown_disabled_leg_is_an_error():
    with pytest.raises(ValueError, match="no legs"):
        compile_model(A1, disabled_legs=("RR", "tail"))


def test_user_robot_errors_name_the_problem():
    legs = {leg: [f"{leg}_abduction", f"{leg}_hip_pitch", f"{leg}_knee"] for leg in ("FR", "FL", "RR", "RL")}
    common = dict(name="toy", base_body="torso", legs=legs, standing_pose=[0.0, 0.8, -1.6] * 4,
                  standing_height=TOY_STANDING_HEIGHT, gait_groups=[["FR", "RL"], ["FL", "RR"]])
    feet = {leg: f"{leg}_toe" for leg in legs}
    with pytest.raises(ValueError, match="'nowhere'.*neither a site nor a body"):
        robot_from_mjcf(TOY_QUADRUPED_XML, feet={**feet, "RL": "nowhere"}, kp=[40.0] * 12, **common)
    with pytest.raises(ValueError, match="no position servo; give kp"):
        compile_model(robot_from_mjcf(TOY_QUADRUPED_XML, feet=feet, **common))  # torque motors and no kp
    with pytest.raises(ValueError, match="kp has 5 values for 12 joints"):
        robot_from_mjcf(TOY_QUADRUPED_XML, feet=feet, kp=[40.0] * 5, **common)
    with pytest.raises(ValueError, match="standing_pose has 4 values for 12 joints"):
        robot_from_mjcf(TOY_QUADRUPED_XML, feet=feet, kp=[40.0] * 12, **{**common, "standing_pose": [0.0] * 4})
    with pytest.raises(FileNotFoundError, match="no such file"):
        robot_from_mjcf("/nonexistent/robot.xml", feet=feet, **common)
