"""Rows derived, never trusted, and records that keep to their job (issue 42, items 3 and 4: cases 4, 6, 7 and 8).

A run's and a study's rows are checked against the evaluation artifacts they come from (labels against the stage,
success and final error against the recorded CoM paths); a record's rows against its own stages, and against its
job's evaluations where the run directory is present; a record store can be signed with a user key. A records
directory keeps one config per job, is refused where the study will put run directories, and a reused job's record
keeps the timings of the build it reports."""

import json
import shutil
from pathlib import Path

import pytest

from hierloco.io import ArtifactError, load_arrays, save_arrays
from hierloco.pipeline import records, studies
from hierloco.pipeline.config import ConfigError
from hierloco.pipeline.rundir import StageSpec
from hierloco.results import read_csv
from tests.runner import run_in_process, snapshot

# the comparison study's LAT job on A1, seed 0, at the tiny preset: the shared tiny LAT run is that job finished
COMPARE_LAT = ["preset=tiny", "robot=a1", "seed=0", "settings=[normal]", "progress=false", "eval.generalization=null"]
TABLES = ("results.csv", "episodes.csv", "results.md")


def evaluation(run_dir: Path, task: str) -> Path:
    return next((run_dir / "evaluation" / "normal").glob(f"{task}-*.npz"))


def edit_evaluation(path: Path, change) -> None:
    """Edits an evaluation's rows (and its metadata or summary) the way a hostile user would, keeping it loadable."""
    arrays, meta = load_arrays(path)
    change(meta)
    save_arrays(path, arrays, meta)


def compare_job(copy_run: Path, tmp_path: Path, monkeypatch) -> studies.Job:
    """The shared tiny LAT run in the comparison's layout (``outputs/lat/tiny/a1_seed0`` under ``tmp_path``, the
    working directory), finished as a study's job leaves it (``job.json`` as :func:`studies.execute` writes it)."""
    monkeypatch.chdir(tmp_path)
    run_dir = tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0"
    run_dir.parent.mkdir(parents=True)
    shutil.move(copy_run, run_dir)
    job = studies.Job("lat", "outputs/lat/tiny/a1_seed0", list(COMPARE_LAT), labels={"method": "lat"})
    (run_dir / studies.DONE).write_text(studies.done_text(job, 60.0))
    return job


def forge(where: Path, change) -> None:
    """Edits a record and recomputes its sha256 digest: what the digest cannot see."""
    path = where / records.RECORD
    record = json.loads(path.read_text())
    change(record)
    body = {key: value for key, value in record.items() if key not in ("digest", records.MAC)}
    record["digest"] = records._digest(body)
    path.write_text(json.dumps(record, indent=1, sort_keys=True))


def test_edited_success_and_errors_in_an_evaluation_are_refused(copy_run):
    """Case 4: an evaluation whose rows say 100 % success where the robot reached no goal (its summary edited to
    match) is refused by the run and by a study, in one line naming the file; the tables stay as they were."""
    tables = {name: (copy_run / name).read_bytes() for name in TABLES}
    path = evaluation(copy_run, "goal_reaching_1p5m")
    assert {row["success"] for row in load_arrays(path)[1]["rows"]} == {0.0}

    def all_reached(meta):
        for row in meta["rows"]:
            row.update(success=1.0, final_error=0.1)
        meta["metrics"].update(success_rate=1.0, final_error=0.1)

    edit_evaluation(path, all_reached)
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert result.lines[0].startswith(f"error: {path}: its rows do not follow from its recording and its stage: "
                                      "episode 0's final_error is 0.1, its recorded CoM path gives 0.8"), result.lines
    assert {name: (copy_run / name).read_bytes() for name in TABLES} == tables
    job = studies.Job("lat", str(copy_run), ["preset=tiny", "progress=false"])
    with pytest.raises(ArtifactError, match="its recorded CoM path gives"):
        studies.evaluation_rows(copy_run, studies.planned_stages(job))


def test_rows_relabelled_to_another_task_are_refused(copy_run):
    """Case 4: the diagonal velocity task's row relabelled as velocity tracking would be merged into it (the real
    row then missing from the table); it is refused in one line naming the file."""
    tables = {name: (copy_run / name).read_bytes() for name in TABLES}
    path = evaluation(copy_run, "velocity_tracking_diagonal")

    def relabel(meta):
        meta["metadata"]["task"] = "velocity_tracking"
        for row in meta["rows"]:
            row["task"] = "velocity_tracking"

    edit_evaluation(path, relabel)
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    assert result.returncode == 2 and result.lines == [
        f"error: {path}: its rows do not follow from its recording and its stage: its metadata names task "
        "'velocity_tracking', its stage 'velocity_tracking_diagonal' (and 1 more)"], result.stderr
    assert {name: (copy_run / name).read_bytes() for name in TABLES} == tables


