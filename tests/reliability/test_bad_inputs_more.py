"""Bad inputs that crashed or hung (issue 42, item 5): a run directory under a file, task names that read as numbers
in a study, dynamics data of another action width, a full disk while the figures are drawn, YAML whose aliases
expand to billions of values, an MJCF file with no actuators. Each is one line (``error: ...``, exit 2) before any
work, within seconds, or (the task names) runs as asked; never a traceback."""

import errno
import gc
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hierloco.io import load_arrays, save_arrays
from tests.runner import ROOT, run_in_process, run_subprocess

QUADRUPED20 = ROOT / "tests" / "fixtures" / "quadruped20"


def _one_line(result) -> str:
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr[-3000:]
    assert result.lines[0].startswith("error: ") and "Traceback" not in result.stderr
    return result.lines[0]


def _nested_aliases(levels: int = 9, width: int = 9) -> str:
    """A YAML flow list of ``levels`` anchors, each a list of ``width`` aliases of the one before: a few hundred
    bytes that expand to ``width ** levels`` values (a "billion laughs")."""
    anchors = [f"&a0 [{', '.join(['0.1'] * width)}]"]
    anchors += [f"&a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    return "[" + ",\n  ".join(anchors) + "]"


def test_a_run_directory_under_a_file_is_one_line(tmp_path):
    """``run_dir=<file>/sub``: no directory can be made there; one line naming the file, nothing written."""
    blocker = tmp_path / "notes.txt"
    blocker.write_text("a file, not a directory\n")
    line = _one_line(run_in_process("lat", "preset=tiny", f"run_dir={blocker / 'sub' / 'run'}"))
    assert line == f"error: run_dir={blocker / 'sub' / 'run'} is under {blocker}, which is a file, not a directory"
    assert blocker.read_text() == "a file, not a directory\n" and sorted(tmp_path.iterdir()) == [blocker]


@pytest.mark.slow  # a whole study (about a minute)
def test_task_names_that_read_as_numbers_are_names_in_a_study(tiny_lat_run, tmp_path):
    """Tasks named ``nan`` and ``inf`` in a study's job: its record keeps them as names (not the float NaN and
    infinity the record stores non-finite numbers as), so the study's table lists them; unquoted in Hydra's grammar
    they are numbers, and the recipe refuses them in one line before any work."""
    run_dir = tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0"  # the compare study's job of LAT on A1, seed 0
    shutil.copytree(tiny_lat_run, run_dir, ignore=shutil.ignore_patterns(".lock"))
    tasks = ['+eval.tasks.nan={task: goal_reaching, radius: 0.6, num_steps: 4}',
             '+eval.tasks.inf={task: velocity_tracking, steps_per_target: 1, rounds: 1}']
    result = run_subprocess("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]", "settings=[normal]",
                            f"out_dir={tmp_path / 'tables'}", "overrides=[" + ",".join(f"'{t}'" for t in tasks) + "]",
                            cwd=tmp_path, timeout=600)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stdout[-2000:] + result.stderr[-3000:]
    table = (tmp_path / "tables" / "comparison.md").read_text()
    for name in ("nan", "inf", "goal_reaching"):
        assert re.search(rf"\| lat \| a1 \| normal \| {name} \| \d", table), table

    line = _one_line(run_in_process("lat", "preset=tiny", f"run_dir={tmp_path / 'floats'}",
                                    "++eval.tasks={nan: {task: goal_reaching}}"))
    assert "eval task nan: name must be a non-empty string, got nan" in line
    assert not (tmp_path / "floats").exists()


def test_dynamics_data_of_another_action_width_is_refused_in_one_line(copy_run):
    """Dynamics data whose actions have one column, collected (its metadata says) on LAT's 2-D latent low level:
    refused when it loads, naming the file: by evaluate.py, and by train.py before a dynamics model is fitted to it
    again (it was fitted, and evaluate.py then failed at its first plan with a traceback)."""
    data = copy_run / "dynamics_data_normal.npz"
    arrays, meta = load_arrays(data)
    assert arrays["action"].shape[1] == len(meta["low_level"]["action_low"]) == 2
    save_arrays(data, {**arrays, "action": arrays["action"][:, :1]}, meta)
    said = (f"error: {data}: action has 1 column(s), but the 'latent' low level it was collected on has 2 action "
            "dimension(s) (its action box)")
    assert _one_line(run_in_process("evaluate.py", f"run_dir={copy_run}", "planner.name=cem")) == said
    assert not (copy_run / "evaluations").exists()
    for path in copy_run.glob("dynamics_model_normal.pt*"):
        path.unlink()  # the model would be fitted again, to the one-column actions
    assert _one_line(run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")) == said
    assert not list(copy_run.glob("dynamics_model_normal.pt*"))


@pytest.mark.parametrize("full_from", ["the first figure", "the start"])
def test_a_full_disk_leaves_no_logger_traceback(copy_run, monkeypatch, full_from):
    """No space left from the first figure on (the CSV logger's files then open on ``/dev/full``, a device that is
    always full), or from the start (the loggers cannot even write the config): the run ends as usual (its results
    kept, with warnings; or one line, exit 2), and every file the loggers opened is closed, so nothing is left for
    TorchRL's ``CSVExperiment.__del__`` to fail on later (the "Exception ignored in ... __del__" traceback)."""
    import builtins

    import matplotlib.figure
    import torchrl.record.loggers.csv as torchrl_csv

    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full on this system")
    disk = {"full": full_from == "the start"}
    ignored = []
    monkeypatch.setattr(sys, "unraisablehook", ignored.append)

    def save_figure(self, *args, **kwargs):
        disk["full"] = True
        raise OSError(errno.ENOSPC, "No space left on device")

    def open_log(path, mode="r", *args, **kwargs):
        return builtins.open("/dev/full" if disk["full"] else path, mode, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", save_figure)
    monkeypatch.setattr(torchrl_csv, "open", open_log, raising=False)
    before = (copy_run / "results.csv").read_bytes()
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    gc.collect()  # the loggers are garbage now: a file they left open with unwritten lines would fail here
    assert not ignored, [f"{hook.exc_type.__name__}: {hook.exc_value} in {hook.object!r}" for hook in ignored]
    assert "Traceback" not in result.stderr and "Exception ignored" not in result.stderr, result.stderr
    if full_from == "the start":
        assert result.lines == ["error: no space left on the device; finished stages are kept: free some space and "
                                "run the same command again to resume"], result.stderr
    else:
        assert result.returncode == 0, result.stderr[-3000:]
        assert "warning: the figures of normal/goal_reaching failed" in result.stdout, result.stdout[-3000:]
    assert (copy_run / "results.csv").read_bytes() == before


@pytest.mark.parametrize("where", ["robot description", "received config.yaml"])
def test_yaml_aliases_that_expand_to_billions_of_values_are_one_line_in_seconds(copy_run, tmp_path, where):
    """A 1.6 kB robot YAML, or a received run's ``config.yaml``, whose nested aliases hold 9**9 values: refused in
    one line naming the file within seconds (it hung for minutes while a message formatted the expanded value),
    and before any work."""
    import hierloco.recipes.lat.utils  # noqa: F401  (the recipe's imports, outside the time bound)

    if where == "robot description":
        robot = tmp_path / "robot.yaml"
        text = (QUADRUPED20 / "quadruped20.yaml").read_text().replace("quadruped20.xml",
                                                                      str(QUADRUPED20 / "quadruped20.xml"))
        robot.write_text(text.replace("kp: 150 ", f"kp: {_nested_aliases()} "))
        assert robot.stat().st_size < 2000
        path, arguments = robot, ("lat", "preset=tiny", f"robot={robot}", f"run_dir={tmp_path / 'new'}")
    else:
        path = copy_run / "config.yaml"
        path.write_text(path.read_text() + f"bomb: {_nested_aliases()}\n")
        arguments = ("evaluate.py", f"run_dir={copy_run}", "planner.name=cem")
    start = time.perf_counter()
    result = run_in_process(*arguments)
    assert time.perf_counter() - start < 10
    line = _one_line(result)
    assert f"{path}: its aliases (*name) expand to more than 100000 values" in line and len(line) < 400
    assert not (tmp_path / "new").exists() and not (copy_run / "evaluations").exists()


def test_an_mjcf_file_without_actuators_needs_its_torque_limits(tmp_path):
    """An MJCF file with no actuators: the servos hierloco makes would have no torque limit; the description is
    refused in one line naming ``torque_limit``, before any work. With ``torque_limit`` given (N m, here per leg
    joint) the robot loads and its servos have those limits."""
    from hierloco.envs.robots import get_robot
    from hierloco.envs.robots.spec import compile_model

    xml = re.sub(r"<actuator>.*?</actuator>", "", (QUADRUPED20 / "quadruped20.xml").read_text(), flags=re.S)
    assert "<actuator" not in xml
    (tmp_path / "bare.xml").write_text(xml)
    description = (QUADRUPED20 / "quadruped20.yaml").read_text().replace("quadruped20.xml", "bare.xml")
    robot = tmp_path / "bare.yaml"
    robot.write_text(description.replace("name: quadruped20", "name: bare"))
    line = _one_line(run_in_process("lat", "preset=tiny", f"robot={robot}", f"run_dir={tmp_path / 'run'}"))
    assert ("12 of its 12 leg joints (FR_hip_joint, FR_thigh_joint, FR_calf_joint, FL_hip_joint, ...; no actuator in "
            "the file drives them) have no torque limit; give torque_limit (N m, the motors' peak torque) in the "
            "robot description") in line and str(robot) in line
    assert not (tmp_path / "run").exists()

    robot.write_text(description.replace("name: quadruped20", "name: bare") + "torque_limit: [30, 30, 40]\n")
    model = compile_model(get_robot(str(robot)))
    np.testing.assert_allclose(model.actuator_forcerange, [[-30, 30], [-30, 30], [-40, 40]] * 4)
    assert model.actuator_forcelimited.all()
