"""LAT with experts over several gaits (``experts.gaits``): one gait policy and latent space over all of them."""

from hierloco.components.expert_library import ExpertLibrary
from tests.recipes.test_device_keys import changed, plan
from tests.runner import run_in_process

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
