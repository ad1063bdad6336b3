"""LAT with experts over several gaits (``experts.gaits``): one gait policy and latent space over all of them."""

import pytest

from hierloco.components.expert_library import ExpertLibrary
from hierloco.results import read_csv
from tests.recipes.test_device_keys import changed, plan
from tests.runner import run_in_process, run_subprocess

GAITS = "experts.gaits={trot: [[FR, RL], [FL, RR]], pace: [[FR, RR], [FL, RL]]}"


def test_a_tiny_lat_run_learns_one_latent_space_over_two_gaits(tmp_path):
    run = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", f"run_dir={run}", GAITS, "eval.videos=[]", "eval.generalization=null",
                            "progress=false", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    library = ExpertLibrary.load(run / "experts.npz")
    assert library.metadata["expert_gaits"] == ["pace"] * 5 + ["trot"] * 5  # the tiny preset's 10 experts

def test_the_gaits_are_in_the_experts_key_and_so_in_every_stage_after_it():
    assert "gaits" not in plan("lat")["experts"].params  # left alone, every existing key stays as it was
    assert plan("lat", GAITS)["experts"].params["gaits"]["pace"] == [["FR", "RR"], ["FL", "RL"]]
    assert changed("lat", GAITS) == set(plan("lat"))  # the experts, and everything learned from them


def test_a_gait_the_robot_cannot_walk_is_one_line_before_any_work(tmp_path):
    run = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", f"run_dir={run}",
                            "experts.gaits={trot: [[FR, RL], [FL, RR]], pace: [[FR, XX], [FL, RL]]}", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert result.lines[0].startswith("error: ") and "gait 'pace'" in result.lines[0] and "'XX'" in result.lines[0]
    assert not run.exists()


@pytest.mark.parametrize("override, message", [
    ("own=pace", "own: gait 'pace' [['FR', 'RR'], ['FL', 'RL']] is not a1's own gait groups"),
    ("own=gallop", "own: 'gallop' is not one of the gaits"),
    ("gaits.pace=[[FR,XX],[FL,RL]]", "gait 'pace': "),
])
def test_the_gait_study_refuses_a_bad_config_in_one_line(tmp_path, override, message):
    result = run_in_process("gaits", "preset=tiny", "seeds=[0]", override, cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1 and result.lines[0].startswith("error: "), result.stderr
    assert message in result.lines[0], result.lines[0]
    assert not (tmp_path / "outputs").exists()


@pytest.mark.slow  # a tiny study through Ray (~1 min)
def test_the_gait_study_labels_every_executed_action_and_draws_the_switches(tmp_path):
    out = tmp_path / "out"
    result = run_subprocess("gaits", "preset=tiny", "seeds=[0]", "compare_records=null", f"out_dir={out}",
                            cwd=tmp_path)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    costs = read_csv(out / "costs.csv")
    assert {r["method"] for r in costs} == {"own gait (trot)", "3 gaits"}
    labels = read_csv(out / "gaits.csv")
    assert {r["gait"] for r in labels} <= {"trot", "pace", "bound"}
    for task in ("velocity_tracking", "goal_reaching", "trajectory_tracking"):
        episodes = {r["episode"] for r in costs if r["method"] == "3 gaits" and r["task"] == task}
        assert {r["episode"] for r in labels if r["task"] == task} == episodes  # every episode, every action
    text = (out / "gaits.md").read_text()
    assert "| goal reaching | " in text and "## Cost" in text
    diagrams = sorted(out.glob("gait_*_episode*.png"))
    assert len(diagrams) == 2 and all(p.read_bytes()[:4] == b"\x89PNG" for p in diagrams)
