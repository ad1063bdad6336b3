"""The robot check (``hierloco-robot-check``, :mod:`hierloco.envs.robots.check`): a description's problems in
milliseconds, one line each with the numbers and the fix, and the experts stage refusing them before it simulates.

Robots: the built-ins, the 20.6 kg quadruped fixture and the fixtures written for these checks
(``tests/fixtures/quadruped9``: pitch axes -y and knees bent both ways; ``hexapod10``: sideways legs, tripod and
wave gait; ``quadruped40``: position servos in the file; ``quadruped50``: torque motors, little joint damping in the
file and a user's kp too soft for its 50 kg, which only the servo search walks). The search's own screening and
what it prints are tested here on small searches; the whole check on the 50 kg robot is ``-m slow``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from hierloco.components.expert_library import ExpertQualityError, build_expert_library, expert_setup_problems
from hierloco.components.expert_tuning import (
    Candidate,
    ExpertParameters,
    TuningResult,
    Verification,
    _limits,
    screen_candidates,
    servo_settings,
    tune_expert_parameters,
    verify_candidate,
)
from hierloco.components.experts import RaibertController, foothold_reach
from hierloco.envs.robots import A1, DAISY, get_robot, load_robot_yaml
from hierloco.envs.robots.check import (
    EXIT_FOUND,
    EXIT_NOT_FOUND,
    MIN_FOOT_DROP,
    description_problems,
    description_summary,
    standing_statics,
    suggested_standing_pose,
)

from hierloco.envs.robots.check.__main__ import main, report_lines  # the command line

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "tests" / "fixtures"
QUADRUPED20 = FIXTURES / "quadruped20" / "quadruped20.yaml"
ROBOT_FILES = {
    "quadruped20": QUADRUPED20,
    "quadruped9": FIXTURES / "quadruped9" / "quadruped9.yaml",
    "hexapod10": FIXTURES / "hexapod10" / "hexapod10.yaml",
    "hexapod10_wave": FIXTURES / "hexapod10" / "hexapod10_wave.yaml",
    "quadruped40": FIXTURES / "quadruped40" / "quadruped40.yaml",
    "quadruped50": FIXTURES / "quadruped50" / "quadruped50.yaml",
}
FOLDED = [0.0, 2.4, -2.7]  # rad: the thigh swung up and the knee closed, the feet 5 cm below the hips


def _yaml_copy(directory: Path, source: Path = QUADRUPED20, **changes) -> Path:
    """A copy of a fixture's YAML in ``directory`` (its MJCF by absolute path) with some keys changed."""
    content = yaml.safe_load(source.read_text())
    content["mjcf"] = str(source.parent / content["mjcf"])
    content.update(changes)
    path = directory / "robot.yaml"
    path.write_text(yaml.safe_dump(content, sort_keys=False))
    return path


@pytest.mark.parametrize("name", ["a1", "daisy", *ROBOT_FILES])
def test_robots_that_walk_have_no_description_problems(name):
    robot = get_robot(str(ROBOT_FILES.get(name, name)))
    assert description_problems(robot) == []
    assert expert_setup_problems(robot) == []
    statics = standing_statics(robot)
    assert all(leg.foot_drop >= MIN_FOOT_DROP * leg.reach for leg in statics.legs)
    assert all(abs(leg.foot_height) < 0.01 for leg in statics.legs)  # every foot on the floor


def test_statics_are_the_robot_standing_on_its_stance_legs():
    """A1: 12.45 kg on the two legs of a trot pair; the knee holds 61 N at 0.2 sin(0.9) m from the foot."""
    statics = standing_statics(A1)
    assert statics.stance_legs == 2 and statics.mass == pytest.approx(12.45, abs=0.01)
    fr = statics.legs[0]
    assert fr.hip_height == pytest.approx(0.27) and fr.foot_drop == pytest.approx(0.4 * np.cos(0.9))
    load = statics.mass * 9.81 / 2
    assert fr.static_torque[2] == pytest.approx(load * 0.2 * np.sin(0.9), rel=0.02)
    assert fr.torque_limit == (33.5,) * 3 and fr.kp == (100.0,) * 3
    assert standing_statics(DAISY).stance_legs == 3


