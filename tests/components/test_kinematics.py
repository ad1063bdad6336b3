"""Leg kinematics: generic FK agrees with MuJoCo, IK round trips, unreachable targets stay sane (both solvers)."""

import mujoco
import numpy as np
import pytest

from hierloco.components.kinematics import LegKinematics
from hierloco.envs import robot_from_mjcf
from hierloco.envs.robots import compile_model, get_robot, joint_qpos_indices
from tests.envs.toy_robot import TOY_HIPS, TOY_LINK, TOY_QUADRUPED_XML, TOY_STANDING_HEIGHT, make_toy_robot


def make_tilted_robot():
    """The toy quadruped with tilted hip axes and rotated calves: joint axes off the coordinate axes and fixed
    rotations in the chain, for the vectorised solver's general case."""
    xml = TOY_QUADRUPED_XML.replace('axis="0 1 0" range="-1.5 2.5"', 'axis="0.2 1 0.4" range="-1.5 2.5"')
    xml = xml.replace(f'_calf" pos="0 0 -{TOY_LINK}"', f'_calf" pos="0.01 0 -{TOY_LINK}" quat="0.97 0.15 0.1 0.1"')
    assert xml.count("quat=") == len(TOY_HIPS)
    return robot_from_mjcf(xml, name="toy_tilted", base_body="torso",
                           legs={leg: [f"{leg}_abduction", f"{leg}_hip_pitch", f"{leg}_knee"] for leg in TOY_HIPS},
                           feet={leg: f"{leg}_toe" for leg in TOY_HIPS}, standing_pose=[0.0, 0.8, -1.6] * 4,
                           standing_height=TOY_STANDING_HEIGHT, gait_groups=[["FR", "RL"], ["FL", "RR"]],
                           kp=[40.0] * 12)


ROBOTS = {"a1": lambda: get_robot("a1"), "daisy": lambda: get_robot("daisy"), "toy": make_toy_robot,
          "tilted": make_tilted_robot}


@pytest.fixture(params=[(robot, solver) for robot in sorted(ROBOTS) for solver in LegKinematics.SOLVERS],
                ids=lambda p: "-".join(p))
def kinematics(request):
    robot, solver = request.param
    return LegKinematics(ROBOTS[robot](), solver=solver)


def _random_poses(kin, rng, count, spread):
    """Joint angles near the standing pose, inside the limits."""
    q = kin.standing_pose + rng.uniform(-spread, spread, (count, kin.robot.num_joints))
    return np.clip(q, kin.joint_low, kin.joint_high)


def test_forward_matches_mujoco(kinematics):
    robot = kinematics.robot
    model = compile_model(robot)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    for q in _random_poses(kinematics, rng, 10, 1.0):
        data.qpos[:] = model.qpos0
        data.qpos[0:7] = (0, 0, 0, 1, 0, 0, 0)  # base at the origin, identity orientation
        data.qpos[joint_qpos_indices(model, robot)] = q
        mujoco.mj_kinematics(model, data)
        expected = np.stack([data.site(leg.foot_site).xpos for leg in robot.legs])
        np.testing.assert_allclose(kinematics.forward(q), expected, atol=1e-10)


def test_jacobian_matches_finite_differences(kinematics):
    q = _random_poses(kinematics, np.random.default_rng(1), 1, 0.3)[0]
    eps = 1e-6
    for leg, jac in enumerate(kinematics.jacobian(q)):
        s = kinematics.leg_slices[leg]
        for j in range(s.stop - s.start):
            dq = np.zeros_like(q)
            dq[s.start + j] = eps
            numeric = (kinematics.forward(q + dq)[leg] - kinematics.forward(q - dq)[leg]) / (2 * eps)
            np.testing.assert_allclose(jac[:, j], numeric, atol=1e-6)


