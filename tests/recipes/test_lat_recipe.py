"""The LAT recipe end to end with the tiny preset: outputs, cached stages, refusals, evaluation of a trained run,
locking, interrupts and resumes."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TRAIN = ROOT / "recipes" / "lat" / "train.py"
COLUMNS = ["method", "robot", "setting", "task", "seed", "normalized_cost", "success_rate", "final_error"]


def run(*overrides, timeout=600):
    env = {**os.environ, "WANDB_MODE": "offline", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run([sys.executable, str(TRAIN), "preset=tiny", "progress=false", *overrides], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("lat") / "run"
    result = run(f"run_dir={run_dir}", "settings=[normal,legs_disabled]")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return run_dir, result


def test_outputs(tiny_run):
    run_dir, result = tiny_run
    with open(run_dir / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == COLUMNS
    tasks = {"velocity_tracking", "goal_reaching", "trajectory_tracking", "goal_reaching_1p5m", "goal_reaching_3m",
             "velocity_tracking_diagonal"}
    assert {(r["setting"], r["task"]) for r in rows} == {(s, t) for s in ("normal", "legs_disabled") for t in tasks}
    assert all(r["method"] == "lat" and r["robot"] == "a1" and float(r["normalized_cost"]) >= 0 for r in rows)
    assert "| lat | a1 | normal | goal_reaching |" in (run_dir / "results.md").read_text()
    assert "normalized cost" in result.stdout  # the table is printed
    figures = {p.name for p in (run_dir / "figures").iterdir()}
    assert {"normal_goal_reaching_paths.png", "normal_gait_during_goal_reaching.png",
            "normal_trajectory_tracking_paths.png", "legs_disabled_velocity_tracking_velocity.png",
            "latent_map.png"} <= figures  # the tiny preset's latent space is 2-D
    assert (run_dir / "videos" / "normal_goal_reaching.mp4").stat().st_size > 1000
    report = json.loads((run_dir / "report.json").read_text())
    assert len(report["dynamics_model_normal"]["heldout_rmse"]) == 5
    assert list((run_dir / "logs").rglob("*.csv")), "the CSV logger wrote metrics"


def test_rerun_reuses_every_stage(tiny_run):
    run_dir, _ = tiny_run
    before = {p.name: p.stat().st_mtime_ns for p in run_dir.rglob("*.npz")}
    result = run(f"run_dir={run_dir}", "settings=[normal,legs_disabled]")
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((run_dir / "report.json").read_text())
    assert all(report["reused_stages"].values()), report["reused_stages"]
    assert before == {p.name: p.stat().st_mtime_ns for p in run_dir.rglob("*.npz")}


def test_another_config_is_refused_without_overwriting(tiny_run):
    run_dir, _ = tiny_run
    experts = (run_dir / "experts.npz").read_bytes()
    result = run(f"run_dir={run_dir}", "experts.num_experts=5")
    assert result.returncode == 2
    assert "another config" in result.stderr and "num_experts" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert (run_dir / "experts.npz").read_bytes() == experts


def test_corrupted_artifact_is_named(tiny_run, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(tiny_run[0], copy)
    policy = copy / "gait_policy.pt"
    policy.write_bytes(policy.read_bytes()[:500])
    result = run(f"run_dir={copy}")
    assert result.returncode == 2 and "corrupted" in result.stderr and "gait_policy.pt" in result.stderr


SLOW = pytest.mark.slow  # the same checks as test_user_errors.py, here in a process of their own


@pytest.mark.parametrize("override, message", [("robot=spot", "unknown robot"),
                                               pytest.param("planner.name=magic", "unknown planner", marks=SLOW),
                                               pytest.param("dynamics.num_transitions=-5", "num_transitions",
                                                            marks=SLOW),
                                               pytest.param("settings=[broken]", "unknown setting", marks=SLOW)])
def test_bad_config_is_refused_before_any_work(tmp_path, override, message):
    run_dir = tmp_path / "never"
    result = run(f"run_dir={run_dir}", override)
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not run_dir.exists()


def artifact_bytes(run_dir: Path) -> dict:
    """Every training artifact and its key, by relative path."""
    return {str(p.relative_to(run_dir)): p.read_bytes() for p in sorted(run_dir.rglob("*"))
            if p.is_file() and p.suffix in (".npz", ".pt", ".json") and "evaluation" not in str(p.relative_to(run_dir))
            and p.name not in ("report.json", "builds.json")  # records of this invocation and of build times
            and not str(p.relative_to(run_dir)).startswith("logs")}


def test_evaluate_adds_a_task_without_touching_training(tiny_run, tmp_path):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(tiny_run[0], copy)
    before = artifact_bytes(copy)
    builds = json.loads((copy / "builds.json").read_text())
    results = (copy / "results.csv").read_bytes()
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "evaluate.py"), f"run_dir={copy}",
                             "name=far", "progress=false", "eval.videos=[]",
                             "+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5.0, num_goals: 2, "
                             "num_steps: 3}"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert artifact_bytes(copy) == before and (copy / "results.csv").read_bytes() == results
    after = json.loads((copy / "builds.json").read_text())  # the new evaluation's build time is added, no other
    assert {k: v for k, v in after.items() if k in builds} == builds and set(after) - set(builds) == {
        f"evaluation_{setting}_goal_reaching_5m" for setting in ("normal", "legs_disabled")}
    rows = list(csv.DictReader(open(copy / "evaluations" / "far" / "results.csv")))
    assert {r["task"] for r in rows} >= {"goal_reaching_5m", "goal_reaching"}
    new = [p for p in (copy / "evaluation" / "normal").iterdir() if p.name.startswith("goal_reaching_5m-")]
    assert len(new) == 2  # the cached evaluation and its key
    # a training change is refused: evaluate.py never trains
    refused = subprocess.run([sys.executable, str(ROOT / "recipes" / "evaluate.py"), f"run_dir={copy}",
                              "policy.epochs=3"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert refused.returncode == 2 and "evaluate.py changes only" in refused.stderr


def test_a_traced_evaluation_replays_the_same_closed_loop_and_scores_the_model_on_its_plans(tiny_run, tmp_path):
    import numpy as np

    from hierloco.recipes.adverse import trace

    out = trace.trace(tiny_run[0], "legs_disabled", "velocity_tracking")
    assert out["normalized_cost"] == pytest.approx(out["recorded_normalized_cost"], rel=1e-6)  # the same episodes
    assert sum(out["cost_terms"].values()) == pytest.approx(out["actual_cost"], rel=1e-6)
    assert np.mean([s["cost"] for s in out["steps"]]) == pytest.approx(out["actual_cost"], rel=1e-6)  # 1 episode
    assert all(out["plan_rmse"][k] >= abs(out["plan_bias"][k]) for k in out["plan_rmse"])
    assert set(out["heldout_rmse"]) == set(out["plan_rmse"]) == {"dx", "dy", "dyaw", "vx_next", "vy_next"}
    trace.main([str(tiny_run[0]), "legs_disabled", "velocity_tracking", "--out", str(tmp_path / "trace.md")])
    assert "| dyaw |" in (tmp_path / "trace.md").read_text()
    with pytest.raises(SystemExit, match="no evaluation of 'walking' in setting 'legs_disabled' \\(it has: goal"):
        trace.main([str(tiny_run[0]), "legs_disabled", "walking"])
    with pytest.raises(SystemExit, match="KEY one of name, horizon, .*got 'depth=3'"):
        trace.main([str(tiny_run[0]), "legs_disabled", "velocity_tracking", "--planner", "depth=3"])
    longer = trace.trace(tiny_run[0], "legs_disabled", "velocity_tracking", planner={"horizon": 2, "name": "cem"})
    assert longer["planner"]["horizon"] == 2 and longer["planner"]["name"] == "cem"
    assert longer["recorded_normalized_cost"] is None  # planned otherwise: no recorded number to compare with


@pytest.mark.slow
def test_a_finished_run_renders_a_video_it_did_not_render(tiny_run, tmp_path):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(tiny_run[0], copy)
    assert not (copy / "videos" / "normal_trajectory_tracking.mp4").exists()  # the first run rendered goal reaching
    again = run(f"run_dir={copy}", "settings=[normal,legs_disabled]", "eval.videos=[trajectory_tracking]")
    assert again.returncode == 0, again.stderr[-3000:]
    report = json.loads((copy / "report.json").read_text())
    assert all(report["reused_stages"].values())  # nothing re-evaluated: drawn from the recorded episode
    assert (copy / "videos" / "normal_trajectory_tracking.mp4").stat().st_size > 1000


@pytest.mark.parametrize("content", ["[]", pytest.param("{", marks=SLOW), pytest.param('{"a": 1}', marks=SLOW)])
def test_a_bad_json_artifact_is_refused_before_outputs_are_rewritten(tiny_run, tmp_path, content):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(tiny_run[0], copy)
    (copy / "gait_policy_check.json").write_text(content)
    outputs = {name: (copy / name).read_bytes() for name in ("results.csv", "episodes.csv", "results.md",
                                                               "report.json")}
    result = run(f"run_dir={copy}", "settings=[normal,legs_disabled]")
    assert result.returncode == 2 and "gait_policy_check.json" in result.stderr, result.stderr
    assert {name: (copy / name).read_bytes() for name in outputs} == outputs


def test_a_bad_evaluation_is_refused(tiny_run, tmp_path):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(tiny_run[0], copy)
    evaluation = next((copy / "evaluation" / "normal").glob("goal_reaching-*.npz"))
    from hierloco.io import load_arrays, save_arrays

    arrays, meta = load_arrays(evaluation)
    save_arrays(evaluation, arrays, {**meta, "rows": []})
    result = run(f"run_dir={copy}", "settings=[normal,legs_disabled]")
    assert result.returncode == 2 and "no episodes" in result.stderr and evaluation.name in result.stderr


def _wait_for(predicate, timeout=300.0):
    import time

    start = time.time()
    while not predicate():
        assert time.time() - start < timeout, "timed out"
        time.sleep(0.2)


def test_a_second_run_into_the_same_directory_is_refused_at_once(tmp_path):
    run_dir = tmp_path / "run"
    env = {**os.environ, "WANDB_MODE": "offline"}
    first = subprocess.Popen([sys.executable, str(TRAIN), "preset=tiny", "progress=false", f"run_dir={run_dir}",
                              "policy.epochs=20"], cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        _wait_for(lambda: (run_dir / "experts.npz.key.json").exists())
        second = run(f"run_dir={run_dir}", "policy.epochs=21")
        assert second.returncode == 2 and f"in use by pid {first.pid}" in second.stderr, second.stderr
        assert "policy.epochs=20" in second.stderr  # the holder's command
    finally:
        first.kill()
        first.wait()


@pytest.mark.slow
def test_interrupt_says_where_and_rerun_resumes_identically(tiny_run, tmp_path):
    import signal

    run_dir = tmp_path / "run"
    process = subprocess.Popen([sys.executable, str(TRAIN), "preset=tiny", "progress=false", f"run_dir={run_dir}",
                                "settings=[normal,legs_disabled]"], cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    _wait_for(lambda: (run_dir / "dynamics_data_normal.npz.key.json").exists())
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130
    assert len(stderr.strip().splitlines()) == 1 and "interrupted in stage 'dynamics_" in stderr, stderr
    assert "run the same command again to resume" in stderr
    resumed = run(f"run_dir={run_dir}", "settings=[normal,legs_disabled]")
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert (run_dir / "episodes.csv").read_text() == (tiny_run[0] / "episodes.csv").read_text()


def test_sigkill_then_resume_is_byte_identical(tiny_run, tmp_path):
    """A run killed after its dynamics model and run again in the same directory ends with the bytes of a run with the
    same config made in one go elsewhere: every artifact, the results and every episode (the same seed gives the
    same numbers, whatever was built before the kill)."""
    import signal

    run_dir = tmp_path / "run"
    process = subprocess.Popen([sys.executable, str(TRAIN), "preset=tiny", "progress=false", f"run_dir={run_dir}",
                                "settings=[normal,legs_disabled]"], cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    _wait_for(lambda: (run_dir / "dynamics_model_normal.pt.key.json").exists())
    process.send_signal(signal.SIGKILL)
    process.wait()
    resumed = run(f"run_dir={run_dir}", "settings=[normal,legs_disabled]")
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert artifact_bytes(run_dir).keys() == artifact_bytes(tiny_run[0]).keys()
    for name, content in artifact_bytes(tiny_run[0]).items():
        if name not in ("run.json", ".lock"):
            assert artifact_bytes(run_dir)[name] == content, name
    assert (run_dir / "results.csv").read_bytes() == (tiny_run[0] / "results.csv").read_bytes()
    assert (run_dir / "episodes.csv").read_text() == (tiny_run[0] / "episodes.csv").read_text()
    assert not [p for p in run_dir.rglob(".*") if ".tmp" in p.name], "a killed write's temporary file was left"


@pytest.mark.slow
def test_a_sweep_gives_each_job_its_own_run_directory(tmp_path):
    env = {**os.environ, "WANDB_MODE": "offline"}
    result = subprocess.run([sys.executable, str(TRAIN), "-m", "preset=tiny", "progress=false", "eval.videos=[]",
                             "eval.generalization=null", "eval.figures=false",
                             "planner.name=random_shooting,cem"], cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = sorted(p.parent.name for p in (tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0").glob("*/results.csv"))
    common = "eval.figures=False,eval.generalization=null,eval.videos=[],planner.name={},preset=tiny,progress=False"
    assert runs == [common.format("cem"), common.format("random_shooting")]
