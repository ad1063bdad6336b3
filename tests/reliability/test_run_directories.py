"""Run directories (the reliability issue's cases 7-10): records never mix with run directories or delete files, a
run directory is hierloco's or new, only hierloco's temporary files are cleaned, evaluations go under the run, and a
multirun on one run directory runs its jobs one after another."""

import json
import os
from pathlib import Path

import pytest

from hierloco.pipeline.config import ConfigError
from hierloco.pipeline.records import check_records
from hierloco.pipeline.rundir import RunDirectory, RunDirectoryError, check_run_dir
from tests.runner import run_in_process, snapshot


def test_records_that_hold_run_directories_are_refused_before_any_job(copy_run, tmp_path):
    """Case 7: ``records=outputs`` (run directories inside) is refused, and nothing in them changes."""
    outputs = tmp_path / "outputs" / "lat" / "tiny"
    outputs.mkdir(parents=True)
    copy_run.rename(outputs / "a1_seed0")
    before = snapshot(tmp_path)
    with pytest.raises(ConfigError, match="holds a run directory"):
        check_records(str(tmp_path / "outputs"))
    result = run_in_process("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]",
                            f"records={tmp_path / 'outputs'}", f"out_dir={tmp_path / 'out'}", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1 and "holds a run directory" in result.lines[0]
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("value, message", [
    ("", "run_dir is empty"),
    ("/", "is /: give a directory of its own"),
    ("~", "give a directory of its own"),
    (".", "is the working directory or one of its parents"),
])
def test_paths_that_cannot_be_run_directories_are_refused(value, message, tmp_path, monkeypatch):
    """Case 8: ``run_dir=/``, the home directory, the working directory and an empty value are refused, before
    anything is written."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    with pytest.raises(RunDirectoryError, match=message.replace("(", "\\(")):
        check_run_dir(value)


def test_a_file_a_symlink_loop_and_a_foreign_directory_are_refused(tmp_path):
    """Case 15 (run_dir): one line each, never a traceback."""
    (tmp_path / "file").write_text("x")
    os.symlink(tmp_path / "loop_b", tmp_path / "loop_a")
    os.symlink(tmp_path / "loop_a", tmp_path / "loop_b")
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "thesis.tex").write_text("mine")
    for value, message in ((tmp_path / "file", "is an existing file"), (tmp_path / "loop_a", "cannot be resolved"),
                           (tmp_path / "foreign", "holds files hierloco did not make (thesis.tex)")):
        result = run_in_process("lat", "preset=tiny", f"run_dir={value}", cwd=tmp_path)
        assert result.returncode == 2 and len(result.lines) == 1 and message in result.lines[0], result.stderr
    assert (tmp_path / "foreign" / "thesis.tex").read_text() == "mine"
    assert sorted(p.name for p in (tmp_path / "foreign").iterdir()) == ["thesis.tex"]


def test_only_hierlocos_own_temporary_files_at_the_top_are_cleaned(tmp_path):
    """Case 8: taking the lock removes ``.hierloco-tmp-*`` files a killed run left at the top level, nothing else
    (before, every ``.*.tmp*`` file under the directory went, two levels down too)."""
    run = tmp_path / "run"
    (run / "sub" / "deeper").mkdir(parents=True)
    (run / "run.json").write_text("{}")
    mine = run / ".hierloco-tmp-experts.npz.abc.npz"
    theirs = [run / ".notes.tmp", run / "sub" / ".draft.txt.tmp1", run / "sub" / "deeper" / ".x.tmp.npz"]
    for path in [mine, *theirs]:
        path.write_text("x")
    directory = RunDirectory(run)
    directory.acquire()
    directory.release()
    assert not mine.exists() and all(path.exists() for path in theirs)


@pytest.mark.parametrize("name", ["..", "/abs/path", "a/b", ""])
def test_an_evaluation_name_is_a_plain_name(copy_run, name, tmp_path):
    """Case 9: ``evaluate.py name=..`` (or a path) is refused; the training run's files stay as they are."""
    before = snapshot(tmp_path)
    result = run_in_process("evaluate.py", f"run_dir={copy_run}", f"name={name}", "planner.name=cem", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1 and "must be a plain name" in result.lines[0]
    assert snapshot(tmp_path) == before


@pytest.mark.slow  # ~25 s: a Hydra multirun of two evaluations
def test_a_multirun_on_one_run_directory_runs_its_jobs_in_turn(tiny_lat_run, tmp_path):
    """Case 10: ``-m run_dir=X planner.name=random_shooting,cem``: both jobs finish; the second reuses every
    training stage (the lock is released when a job's main returns)."""
    import shutil

    run_dir = tmp_path / "run"
    shutil.copytree(tiny_lat_run, run_dir, ignore=shutil.ignore_patterns(".lock", "evaluation", "videos"))
    result = run_in_process("lat", "-m", "preset=tiny", "progress=false", f"run_dir={run_dir}",
                            "planner.name=random_shooting,cem", cwd=tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "in use by" not in result.stdout + result.stderr
    report = json.loads((run_dir / "report.json").read_text())
    training = [name for name in report["reused_stages"] if not name.startswith("evaluation_")]
    assert training and all(report["reused_stages"][name] for name in training)
    assert "name: cem" in (run_dir / "config.yaml").read_text()  # the last job's
    assert len(list((run_dir / "evaluation" / "normal").glob("goal_reaching-*.npz"))) == 2  # one per planner
