"""Users' own robots: YAML descriptions, entry points, fingerprints, input checks, contact sensing, derived values.

Most tests use the 20.6 kg quadruped fixture (``tests/fixtures/quadruped20``): an MJCF file written the way many
published robots are (torque motors, no free joint, no floor, feet as bodies with a sphere geom and a foot site
exactly that size, a contact margin), and its YAML description.
"""

from __future__ import annotations

import inspect
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from hierloco.envs.robots import (
    A1,
    DAISY,
    ROBOTS,
    admissible_gait_periods,
    available_robots,
    compile_model,
    derive_gait_period,
    derive_standing_height,
    get_robot,
    load_robot_yaml,
    register_robot,
    robot_fingerprint,
    robot_from_mjcf,
    robot_reference,
    standing_qpos,
)
from hierloco.envs.locomotion import FOOT_CONTACT_FORCE
from hierloco.envs.robots.yaml_robot import KEY_TYPES, REQUIRED_KEYS
from tests.envs.robot_yaml import changed_copy
from tests.envs.toy_robot import make_toy_robot

REPO = Path(__file__).resolve().parents[2]
FIXTURE_DIR = REPO / "tests" / "fixtures" / "quadruped20"
FIXTURE_YAML = FIXTURE_DIR / "quadruped20.yaml"
FIXTURE_XML = FIXTURE_DIR / "quadruped20.xml"
LEGS = ("FR", "FL", "RR", "RL")
LINK, FOOT_RADIUS, THIGH, KNEE = 0.25, 0.0265, 0.8, -1.6  # m, m, rad, rad: the fixture's published dimensions
FIXTURE_HEIGHT = 2 * LINK * math.cos(THIGH) + FOOT_RADIUS  # m: the feet are straight under the hips


@pytest.fixture
def registry():
    """The robot registry, restored after the test."""
    saved = dict(ROBOTS)
    yield ROBOTS
    ROBOTS.clear()
    ROBOTS.update(saved)


def _fixture_kwargs(**changes) -> dict:
    """The fixture's YAML content as robot_from_mjcf keyword arguments."""
    content = yaml.safe_load(FIXTURE_YAML.read_text())
    content.pop("mjcf")
    return {**content, **changes}


def _write_yaml(directory: Path, **changes) -> Path:
    """A copy of the fixture's YAML in ``directory``, with some keys changed (``None`` deletes a key)."""
    return changed_copy(FIXTURE_YAML, directory, **changes)


# ---------------------------------------------------------------------------------------------------- YAML
def test_yaml_robot_is_the_described_robot():
    robot = get_robot(str(FIXTURE_YAML))
    assert robot.name == "quadruped20" and robot.base_body == "trunk"
    assert robot.leg_names == LEGS
    assert robot.joint_names[:3] == ("FR_hip_joint", "FR_thigh_joint", "FR_calf_joint")
    assert robot.standing_pose == (0.0, THIGH, KNEE) * 4  # one leg's angles, for every leg
    assert robot.kp == (150.0,) * 12 and robot.joint_damping == (2.0, 4.0, 4.0) * 4
    assert robot.gait_groups == (("FR", "RL"), ("FL", "RR"))
    assert robot.source == f"yaml:{FIXTURE_YAML}" and robot.reference == str(FIXTURE_YAML)
    # the compiled model: 20.637 kg, position servos with the YAML's gain and the motors' torque ranges
    model = compile_model(robot)
    assert model.body_mass.sum() == pytest.approx(20.637)
    np.testing.assert_allclose(model.actuator_gainprm[:, 0], 150.0)
    np.testing.assert_allclose(model.actuator_forcerange[:3], [[-35.278, 35.278]] * 2 + [[-44.4, 44.4]])
    np.testing.assert_allclose(model.dof_damping[6:9], [2.0, 4.0, 4.0])


def test_yaml_robot_is_found_by_any_spelling_of_its_path(monkeypatch):
    robot = get_robot(str(FIXTURE_YAML))
    assert get_robot(FIXTURE_YAML) is robot  # a Path
    monkeypatch.chdir(FIXTURE_DIR)
    assert get_robot("quadruped20.yaml") is robot  # relative to the working directory
    assert robot_reference("quadruped20.yaml") == str(FIXTURE_YAML)
    assert load_robot_yaml("quadruped20.yaml") == robot


