"""Terrain, pushes and randomised dynamics (``docs/terrain.md``): the compiled ground matches the generated one, robots
start on it, flat ground changes nothing, seeds decide, pushes and randomised dynamics act as stated, user files
work and broken ones are one clear error."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch
from matplotlib import pyplot as plt
from torchrl.envs.utils import check_env_specs

from hierloco.envs import make_env
from hierloco.envs.batched_sim import STATE_SPEC, BatchedSimulator
from hierloco.envs.navigation import Navigation
from hierloco.envs.robots import compile_model, get_robot
from hierloco.envs.robots.spec import _geom_bottom, foot_geoms
from hierloco.envs.terrain import (
    FLOOR_DROP_M,
    START_CLEARANCE_M,
    TERRAINS,
    BoxTerrain,
    DynamicsRandomization,
    Pushes,
    TerrainError,
    make_terrain,
)

BUILT_IN = ("rough", "slope", "stairs", "blocks", "slippery")
SEEDED = ("rough", "blocks", "slippery")
ROBOTS = ("a1", "daisy")


def _mjb(model: mujoco.MjModel) -> bytes:
    buffer = np.empty(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


def _ray_heights(model: mujoco.MjModel, xs, ys, top=5.0):
    """Heights (m) and geom ids of the first geom a vertical ray from ``top`` meets at each point."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    heights, geoms = [], []
    geom = np.zeros(1, dtype=np.int32)
    for x, y in zip(xs, ys):
        distance = mujoco.mj_ray(model, data, np.array([x, y, top]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geom)
        heights.append(top - distance)
        geoms.append(int(geom[0]))
    return np.array(heights), np.array(geoms)


def _points_away_from_the_robot(n=400, extent=5.5, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-extent, extent, (4 * n, 2))
    xy = xy[np.max(np.abs(xy), axis=1) > 0.9][:n]  # the robot stands within 0.6 m of the origin
    return xy[:, 0], xy[:, 1]


def _write_png(path, pixels):
    plt.imsave(path, pixels, cmap="gray", vmin=0.0, vmax=1.0)
    return path


GROUND_XML = """<mujoco>
  <worldbody>
    <geom name="ground" type="plane" size="10 10 0.1" pos="0 0 -0.02"/>
    <geom name="step" type="box" size="0.5 0.5 0.05" pos="2 0 0.03" rgba="0.3 0.6 0.3 1"/>
    <body name="ramp_holder" pos="-2 0 0">
      <geom name="ramp" type="box" size="0.5 0.5 0.05" euler="0 0.2 0" pos="0 0 0"/>
    </body>
    <body name="ball" pos="0 3 1">
      <freejoint/>
      <geom type="sphere" size="0.1"/>
    </body>
  </worldbody>
</mujoco>
"""


# ---------------------------------------------------------------- the compiled ground is the generated one
@pytest.mark.parametrize("name", BUILT_IN)
def test_height_at_matches_ray_casts_onto_the_compiled_terrain(name):
    terrain = make_terrain(name, difficulty=0.8, seed=3)
    model = compile_model(get_robot("a1"), terrain=terrain)
    xs, ys = _points_away_from_the_robot()
    rays, _ = _ray_heights(model, xs, ys)
    np.testing.assert_allclose(terrain.height_at(xs, ys), rays, rtol=0, atol=1e-6)
    assert np.ptp(rays) >= 0.002  # the ground is not flat (slippery patches are 2 mm)


def test_heightfield_heights_are_where_the_grid_puts_them():
    terrain = make_terrain("rough", amplitude_m=0.08, resolution_m=0.25, extent_m=2.0, seed=5)
    grid = np.linspace(-2.0, 2.0, 17)
    x, y = np.meshgrid(grid, grid)
    heights = terrain.height_at(x, y)
    assert heights.shape == (17, 17)
    assert heights.max() == pytest.approx(0.08, abs=0.01) and heights.min() >= 0.0
    assert np.all(heights[[0, -1], :] == 0.0) and np.all(heights[:, [0, -1]] == 0.0)  # it meets the floor
    assert float(terrain.height_at(2.5, 0.0)) == -FLOOR_DROP_M  # beyond it: the floor, moved down


def test_slippery_patches_have_the_friction_of_the_difficulty():
    terrain = make_terrain("slippery", difficulty=1.0, seed=2)
    model = compile_model(get_robot("a1"), terrain=terrain)
    xs, ys = _points_away_from_the_robot()
    _, geoms = _ray_heights(model, xs, ys)
    np.testing.assert_allclose(model.geom_friction[geoms, 0], terrain.friction_at(xs, ys))
    assert set(np.round(terrain.friction_at(xs, ys), 6)) == {0.1, 1.0}


@pytest.mark.parametrize("difficulty", [0.25, 1.0])
def test_difficulty_maps_to_the_documented_sizes(difficulty):
    rough = make_terrain("rough", difficulty=difficulty, seed=0)
    assert rough.height_at(*np.meshgrid(np.linspace(-4, 4, 41), np.linspace(-4, 4, 41))).max() == pytest.approx(
        0.10 * difficulty, rel=0.05)
    stairs = make_terrain("stairs", difficulty=difficulty)
    first = float(stairs.height_at(stairs.platform_m + 0.01, 0.0))
    top = float(stairs.height_at(stairs.platform_m + (stairs.num_steps - 0.5) * stairs.step_depth_m, 0.0))
    assert first == pytest.approx(0.20 * difficulty) and top == pytest.approx(stairs.num_steps * 0.20 * difficulty)
    slope = make_terrain("slope", difficulty=difficulty)
    r = np.array([slope.platform_m + 0.2, slope.platform_m + 0.6])
    rise = np.diff(slope.height_at(r, 0.0))[0]  # on grid points along the x axis: exact
    assert rise / 0.4 == pytest.approx(np.tan(0.40 * difficulty), rel=1e-4)
    blocks = make_terrain("blocks", difficulty=difficulty, seed=1)
    assert blocks._boxes[:, 4].max() <= 0.20 * difficulty and blocks._boxes[:, 4].min() >= 0.10 * difficulty


# ---------------------------------------------------------------- robots start on the ground
def _start_data(model, state):
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state, STATE_SPEC)
    mujoco.mj_forward(model, data)
    return data


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("name", BUILT_IN + ("flat",))
def test_robots_start_just_above_the_ground(robot, name):
    terrain = make_terrain(name, difficulty=1.0, seed=4)
    sim = BatchedSimulator(robot, 1, terrain=terrain)
    data = _start_data(sim.model, sim.state[0])
    assert all(data.contact[i].dist >= -1e-12 for i in range(data.ncon))  # nothing penetrates the ground
    feet = foot_geoms(sim.model, sim.robot)
    gaps = [_geom_bottom(sim.model, data, g) - terrain.highest_in_disc(*data.geom_xpos[g][:2],
                                                                         sim.model.geom_rbound[g]) for g in feet]
    if name != "flat":
        assert min(gaps) == pytest.approx(START_CLEARANCE_M, abs=1e-9)  # the lowest foot just above the ground
    result = sim.run(np.tile(np.asarray(sim.robot.standing_pose), (1, 50, 1)))
    assert not result.failed.any()  # it lands and stands


