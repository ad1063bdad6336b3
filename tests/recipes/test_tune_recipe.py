"""Tuning a baseline on its training targets (tiny settings): every candidate evaluated on the training splits only,
starting from a finished run's stages when asked, and the candidate the stated rule chooses per robot named."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.results import read_csv
from tests.runner import run_in_process

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["eval.generalization=null", "eval.videos=[]", "eval.figures=false", "progress=false"]


def finished_run(tmp_path: Path, method: str, env: dict) -> Path:
    """A finished tiny run of ``method`` on A1, seed 0, where the comparison would have it."""
    source = tmp_path / "outputs" / method / "tiny" / "a1_seed0"
    done = subprocess.run([sys.executable, str(ROOT / "recipes" / method / "train.py"), "preset=tiny", "seed=0",
                           f"run_dir={source}", *SMALL], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return source


def test_tune_ik_tiny(tmp_path):
    env = {**os.environ, "WANDB_MODE": "offline"}
    source = finished_run(tmp_path, "ik", env)  # a finished IK run the integral candidate reuses
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "tune" / "run.py"), "preset=tiny", "robots=[a1]",
                             "seeds=[0]", f"out_dir={out}", f"runs_dir={out}"], cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(out / "tune.csv")
    assert {r["task"] for r in rows} == {"velocity_tracking_train", "goal_reaching_train", "trajectory_tracking_train"}
    test_goals = len([r for r in read_csv(source / "episodes.csv") if r["task"] == "goal_reaching"])
    train_goals = [r for r in rows if r["task"] == "goal_reaching_train" and r["candidate"] == "plain"]
    assert len(train_goals) == (test_goals + 1) // 2, "every other goal"
    reused = out / "integral" / "a1_seed0" / "dynamics_data_normal.npz"
    assert reused.read_bytes() == (source / "dynamics_data_normal.npz").read_bytes()
    table = (out / "tune.md").read_text()
    lines = [line for line in table.splitlines() if line.startswith("| a1 |")]
    # one seed decides nothing: the rule keeps the incumbent whichever mean is lower
    chosen = [line for line in lines if line.endswith("| chosen |")]
    assert len(lines) == 2 and len(chosen) == 1 and chosen[0].startswith("| a1 | integral |"), table
    assert "Chosen: a1: integral." in table and "inconclusive (fewer than 2 seeds" in table


def test_the_rule_keeps_the_incumbent_unless_a_candidate_is_established_better():
    import numpy as np

    from hierloco.recipes.tune.run import choose

    incumbent = np.array([0.30, 0.32, 0.31])
    chosen, decisions = choose({"paper": incumbent, "lower": np.array([0.29, 0.33, 0.30])}, "paper")
    assert chosen == "paper" and decisions["lower"].verdict != "holds"  # a lower mean within the seeds' spread
    chosen, _ = choose({"paper": incumbent, "a": np.array([0.20, 0.21, 0.19]), "b": np.array([0.10, 0.12, 0.11])},
                       "paper")
    assert chosen == "b"  # of the candidates established better, the lowest mean
    chosen, decisions = choose({"paper": incumbent, "one_seed": np.array([0.05])}, "paper")
    assert chosen == "paper" and decisions["one_seed"].verdict == "inconclusive"


@pytest.mark.slow  # a SAC tuning study (~40 s); test_tune_ik_tiny keeps the tuning recipe in the default suite
def test_tune_sac_tiny_reuses_the_comparison_agents_for_the_paper_candidate(tmp_path):
    env = {**os.environ, "WANDB_MODE": "offline"}
    source = finished_run(tmp_path, "sac", env)  # the comparison's SAC run
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "tune" / "run.py"), "target=sac", "preset=tiny",
                             "robots=[a1]", "seeds=[0]", f"out_dir={out}", f"runs_dir={out}"], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(out / "tune.csv")
    assert {r["candidate"] for r in rows} == {"paper", "lr_3e-4"}
    assert {r["task"] for r in rows} == {"velocity_tracking_train", "goal_reaching_train", "trajectory_tracking_train"}
    # the agents are trained on the training split whatever split is evaluated: the paper candidate's agents are the
    # comparison run's (their keys match, nothing is retrained), the other candidate trains its own
    import json

    for task in ("velocity_tracking", "goal_reaching", "trajectory_tracking"):
        agent = f"sac_{task}.pt"
        assert (out / "paper" / "a1_seed0" / agent).read_bytes() == (source / agent).read_bytes()
        assert (out / "lr_3e-4" / "a1_seed0" / agent).read_bytes() != (source / agent).read_bytes()
    built = json.loads((out / "paper" / "a1_seed0" / "builds.json").read_text())
    agents = {name: entry for name, entry in built.items() if name.startswith("sac_")}
    assert len(agents) == 3 and all("copied_from" in entry for entry in agents.values()), built
    # evaluated on the half of the targets the agents were trained on (not a half of that half)
    test_goals = len([r for r in read_csv(source / "episodes.csv") if r["task"] == "goal_reaching"])
    for candidate in ("paper", "lr_3e-4"):
        train_goals = [r for r in rows if r["candidate"] == candidate and r["task"] == "goal_reaching_train"]
        assert len(train_goals) == (test_goals + 1) // 2
    assert "Tuning SAC" in (out / "tune.md").read_text()


@pytest.mark.parametrize("override, message", [
    ("incumbent=tuned", "incumbent 'tuned' is not a candidate (integral, plain)"),
    ("incumbent=null", "incumbent None is not a candidate"),
])
def test_an_incumbent_that_is_not_a_candidate_is_one_line_before_any_work(tmp_path, override, message):
    result = run_in_process("tune", "preset=tiny", "robots=[a1]", "seeds=[0]", override, cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1 and result.lines[0].startswith("error: "), result.stderr
    assert message in result.lines[0], result.lines[0]
    assert not (tmp_path / "outputs").exists()