def test_yaml_mjcf_path_relative_to_the_yaml_file_or_absolute(tmp_path):
    (tmp_path / "models").mkdir()
    shutil.copy(FIXTURE_XML, tmp_path / "models" / "q.xml")
    relative = _write_yaml(tmp_path, mjcf="models/q.xml")
    absolute = get_robot(str(FIXTURE_YAML))
    robot = load_robot_yaml(relative)
    assert robot_fingerprint(robot) == robot_fingerprint(absolute)  # same file content, same robot


def test_editing_a_yaml_robot_is_seen_and_changes_its_fingerprint(tmp_path):
    path = _write_yaml(tmp_path)
    before = get_robot(str(path))
    path.write_text(path.read_text().replace("kp: 150", "kp: 175.5"))
    after = get_robot(str(path))
    assert after.kp == (175.5,) * 12 and after.name == before.name
    assert robot_fingerprint(after) != robot_fingerprint(before)


@pytest.mark.parametrize("changes, message", [
    ({"kpp": 150}, r"unknown key 'kpp' \(did you mean 'kp'\?\)"),
    ({"legs": None}, r"missing key 'legs'"),
    ({"kp": "stiff"}, r"key 'kp' must be a number, a list of numbers"),
    ({"gait_groups": "trot"}, r"key 'gait_groups' must be a list of lists of leg names"),
    ({"command_low": [-0.3, -0.3]}, r"key 'command_low' must be 3 numbers"),
    ({"mjcf": "nowhere/robot.xml"}, r"key 'mjcf': no such MJCF file .*nowhere/robot.xml"),
    ({"base_body": "trunkk"}, r"base_body: no body named 'trunkk' \(close: 'trunk'"),
    ({"feet": {leg: f"{leg}_fot" for leg in LEGS}}, r"feet\['FR'\]: 'FR_fot' is neither a site nor a body.*'FR_foot'"),
    ({"legs": {**{leg: [f"{leg}_hip_joint", f"{leg}_thigh_joint", f"{leg}_calf_joint"] for leg in LEGS},
               "FR": ["FR_hip_joint", "FR_thigh_jiont", "FR_calf_joint"]}},
     r"legs\['FR'\]: no joint named 'FR_thigh_jiont' \(close: 'FR_thigh_joint'"),
    ({"kp": [150, float("nan"), 150]}, r"kp of joint 'FR_thigh_joint' must be a finite positive number, got nan"),
    ({"gait_groups": [["FR", "RL"], ["FL", "RX"]]}, r"gait_groups: .*no leg named 'RX' \(close: "),
])
def test_yaml_errors_name_the_file_and_the_key(tmp_path, changes, message):
    path = _write_yaml(tmp_path, **changes)
    with pytest.raises(ValueError, match=message) as error:
        get_robot(str(path))
    assert str(error.value).startswith(str(path)), error.value


def test_yaml_keys_are_robot_from_mjcf_keyword_arguments():
    parameters = inspect.signature(robot_from_mjcf).parameters
    assert set(KEY_TYPES) == {"mjcf"} | set(parameters) - {"xml", "source"}
    assert set(REQUIRED_KEYS) == {"mjcf", "name", "base_body", "legs", "feet", "standing_pose", "gait_groups"}


def test_missing_or_malformed_yaml_file_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match=r"robot description .*absent.yaml.*no such file"):
        get_robot(str(tmp_path / "absent.yaml"))
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(ValueError, match="bad.yaml: not a valid YAML file"):
        get_robot(str(bad))
    bad.write_text("- a list\n")
    with pytest.raises(ValueError, match="bad.yaml: a robot description is a mapping"):
        get_robot(str(bad))


def test_yaml_robot_resolves_in_another_process_with_the_same_fingerprint(tmp_path):
    """A worker that receives only the config string builds the same robot (absolute and relative paths)."""
    script = textwrap.dedent(f"""
        import json, sys
        from hierloco.envs.robots import A1, get_robot, robot_fingerprint
        robot = get_robot(sys.argv[1])
        print(json.dumps([robot.name, robot.gait_period, robot_fingerprint(robot), robot_fingerprint(A1)]))
    """)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", script, "quadruped20.yaml"], cwd=FIXTURE_DIR, env=env,
                         capture_output=True, text=True, timeout=600, check=True)
    name, period, fingerprint, a1 = json.loads(out.stdout.strip().splitlines()[-1])
    robot = get_robot(str(FIXTURE_YAML))
    assert (name, period) == (robot.name, robot.gait_period)
    assert fingerprint == robot_fingerprint(robot)
    assert a1 == robot_fingerprint(A1)


