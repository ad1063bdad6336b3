"""The search of the expert controller's parameters (:mod:`hierloco.components.expert_tuning`): candidates side by
side on one batched simulator, told apart by what their experts do; the parameters it prints read back as the
robot; the fixture robots walk with the derived defaults and, after the check, at every stage."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from hierloco.components.evaluation import replayed_fraction
from hierloco.components.expert_library import build_expert_library, diagnose_expert_library
from hierloco.components.expert_tuning import (
    Candidate,
    ExpertParameters,
    per_joint_yaml,
    rank,
    screen_candidates,
    tune_expert_parameters,
)
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.robots import A1, get_robot, load_robot_yaml

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
ROBOT_FILES = {
    "quadruped20": FIXTURES / "quadruped20" / "quadruped20.yaml",
    "quadruped9": FIXTURES / "quadruped9" / "quadruped9.yaml",
    "hexapod10": FIXTURES / "hexapod10" / "hexapod10.yaml",
    "hexapod10_wave": FIXTURES / "hexapod10" / "hexapod10_wave.yaml",
    "quadruped40": FIXTURES / "quadruped40" / "quadruped40.yaml",
}


def test_copy_robots_simulate_each_variant_as_its_own_simulator_would():
    """One rollout call for several robot variants gives each copy exactly what a simulator of that variant gives."""
    variants = [A1, A1.replace(kp=(160.0,) * 12, joint_damping=(3.0,) * 12),
                A1.replace(standing_height=0.25, standing_pose=(0.0, 1.0, -2.0) * 4)]
    rng = np.random.default_rng(0)
    targets = np.asarray(A1.standing_pose) + 0.3 * rng.standard_normal((3, 30, 12))
    batched = BatchedSimulator(A1, 3, copy_robots=variants, nthread=1)
    together = batched.run(targets)
    for i, variant in enumerate(variants):
        alone = BatchedSimulator(variant, 1, nthread=1).run(targets[i:i + 1])
        np.testing.assert_array_equal(together.qpos[i], alone.qpos[0])
    assert not np.allclose(together.qpos[0], together.qpos[1])  # the gains make a difference
    batched.reset()
    np.testing.assert_allclose(batched.qpos[2, 2], 0.25)  # each copy stands in its own pose
    with pytest.raises(ValueError, match="one robot per copy"):
        BatchedSimulator(A1, 2, copy_robots=variants)


def test_screening_tells_a_trot_that_walks_from_one_that_walks_backward():
    """The 40 kg quadruped: at 0.5 s with stiffer servos and a 5 cm foot lift its experts follow every command
    and replay steadily; at 0.2 s they walk backward whatever they are told."""
    robot = get_robot(str(ROBOT_FILES["quadruped40"]))
    reference = ExpertParameters.of(robot)
    good = replace(reference, gait_period=0.5, swing_height=0.05, kp=tuple(2 * k for k in reference.kp))
    bad = replace(reference, gait_period=0.2)
    scores = screen_candidates(robot, [Candidate(bad, "0.2 s"), Candidate(good, "0.5 s, kp x2")])
    bad_score, good_score = scores
    assert good_score.passes and good_score.worst_reach > 0.8 and good_score.replayed_fraction >= 0.9
    assert not bad_score.passes
    vx = bad_score.axes[0]
    assert vx.offset < -0.2 and not vx.ok, vx.describe()  # backward at more than 0.2 m/s, whatever the command
    assert [s.candidate.label for s in rank(scores, reference)] == ["0.5 s, kp x2", "0.2 s"]


def test_printed_parameters_read_back_as_the_robot(tmp_path):
    """The YAML lines the check prints, pasted into the robot's file, give a robot with exactly those parameters."""
    source = ROBOT_FILES["quadruped9"]
    robot = get_robot(str(source))
    reference = ExpertParameters.of(robot)
    pose = tuple(v + 0.05 * (i % 3) for i, v in enumerate(reference.standing_pose))
    found = replace(reference, gait_period=0.5, swing_height=0.07, standing_height=0.29, standing_pose=pose,
                    kp=(75.0, 90.0, 90.0) * 4, joint_damping=(1.5,) * 12, command_low=(-0.15, -0.15, -0.3),
                    command_high=(0.15, 0.15, 0.3))
    lines = found.yaml_lines(robot, only=found.changed(reference))
    assert lines[0] == "gait_period: 0.5" and "kp: [75, 90, 90]" in lines and "joint_damping: 1.5" in lines
    content = yaml.safe_load(source.read_text())
    content["mjcf"] = str(source.parent / content["mjcf"])
    content.update(yaml.safe_load("\n".join(lines)))
    path = tmp_path / "tuned.yaml"
    path.write_text(yaml.safe_dump(content, sort_keys=False))
    tuned = ExpertParameters.of(load_robot_yaml(path))
    assert tuned.changed(found) == []
    assert per_joint_yaml(robot, [0.0, -0.8, 1.6] * 2 + [0.0, 0.8, -1.6] * 2) == (
        "{FR: [0, -0.8, 1.6], FL: [0, -0.8, 1.6], RR: [0, 0.8, -1.6], RL: [0, 0.8, -1.6]}")


@pytest.mark.parametrize("name", ["quadruped20", "hexapod10_wave"])
def test_a_yaml_with_names_and_a_pose_walks_with_the_derived_defaults(name):
    """With the derived gait period, standing height and swing height (docs/robots.md), the experts stage's
    experts walk as commanded and their own targets replay as recorded (the wave gait had no admissible period
    before)."""
    robot = get_robot(str(ROBOT_FILES[name]))
    assert robot.gait_period == 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        library = build_expert_library(robot, 12, settle_time=2.0, seed=0, progress=False)
    report = diagnose_expert_library(library, robot=robot)
    assert report.ok and report.worst_reach > 0.8, str(report)
    assert replayed_fraction(library, robot=robot) >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize("name", list(ROBOT_FILES))
def test_each_fixture_robot_walks_after_the_check(name):
    """The check on a tiny budget (screening only), then the experts stage with what it found: the experts walk
    as commanded and their own targets replay steadily (what the gait policy must reproduce)."""
    robot = get_robot(str(ROBOT_FILES[name]))
    result = tune_expert_parameters(robot, budget_seconds=30, verify=False)
    assert result.found, result.limits
    tuned = result.params.apply(robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        library = build_expert_library(tuned, 12, settle_time=2.0, seed=1, progress=False)
    report = diagnose_expert_library(library, robot=tuned)
    assert report.ok and report.worst_reach > 0.6, str(report)
    assert replayed_fraction(library, robot=tuned) >= 0.75
