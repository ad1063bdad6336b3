"""A robot described by a YAML file runs LAT end to end from the command line, with no Python of the user's; an
edited robot is another robot; a robot whose experts do not walk as commanded stops the run with a diagnosis."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
FIXTURE = ROOT / "tests" / "fixtures" / "quadruped20"
TINY = ["preset=tiny", "progress=false", "eval.generalization=null", "eval.videos=[]"]


def lat(*overrides, cwd=ROOT):
    env = {**os.environ, "WANDB_MODE": "offline"}
    return subprocess.run([sys.executable, str(ROOT / "recipes" / "lat" / "train.py"), *TINY, *overrides], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="module")
def robot_yaml(tmp_path_factory):
    """A copy of the fixture (the YAML names its MJCF relative to itself)."""
    folder = tmp_path_factory.mktemp("robot")
    shutil.copytree(FIXTURE, folder, dirs_exist_ok=True)
    return folder / "quadruped20.yaml"


@pytest.fixture(scope="module")
def user_run(robot_yaml, tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("user") / "run"
    # trained enough to walk (the tiny preset's policy is a smoke test that barely lifts a foot)
    result = lat(f"robot={robot_yaml}", f"run_dir={run_dir}", "experts.settle_time=3.0", "policy.epochs=300",
                 "policy.hidden=128")
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-3000:]
    return run_dir


def test_a_yaml_robot_runs_lat_end_to_end(user_run):
    from hierloco.results import TaskEvaluation, read_csv

    rows = read_csv(user_run / "results.csv")
    assert {r["robot"] for r in rows} == {"quadruped20"} and len(rows) == 3
    assert (user_run / "figures" / "normal_gait_during_goal_reaching.png").exists()
    from hierloco.components.expert_library import ExpertLibrary

    experts = ExpertLibrary.load(user_run / "experts.npz").foot_contacts.mean(1)  # G x L stance fractions
    assert np.all((experts > 0.3) & (experts < 0.9)), f"the experts' feet alternate stance and swing: {experts}"
    evaluation = TaskEvaluation.load(next((user_run / "evaluation" / "normal").glob("goal_reaching-*.npz")))
    stance = evaluation.recording["foot_contacts"][0].mean(0)  # fraction of time each foot is in stance
    assert np.all((stance > 0.2) & (stance < 0.95)), f"every foot alternates stance and swing: {stance}"
    import json

    reference = json.loads((user_run / "run.json").read_text())["robot"]
    assert Path(reference).is_absolute() and reference.endswith("quadruped20.yaml")  # found from any directory


def test_load_run_rebuilds_a_yaml_robot_s_parts_elsewhere(user_run, tmp_path, monkeypatch):
    import hierloco
    from hierloco.envs.tasks import GoalReaching

    monkeypatch.chdir(tmp_path)  # another working directory
    run = hierloco.load_run(user_run)
    assert run.robot.name == "quadruped20" and run.method == "lat"
    planner = run.planner(GoalReaching(num_goals=2), num_candidates=64)
    state = planner.env.initial_state(episode=np.array([0, 1]))
    action = planner(state)["action"]
    low = run.low_level()
    assert action.shape == (2, low.action_dim)
    assert np.all(action.numpy() >= low.action_low - 1e-6) and np.all(action.numpy() <= low.action_high + 1e-6)


def test_an_edited_robot_is_another_robot(user_run, robot_yaml, tmp_path):
    edited = tmp_path / "quadruped20.yaml"
    shutil.copy(robot_yaml.parent / "quadruped20.xml", tmp_path)
    edited.write_text(robot_yaml.read_text().replace("kp: 150", "kp: 120"))
    result = lat(f"robot={edited}", f"run_dir={user_run}")
    assert result.returncode == 2 and "another config" in result.stderr and "after.robot" in result.stderr


def test_experts_that_do_not_walk_as_commanded_stop_the_run(robot_yaml, tmp_path):
    short = tmp_path / "quadruped20.yaml"
    shutil.copy(robot_yaml.parent / "quadruped20.xml", tmp_path)
    short.write_text(robot_yaml.read_text() + "gait_period: 0.2\n")
    run_dir = tmp_path / "run"
    result = lat(f"robot={short}", f"run_dir={run_dir}", "experts.settle_time=3.0")
    assert result.returncode == 2, result.stderr[-2000:]
    assert len(result.stderr.strip().splitlines()) == 1 and "gait_period" in result.stderr, result.stderr
    assert not (run_dir / "gait_policy.pt").exists()  # stopped before learning from them


@pytest.mark.slow
def test_a_gait_policy_that_reproduces_too_few_experts_stops_the_run(tmp_path):
    result = lat(f"run_dir={tmp_path / 'run'}", "checks.min_reproduced_fraction=0.9")
    assert result.returncode == 2 and "the gait policy reproduces" in result.stderr, result.stderr
    assert not (tmp_path / "run" / "dynamics_data_normal.npz").exists()


@pytest.mark.slow
def test_a_yaml_robot_runs_through_the_comparison_study(robot_yaml, tmp_path):
    """The robot reaches the study's Ray workers as a path (no Python of the user's anywhere)."""
    from hierloco.results import read_csv

    command = [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny", f"robots=[{robot_yaml}]",
               "methods=[lib]", "seeds=[0]", "settings=[normal]", f"out_dir={tmp_path / 'out'}",
               'overrides=["eval.generalization=null","eval.videos=[]","eval.figures=false"]']
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=900,
                            env={**os.environ, "WANDB_MODE": "offline"})
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    rows = read_csv(tmp_path / "out" / "comparison.csv")
    assert {(r["method"], r["robot"]) for r in rows} == {("lib", "quadruped20")}
    assert (tmp_path / "outputs" / "lib" / "tiny" / "quadruped20_seed0" / "results.csv").exists()


def test_an_adaptive_gait_policy_is_keyed_and_records_its_fits(tmp_path):
    """``policy.adaptive=true``: the gait policy is fitted until it reproduces the bar or the epoch budget ends; the
    stage key holds the options and the bar (only then), the checkpoint the fits tried."""
    import json

    import torch

    from tests.runner import run_in_process

    run_dir = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={run_dir}", "eval.videos=[]",
                            "eval.generalization=null", "policy.adaptive=true", "policy.budget_epochs=250",
                            "checks.min_reproduced_fraction=0.9")
    assert result.returncode in (0, 2), result.stderr[-3000:]  # a policy below the bar stops the run, as before
    key = json.loads((run_dir / "gait_policy.pt.key.json").read_text())["params"]
    assert key["adaptive"] is True and key["budget_epochs"] == 250 and key["min_reproduced_fraction"] == 0.9
    attempts = torch.load(run_dir / "gait_policy.pt", weights_only=True)["metadata"]["adaptive_fit"]["attempts"]
    assert attempts and sum(a["epochs"] for a in attempts) <= 100 + 250  # the configured fit, then the budget


@pytest.mark.slow
def test_experts_tune_searches_the_robot_first_and_records_what_it_found(robot_yaml, tmp_path):
    """``experts.tune=true``: the expert parameters are searched (cached, ``expert_tuning.json``) before anything
    is planned; later stages key on the tuned robot; ``run.json`` holds the YAML lines found."""
    import json

    from tests.runner import run_in_process

    run_dir = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", "progress=false", f"robot={robot_yaml}", f"run_dir={run_dir}",
                            "eval.videos=[]", "experts.tune=true", "experts.tune_budget=60")
    assert result.returncode == 0, result.stderr[-3000:]
    tuning = json.loads((run_dir / "run.json").read_text())["expert_tuning"]
    assert tuning["yaml"] and tuning["tuned_fingerprint"]
    experts_key = json.loads((run_dir / "experts.npz.key.json").read_text())
    assert experts_key["after"]["robot"] == tuning["tuned_fingerprint"] and experts_key["params"]["tune"] is True
    again = run_in_process("lat", "preset=tiny", "progress=false", f"robot={robot_yaml}", f"run_dir={run_dir}",
                           "eval.videos=[]", "experts.tune=true", "experts.tune_budget=60")
    assert again.returncode == 0 and "expert_tuning" in again.stdout and "(cached)" in again.stdout