# ---------------------------------------------------------------------------------------------------- entry points
def _install_entry_points(directory: Path, module: str, entries: dict[str, str]) -> None:
    """A distribution on ``directory`` (put it on sys.path) whose ``hierloco.robots`` entry points are ``entries``."""
    info = directory / "hierloco_test_robots-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: hierloco-test-robots\nVersion: 0.1\n")
    lines = "\n".join(f"{name} = {module}:{target}" for name, target in entries.items())
    (info / "entry_points.txt").write_text(f"[hierloco.robots]\n{lines}\n")


def test_entry_point_robots_load_lazily_on_first_lookup(tmp_path, monkeypatch, registry):
    module = "hierloco_test_robot_pkg"
    (tmp_path / f"{module}.py").write_text(textwrap.dedent(f"""
        from hierloco.envs.robots import A1, load_robot_yaml
        A1_SOFT = A1.replace(name="a1_soft", kp=(60.0,) * 12)          # a RobotSpec
        def make_quadruped20():                                          # a zero-argument callable
            return load_robot_yaml({str(FIXTURE_YAML)!r})
        def make_wrong_name():
            return A1
        NOT_A_ROBOT = 42
    """))
    _install_entry_points(tmp_path, module, {"a1_soft": "A1_SOFT", "quadruped20": "make_quadruped20",
                                             "misnamed": "make_wrong_name", "broken": "NOT_A_ROBOT",
                                             "missing": "NO_SUCH_NAME"})
    monkeypatch.syspath_prepend(str(tmp_path))
    assert {"a1_soft", "quadruped20", "broken"} <= set(available_robots())
    assert module not in sys.modules and "a1_soft" not in ROBOTS  # nothing loaded before the first lookup
    soft = get_robot("a1_soft")
    assert soft.kp == (60.0,) * 12 and ROBOTS["a1_soft"] is soft and get_robot("a1_soft") is soft
    assert soft.source == f"entry_point:a1_soft = {module}:A1_SOFT" and soft.reference == "a1_soft"
    quad = get_robot("quadruped20")
    assert robot_fingerprint(quad) == robot_fingerprint(get_robot(str(FIXTURE_YAML)))
    with pytest.raises(ValueError, match="entry point's name must be the robot's name, got a robot named 'a1'"):
        get_robot("misnamed")
    with pytest.raises(ValueError, match="must name a RobotSpec or a zero-argument callable returning one, got int"):
        get_robot("broken")
    with pytest.raises(ValueError, match=f"'missing' \\(entry point '{module}:NO_SUCH_NAME'.*loading it failed"):
        get_robot("missing")
    with pytest.raises(ValueError, match="unknown robot 'cheetah'; robots: .*a1_soft"):
        get_robot("cheetah")


# ---------------------------------------------------------------------------------------------------- fingerprint
def test_fingerprint_is_a_cached_sha256_that_follows_every_field():
    robot = get_robot(str(FIXTURE_YAML))
    fingerprint = robot_fingerprint(robot)
    assert len(fingerprint) == 64 and int(fingerprint, 16) >= 0
    assert robot_fingerprint(robot) is fingerprint  # cached on the instance
    assert robot_fingerprint(load_robot_yaml(FIXTURE_YAML)) == fingerprint  # a fresh load, the same digest
    assert robot_fingerprint(robot.replace(kp=(151.0,) * 12)) != fingerprint  # in the compiled model
    assert robot_fingerprint(robot.replace(gait_period=0.2)) != fingerprint  # only in the description
    assert robot_fingerprint(robot.replace(swing_height=0.05)) != fingerprint
    assert len({robot_fingerprint(r) for r in (A1, DAISY, robot)}) == 3


def test_user_robot_registered_as_a1_differs_from_the_builtin_a1(registry):
    builtin = robot_fingerprint(A1)
    impostor = register_robot(robot_from_mjcf(FIXTURE_XML, **_fixture_kwargs(name="a1")))
    assert get_robot("a1") is impostor
    assert robot_fingerprint(get_robot("a1")) != builtin
    # even a copy of A1 with one gain changed is another robot
    assert robot_fingerprint(A1.replace(kp=(100.0,) * 11 + (101.0,))) != builtin


