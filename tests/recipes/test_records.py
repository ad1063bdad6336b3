"""Job records (``hierloco/pipeline/records.py``): where a job's record goes, what it holds, when it counts as current.
The study-level behaviour (a study taken whole from records on another machine) is in ``test_compare_recipe.py``."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.pipeline.rundir import StageSpec, normalized
from hierloco.pipeline import records
from hierloco.pipeline.config import ConfigError
from hierloco.pipeline.studies import check_records

ROOT = Path(__file__).resolve().parents[2]


def finished_run(path: Path, signature: dict, key: dict) -> Path:
    path.mkdir(parents=True)
    (path / "job.json").write_text(json.dumps({"signature": signature, "seconds": 12.0}))
    (path / "episodes.csv").write_text("method,seed,task,episode,normalized_cost\nlat,0,goal_reaching,0,0.25\n")
    (path / "model.pt").write_bytes(b"\0" * 1000)  # an artifact: not part of the record
    (path / "model.pt.key.json").write_text(json.dumps(normalized(key)))
    (path / "evaluation").mkdir()
    (path / "evaluation" / "goals.npz.key.json").write_text(json.dumps(normalized(key)))  # a stage in a folder
    return path


def test_record_dir_keeps_the_run_directory_below_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert records.record_dir("rec", "outputs/sac/paper/a1_seed1") == Path("rec/sac/paper/a1_seed1")
    assert records.record_dir("rec", tmp_path / "outputs" / "adverse" / "x" / "a1") == Path("rec/adverse/x/a1")
    assert records.record_dir("rec", "/elsewhere/deep/sac/paper/a1_seed1") == Path("rec/sac/paper/a1_seed1")
    with pytest.raises(ValueError, match="no place"):
        records.record_dir("rec", "outputs/../../x")


def test_a_record_holds_the_small_files_and_is_current_only_with_todays_keys(tmp_path):
    signature = {"method": "lat", "overrides": ["seed=0"]}
    key = {"params": {"lr": 1e-3}, "code": "abc"}
    run = finished_run(tmp_path / "outputs" / "lat" / "paper" / "a1_seed0", signature, key)
    record = records.files_of(run)
    assert set(record) == {"job.json", "episodes.csv", "model.pt.key.json", "evaluation/goals.npz.key.json"}
    target = tmp_path / "rec" / "lat" / "paper" / "a1_seed0"
    assert records.save(record, target) and not records.save(record, target)  # the second writes nothing
    spec = StageSpec("model", key, "model.pt")
    assert records.current(target, signature, [spec, StageSpec("goals", key, "evaluation/goals.npz")])
    assert records.rows(target)[0]["normalized_cost"] == 0.25
    assert not records.current(target, {**signature, "overrides": ["seed=1"]}, [spec])
    assert not records.current(target, signature, [StageSpec("model", {**key, "code": "def"}, "model.pt")])
    assert not records.current(target, signature, [spec, StageSpec("other", key, "other.pt")])  # a stage it lacks
    (target / "evaluation" / "stale.key.json").write_text("{}")
    assert records.save(record, target) and not (target / "evaluation" / "stale.key.json").exists()  # whole


def test_a_finding_is_recorded_and_holds_only_while_the_stage_it_failed_in_keeps_its_key(tmp_path):
    signature = {"method": "lat", "overrides": ["settings=[rear_limp]"]}
    key = {"params": {"samples": 500}, "after": {"low_level": "abc"}}
    run = tmp_path / "outputs" / "lat" / "paper" / "a1_seed0_rear_limp"
    run.mkdir(parents=True)
    (run / "gait_policy.pt.key.json").write_text(json.dumps(normalized({"params": {}})))
    (run / records.FAILED).write_text(json.dumps({"stage": "dynamics_data_rear_limp", "key": normalized(key),
                                                  "error": "a1: 500 of 500 random actions ended in a fall"}))
    record = records.failure_of(run, signature)
    assert set(record) == {records.FAILED, "gait_policy.pt.key.json"}
    target = tmp_path / "rec" / "lat" / "paper" / "a1_seed0_rear_limp"
    records.save(record, target)
    failing = StageSpec("dynamics_data_rear_limp", key, "dynamics_data_rear_limp.npz")
    assert records.finding(target, signature, [failing]) == "a1: 500 of 500 random actions ended in a fall"
    assert records.finding(run, signature, [failing]) is None  # the recipe's own file has no job signature
    assert records.finding(target, {**signature, "overrides": []}, [failing]) is None  # another job
    upstream_changed = StageSpec(failing.name, {**key, "after": {"low_level": "def"}}, failing.filename)
    assert records.finding(target, signature, [upstream_changed]) is None  # a changed low level: run it again
    assert records.finding(target, signature, []) is None  # the stage is no longer planned
    assert not records.current(target, signature, [failing])  # not a finished job's record


def test_a_run_directory_without_a_finished_job_has_no_record(tmp_path):
    (tmp_path / "run").mkdir()
    with pytest.raises(ValueError, match="no finished job"):
        records.files_of(tmp_path / "run")


def test_bad_records_settings_are_refused(tmp_path):
    check_records(None)
    check_records(str(tmp_path / "new"))
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="not a directory"):
        check_records(str(tmp_path / "file"))
    with pytest.raises(ConfigError, match="directory path or null"):
        check_records(3)


def test_a_study_refuses_a_records_file_in_one_line_before_any_job(tmp_path):
    (tmp_path / "file").write_text("x")
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny",
                             "methods=[lib]", "robots=[a1]", f"records={tmp_path / 'file'}",
                             f"out_dir={tmp_path / 'out'}"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"error: records={tmp_path / 'file'} exists and is not a directory"], result.stderr
    assert not (tmp_path / "outputs").exists() and not (tmp_path / "out").exists()
