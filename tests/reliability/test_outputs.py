"""Outputs tied to what made them (the reliability issue's cases 1-6): a study's rows come from the evaluations its
plan names, records are verified, a run directory belongs to one method, videos follow their evaluation, artifacts
that load but are wrong are refused, and a table says which jobs it leaves out."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from hierloco.io import load_arrays, save_arrays
from hierloco.pipeline import records, studies
from hierloco.pipeline.study import write_tables
from hierloco.results import read_csv
from tests.runner import run_in_process, snapshot

LIB = ["preset=tiny", "robot=a1", "seed=0", "settings=[normal]", "progress=false", "eval.generalization=null"]


def lib_job(run_dir: Path) -> studies.Job:
    return studies.Job("lib", str(run_dir), list(LIB), labels={"method": "lib"})


def test_a_reused_job_reports_its_planned_evaluations_not_a_later_run_with_another_planner(tmp_path):
    """Case 1: the study's LIB run directory is run again with planner.horizon=2; the study still reports the
    default planner's numbers (read from the evaluation artifacts its plan names), never the horizon-2 table."""
    run_dir = tmp_path / "outputs" / "lib" / "tiny" / "a1_seed0"
    job = lib_job(run_dir)
    assert run_in_process("lib", f"run_dir={run_dir}", *LIB).returncode == 0
    (run_dir / studies.DONE).write_text(json.dumps({"signature": job.signature(), "seconds": 1.0}))
    specs = studies.planned_stages(job)
    default_rows = studies.evaluation_rows(run_dir, specs)
    assert run_in_process("lib", f"run_dir={run_dir}", *LIB, "planner.horizon=2").returncode == 0
    horizon2 = read_csv(run_dir / "episodes.csv")  # the horizon-2 run's table, now in the run directory
    assert studies.finished(job, specs)
    record = studies.run_record(job, specs)
    reported = [(r["task"], r["episode"], r["normalized_cost"]) for r in record["rows"]]
    assert reported == [(r["task"], r["episode"], r["normalized_cost"]) for r in default_rows]
    assert reported != [(r["task"], r["episode"], r["normalized_cost"]) for r in horizon2]


def test_an_edited_record_is_refused_by_the_study_in_one_line(tmp_path):
    """Case 2: a record whose rows were edited is refused, naming the file; nothing is published."""
    job = lib_job(tmp_path / "outputs" / "lib" / "tiny" / "a1_seed0")
    specs = studies.planned_stages(job)
    rows = [{"method": "lib", "robot": "a1", "setting": "normal", "task": task, "seed": 0, "episode": 0,
             "normalized_cost": 0.5, "success": 0.0, "final_error": 1.0}
            for task in ("velocity_tracking", "goal_reaching", "trajectory_tracking")]
    where = tmp_path / "records" / "lib" / "tiny" / "a1_seed0"
    records.save(records.make_record(job.signature(), specs, rows=rows), where)
    text = (where / records.RECORD).read_text()
    (where / records.RECORD).write_text(text.replace('"normalized_cost": 0.5', '"normalized_cost": 0.0123', 1))
    result = run_in_process("compare", "preset=tiny", "methods=[lib]", "robots=[a1]", "seeds=[0]",
                            "generalization=false", f"records={tmp_path / 'records'}", f"out_dir={tmp_path / 'out'}",
                            cwd=tmp_path)
    assert result.returncode == 2 and result.lines == [
        f"error: record {where / records.RECORD} was edited or is damaged (its digest does not match its contents); "
        "restore it from git or remove it to run the job again"], result.stderr
    assert not (tmp_path / "out").exists()