def test_folded_pose_is_refused_in_under_5_s_with_the_feet_against_the_hips(tmp_path):
    """A 'home' keyframe with the legs folded (feet 5 cm below the hips): before, the experts stage ground in leg
    IK for minutes; now the description and the experts stage refuse it at once, with the numbers."""
    path = _yaml_copy(tmp_path, standing_pose=FOLDED)
    start = time.perf_counter()
    robot = load_robot_yaml(path)
    problems = description_problems(robot)
    assert len(problems) == 1, problems
    line = problems[0]
    for part in ("the feet are only 0.054 m below their hips", "legs FR, FL, RR, RL", "hip 0.081 m",
                 "foot 0.026 m above the floor", "0.583 m of leg", "need at least 0.146 m (25% of the reach)",
                 "give a standing_pose with the feet further down, e.g. [0.00, "):
        assert part in line, line
    with pytest.raises(ExpertQualityError, match="feet are only 0.054 m below their hips") as caught:
        build_expert_library(robot, 30, progress=False)
    assert caught.value.report is None  # stopped before any expert could be judged
    assert time.perf_counter() - start < 5.0
    # the pose the line suggests has no problem
    pose = suggested_standing_pose(robot)
    fixed = robot.replace(standing_pose=pose, standing_height=None, min_height=None)
    assert description_problems(fixed) == []


def test_over_heavy_robot_is_refused_with_the_torque_it_needs():
    robot = get_robot(str(QUADRUPED20)).replace(mass_scale=2.5)  # 51.6 kg on the same motors
    start = time.perf_counter()
    problems = description_problems(robot)
    assert len(problems) == 2, problems  # the torque, and the servos' sag under it
    for part in ("torque: holding 51.6 kg on 2 stance legs (253 N per foot)", "45.4 N m at joint 'RR_calf_joint'",
                 "102% of its 44.4 N m limit", "give torque_limit of at least 60.5 N m"):
        assert part in problems[0], problems[0]
    assert "sags 0.30 rad" in problems[1] and "give kp of at least 363 N m/rad" in problems[1], problems[1]
    with pytest.raises(ExpertQualityError, match="102% of its 44.4 N m limit"):
        build_expert_library(robot, 30, progress=False)
    assert time.perf_counter() - start < 5.0


def test_soft_servos_are_refused_with_the_gain_they_need():
    robot = get_robot(str(QUADRUPED20)).replace(kp=(20.0,) * 12)
    problems = description_problems(robot)
    assert len(problems) == 1 and "sags 0.91 rad off its target" in problems[0], problems
    assert "give kp of at least 145 N m/rad" in problems[0]


def test_feet_off_the_floor_and_angles_outside_the_joint_ranges_are_named():
    robot = get_robot(str(QUADRUPED20))
    (line,) = description_problems(robot.replace(standing_height=0.45))
    assert "at 0.450 m the feet are 0.075 m above the floor: give standing_height: 0.375" in line
    uneven = description_problems(robot.replace(standing_pose=(0.0, 0.8, -1.6) * 3 + (0.0, 0.6, -1.2)))
    assert len(uneven) == 1 and "the feet are not level" in uneven[0] and "-0.064" in uneven[0], uneven
    outside = description_problems(robot.replace(standing_pose=(0.0, 0.8, -2.9) * 4))
    assert "joint 'FR_calf_joint' at -2.900 rad is outside its range [-2.774, -0.645] rad (and 3 more" in outside[0]


def test_unreachable_footholds_stop_the_experts_in_milliseconds():
    """The wave-gait hexapod at a 1 s period: each stance lasts 0.84 s, the feet would sweep 0.24 m, and the
    legs are 4 cm short. The experts stage took 382 s grinding in IK restarts before; now it refuses at once."""
    robot = get_robot(str(ROBOT_FILES["hexapod10_wave"])).replace(gait_period=1.0)
    assert description_problems(robot) == []  # the standing robot is fine
    reach = foothold_reach(robot)
    assert reach.shortfall.max() == pytest.approx(0.042, abs=0.002) and reach.stride == pytest.approx(0.24, abs=0.01)
    start = time.perf_counter()
    with pytest.raises(ExpertQualityError, match=r"footholds: leg \w+ cannot reach .* 0.04\d m short"):
        build_expert_library(robot, 12, progress=False)
    assert time.perf_counter() - start < 5.0
    assert foothold_reach(robot.replace(gait_period=0.5)).shortfall.max() < 1e-3  # the derived period reaches