@pytest.mark.parametrize("name", ("rough", "stairs"))
def test_the_dm_control_env_starts_on_the_terrain_as_the_batched_simulator(name):
    terrain = make_terrain(name, difficulty=1.0)
    env = make_env("a1", seed=0, init_joint_noise=0.0, terrain=terrain)
    check_env_specs(env)
    td = env.reset()
    sim = BatchedSimulator("a1", 1, terrain=terrain)
    np.testing.assert_array_equal(env.base_env.physics.data.qpos, sim.qpos[0])
    td = env.rollout(20, policy=lambda td: td.set("action", torch.as_tensor(get_robot("a1").standing_pose,
                                                                            dtype=torch.float32)))
    assert not td["next", "done"].any()


def test_falls_are_measured_from_the_ground_under_the_robot(tmp_path):
    # on a plateau 0.3 m high a collapsed robot's base is above min_height in world z, yet it has fallen
    path = _write_png(tmp_path / "plateau.png", np.ones((8, 8)))
    terrain = make_terrain(str(path), height_m=0.3)
    robot = get_robot("a1")
    standing = BatchedSimulator(robot, 1, terrain=terrain)
    assert standing.qpos[0, 2] == pytest.approx(0.3 + robot.standing_height, abs=0.01)
    assert not standing.run(np.tile(np.asarray(robot.standing_pose), (1, 50, 1))).fallen.any()
    collapsed = BatchedSimulator(robot, 1, terrain=terrain, limp_legs=robot.leg_names)
    result = collapsed.run(np.tile(np.asarray(robot.standing_pose), (1, 100, 1)))
    assert result.height[0, -1] > robot.min_height  # above the floor's min height in world z ...
    assert result.fallen[0, -1] and not result.unstable.any()  # ... yet fallen: it lies on the plateau
    env = make_env(robot, terrain=terrain, seed=0)
    physics = env.base_env.physics
    env.reset()
    assert not physics.has_fallen()
    physics.data.qpos[2] = 0.3 + 0.5 * robot.min_height
    assert physics.has_fallen()


