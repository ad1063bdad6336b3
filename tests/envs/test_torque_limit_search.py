"""Torque limits searched by the robot check for a file that gives none (``docs/robots.md``, choosing kp).

``tests/fixtures/quadruped20_nolimit`` is the 20.6 kg quadruped of ``tests/fixtures/quadruped20`` with its torque
motors' ``ctrlrange`` removed and no ``torque_limit`` in its description: loading it is refused in one line, which
now says that ``hierloco-robot-check`` proposes one; the check reads it with provisional limits (6 x the largest
torque standing), searches lower levels as part of its servo grid and prints the smallest that walks as a
``torque_limit:`` line to paste, named in what made the difference. (The original file's motors are 35.3 N m at
the abduction and thigh joints and 44.4 N m at the knee; the check finds 36 N m.) The whole check, verification
included, is ``-m slow``.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from hierloco.components.expert_tuning import (
    ExpertParameters,
    servo_settings,
    torque_limit_levels,
    tune_expert_parameters,
)
from hierloco.envs.robots import compile_model, get_robot
from hierloco.envs.robots.check import (
    EXIT_FOUND,
    MAX_STATIC_TORQUE,
    PROVISIONAL_TORQUE_FACTOR,
    TORQUE_LIMIT_FACTORS,
    description_problems,
    largest_static_torque,
    robot_for_check,
    standing_statics,
)
from hierloco.envs.robots.check.__main__ import main, report_lines
from tests.envs.robot_yaml import changed_copy
from tests.runner import run_in_process

FIXTURES = Path(__file__).resolve().parents[2] / "tests" / "fixtures"
NOLIMIT = FIXTURES / "quadruped20_nolimit" / "quadruped20_nolimit.yaml"
QUADRUPED20 = FIXTURES / "quadruped20" / "quadruped20.yaml"


def _copy(directory: Path, **changes) -> Path:
    """A copy of the no-limit fixture's YAML in ``directory``, some keys changed (``None`` removes one)."""
    return changed_copy(NOLIMIT, directory, **changes)


def test_a_file_without_torque_limits_is_refused_in_one_line_that_names_torque_limit_and_the_check(tmp_path):
    """Loading it (``get_robot``, a recipe) is refused before any work, in one line naming ``torque_limit`` and
    saying that the check proposes one; the check reads the same file with provisional limits."""
    with pytest.raises(ValueError) as refused:
        get_robot(str(NOLIMIT))
    message = str(refused.value)
    assert "\n" not in message and "give torque_limit (N m, the motors' peak torque)" in message
    assert "hierloco-robot-check proposes a torque_limit for this file" in message, message

    result = run_in_process("lat", "preset=tiny", f"robot={NOLIMIT}", f"run_dir={tmp_path / 'run'}")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr[-3000:]
    line = result.lines[0]
    assert line.startswith("error: ") and "Traceback" not in result.stderr
    assert str(NOLIMIT) in line and "torque_limit" in line and "hierloco-robot-check proposes" in line, line
    assert not (tmp_path / "run").exists()

    # a missing gain stays a refusal, for the check too, naming kp
    no_kp = _copy(tmp_path, kp=None)
    with pytest.raises(ValueError, match=r"give kp \(N m / rad\) and torque_limit .*once kp is given, "
                       r"hierloco-robot-check proposes a torque_limit"):
        robot_for_check(str(no_kp))
    # with the line the check prints pasted, the robot loads as any other, with those limits
    pasted = _copy(tmp_path, torque_limit=36)
    model = compile_model(get_robot(str(pasted)))
    np.testing.assert_allclose(model.actuator_forcerange, [[-36.0, 36.0]] * 12)
    assert robot_for_check(str(pasted)).provisional_torque_joints == ()


def test_the_servo_grid_holds_torque_limit_levels_from_the_standing_load():
    """The provisional limit is 6 x the largest torque standing (18.2 N m at the knees: 110 N m), above every
    joint's static torque; the servo grid is quadruped20's kp x damping grid at it, then the same at each lower
    level (73, 54, 36, 27 N m). A robot whose file has limits gets the grid it always had, without them."""
    robot = robot_for_check(str(NOLIMIT))
    assert robot.provisional_torque_joints == robot.joint_names and robot.reference == str(NOLIMIT)
    torque, joint = largest_static_torque(robot)
    assert joint.endswith("calf_joint") and torque == pytest.approx(18.15, abs=0.01)
    static = np.array([t for leg in standing_statics(robot).legs for t in leg.static_torque])
    provisional = np.asarray(robot.torque_limit)
    assert np.all(provisional == 110.0) and np.all(provisional >= PROVISIONAL_TORQUE_FACTOR * static - 1)
    assert description_problems(robot) == []

    settings = servo_settings(robot, ExpertParameters.of(robot))
    levels = [limit for limit, _ in torque_limit_levels(robot)]
    assert [limit[0] for limit in levels] == [27.0, 36.0, 54.0, 73.0, 110.0]
    assert all(np.all(np.asarray(limit) >= static / MAX_STATIC_TORQUE) for limit in levels)  # the check passes
    assert [s.torque_limit[0] for s in settings[::12]] == [110.0, 73.0, 54.0, 36.0, 27.0]
    assert len(settings) == 12 * len(TORQUE_LIMIT_FACTORS)
    with_limits = get_robot(str(QUADRUPED20))
    own = servo_settings(with_limits, ExpertParameters.of(with_limits))
    assert [(s.kp, s.joint_damping, s.label) for s in own] == [(s.kp, s.joint_damping, s.label) for s in settings[:12]]
    assert {s.torque_limit for s in own} == {None} and torque_limit_levels(with_limits) == []
    assert ExpertParameters.of(with_limits).torque_limit is None
    assert not any(line.startswith("torque_limit") for line in ExpertParameters.of(with_limits).yaml_lines(with_limits))
    assert settings[-1].label.endswith(", torque_limit 27 N m (1.5 x the torque standing)")