def test_another_method_cannot_take_a_run_directory(copy_run):
    """Case 3: SAC into a finished LAT run directory is refused; nothing of LAT's is overwritten."""
    before = snapshot(copy_run)
    result = run_in_process("sac", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    assert result.returncode == 2 and result.lines == [
        f"error: run directory {copy_run} belongs to method 'lat' (its run.json); sac needs a run directory of its "
        "own (run_dir=...)"]
    assert snapshot(copy_run) == before


def test_a_video_follows_the_evaluation_it_shows(copy_run):
    """Case 4: with another planner the goal-reaching video is rendered again from the new evaluation (or, where
    rendering is off, the old one is removed): never the old planner's video beside the new tables."""
    outputs = json.loads((copy_run / "outputs.json").read_text())["files"]
    video = "videos/normal_goal_reaching.mp4"
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "planner.name=cem")
    assert result.returncode == 0, result.stderr
    after = json.loads((copy_run / "outputs.json").read_text())["files"]
    evaluations = {p.name.rsplit("-", 1)[1].removesuffix(".npz") for p in (copy_run / "evaluation" / "normal").glob(
        "goal_reaching-*.npz")}
    if video in outputs:
        assert video in after or not (copy_run / video).exists()
        if video in after:
            assert after[video] != outputs[video] and after[video] in evaluations
    paths = "figures/normal_goal_reaching_paths.png"
    assert after[paths] != outputs[paths]  # the figure too


def test_artifacts_that_load_but_are_wrong_are_refused(copy_run):
    """Case 5: wrong shapes, NaN weights, forged costs: one line naming the file; the tables stay as they were."""
    tables = {name: (copy_run / name).read_bytes() for name in ("results.csv", "episodes.csv", "results.md")}

    def refused(name, change, message):
        path = copy_run / name
        original = path.read_bytes()
        change(path)
        result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")
        path.write_bytes(original)
        assert result.returncode == 2, result.stderr
        assert len(result.lines) == 1 and str(path) in result.lines[0] and message in result.lines[0], result.stderr
        assert {n: (copy_run / n).read_bytes() for n in tables} == tables

    def reshape_targets(path):
        arrays, meta = load_arrays(path)
        arrays["joint_targets"] = arrays["joint_targets"][:, :-1]
        save_arrays(path, arrays, meta)

    def nan_weights(path):
        import torch

        payload = torch.load(path, weights_only=True)
        key = next(k for k in payload["state_dict"] if k.endswith("weight"))
        payload["state_dict"][key][0, 0] = float("nan")
        torch.save(payload, path)

    def forge_cost(path):
        arrays, meta = load_arrays(path)
        meta["rows"][0]["normalized_cost"] = 0.0123
        save_arrays(path, arrays, meta)

    evaluation = next((copy_run / "evaluation" / "normal").glob("goal_reaching-*.npz")).relative_to(copy_run)
    refused("experts.npz", reshape_targets, "joint_targets has shape")
    refused("dynamics_model_normal.pt", nan_weights, "holds NaN or inf")
    refused(str(evaluation), forge_cost, "differs from the summary")


def test_an_evaluation_without_its_recording_removes_the_figures_it_drew(copy_run):
    """Case 5: figures drawn from an evaluation that no longer holds a recording are removed, with a warning."""
    evaluation = next((copy_run / "evaluation" / "normal").glob("goal_reaching-*.npz"))
    arrays, meta = load_arrays(evaluation)
    save_arrays(evaluation, {}, meta)
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "eval.videos=[]")
    assert result.returncode == 0, result.stderr
    assert not (copy_run / "figures" / "normal_goal_reaching_paths.png").exists()
    assert any("no figures of normal/goal_reaching" in w for w in json.loads(
        (copy_run / "report.json").read_text())["warnings"])


def test_a_table_names_the_jobs_it_leaves_out(tmp_path):
    """Case 6: a failed job is listed under the table with its reason; a robot never disappears silently."""
    ok = studies.JobResult(studies.Job("lat", "outputs/lat/tiny/a1_seed0", []), True,
                           [{"method": "lat", "robot": "a1", "setting": "normal", "task": "goal_reaching", "seed": 0,
                             "episode": 0, "normalized_cost": 0.4, "success": 1.0, "final_error": 0.1}], 1.0)
    failed = studies.JobResult(studies.Job("lat", "outputs/lat/tiny/daisy_seed0", []), False, [], 1.0,
                               error="exit code 1: boom")
    write_tables(ok.rows, [ok, failed], tmp_path, name="comparison", title="t")
    text = (tmp_path / "comparison.md").read_text()
    assert "## Jobs not in this table" in text and "outputs/lat/tiny/daisy_seed0 | failed: exit code 1: boom" in text