# ---------------------------------------------------------------- flat changes nothing
@pytest.mark.parametrize("robot", ROBOTS)
def test_flat_leaves_the_model_and_the_simulation_bit_identical(robot):
    spec = get_robot(robot)
    assert _mjb(compile_model(spec)) == _mjb(compile_model(spec, terrain=make_terrain("flat")))
    targets = np.tile(np.asarray(spec.standing_pose), (3, 40, 1)) + 0.1
    plain = BatchedSimulator(robot, 3, init_joint_noise=0.05, seed=2, nthread=1)
    flat = BatchedSimulator(robot, 3, init_joint_noise=0.05, seed=2, nthread=1, terrain="flat", pushes=Pushes(),
                            randomization=DynamicsRandomization())
    np.testing.assert_array_equal(plain.state, flat.state)
    a, b = plain.run(targets), flat.run(targets)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.fallen, b.fallen)
    np.testing.assert_array_equal(plain.state, flat.state)
    assert make_terrain(None).key() == make_terrain("flat").key() == {}
    assert Pushes().key() == {} and DynamicsRandomization().key() == {}


def test_navigation_boxes_stand_on_the_terrain():
    task = Navigation(arena_seed=0, num_obstacles=4)
    terrain = make_terrain("rough", difficulty=1.0)
    flat_model = compile_model(get_robot("a1"), obstacles=task.obstacles)
    model = compile_model(get_robot("a1"), obstacles=task.obstacles, terrain=terrain)
    for i, obstacle in enumerate(task.obstacles):
        flat_box, box = flat_model.geom(f"obstacle_{i}"), model.geom(f"obstacle_{i}")
        bottom, top = box.pos[2] - box.size[2], box.pos[2] + box.size[2]
        assert bottom == pytest.approx(0.0) and top > flat_box.pos[2] + flat_box.size[2]
        ground = terrain.height_at(obstacle.x, obstacle.y)
        assert top == pytest.approx(2 * obstacle.half_size[2] + float(ground), abs=0.1)