def test_only_the_joints_without_a_limit_are_provisional(tmp_path):
    """quadruped20's file with the knee motors' ``ctrlrange`` alone removed: the knees get the provisional
    110 N m and the torque-limit levels, the abduction and thigh joints keep the file's 35.278 N m."""
    xml = (FIXTURES / "quadruped20" / "quadruped20.xml").read_text()
    knees = '<motor ctrlrange="-44.4 44.4" gear="1"/>'
    assert knees in xml
    (tmp_path / "knees.xml").write_text(xml.replace(knees, '<motor gear="1"/>'))
    path = _copy(tmp_path, mjcf=str(tmp_path / "knees.xml"))
    robot = robot_for_check(str(path))
    assert robot.provisional_torque_joints == tuple(f"{leg}_calf_joint" for leg in ("FR", "FL", "RR", "RL"))
    assert robot.torque_limit == (35.278, 35.278, 110.0) * 4
    levels = [limit for limit, _ in torque_limit_levels(robot)]
    assert [limit[:3] for limit in levels] == [(35.278, 35.278, v) for v in (27.0, 36.0, 54.0, 73.0, 110.0)]


def test_a_small_search_finds_the_smallest_torque_limit_that_walks_and_prints_the_line():
    """Screening at the description's gait (0.5 s, 6 cm lift): 110 N m walks, so do 73, 54 and 36; at 27 N m an
    expert falls. 36 N m is found, named in what made the difference (lowered to 27 N m it fails), said to be the
    motors' peak torque the gait needs, and printed as ``torque_limit: 36``; the experts stage's ``experts.tune``
    report applies it (``hierloco.pipeline.tuning.tuned_robot``)."""
    from hierloco.pipeline.tuning import tuned_robot

    robot = robot_for_check(str(NOLIMIT))
    start = time.perf_counter()
    result = tune_expert_parameters(robot, verify=False, gait_periods=(0.5,), swing_heights=(0.06,))
    seconds = time.perf_counter() - start
    torque_stage = result.screened["torque limit"]
    assert [s.candidate.params.torque_limit[0] for s in torque_stage] == [27.0, 36.0, 54.0, 73.0]
    assert [s.passes for s in torque_stage] == [False, True, True, True], [s.describe() for s in torque_stage]
    assert result.found and result.params.torque_limit == (36.0,) * 12
    assert [(d.name, d.needed) for d in result.differences] == [("torque_limit", True)]
    lines = report_lines(result, where="robot.yaml", epochs=150, hidden=512)
    assert "what made the difference (screened, each change undone alone, the others kept): torque_limit" in lines
    assert any(line.startswith("  - torque_limit none -> 36 N m: at the next lower level, 27 N m, ")
               and "the motors' peak torque the gait needs" in line for line in lines), lines
    paste = lines.index("paste into robot.yaml (replacing these keys):")
    assert lines[paste + 1:] == ["gait_period: 0.5", "standing_height: 0.3749", "torque_limit: 36"]
    assert re.match(r"torque_limit 36 N m, 2 x the largest torque standing: the motors' peak torque the gait needs "
                    r".*check it against your motors' peak torque", lines[paste - 1]), lines[paste - 1]

    report = json.loads(json.dumps(result.summary(), default=float))
    assert report["changed"] == ["torque_limit"] and "torque_limit: 36" in report["yaml"]
    tuned = tuned_robot(robot, report)
    assert tuned.torque_limit == (36.0,) * 12 and tuned.provisional_torque_joints == ()
    np.testing.assert_allclose(compile_model(tuned).actuator_forcerange, [[-36.0, 36.0]] * 12)
    print(f"small torque-limit search: {seconds:.1f} s")


def test_the_check_prints_the_provisional_limits_with_the_description(capsys):
    assert main([str(NOLIMIT), "--description-only"]) == EXIT_FOUND
    out = capsys.readouterr().out
    assert "torque limits: the file and the description give 12 of 12 leg joints none; the search starts them at " \
        "110 N m (6 x the largest torque standing, 18.2 N m at joint " in out
    assert "of a joint's provisional torque limit" in out and "description: ok" in out


@pytest.mark.slow  # the whole check: screening every gait period, a 30-expert library and a gait policy (minutes)
def test_the_whole_check_walks_the_file_without_torque_limits(capsys):
    """``hierloco-robot-check quadruped20_nolimit.yaml`` with its defaults: found and verified, with a
    ``torque_limit:`` line to paste, named in what made the difference."""
    assert main([str(NOLIMIT)]) == EXIT_FOUND
    out = capsys.readouterr().out
    assert "verified: the gait policy reproduces" in out
    assert re.search(r"what made the difference \(screened, each change undone alone, the others kept\): "
                     r".*torque_limit", out), out
    paste = out.split("(replacing these keys):\n")[1].splitlines()
    assert any(line.startswith("torque_limit: ") for line in paste), out