def test_a_record_with_a_recomputed_digest_is_checked_against_its_run_directory(copy_run, tmp_path, monkeypatch,
                                                                                capsys):
    """Case 4: a record whose costs were edited and its digest recomputed. Where its job's run directory is finished,
    the study derives the record again from the evaluations (and says it replaced the edited one); where the run
    directory holds the evaluations but is not finished, the record is refused in one line naming both."""
    job = compare_job(copy_run, tmp_path, monkeypatch)
    store = tmp_path / "records"
    [first] = studies.run_jobs([job], records=str(store))  # every job finished: no Ray, nothing runs
    where = store / "lat" / "tiny" / "a1_seed0"
    true_rows = records.read(where)["rows"]
    assert first.reused and records.canonical(first.rows) == records.canonical(true_rows)
    original = (where / records.RECORD).read_text()

    def halve_costs(record):
        for row in record["rows"]:
            row["normalized_cost"] = row["normalized_cost"] / 2

    forge(where, halve_costs)
    assert records.read(where)["rows"] != true_rows  # the digest verifies: it cannot see this
    job = studies.Job("lat", "outputs/lat/tiny/a1_seed0", list(COMPARE_LAT), labels={"method": "lat"})
    capsys.readouterr()
    [again] = studies.run_jobs([job], records=str(store))
    assert records.canonical(again.rows) == records.canonical(true_rows)
    assert f"study: the record {where / records.RECORD} differed from the evaluations in " in capsys.readouterr().out
    assert (where / records.RECORD).read_text() == original  # re-derived from the evaluations

    forge(where, halve_costs)
    (tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0" / studies.DONE).unlink()  # received without its job.json
    before = snapshot(tmp_path)
    result = run_in_process("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]",
                            "settings=[normal]", f"records={store}", f"out_dir={tmp_path / 'out'}", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert result.lines[0].startswith(f"error: record {where / records.RECORD}: its rows differ from the evaluations "
                                      f"in the job's run directory {tmp_path / 'outputs/lat/tiny/a1_seed0'} "
                                      "(normal/goal_reaching episode 0: normalized_cost "), result.lines
    assert snapshot(tmp_path) == before and not (tmp_path / "out").exists()

    # the job made again in its run directory since the record (its stages built at other times): another build,
    # not an edit, and the line says so
    builds_path = tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0" / "builds.json"
    builds = json.loads(builds_path.read_text())
    for entry in builds.values():
        entry["finished"] = "2030-01-01T00:00:00Z"
    builds_path.write_text(json.dumps(builds))
    result = run_in_process("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]",
                            "settings=[normal]", f"records={store}", f"out_dir={tmp_path / 'out'}", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "holds another build of it (its stages were made again after the record's)" in result.lines[0]


def evaluation_specs():
    def spec(task, options=None):
        params = {"seed": 0, "setting": "normal", "task_name": task, "task": options or {}}
        return StageSpec(f"evaluation_normal_{task}", {"params": params, "after": {}},
                         f"evaluation/normal/{task}-0123456789ab.npz")

    return [StageSpec("experts", {"params": {}, "after": {}}, "experts.npz"), spec("goal_reaching"),
            spec("velocity_tracking", {"split": "train"})]


def record_rows():
    row = {"method": "lat", "robot": "a1", "setting": "normal", "seed": 0, "normalized_cost": 0.5}
    return ([{**row, "task": "goal_reaching", "episode": e, "success": float(e == 0), "final_error": 0.1 + e}
             for e in range(2)]
            + [{**row, "task": "velocity_tracking_train", "episode": 0, "success": float("nan"), "final_error": 0.02}])


@pytest.mark.parametrize("change, said", [
    (lambda rows: rows[2].update(task="goal_reaching", episode=2), "no rows of normal/velocity_tracking_train"),
    (lambda rows: rows[1].update(success=1.0), "row 1's success is 1.0, its final error 1.1 m"),
    (lambda rows: rows[0].update(task="trajectory_tracking"), "row 0 is of setting 'normal' and task "
                                                              "'trajectory_tracking', which no stage evaluates"),
    (lambda rows: rows[1].update(seed=1), "row 1 is of seed 1, its stage of seed 0"),
    (lambda rows: rows[1].update(episode=0), "the rows of normal/goal_reaching are numbered [0, 0]"),
])
def test_a_record_whose_rows_disagree_with_its_stages_is_refused_under_a_recomputed_digest(tmp_path, change, said):
    """Case 4 without the run directory: a row relabelled to another task, a success its final error denies, a row
    of another seed or a repeated episode is refused when the record is read, even with its digest recomputed."""
    where = tmp_path / "records" / "lat" / "tiny" / "a1_seed0"
    records.save(records.make_record({"method": "lat", "overrides": []}, evaluation_specs(), rows=record_rows()), where)
    assert records.read(where)["rows"][0]["task"] == "goal_reaching"

    def edit(record):
        change(record["rows"])

    forge(where, edit)
    with pytest.raises(records.RecordError, match="its rows do not agree with its stages") as refused:
        records.read(where)
    assert said in str(refused.value) and str(where / records.RECORD) in str(refused.value)


def test_signed_records_are_verified_and_unsigned_ones_refused_while_a_key_is_set(tmp_path, monkeypatch):
    """Case 4's remedy for shared record stores: with HIERLOCO_RECORD_KEY naming a key file, records are signed
    (HMAC-SHA256) when saved; an edit with a recomputed digest, a record signed with another key and an unsigned
    one are refused in one line; `python -m hierloco.pipeline.records sign` signs the records you trust."""
    key, other = tmp_path / "record.key", tmp_path / "other.key"
    key.write_text("k" * 64 + "\n")
    other.write_text("o" * 64 + "\n")
    signature = {"method": "lat", "overrides": []}
    unsigned, signed = tmp_path / "store" / "unsigned", tmp_path / "store" / "signed"
    records.save(records.make_record(signature, evaluation_specs(), rows=record_rows()), unsigned)
    assert records.MAC not in json.loads((unsigned / records.RECORD).read_text())

    monkeypatch.setenv(records.KEY_VARIABLE, str(key))
    records.save(records.make_record(signature, evaluation_specs(), rows=record_rows()), signed)
    assert records.read(signed)["rows"][0]["final_error"] == 0.1
    with pytest.raises(records.RecordError, match=f"record {unsigned / records.RECORD} is not signed, and "
                                                  "HIERLOCO_RECORD_KEY is set"):
        records.read(unsigned)

    def lower_errors(record):
        for row in record["rows"]:
            row["final_error"] = 0.01

    text = (signed / records.RECORD).read_text()
    forge(signed, lower_errors)
    with pytest.raises(records.RecordError, match="is not signed with the key HIERLOCO_RECORD_KEY names: it was "
                                                  "edited, or signed with another key"):
        records.read(signed)
    (signed / records.RECORD).write_text(text)
    monkeypatch.setenv(records.KEY_VARIABLE, str(other))
    with pytest.raises(records.RecordError, match="not signed with the key"):
        records.read(signed)

    monkeypatch.setenv(records.KEY_VARIABLE, str(key))
    assert records.main(["sign", str(tmp_path / "store")]) == 0  # signs the unsigned one, leaves the signed one
    assert records.read(unsigned)["signature"] == signature and (signed / records.RECORD).read_text() == text
    monkeypatch.delenv(records.KEY_VARIABLE)
    assert records.read(signed)["signature"] == signature  # without a key, a signed record reads as before

    for content, message in ((b"short", "holds 16 to 4096 bytes, this one 5"),
                             (None, "is not a key file")):
        bad = tmp_path / "bad.key"
        bad.unlink(missing_ok=True)
        if content is not None:
            bad.write_bytes(content)
        monkeypatch.setenv(records.KEY_VARIABLE, str(bad))
        with pytest.raises(ConfigError, match=message):
            records.check_records(str(tmp_path / "store"))


def test_a_study_refuses_an_unsigned_record_in_one_line_while_a_key_is_set(copy_run, tmp_path, monkeypatch):
    """Case 4 through a study: with a key set, the job's unsigned record is refused before any job."""
    job = compare_job(copy_run, tmp_path, monkeypatch)
    store = tmp_path / "records"
    studies.run_jobs([job], records=str(store))
    (tmp_path / "record.key").write_text("s" * 64)
    result = run_in_process("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]",
                            "settings=[normal]", f"records={store}", f"out_dir={tmp_path / 'out'}", cwd=tmp_path,
                            env={records.KEY_VARIABLE: str(tmp_path / "record.key")})
    where = store / "lat" / "tiny" / "a1_seed0" / records.RECORD
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert result.lines[0].startswith(f"error: record {where} is not signed, and HIERLOCO_RECORD_KEY is set")
    assert not (tmp_path / "out").exists()


def test_a_records_directory_keeps_one_config_per_job(copy_run, tmp_path, monkeypatch):
    """Case 6: a second study with another config for the same job is refused before any job, naming the record
    and what differs; the first study's record stays as it was. Two jobs of one study with one place are refused."""
    job = compare_job(copy_run, tmp_path, monkeypatch)
    store = tmp_path / "records"
    studies.run_jobs([job], records=str(store))
    where = store / "lat" / "tiny" / "a1_seed0" / records.RECORD
    kept = where.read_bytes()
    other = studies.Job("lat", "outputs/lat/tiny/a1_seed0", [*COMPARE_LAT, "planner.horizon=2"])
    with pytest.raises(ConfigError, match="made with another config \\(overrides only there: none; only here: "
                                          "planner.horizon=2\\): a records directory keeps one config per job"):
        studies.run_jobs([other], records=str(store))
    before = snapshot(tmp_path)
    result = run_in_process("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]",
                            "settings=[normal]", 'overrides=["planner.horizon=2"]', f"records={store}",
                            f"out_dir={tmp_path / 'out'}", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "made with another config" in result.lines[0] and f"remove {where}" in result.lines[0]
    assert snapshot(tmp_path) == before and where.read_bytes() == kept
    twins = [studies.Job("lat", str(tmp_path.parent / f"{tmp_path.name}_{side}" / "lat" / "tiny" / "a1_seed0"), [])
             for side in ("a", "b")]  # outside the working directory: a record's place is the last three parts
    with pytest.raises(ConfigError, match="would share one record"):
        studies.check_records(str(tmp_path / "elsewhere"), twins)


def test_records_where_the_study_will_put_run_directories_are_refused(tmp_path):
    """Case 7: on a machine with no run directories yet, records=outputs (and a records path inside a run directory
    the study plans) is refused in one line before any job, from the study's layout; nothing is written."""
    result = run_in_process("compare", "preset=tiny", "methods=[lat]", "robots=[a1]", "seeds=[0]",
                            "settings=[normal]", "records=outputs", f"out_dir={tmp_path / 'out'}", cwd=tmp_path)
    assert result.returncode == 2 and result.lines == [
        "error: records=outputs would hold the run directory outputs/lat/tiny/a1_seed0 this study plans (its records "
        "would lie inside run directories): records live apart from run directories (e.g. "
        "records=results/<study>/records)"], result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    planned = [studies.Job("lat", str(tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0"), [])]
    with pytest.raises(ConfigError, match="is \\(or is inside\\) the run directory .* this study plans"):
        studies.check_records(str(tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0" / "records"), planned)
    studies.check_records(str(tmp_path / "results" / "study" / "records"), planned)  # apart: fine
    studies.check_records(str(tmp_path / "outputs" / "records"), planned)  # beside the run directories: fine


def test_a_reused_jobs_record_keeps_the_timings_of_the_build_it_reports(copy_run, tmp_path, monkeypatch):
    """Case 8: after the study's job finished, its run directory is run again with another planner (which rewrites
    report.json and builds.json); the reused job's record and the study's wall-clock keep the timings of the build
    the record reports."""
    job = compare_job(copy_run, tmp_path, monkeypatch)
    run_dir = tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0"
    builds, report = (json.loads((run_dir / name).read_text()) for name in ("builds.json", "report.json"))
    again = run_in_process("lat", f"run_dir={run_dir}", *COMPARE_LAT, "planner.horizon=2", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    later = json.loads((run_dir / "builds.json").read_text())
    assert later["evaluation_normal_goal_reaching"] != builds["evaluation_normal_goal_reaching"]  # rewritten
    store = tmp_path / "records"
    [result] = studies.run_jobs([job], records=str(store))
    record = records.read(store / "lat" / "tiny" / "a1_seed0")
    assert result.reused and result.builds == builds and record["builds"] == builds
    assert record["report"]["stage_seconds"] == report["stage_seconds"] == result.report["stage_seconds"]
    rows = studies.evaluation_rows(run_dir, studies.planned_stages(job))
    assert records.canonical(record["rows"]) == records.canonical(rows)  # the default planner's rows, as before
    costs = lambda table: {(r["task"], r["episode"]): r["normalized_cost"] for r in table}  # noqa: E731
    assert costs(read_csv(run_dir / "episodes.csv")) != costs(rows)  # the run directory's table: the horizon-2 run's
