"""The transfer study on tiny settings: LAT's low level from the nominal robot, evaluated on the nominal robot, on
the perturbed copy with the nominal CoM model, and on the copy with the model learned again on it."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hierloco.components.dynamics_data import TransitionData
from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # a study through Ray (~30 s)
def test_hardware_tiny(tmp_path):
    out = tmp_path / "out"
    command = [sys.executable, str(ROOT / "recipes" / "hardware" / "run.py"), "preset=tiny", "robots=[a1]",
               "seeds=[0]", "methods=[lat]", "num_transitions=50", "+hardware.servo_latency=0.04", f"out_dir={out}",
               'overrides=["eval.generalization=null","eval.figures=false","eval.videos=[]"]']
    result = subprocess.run(command, cwd=tmp_path, env={**os.environ, "WANDB_MODE": "offline"}, capture_output=True,
                            text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(out / "hardware.csv")
    assert {r["setting"] for r in rows} == {"normal", "hardware_unadapted", "hardware"}
    summary = (out / "hardware.md").read_text()
    assert "| a1 | lat | perturbed, model re-learned |" in summary and "servo_latency 0.04" in summary
    run = tmp_path / "outputs" / "hardware" / "tiny" / "lat" / "a1_seed0-servo_latency0.04"  # beside the default gap
    assert not list(run.glob("dynamics_*_hardware_unadapted*")), "the unadapted setting learns nothing"
    normal, hardware = (TransitionData.load(run / f"dynamics_data_{s}.npz") for s in ("normal", "hardware"))
    assert len(hardware) == 50 and not np.allclose(normal.next_com_state, hardware.next_com_state)
    key = json.loads(next((run / "evaluation" / "hardware_unadapted").glob("goal_reaching-*.key.json")).read_text())
    normal_model = json.loads((run / "dynamics_model_normal.pt.key.json").read_text())
    from hierloco.pipeline.rundir import digest

    assert key["after"]["model"] == digest(normal_model), "planned with the nominal robot's CoM model"
    assert key["params"]["hardware"]["servo_latency"] == 0.04


def test_each_gap_gets_its_own_run_directories():
    """A study of another perturbation runs beside the default one instead of meeting its cached stages."""
    from omegaconf import OmegaConf

    from hierloco.envs.robots import get_robot
    from hierloco.recipes.hardware.run import jobs

    cfg = OmegaConf.create({"methods": ["lat"], "variants": {}, "seeds": [0], "preset_name": "paper",
                            "num_experts": 20, "num_transitions": 2000, "overrides": []})
    run_dir = lambda options: jobs(cfg, [get_robot("daisy")], options)[0].run_dir  # noqa: E731
    assert run_dir({}) == run_dir({"servo_latency": 0.02}) == "outputs/hardware/paper/lat/daisy_seed0"
    assert run_dir({"motor_strength": 0.6, "com_noise": [0.04, 0.06, 0.1]}) == \
        "outputs/hardware/paper/lat/daisy_seed0-motor_strength0.6-com_noise0.04_0.06_0.1"


def test_the_perturbed_robot_s_world_gets_its_own_run_directories_and_overrides():
    """``hardware_world`` reaches every job as ``+hardware_world.*`` overrides and names its run directories."""
    from omegaconf import OmegaConf

    from hierloco.envs.robots import get_robot
    from hierloco.recipes.hardware.run import jobs, world_tag

    cfg = OmegaConf.create({"methods": ["lat"], "variants": {}, "seeds": [0], "preset_name": "paper",
                            "num_experts": 20, "num_transitions": 2000, "overrides": []})
    rough = {"terrain": {"name": "rough", "difficulty": 0.5}}
    both = {**rough, "randomization": "standard"}
    job = jobs(cfg, [get_robot("daisy")], {}, both)[0]
    assert "+hardware_world.terrain={name: rough, difficulty: 0.5}" in job.overrides
    assert "+hardware_world.randomization=standard" in job.overrides
    assert job.run_dir.startswith("outputs/hardware/paper/lat/daisy_seed0-on_rough0.5-randomized-world")
    tags = {world_tag(world) for world in ({}, rough, both, {"terrain": {"name": "rough", "difficulty": 0.75}},
                                           {"randomization": "standard"}, {"terrain": "flat"})}
    assert len(tags) == 5 and "" in tags  # flat ground is the simulation's own world: no suffix
    assert world_tag({"terrain": {"name": "rough", "difficulty": 0.5, "amplitude_m": 0.03}}) != world_tag(rough)
