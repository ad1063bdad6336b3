"""Devices and the options of the hot loops in stage keys (``docs/gpu.md``): ``device=auto`` is the default and keys
record the device it resolves to, so on a machine without a GPU every key is what it was before (the committed
records of every method still match); ``planner.compile``, ``planner.precision`` and ``sac.compile`` enter a key only
when they are not at their defaults; a study places each job on a device and a share of a GPU."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf, open_dict

from hierloco.pipeline import records, studies
from hierloco.pipeline.config import compose_recipe
from hierloco.pipeline.errors import ConfigError
from tests.recipes.stage_plans import changed, plan

ROOT = Path(__file__).resolve().parents[2]
no_gpu = pytest.mark.skipif(torch.cuda.is_available(), reason="auto resolves to cuda on this machine")




@no_gpu
@pytest.mark.parametrize("method", ["lat", "lib", "ik", "ik_plain", "sac", "sac_sac"])
def test_the_records_of_every_method_keep_their_keys_under_device_auto(method):
    """A committed record of the comparison (made when ``device: cpu`` was the default) matches the keys planned
    today, with ``device: auto`` and the new options at their defaults, planned as a study places the job (on the
    CPU) and as the recipe alone would (the default device)."""
    where = ROOT / "results" / "compare_full" / "records" / method / "paper" / "a1_seed0"
    record = records.read(where)
    recipe = {"ik_plain": "ik"}.get(method, method)
    for device in (None, "cpu"):
        job = studies.Job(recipe, f"outputs/{method}/paper/a1_seed0", record["signature"]["overrides"], device=device)
        assert records.matches(record, job.signature(), studies.planned_stages(job)), (method, device)


@no_gpu
def test_auto_resolves_to_the_cpu_here_and_keys_record_it():
    auto, cpu = plan("lat"), plan("lat", "device=cpu")
    assert {name: stage.digest for name, stage in auto.items()} == {name: stage.digest for name, stage in cpu.items()}
    assert auto["gait_policy"].params["device"] == "cpu"
    assert auto["evaluation_normal_goal_reaching"].params["device"] == "cpu"
    with pytest.raises(ConfigError, match="device=cuda asked but no GPU is available"):
        plan("lat", "device=cuda")
    with pytest.raises(ConfigError, match="device must be auto, cpu, cuda or cuda:<index>, got 'gpu'"):
        plan("lat", "device=gpu")


def test_the_scoring_options_are_keyed_only_when_not_at_their_defaults():
    evaluations = {name for name in plan("lat") if name.startswith("evaluation_")}
    for override in ("planner.compile=false", "planner.precision=fp32", "sac.compile=false"):
        recipe = "sac" if override.startswith("sac") else "lat"
        assert changed(recipe, override) == set(), override
    assert changed("lat", "planner.compile=true") == evaluations
    assert changed("lat", "planner.precision=bf16") == evaluations
    assert plan("lat", "planner.precision=bf16")["evaluation_normal_goal_reaching"].params["planner"][
        "precision"] == "bf16"
    sac = changed("sac", "sac.compile=true")
    assert sac and all(name.startswith(("sac_", "evaluation_")) for name in sac)
    lib = changed("lib", "planner.compile=true")
    assert lib and all(name.startswith("evaluation_") for name in lib)


def test_bad_scoring_options_are_named():
    for override, said in (("planner.precision=fp16", "unknown precision 'fp16' (planner.precision: choose from "
                                                      "fp32, tf32, bf16)"),
                           ("planner.compile=7", "planner.compile must be true or false, got 7"),
                           ("sac.compile=yes", "sac.compile must be true or false, got 'yes'")):
        with pytest.raises(ConfigError, match=said.replace("(", r"\(").replace(")", r"\)")):
            plan("sac" if override.startswith("sac") else "lat", override)


def test_the_sac_sac_low_level_keys_a_device_only_off_the_cpu():
    from hierloco.recipes.sac_sac.utils import low_level_device

    cfg = compose_recipe("sac_sac", ["preset=tiny"])
    with open_dict(cfg):
        cfg.device = "cpu"
        assert low_level_device(cfg) == {}
        cfg.device = "cuda"
        assert low_level_device(cfg) == {"device": "cuda"}
    if not torch.cuda.is_available():
        assert "device" not in plan("sac_sac")["sac_low_level"].params


def test_a_study_places_its_jobs():
    """A job's device goes before its own overrides (its own ``device=`` wins) and stays out of its signature
    (records keep matching); a GPU share is checked and sets how many jobs run at once."""
    job = studies.Job("lat", "outputs/x", ["preset=tiny", "seed=1"], cores=2, device="cuda")
    command = job.command()
    assert command[-3:] == ["device=cuda", "preset=tiny", "seed=1"] and job.signature() == {
        "method": "lat", "overrides": ["preset=tiny", "seed=1"]}
    assert studies.Job("lat", "outputs/x", []).runtime_overrides() == []
    assert studies.machine_slots(4, 0.25, cores=16, gpus=1) == (4, "16 cores, 1 GPU; 4 cores and 0.25 GPU a job")
    assert studies.machine_slots(2, 0.25, cores=16, gpus=1)[0] == 4  # the GPU shares bound it, not the cores
    assert studies.machine_slots(1, 0, cores=2, gpus=0) == (2, "2 cores, 0 GPUs; 1 core a job")
    assert studies.machine_slots(1, 0.5, cores=2, gpus=0)[0] == 0
    assert studies.check_gpus_per_job(0.25) == 0.25 and studies.check_gpus_per_job(None) == 0.0
    for bad in (-0.5, 1.5, "a", True):
        with pytest.raises(ConfigError, match="ray.gpus_per_job must be"):
            studies.check_gpus_per_job(bad)
    with pytest.raises(ConfigError, match="ask for device=cuda .* but ray.gpus_per_job is 0"):
        studies.check_gpus_per_job(0, [studies.Job("lat", "outputs/x", ["device=cuda"])])


def test_every_study_has_a_gpu_share_option():
    for study in ("compare", "ablations", "adverse", "hardware", "ensemble", "tune"):
        from hydra import compose, initialize_config_dir
        from hydra.core.global_hydra import GlobalHydra

        GlobalHydra.instance().clear()
        with initialize_config_dir(config_dir=str(ROOT / "recipes" / study), version_base=None):
            cfg = compose(config_name="config")
        GlobalHydra.instance().clear()
        assert OmegaConf.select(cfg, "ray.gpus_per_job") == 0 and OmegaConf.select(cfg, "ray.cores_per_job") == 1


@pytest.mark.parametrize("recipe", ["lat", "sac", "sac_sac"])
def test_a_run_evaluated_on_another_device_keeps_its_trained_stages(recipe):
    """``recipes/evaluate.py run_dir=... device=cuda`` on a run trained on the CPU: the trained stages keep their keys
    (``trained_device``, set by the evaluation), the evaluations record the device they run on. Planned without the
    device check, which needs the GPU."""
    from hierloco.envs.robots import get_robot

    utils = importlib.import_module(f"hierloco.recipes.{recipe}.utils")
    cpu = plan(recipe, "device=cpu")
    cfg = compose_recipe(recipe, ["preset=tiny", "device=cuda", "+trained_device=cpu"])
    elsewhere = {stage.name: stage for stage in utils.plan(cfg, get_robot("a1")).stages()}
    changed = {name for name in cpu if cpu[name].digest != elsewhere[name].digest}
    trained = {name for name, stage in cpu.items() if stage.trains}
    assert not changed & trained
    if recipe == "lat":
        assert changed == {name for name in cpu if name.startswith("evaluation_")}
        assert elsewhere["evaluation_normal_goal_reaching"].params["device"] == "cuda"