# ---------------------------------------------------------------------------------------------------- input checks
@pytest.mark.parametrize("key", ["kp", "torque_limit", "joint_damping"])
@pytest.mark.parametrize("bad", [float("nan"), -5.0, 0.0, float("inf")])
def test_gains_limits_and_damping_must_be_finite_and_positive(key, bad):
    values = [10.0] * 12
    values[4] = bad  # FL thigh
    with pytest.raises(ValueError, match=f"{key} of joint 'FL_thigh_joint' must be a finite positive number"):
        robot_from_mjcf(FIXTURE_XML, **_fixture_kwargs(**{key: values}))


@pytest.mark.parametrize("num_legs", [0, 1, 2])
def test_fewer_than_three_legs_are_refused(num_legs):
    legs = LEGS[:num_legs]
    kwargs = _fixture_kwargs(legs={leg: _fixture_kwargs()["legs"][leg] for leg in legs},
                             feet={leg: f"{leg}_foot" for leg in legs}, gait_groups=[[leg] for leg in legs],
                             rear_legs=list(legs), kp=10.0, joint_damping=1.0)
    with pytest.raises(ValueError, match=f"has {num_legs} legs .*expert gaits .*need at least 3 legs"):
        robot_from_mjcf(FIXTURE_XML, **kwargs)


def test_gait_groups_are_checked():
    with pytest.raises(ValueError, match=r"gait_groups .* must hold every leg exactly once \(missing \['RR'\]"):
        robot_from_mjcf(FIXTURE_XML, **_fixture_kwargs(gait_groups=[["FR", "RL"], ["FL"]]))
    with pytest.raises(ValueError, match="gait_groups must be at least two non-empty groups"):
        robot_from_mjcf(FIXTURE_XML, **_fixture_kwargs(gait_groups=[list(LEGS)]))
    with pytest.raises(ValueError, match=r"rear_legs .*no leg named 'rr' \(close: 'RR'"):
        robot_from_mjcf(FIXTURE_XML, **_fixture_kwargs(rear_legs=["rr", "RL"]))


def test_custom_builder_names_are_checked_at_compile_time():
    with pytest.raises(ValueError, match=r"base_body: no body named 'trnk' \(close: 'trunk'"):
        compile_model(A1.replace(base_body="trnk"))


# ---------------------------------------------------------------------------------------------------- contacts
def _stand(model, robot, seconds: float = 1.0) -> mujoco.MjData:
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, robot)
    data.ctrl[:] = robot.standing_pose
    mujoco.mj_step(model, data, nstep=int(round(seconds / model.opt.timestep)))
    return data


def test_standing_feet_read_stance_where_foot_sized_sites_read_nothing():
    robot = get_robot(str(FIXTURE_YAML))
    model = compile_model(robot)
    data = _stand(model, robot)
    weight = model.body_mass.sum() * -model.opt.gravity[2]
    touch = data.sensordata[: len(robot.legs)]
    assert np.all(touch > FOOT_CONTACT_FORCE), touch  # every foot reads stance
    assert touch.sum() == pytest.approx(weight, rel=0.05)  # and together they carry the robot
    # the same model and motion, with the touch sensors moved to the file's own foot sites (exactly the size of
    # the foot spheres): the contact point lies outside the sphere, and MuJoCo's touch sensor misses it
    own = compile_model(robot)
    own.sensor_objid[: len(robot.legs)] = [own.site(leg.foot_site).id for leg in robot.legs]
    own_data = _stand(own, robot)
    np.testing.assert_array_equal(own_data.qpos, data.qpos)
    assert np.all(own_data.sensordata[: len(robot.legs)] < FOOT_CONTACT_FORCE), own_data.sensordata


def test_lifted_foot_reads_swing_and_the_others_stance():
    robot = get_robot(str(FIXTURE_YAML))
    model = compile_model(robot)
    data = _stand(model, robot, seconds=0.5)
    assert np.all(data.sensordata[:4] > FOOT_CONTACT_FORCE)
    targets = np.array(robot.standing_pose)
    targets[1:3] = (THIGH + 0.6, KNEE - 1.0)  # FR: thigh forward, knee folded: the foot comes up
    data.ctrl[:] = targets
    mujoco.mj_step(model, data, nstep=100)  # 0.2 s
    fr = model.site(robot.legs[0].foot_site).id
    assert data.site_xpos[fr][2] > FOOT_RADIUS + 0.03, "the FR foot should be in the air"
    assert data.sensordata[0] < FOOT_CONTACT_FORCE
    assert np.all(data.sensordata[1:4] > FOOT_CONTACT_FORCE)