def test_ik_round_trip_within_1mm(kinematics):
    rng = np.random.default_rng(2)
    targets = kinematics.forward(_random_poses(kinematics, rng, 200, 0.4))  # reachable by construction
    q = kinematics.inverse(targets)  # from the standing pose
    assert np.all(q >= kinematics.joint_low - 1e-12) and np.all(q <= kinematics.joint_high + 1e-12)
    error = np.linalg.norm(kinematics.forward(q) - targets, axis=-1)
    assert error.max() < 1e-3, f"worst foot error {error.max() * 1000:.2f} mm"


def test_unreachable_targets_give_the_nearest_pose(kinematics):
    """Far targets: no NaN, limits respected, and no joint pose on a dense grid gets the foot closer."""
    rng = np.random.default_rng(3)
    nominal = kinematics.forward(kinematics.standing_pose)
    directions = rng.normal(size=(5, kinematics.num_legs, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    targets = nominal + 2.0 * directions  # 2 m away: out of every leg's reach
    q = kinematics.inverse(targets)
    assert np.all(np.isfinite(q))
    assert np.all(q >= kinematics.joint_low - 1e-12) and np.all(q <= kinematics.joint_high + 1e-12)
    reached = np.linalg.norm(kinematics.forward(q) - targets, axis=-1)  # 5 x L

    # brute force: every pose of a 25^3 grid over each leg's joint range (limits clipped to +-pi)
    low, high = np.maximum(kinematics.joint_low, -np.pi), np.minimum(kinematics.joint_high, np.pi)
    for leg, s in enumerate(kinematics.leg_slices):
        axes = [np.linspace(low[i], high[i], 25) for i in range(s.start, s.stop)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, s.stop - s.start)
        poses = np.broadcast_to(kinematics.standing_pose, (len(grid), kinematics.robot.num_joints)).copy()
        poses[:, s] = grid
        feet = kinematics.forward(poses)[:, leg]
        best = np.linalg.norm(feet[None] - targets[:, None, leg], axis=-1).min(1)  # 5
        assert np.all(reached[:, leg] <= best + 5e-3), (leg, reached[:, leg], best)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_vectorised_solver_agrees_with_the_reference(robot):
    """Same targets, same warm starts (a walking-like batch B x k x L): the two solvers land within the tolerance
    of each other's feet, and the vectorised one never ends farther from a target than the reference."""
    reference = LegKinematics(ROBOTS[robot]())
    vectorised = LegKinematics(ROBOTS[robot](), solver="vectorised")
    rng = np.random.default_rng(4)
    start = _random_poses(reference, rng, 12, 0.3)  # B x J
    targets = reference.forward(start[:, None] + rng.uniform(-0.15, 0.15, (12, 10, reference.robot.num_joints)))
    targets[:3, :2] += 0.5  # a few feet out of reach
    initial = np.repeat(start[:, None], 10, 1)
    ref_q, vec_q = reference.inverse(targets, initial), vectorised.inverse(targets, initial)
    np.testing.assert_allclose(vectorised.forward(vec_q), reference.forward(vec_q), atol=1e-12)
    ref_error = np.linalg.norm(reference.forward(ref_q) - targets, axis=-1)
    vec_error = np.linalg.norm(reference.forward(vec_q) - targets, axis=-1)
    reachable = ref_error < 1e-4
    assert reachable.mean() > 0.9
    assert vec_error[reachable].max() < 2e-6
    assert np.all(vec_error <= ref_error + 1e-5), (vec_error - ref_error).max()
    assert np.abs(vec_q - ref_q)[reachable.all(-1)].max() < 1e-3  # same solution branch


def test_unknown_solver_is_refused():
    with pytest.raises(ValueError, match="solver"):
        LegKinematics("a1", solver="analytic")


def test_bad_targets_are_refused():
    kin = LegKinematics("a1")
    with pytest.raises(ValueError, match="4 x 3"):
        kin.inverse(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="NaN"):
        kin.inverse(np.full((4, 3), np.nan))