def test_wave_gait_swings_one_leg_at_a_time_then_stands_on_all_feet():
    """Six groups in a 0.5 s period (50 steps): 8-step swing phases in turn, then 2 steps on all six feet."""
    robot = get_robot(str(ROBOT_FILES["hexapod10_wave"]))
    assert robot.gait_period == 0.5 and len(robot.gait_groups) == 6
    controller = RaibertController(robot, 1)
    assert controller.swing_steps == 8
    swinging = np.array([controller.swing_progress(step) > 0 for step in range(50)])  # 50 x 6
    assert swinging.sum(1)[:48].tolist() == [1] * 48 and swinging[48:].sum() == 0
    order = [robot.leg_names[int(np.argmax(swinging[8 * g]))] for g in range(6)]
    assert order == [group[0] for group in robot.gait_groups]
    assert np.all(swinging.sum(0) == 8)  # every leg swings 8 steps per period
    assert controller.stance_duration == pytest.approx(0.42)


# ---------------------------------------------------------------------------------------------------- command line
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    typo = _yaml_copy(tmp_path, kpp=150)
    for argv, message in (([str(tmp_path / "absent.yaml")], "absent.yaml.*no such file"),
                          ([str(bad)], "not a valid YAML file"),
                          ([str(typo)], r"unknown key 'kpp' \(did you mean 'kp'\?\)"),
                          ([str(QUADRUPED20), "--budget", "-1"], "--budget must be a positive number")):
        assert main(argv) == EXIT_NOT_FOUND
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), err
        assert re.search(message, lines[0]), lines[0]
        assert "Traceback" not in err + out


def test_cli_description_only(capsys):
    assert main([str(ROBOT_FILES["quadruped9"]), "--description-only"]) == EXIT_FOUND
    out = capsys.readouterr().out
    assert "robot quadruped9" in out and "description: ok" in out and "on the floor" in out