def test_touch_sites_sit_on_the_foot_geoms():
    for robot in (A1, DAISY, get_robot(str(FIXTURE_YAML)), make_toy_robot("body")):
        model = compile_model(robot)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        for leg in robot.legs:
            site = model.site(f"hierloco_touch_{leg.name}")
            foot = model.geom(f"{leg.name}_foot")
            np.testing.assert_allclose(data.site_xpos[site.id], data.geom_xpos[foot.id], atol=1e-12)
            assert site.bodyid == foot.bodyid
            assert model.site_size[site.id, 0] >= 1.25 * model.geom_size[foot.id, 0] + model.geom_margin[foot.id]


# ---------------------------------------------------------------------------------------------------- derived values
def test_standing_height_is_derived_from_the_standing_pose():
    robot = get_robot(str(FIXTURE_YAML))
    assert robot.standing_height == pytest.approx(FIXTURE_HEIGHT, abs=1e-9)
    assert robot.min_height == pytest.approx(FIXTURE_HEIGHT / 2)
    assert derive_standing_height(A1) == pytest.approx(2 * 0.2 * math.cos(0.9) + 0.02, abs=1e-9)
    assert derive_standing_height(DAISY) == pytest.approx(DAISY.standing_height, abs=1e-9)
    # in that pose the lowest foot touches the floor
    model = compile_model(robot)
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, robot)
    mujoco.mj_kinematics(model, data)
    feet = [model.geom(f"{leg}_foot").id for leg in LEGS]
    np.testing.assert_allclose(data.geom_xpos[feet, 2] - model.geom_size[feet, 0], 0.0, atol=1e-9)


def test_gait_period_is_derived_from_the_robot_size():
    """0.6 pi sqrt(h / g) for a trot, twice that for a statically stable gait, rounded to a period that splits 100
    steps: A1 (h = 0.27 m) 0.31 s -> 0.2 s (its own), the 20 kg robot (0.375 m) 0.37 s -> 0.5 s, Daisy's tripod
    (0.23 m) 0.57 s -> 0.5 s (the built-ins keep the periods they were tuned with)."""
    robot = get_robot(str(FIXTURE_YAML))
    assert robot.gait_period == 0.5
    assert derive_gait_period(A1) == 0.2 and derive_gait_period(DAISY) == 0.5
    assert (A1.gait_period, DAISY.gait_period) == (0.2, 1.0)
    for r in (A1, DAISY, robot, make_toy_robot("site")):
        period = derive_gait_period(r)
        steps = round(period / 0.01)
        assert 0.2 <= period <= 1.0 and 100 % steps == 0 and steps % len(r.gait_groups) == 0
    assert admissible_gait_periods(2) == (0.04, 0.1, 0.2, 0.5, 1.0)
    # three swing phases cannot split 100 steps exactly: the period ends with a step or two on all feet
    assert admissible_gait_periods(3) == (0.1, 0.2, 0.25, 0.5, 1.0)
    three = robot_from_mjcf(FIXTURE_XML, **_fixture_kwargs(gait_groups=[["FR"], ["FL", "RR"], ["RL"]]))
    assert three.gait_period in admissible_gait_periods(3)
    assert admissible_gait_periods(51) == ()  # fewer than 2 steps per swing phase
    # the fixtures written for the robot check (docs/robots.md): period and foot lift from the hips' height
    fixtures = REPO / "tests" / "fixtures"
    derived = {name: (r.gait_period, r.swing_height) for name, r in (
        (p.stem, get_robot(str(p))) for p in (fixtures / "quadruped9" / "quadruped9.yaml",
                                              fixtures / "quadruped40" / "quadruped40.yaml",
                                              fixtures / "hexapod10" / "hexapod10.yaml",
                                              fixtures / "hexapod10" / "hexapod10_wave.yaml"))}
    assert derived == {"quadruped9": (0.5, 0.045), "quadruped40": (0.5, 0.078), "hexapod10": (0.5, 0.026),
                       "hexapod10_wave": (0.5, 0.026)}
