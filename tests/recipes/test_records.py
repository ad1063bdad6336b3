"""Job records (``hierloco/pipeline/records.py``): where a job's record goes, what it holds, that it is verified on
read, and when it counts as current. The study-level behaviour (a study taken whole from records on another machine)
is in ``test_compare_recipe.py``."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.pipeline import records
from hierloco.pipeline.config import ConfigError
from hierloco.pipeline.rundir import StageSpec

ROOT = Path(__file__).resolve().parents[2]
SIGNATURE = {"method": "lat", "overrides": ["seed=0"]}
KEY = {"params": {"lr": 1e-3}, "after": {"data": "abc"}}
ROWS = [{"method": "lat", "seed": 0, "task": "goal_reaching", "episode": 0, "normalized_cost": 0.25,
         "steps_to_goal": float("nan")}]


def specs(key=KEY):
    return [StageSpec("model", key, "model.pt"), StageSpec("evaluation_normal_goals", key, "evaluation/goals.npz")]


def test_record_dir_keeps_the_run_directory_below_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert records.record_dir("rec", "outputs/sac/paper/a1_seed1") == Path("rec/sac/paper/a1_seed1")
    assert records.record_dir("rec", tmp_path / "outputs" / "adverse" / "x" / "a1") == Path("rec/adverse/x/a1")
    assert records.record_dir("rec", "/elsewhere/deep/sac/paper/a1_seed1") == Path("rec/sac/paper/a1_seed1")
    with pytest.raises(ValueError, match="no place"):
        records.record_dir("rec", "outputs/../../x")


def test_a_record_is_one_verified_file_current_only_with_todays_keys(tmp_path):
    record = records.make_record(SIGNATURE, specs(), rows=ROWS, report={"stage_seconds": {"model": 1.0}},
                                 builds={"model": {"seconds": 3.0}}, seconds=12.0)
    target = tmp_path / "rec" / "lat" / "paper" / "a1_seed0"
    assert records.save(record, target) and not records.save(record, target)  # the second writes nothing
    assert [p.name for p in target.iterdir()] == [records.RECORD]
    read = records.read(target)
    assert read["rows"][0]["normalized_cost"] == 0.25 and read["rows"][0]["steps_to_goal"] != 0.0  # nan kept
    assert records.matches(read, SIGNATURE, specs())
    assert not records.matches(read, {**SIGNATURE, "overrides": ["seed=1"]}, specs())  # another job
    assert not records.matches(read, SIGNATURE, specs({**KEY, "after": {"data": "def"}}))  # a changed key
    assert not records.matches(read, SIGNATURE, [*specs(), StageSpec("other", KEY, "other.pt")])  # a stage it lacks


def test_an_edited_or_incomplete_record_is_refused_naming_the_file(tmp_path):
    target = tmp_path / "rec"
    records.save(records.make_record(SIGNATURE, specs(), rows=ROWS), target)
    path = target / records.RECORD
    text = path.read_text()
    path.write_text(text.replace('"normalized_cost": 0.25', '"normalized_cost": 0.0123'))
    with pytest.raises(records.RecordError, match=f"record {path} was edited"):
        records.read(target)
    record = json.loads(text)
    del record["stages"]
    path.write_text(json.dumps(record))
    with pytest.raises(records.RecordError, match="incomplete"):
        records.read(target)
    path.write_text("{not json")
    with pytest.raises(records.RecordError, match="unreadable"):
        records.read(target)


EPISODES = [{"method": "lat", "robot": "daisy", "setting": "normal", "task": "speed_profile", "seed": 0, "episode": e,
             "normalized_cost": 0.2} for e in range(2)]
ACTIONS = [{"setting": "normal", "task": "speed_profile", "episode": e, "action": a, "target_speed": 0.3,
            "speed": float("nan") if a == 1 else 0.29, "gait": "nan" if a == 2 else "tripod", "needed": "tripod"}
           for e in range(2) for a in range(3)]


def _forged(target, change) -> None:
    """The record in ``target`` edited and its digest recomputed (what only its checks against itself can see)."""
    path = target / records.RECORD
    record = json.loads(path.read_text())
    change(record)
    record["digest"] = records._digest({k: v for k, v in record.items() if k not in ("digest", records.MAC)})
    path.write_text(json.dumps(record))


def test_a_per_action_table_is_sealed_and_checked_and_a_record_without_one_is_as_before(tmp_path):
    """A job's per-action table (the gait study's: each action's gait) is part of its record, under its digest and
    checked against its rows when read; a record without one has no such field and the digest it had before tables
    existed (the value below: this record made by the code before them), so every committed record verifies."""
    before = records.make_record(SIGNATURE, specs(), rows=ROWS, report={"stage_seconds": {"model": 1.0}},
                                 builds={"model": {"seconds": 3.0}}, seconds=12.0)
    assert "actions" not in before
    assert before["digest"] == "24e2e57882facb00033af7a0733bceda28bada690e789a9134eff64be546f55b"
    target = tmp_path / "rec"
    records.save(records.make_record(SIGNATURE, specs(), rows=EPISODES, actions=ACTIONS), target)
    read = records.read(target)
    assert [(a["episode"], a["action"], a["gait"]) for a in read["actions"]] == [
        (e, a, "nan" if a == 2 else "tripod") for e in range(2) for a in range(3)]  # a gait is a name, never a NaN
    assert read["actions"][1]["speed"] != read["actions"][1]["speed"]  # a NaN speed stays NaN
    path = target / records.RECORD
    text = path.read_text()
    path.write_text(text.replace('"gait": "tripod"', '"gait": "ripple"', 1))
    with pytest.raises(records.RecordError, match=f"record {path} was edited"):
        records.read(target)
    path.write_text(text)
    _forged(target, lambda record: record["actions"][0].update(episode=5))
    with pytest.raises(records.RecordError, match="action row 0 is of normal/speed_profile episode 5, which no row"):
        records.read(target)
    path.write_text(text)
    _forged(target, lambda record: record["actions"].pop(4))  # episode 1 loses its action 1
    with pytest.raises(records.RecordError, match="actions of normal/speed_profile episode 1 are numbered \\[0, 2\\]"):
        records.read(target)
    path.write_text(text)
    assert len(records.read(target)["actions"]) == len(ACTIONS)  # as written, it verifies again


def test_saving_a_record_deletes_nothing(tmp_path):
    target = tmp_path / "rec"
    target.mkdir()
    (target / "experts.npz").write_bytes(b"an artifact someone keeps here")
    (target / "notes.md").write_text("mine")
    records.save(records.make_record(SIGNATURE, specs(), rows=ROWS), target)
    assert sorted(p.name for p in target.iterdir()) == ["experts.npz", "notes.md", records.RECORD]


def test_a_finding_holds_only_while_the_stage_it_failed_in_keeps_its_key(tmp_path):
    signature = {"method": "lat", "overrides": ["settings=[rear_limp]"]}
    key = {"params": {"samples": 500}, "after": {"low_level": "abc"}}
    failing = StageSpec("dynamics_data_rear_limp", key, "dynamics_data_rear_limp.npz")
    finding = {"stage": failing.name, "key": key, "error": "a1: 500 of 500 random actions ended in a fall"}
    target = tmp_path / "rec"
    records.save(records.make_record(signature, [failing], finding=finding), target)
    record = records.read(target)
    assert records.finding_of(record, signature, [failing]) == finding["error"]
    assert records.finding_of(record, {**signature, "overrides": []}, [failing]) is None  # another job
    upstream_changed = StageSpec(failing.name, {**key, "after": {"low_level": "def"}}, failing.filename)
    assert records.finding_of(record, signature, [upstream_changed]) is None  # a changed low level: run it again
    assert records.finding_of(record, signature, []) is None  # the stage is no longer planned


def test_bad_records_settings_are_refused(tmp_path):
    records.check_records(None)
    records.check_records(str(tmp_path / "new"))
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="not a directory"):
        records.check_records(str(tmp_path / "file"))
    with pytest.raises(ConfigError, match="directory path or null"):
        records.check_records(3)
    run = tmp_path / "outputs" / "lat" / "paper" / "a1_seed0"
    run.mkdir(parents=True)
    (run / "run.json").write_text("{}")
    with pytest.raises(ConfigError, match="holds a run directory"):  # records=outputs
        records.check_records(str(tmp_path / "outputs"))
    with pytest.raises(ConfigError, match="is \\(or is inside\\) the run directory"):
        records.check_records(str(run / "records"))


def test_a_study_refuses_a_records_file_in_one_line_before_any_job(tmp_path):
    (tmp_path / "file").write_text("x")
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny",
                             "methods=[lib]", "robots=[a1]", f"records={tmp_path / 'file'}",
                             f"out_dir={tmp_path / 'out'}"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"error: records={tmp_path / 'file'} exists and is not a directory"], result.stderr
    assert not (tmp_path / "outputs").exists() and not (tmp_path / "out").exists()