@pytest.mark.slow  # a fresh process imports torch and MuJoCo: seconds of imports for a check of milliseconds
def test_cli_refuses_a_folded_pose_with_the_numbers(tmp_path):
    """The console command itself (a fresh process): exit 2, the feet-vs-hips line, no traceback, no search."""
    path = _yaml_copy(tmp_path, standing_pose=FOLDED)
    env = {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "disable"}
    out = subprocess.run([sys.executable, "-m", "hierloco.envs.robots.check", str(path)], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == EXIT_NOT_FOUND, out.stderr
    assert "description: 1 problem" in out.stdout and "0.054 m below their hips" in out.stdout
    assert "search" not in out.stdout and "Traceback" not in out.stderr


# ---------------------------------------------------------------------------------------------------- the search
QUADRUPED50 = ROBOT_FILES["quadruped50"]  # 49.6 kg, torque motors, the file's damping 0.6, the user's kp 300


def test_the_servo_grid_reaches_the_gains_a_heavy_robot_needs():
    """The 50 kg quadruped's file damps its joints with 0.6 N m s/rad and its user chose kp 300 (a 0.18 rad sag
    standing): the search used to try damping x1 and x2 only (0.6, 1.2) and kp x2; its grid now sets kp for a
    0.1 and 0.05 rad sag and damping 0.01 to 0.04 s x kp, the docs' rule (kp 550, damping 11) screened first."""
    robot = get_robot(str(QUADRUPED50))
    reference = ExpertParameters.of(robot)
    assert reference.kp == (300.0,) * 12 and reference.joint_damping == (0.6,) * 12
    # the description passes (0.18 rad is under the 0.25 refused), and its line says what kp walks
    assert description_problems(robot) == []
    assert "sag 0.18 rad at most (need 0.25 or less); servos that walk sag about 0.1 rad, kp 549 N m/rad at that " \
        "joint" in description_summary(robot)
    assert "servos that walk" not in description_summary(get_robot(str(QUADRUPED20)))  # 0.12 rad: no advice
    settings = servo_settings(robot, reference)
    assert settings[0].label == "" and settings[0].kp == reference.kp  # the description's own first
    assert settings[1].kp == (550.0,) * 12 and settings[1].joint_damping == (11.0,) * 12  # then the rule
    assert settings[1].label == ", kp 550 (sag 0.1 rad), joint_damping 11 (0.02 s x kp)"
    kps = {s.kp[0] for s in settings}
    dampings = {s.joint_damping[0] for s in settings}
    assert kps == {300.0, 550.0, 1100.0} and {3.0, 6.0, 11.0, 12.0, 22.0, 44.0} <= dampings, (kps, dampings)
    # kp is capped where a 0.05 rad error would saturate a motor: the A1's 33.5 N m allow 670 N m/rad
    a1 = servo_settings(A1, ExpertParameters.of(A1))
    assert max(s.kp[0] for s in a1) == 190.0 <= 33.5 / 0.05
    heavy = A1.replace(mass_scale=4.0)  # a 0.38 rad sag: the 0.05 rad level would ask for kp 770, 670 caps it
    assert {s.kp[0] for s in servo_settings(heavy, ExpertParameters.of(heavy))} == {100.0, 380.0, 670.0}


def test_a_small_search_finds_the_gains_a_50kg_quadruped_needs_and_says_which():
    """The search at the derived gait (0.5 s, 0.085 m lift): the description's servos fall (the search used to
    refuse this robot), the rule's walk; undoing either kp or the damping alone fails, so both made the
    difference, and the lines to paste give both."""
    robot = get_robot(str(QUADRUPED50))
    start = time.perf_counter()
    result = tune_expert_parameters(robot, verify=False, gait_periods=(0.5,), swing_heights=(0.085,))
    seconds = time.perf_counter() - start
    own, rule = result.screened["gait period x swing height x servo gains"]
    assert not own.passes and own.fell > 0, own.describe()
    assert rule.passes and rule.replayed_fraction >= 0.9, rule.describe()
    assert result.found and result.params.kp == (550.0,) * 12 and result.params.joint_damping == (11.0,) * 12
    assert list(result.screened) == ["gait period x swing height x servo gains"]  # passed with margin: no more
    assert [(d.name, d.needed) for d in result.differences] == [("kp", True), ("joint_damping", True)]
    lines = report_lines(result, where="robot.yaml", epochs=150, hidden=512)
    assert "what made the difference (screened, each change undone alone, the others kept): kp, joint_damping" \
        in lines
    assert any(line.startswith("  - kp 300 -> 550: undone, ") and line.endswith("it made the difference")
               for line in lines), lines
    assert lines[lines.index("paste into robot.yaml (replacing these keys):") + 1:] == [
        "gait_period: 0.5", "standing_height: 0.5654", "kp: 550", "joint_damping: 11"]
    print(f"small search: {seconds:.1f} s, load {os.getloadavg()}")


@pytest.fixture(scope="module")
def own_q50_verification():
    """The 50 kg quadruped's own servos verified as the experts stage builds them (a small library: it fails
    its tracking at once, no gait policy is trained), and the same parameters screened."""
    robot = get_robot(str(QUADRUPED50))
    candidate = Candidate(ExpertParameters.of(robot), "its own parameters")
    verification = verify_candidate(robot, candidate, num_experts=8, settle_time=2.0, steps_per_action=100,
                                    policy=None, min_reach=0.4, min_reproduced_fraction=0.8, seed=0,
                                    budget_seconds=60.0, log=lambda line: None)
    (screened,) = screen_candidates(robot, [candidate])
    return robot, verification, screened


def test_what_limits_it_gives_the_verified_numbers_under_verified(own_q50_verification):
    """Not found: the table, the replay and the "verified" lines of what limits it are the verification's own
    numbers; the screening's numbers appear only on lines that say "screened"."""
    robot, verification, screened = own_q50_verification
    assert verification.report is not None and not verification.report.ok and verification.problem
    reference = ExpertParameters.of(robot)
    result = TuningResult(robot=robot, reference=reference, found=False, best=screened,
                          verifications=[verification], screened={"one": [screened]},
                          limits=_limits(screened, [verification]), seconds=1.0)
    lines = report_lines(result, where="robot.yaml", epochs=150, hidden=512)
    text = "\n".join(lines)
    verified_axes = [a.describe() for a in verification.report.axes if not a.ok]
    screened_axes = [a.describe() for a in screened.axes if not a.ok]
    assert verified_axes and screened_axes and set(verified_axes).isdisjoint(screened_axes)
    for line in verified_axes:
        assert f"  - verified (its own parameters): {line}" in lines
    for line in screened_axes:
        assert f"  - screened (its own parameters): {line}" in lines
    for line in lines:
        if "verified" in line:
            assert not any(s in line for s in screened_axes), line
            assert f"{screened.replayed_fraction:.0%} within" not in line or \
                screened.replayed_fraction == verification.replayed_fraction
    assert f"verified: the experts' own targets replayed open loop: {verification.replayed_fraction:.0%}" in text
    assert f"tracking of the 8 experts of the experts stage (its own parameters)" in text
    assert lines[lines.index("its parameters:") + 1:] == ["gait_period: 0.5", "standing_height: 0.5654"]


def test_every_setting_found_is_a_line_to_paste():
    """A gait policy that needs longer training: the override is its own line (not a comment inside the YAML
    lines), and the pipeline's ``experts.tune=true`` applies the same overrides (``TuningReport``)."""
    robot = get_robot(str(ROBOT_FILES["quadruped9"]))
    reference = ExpertParameters.of(robot)
    candidate = Candidate(replace(reference, gait_period=0.2), "gait_period 0.2 s")
    attempts = [{"name": "as configured", "overrides": {}, "reproduced_fraction": 0.6},
                {"name": "longer", "overrides": {"epochs": 300}, "reproduced_fraction": 1.0}]
    verification = Verification(candidate, replayed_fraction=1.0, reproduced_fraction=1.0, policy_attempts=attempts)
    result = TuningResult(robot=robot, reference=reference, found=True, best=None, verifications=[verification],
                          screened={}, limits=[], seconds=1.0)
    lines = report_lines(result, where="robot.yaml", epochs=150, hidden=512)
    assert lines[-1] == "policy.epochs=300" and "experts.tune=true" in lines[-2] and "60%" in lines[-2]
    assert not any(line.startswith("#") for line in lines)
    assert lines[lines.index("paste into robot.yaml (replacing these keys):") + 1:-2] == [
        "gait_period: 0.2", f"standing_height: {reference.standing_height:.4f}".rstrip("0")]
    assert result.summary()["policy_overrides"] == {"epochs": 300}  # what experts.tune=true applies


def test_stages_print_one_line_each_with_progress_false(copy_run):
    """``progress=false`` hides the bars, not the stages: a line per stage, with the run's elapsed seconds, when it
    starts building or is loaded (an hour-long run used to print nothing until its table)."""
    from tests.runner import run_in_process

    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "eval.videos=[]",
                            "eval.generalization.goal_reaching_3m.num_steps=1", env={"WANDB_MODE": "offline"})
    assert result.returncode == 0, result.stderr[-2000:]
    stages = dict(re.findall(r"^\[ *\d+ s\] stage (\S+): (building|cached)$", result.stdout, re.M))
    assert len(stages) == result.stdout.count("] stage "), result.stdout  # one line each
    assert stages["experts"] == stages["gait_policy"] == "cached", stages
    assert stages["evaluation_normal_goal_reaching_3m"] == "building", stages  # its task changed
    assert "it/s" not in result.stdout + result.stderr  # and no bar


@pytest.mark.slow  # the whole check: screening, a 30-expert library and a gait policy trained (minutes)
def test_the_check_walks_the_50kg_quadruped_it_used_to_refuse(capsys):
    """``hierloco-robot-check quadruped50.yaml`` with its defaults: found (it was "not found"), verified with the
    gait policy as configured, kp and joint damping named as what made the difference, and both to paste."""
    assert main([str(QUADRUPED50)]) == EXIT_FOUND
    out = capsys.readouterr().out
    assert "verified: the gait policy reproduces" in out
    assert "what made the difference (screened, each change undone alone, the others kept): kp, joint_damping" in out
    paste = out.split("(replacing these keys):\n")[1].splitlines()
    assert "kp: 550" in paste and "joint_damping: 11" in paste, out