# ---------------------------------------------------------------- seeds
@pytest.mark.parametrize("name", SEEDED)
def test_same_seed_same_terrain_another_seed_another(name):
    x, y = np.meshgrid(np.linspace(-4, 4, 81), np.linspace(-4, 4, 81))
    first, again, other = (make_terrain(name, seed=s) for s in (7, 7, 8))
    np.testing.assert_array_equal(first.height_at(x, y), again.height_at(x, y))
    robot = get_robot("a1")
    assert _mjb(compile_model(robot, terrain=first)) == _mjb(compile_model(robot, terrain=again))
    assert not np.array_equal(first.height_at(x, y), other.height_at(x, y))
    assert first.key() == again.key() != other.key()


def test_keys_hold_the_options_that_change_the_terrain():
    assert make_terrain("rough").key() == {"name": "rough", "difficulty": 0.5, "seed": 0}
    assert make_terrain("stairs", seed=3).key() == make_terrain("stairs").key()  # stairs do not depend on the seed
    assert make_terrain("slope", angle_rad=0.2).key() == {"name": "slope", "difficulty": 0.5, "angle_rad": 0.2}
    assert make_terrain({"name": "blocks", "difficulty": 1.0, "seed": 2}).key() == \
        {"name": "blocks", "difficulty": 1.0, "seed": 2}
    assert set(TERRAINS.names()) >= {"flat", *BUILT_IN, "heightmap", "mjcf"}


def test_a_terrain_of_ones_own_is_registered_and_used_by_name():
    @TERRAINS.register("test_platform")
    class Platform(BoxTerrain):
        def __init__(self, *, height_m: float = 0.1):
            self.height_m = height_m
            self._boxes = np.array([[0.0, 0.0, 1.0, 1.0, height_m]])

    try:
        assert make_terrain("test_platform", height_m=0.2).key() == {"name": "test_platform", "height_m": 0.2}
        sim = BatchedSimulator("a1", 1, terrain={"name": "test_platform"})
        assert sim.model.geom("terrain_test_platform_0").size[2] == pytest.approx(0.05)
        assert sim.qpos[0, 2] == pytest.approx(0.1 + sim.robot.standing_height, abs=0.01)  # on the platform
    finally:
        TERRAINS.unregister("test_platform")


# ---------------------------------------------------------------- pushes
def test_a_push_changes_the_trunk_velocity_by_the_impulse():
    sim = BatchedSimulator("a1", 3, seed=0)
    sim.run(np.tile(np.asarray(sim.robot.standing_pose), (3, 10, 1)))
    before = sim.com_state.copy()
    change = np.array([[0.5, 0.0], [0.0, -0.7], [0.3, 0.4]])
    sim.push(change)
    after = sim.com_state
    np.testing.assert_allclose(after[:, 3:5] - before[:, 3:5], change, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(after[:, :3], before[:, :3])
    assert [event.copy for event in sim.push_log] == [0, 1, 2]
    assert sim.push_log[1].velocity_change_mps == (0.0, -0.7) and sim.push_log[1].run_step == -1


def test_scheduled_pushes_act_at_their_step_with_their_magnitude_and_direction():
    robot = get_robot("a1")
    targets = np.tile(np.asarray(robot.standing_pose), (2, 60, 1))
    pushed = BatchedSimulator(robot, 2, seed=1, pushes=Pushes(magnitude_mps=0.4, direction_rad=np.pi / 2,
                                                              interval_s=(0.25, 0.25)))
    twin = BatchedSimulator(robot, 2, seed=1)
    result = pushed.run(targets)
    assert [(e.copy, e.run_step, e.episode_step) for e in pushed.last_pushes] == [(0, 25, 25), (1, 25, 25),
                                                                                  (0, 50, 50), (1, 50, 50)]
    first = twin.run(targets[:, :25])
    yaw = twin.com_state[:, 2]
    change = 0.4 * np.stack([np.cos(yaw + np.pi / 2), np.sin(yaw + np.pi / 2)], axis=1)  # to the robot's left
    np.testing.assert_allclose([e.velocity_change_mps for e in pushed.last_pushes[:2]], change, atol=1e-12)
    twin.push(change)
    middle = twin.run(targets[:, 25:50])
    twin.push(np.array([e.velocity_change_mps for e in pushed.last_pushes[2:]]))
    last = twin.run(targets[:, 50:])
    np.testing.assert_array_equal(result.qpos, np.concatenate([first.qpos, middle.qpos, last.qpos], axis=1))
    np.testing.assert_array_equal(pushed.state, twin.state)


def test_push_times_are_seeded_and_reset_with_the_copy():
    options = dict(magnitude_mps=0.3, interval_s=(0.1, 0.5))
    targets = np.tile(np.asarray(get_robot("a1").standing_pose), (4, 100, 1))
    logs = []
    for seed in (3, 3, 4):
        sim = BatchedSimulator("a1", 4, seed=seed, pushes=options)
        sim.run(targets)
        logs.append([(e.copy, e.run_step, round(e.direction_rad, 12)) for e in sim.last_pushes])
    assert logs[0] == logs[1] != logs[2]
    assert all(10 <= step for _, step, _ in logs[0])  # none before the first interval


def test_a_hard_push_is_counted_as_a_fall():
    robot = get_robot("a1")
    sim = BatchedSimulator(robot, 2, seed=0)
    sim.push(np.array([[0.0, 0.0], [0.0, 4.0]]))  # 4 m/s sideways on the second
    result = sim.run(np.tile(np.asarray(robot.standing_pose), (2, 100, 1)))
    assert not result.fallen[0].any() and result.fallen[1, -1]


# ---------------------------------------------------------------- randomised dynamics
def test_randomized_dynamics_respect_their_ranges_and_reach_the_models():
    randomization = DynamicsRandomization(payload_fraction=(0.05, 0.1), com_offset_m=0.02, friction=(0.3, 0.6),
                                          kp_scale=(0.8, 0.9), torque_scale=(1.1, 1.2), latency_steps=(1, 3),
                                          damping_scale=(1.5, 2.0))
    sim = BatchedSimulator("a1", 16, seed=0, randomization=randomization)
    draws, nominal = sim.dynamics, sim.model
    for name, (low, high) in (("payload_fraction", (0.05, 0.1)), ("friction", (0.3, 0.6)), ("kp_scale", (0.8, 0.9)),
                              ("torque_scale", (1.1, 1.2)), ("damping_scale", (1.5, 2.0)), ("latency_steps", (1, 3)),
                              ("com_offset_m", (-0.02, 0.02))):
        assert draws[name].min() >= low and draws[name].max() <= high, name
        assert np.unique(draws[name]).size > 1, name
    base, feet = nominal.body("trunk").id, foot_geoms(nominal, sim.robot)
    dofs = [nominal.joint(j).dofadr[0] for j in sim.robot.joint_names]
    total = nominal.body_mass.sum()
    for i, model in enumerate(sim._copy_models):
        assert model.body_mass[base] == pytest.approx(nominal.body_mass[base] + draws["payload_fraction"][i] * total)
        np.testing.assert_allclose(model.body_ipos[base] - nominal.body_ipos[base], draws["com_offset_m"][i])
        np.testing.assert_allclose(model.geom_friction[feet, 0], draws["friction"][i])
        np.testing.assert_allclose(model.actuator_gainprm[:, 0], nominal.actuator_gainprm[:, 0] * draws["kp_scale"][i])
        np.testing.assert_allclose(model.actuator_biasprm[:, 1], -model.actuator_gainprm[:, 0])
        np.testing.assert_allclose(model.actuator_forcerange, nominal.actuator_forcerange * draws["torque_scale"][i])
        np.testing.assert_allclose(model.dof_damping[dofs], nominal.dof_damping[dofs] * draws["damping_scale"][i])
    np.testing.assert_array_equal(sim._copy_latency, draws["latency_steps"])
    assert not sim.run(np.tile(np.asarray(sim.robot.standing_pose), (16, 50, 1))).failed.any()


def test_randomized_dynamics_are_seeded_and_redrawn_at_reset():
    def draws(seed):
        return BatchedSimulator("a1", 4, seed=seed, randomization="standard").dynamics

    first, again, other = draws(1), draws(1), draws(2)
    for name in first:
        np.testing.assert_array_equal(first[name], again[name])
    assert not np.array_equal(first["kp_scale"], other["kp_scale"])
    sim = BatchedSimulator("a1", 4, seed=1, randomization="standard")
    before = {name: value.copy() for name, value in sim.dynamics.items()}
    sim.reset(np.array([False, True, False, False]))
    changed = before["kp_scale"] != sim.dynamics["kp_scale"]
    assert changed.tolist() == [False, True, False, False]
    assert DynamicsRandomization.standard().key()["latency_steps"] == [0, 5]


def test_randomized_latency_is_the_servo_latency_of_a_slower_robot():
    robot = get_robot("a1")
    targets = np.tile(np.asarray(robot.standing_pose), (2, 30, 1)) + np.linspace(0, 0.2, 30)[None, :, None]
    delayed = BatchedSimulator(robot, 2, seed=0, randomization=DynamicsRandomization(latency_steps=(3, 3)))
    slow = BatchedSimulator(robot.replace(servo_latency=0.006), 2, seed=0)
    np.testing.assert_array_equal(delayed.run(targets).qpos, slow.run(targets).qpos)
    np.testing.assert_array_equal(delayed.run(targets).qpos, slow.run(targets).qpos)  # the delay carries over


# ---------------------------------------------------------------- the latent-action env
def test_the_latent_action_env_walks_on_mild_rough_ground_with_pushes():
    from hierloco.components.low_level import CommandLowLevel
    from hierloco.envs.latent_env import LatentActionEnv

    env = LatentActionEnv(CommandLowLevel("a1", num_robots=2), num_robots=2, seed=0,
                          terrain={"name": "rough", "difficulty": 0.3}, pushes={"magnitude_mps": 0.3})
    assert env.sim.terrain.key() == {"name": "rough", "difficulty": 0.3, "seed": 0}
    td = env.reset()
    start = td["com_state"].clone()
    for _ in range(3):
        td["action"] = torch.tensor([[0.3, 0.0, 0.0], [0.3, 0.0, 0.0]])
        td = env.step(td)["next"]
    assert not td["done"].any()
    assert env.sim.push_log  # pushed at least once in 3 s (every 2 to 4 s)
    forward = (td["com_state"][:, 1] - start[:, 1])  # facing +y
    assert (forward > 0.3).all()


# ---------------------------------------------------------------- the user's own ground
def test_a_user_heightfield_image_works(tmp_path):
    pixels = np.zeros((20, 40))
    pixels[:, 30:] = 1.0  # a white band on the right (+x)
    pixels[:5, :] = 0.5  # a grey band at the top (+y)
    path = _write_png(tmp_path / "ground.png", pixels)
    terrain = make_terrain(str(path), size_m=(8.0, 4.0), height_m=0.1)
    assert terrain.key()["name"] == "heightmap" and len(terrain.key()["sha256"]) == 64
    assert float(terrain.height_at(3.9, -1.9)) == pytest.approx(0.1, abs=1e-6)  # right: white
    assert float(terrain.height_at(-3.9, 1.95)) == pytest.approx(0.05, abs=1e-3)  # top: grey
    assert float(terrain.height_at(-3.9, -1.9)) == pytest.approx(0.0, abs=1e-6)
    model = compile_model(get_robot("a1"), terrain=terrain)
    xs, ys = _points_away_from_the_robot(extent=3.9)
    np.testing.assert_allclose(terrain.height_at(xs, ys), _ray_heights(model, xs, ys)[0], rtol=0, atol=1e-6)
    sim = BatchedSimulator("a1", 1, terrain=terrain)
    assert not sim.run(np.tile(np.asarray(sim.robot.standing_pose), (1, 50, 1))).failed.any()


def test_a_user_mjcf_ground_file_works(tmp_path):
    path = tmp_path / "scene.xml"
    path.write_text(GROUND_XML)
    terrain = make_terrain(str(path))
    assert terrain.key() == {"name": "mjcf", "sha256": terrain.file_digest}
    assert float(terrain.height_at(2.0, 0.0)) == pytest.approx(0.08)  # on the step
    assert float(terrain.height_at(0.5, 0.5)) == pytest.approx(-0.02)  # the file's plane replaces the floor
    assert float(terrain.height_at(0.0, 3.0)) == pytest.approx(-0.02)  # the free ball is no ground
    model = compile_model(get_robot("a1"), terrain=terrain)
    planes = np.flatnonzero(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
    assert len(planes) == 1 and model.geom_pos[planes[0], 2] == pytest.approx(-0.02)
    xs, ys = _points_away_from_the_robot(extent=3.0)
    np.testing.assert_allclose(terrain.height_at(xs, ys), _ray_heights(model, xs, ys)[0], rtol=0, atol=1e-6)
    sim = BatchedSimulator("a1", 1, terrain=terrain)
    assert sim.qpos[0, 2] == pytest.approx(-0.02 + sim.robot.standing_height, abs=0.01)
    assert not sim.run(np.tile(np.asarray(sim.robot.standing_pose), (1, 50, 1))).failed.any()


@pytest.mark.parametrize("content, suffix", [(b"not an image at all", ".png"),
                                             (b"<mujoco><worldbody><geom type='box'</worldbody>", ".xml"),
                                             (b"<mujoco><worldbody><geom type='box' size='1 1 1' contype='0' "
                                              b"conaffinity='0'/></worldbody></mujoco>", ".xml")])
def test_a_broken_terrain_file_is_one_clear_error(tmp_path, content, suffix):
    path = tmp_path / f"broken{suffix}"
    path.write_bytes(content)
    with pytest.raises(TerrainError) as error:
        make_terrain(str(path))
    message = str(error.value)
    assert "\n" not in message and str(path) in message


@pytest.mark.parametrize("terrain, options, expected", [
    ("lava", {}, "unknown terrain 'lava'"),
    ("rough", {"amplitude": 0.1}, "has no option 'amplitude'"),
    ("rough", {"difficulty": 1.5}, "difficulty must be in [0.0, 1.0]"),
    ("stairs", {"num_steps": 0}, "num_steps must be a whole number >= 1"),
    ("blocks", {"min_size_m": 2.0}, "min_size_m 2.0 exceeds max_size_m"),
    ("heightmap", {}, "give path="),
    ("/nowhere/ground.png", {}, "no terrain file /nowhere/ground.png"),
    ({"difficulty": 0.5}, {}, "needs a 'name'"),
])
def test_bad_terrains_are_one_line_errors(terrain, options, expected):
    with pytest.raises(ValueError) as error:
        make_terrain(terrain, **options)
    assert expected in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("make, expected", [
    (lambda: Pushes(magnitude_mps=-1.0), "magnitude_mps must be in"),
    (lambda: Pushes(interval_s=(3.0, 2.0)), "interval_s low 3.0 exceeds high 2.0"),
    (lambda: DynamicsRandomization(latency_steps=(0, 2.5)), "latency_steps must be a whole number"),
    (lambda: DynamicsRandomization(friction=(0.0, 1.0)), "friction must be in"),
    (lambda: BatchedSimulator("a1", 2, pushes={"strength": 1.0}), "pushes has no option 'strength'"),
    (lambda: BatchedSimulator("a1", 2, randomization="wild"), "randomization must be 'standard'"),
])
def test_bad_pushes_and_randomization_are_one_line_errors(make, expected):
    with pytest.raises(ValueError) as error:
        make()
    assert expected in str(error.value) and "\n" not in str(error.value)
