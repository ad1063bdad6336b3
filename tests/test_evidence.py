"""hierloco.evidence: job records read into runs, labelled from their signatures and stage keys, replicates pooled."""

import hashlib
import json
import math

import pytest

from hierloco.evidence import (adopt_configs, distinct, job_compute, read_findings, read_records, read_table,
                               replicates, rows_of, seed_values, select)

# the variants the runs below are of, as a study's config declares them (recipes/compare/config.yaml)
VARIANTS = {"ik_plain": {"recipe": "ik", "overrides": ["controller.footstep_law=plain"]},
            "sac_sac_2x512": {"recipe": "sac_sac", "overrides": ["low_level.hidden=512"]}}
COLUMNS = "method,robot,setting,task,seed,episode,normalized_cost,success,final_error,path_distance,steps_to_goal\n"


def write_record(root, relative, *, method, robot, seed, costs, overrides=(), keys=None, factors=None, cpu="",
                 seconds=60.0, recipe_method=None, fields=None, report=None):
    """A verified job record (``record.json``, :mod:`hierloco.pipeline.records`) under ``root/relative``: ``costs``
    maps (setting, task) to episode costs; ``keys`` maps (setting, task) to the evaluation key's hash (default: one
    per method, robot, seed, setting, task and overrides); ``factors`` the stage-key sizes (latent_dim, num_experts,
    num_transitions, high_level_frames); ``fields`` maps (setting, task) to other columns' per-episode values
    (``{"final_error": [0.03]}``); ``report`` maps a stage of its own (``latent_continuity``) to what it reported."""
    from hierloco.pipeline import records
    from hierloco.pipeline.rundir import StageSpec

    record = root / relative
    signature = {"method": recipe_method or method, "overrides": [f"robot={robot}", f"seed={seed}", *overrides]}
    rows, builds, specs = [], {}, []
    for (setting, task), episodes in costs.items():
        for e, c in enumerate(episodes):
            rows.append({"method": recipe_method or method, "robot": robot, "setting": setting, "task": task,
                         "seed": seed, "episode": e, "normalized_cost": c, "success": float("nan"),
                         "final_error": 0.0,
                         **{k: v[e] for k, v in (fields or {}).get((setting, task), {}).items()}})
        digest = (keys or {}).get((setting, task)) or hashlib.sha1(
            repr((method, robot, seed, setting, task, tuple(overrides))).encode()).hexdigest()[:12]
        specs.append(StageSpec(f"evaluation_{setting}_{task}", {}, f"evaluation/{setting}/{task}-{digest}.npz"))
        builds[f"evaluation_{setting}_{task}"] = {"seconds": seconds / max(len(costs), 1), "threads": 1,
                                                  **({"cpu": cpu} if cpu else {})}
    factors = factors or {}
    if "latent_dim" in factors:
        specs.append(StageSpec("gait_policy", {"params": {"latent_dim": factors["latent_dim"]}}, "gait_policy.pt"))
    if "num_experts" in factors:
        specs.append(StageSpec("experts", {"params": {"num_experts": factors["num_experts"]}}, "experts.npz"))
    if "high_level_frames" in factors:
        specs += [StageSpec(f"sac_{task}", {"params": {"total_frames": factors["high_level_frames"]}}, f"sac_{task}.pt")
                  for task in sorted({t for _, t in costs})]
    for setting in {s for s, _ in costs}:
        if "num_transitions" in factors:
            specs.append(StageSpec(f"dynamics_data_{setting}", {"params": {"num_transitions": factors["num_transitions"]}},
                                   f"dynamics_data_{setting}.npz"))
    specs += [StageSpec(name, {"params": {"seed": seed}}, f"{name}.json") for name in (report or {})]
    records.save(records.make_record(signature, specs, rows=rows, builds=builds, seconds=seconds, report=report),
                 record)
    return record


def test_records_are_labelled_from_their_signatures_and_stage_keys(tmp_path):
    write_record(tmp_path, "ik_plain/paper/daisy_seed1", method="ik_plain", recipe_method="ik", robot="daisy", seed=1,
                 overrides=["controller.footstep_law=plain", "robot_profile=stiff", "progress=false"],
                 costs={("legs_disabled", "velocity_tracking"): [0.9],
                        ("normal", "goal_reaching"): [0.1, float("nan")]},
                 keys={("legs_disabled", "velocity_tracking"): "aaaaaaaaaaaa"}, factors={"num_transitions": 2000},
                 cpu="Intel", seconds=120.0)
    runs = read_records(tmp_path, folder="study", variants=VARIANTS)
    assert {(r.method, r.profile, r.setting, r.task) for r in runs} == {
        ("ik_plain", "stiff", "legs_disabled", "velocity_tracking"), ("ik_plain", "stiff", "normal", "goal_reaching")}
    damaged = select(runs, setting="legs_disabled")[0]
    assert (damaged.config, damaged.cpu, damaged.folder, damaged.seed) == ("aaaaaaaaaaaa", "Intel", "study", 1)
    assert damaged.factor("num_transitions") == 2000 and damaged.minutes == pytest.approx(2.0)
    assert damaged.options == ()  # the variant's override and bookkeeping are not options
    [plain] = {(r.method, r.options) for r in read_records(tmp_path)}   # no variants given: the recipe, overridden
    assert plain == ("ik", ("controller.footstep_law=plain",))
    goals = select(runs, task="goal_reaching")[0]
    assert goals.cost == pytest.approx(0.55)  # a fallen robot's NaN counts as 1
    assert job_compute(damaged.record) == (pytest.approx(2.0), 1, "Intel")
    assert math.isnan(job_compute(tmp_path / "nothing")[0])


def test_a_high_levels_budget_and_the_2x512_sac_sac_are_read_from_the_record(tmp_path):
    """SAC's steps per task come from its task's stage key (the sample-efficiency study varies them); SAC-SAC with
    its low level at 2 x 512 is its own method, never a replicate of the 2 x 256 runs."""
    costs = {("normal", "goal_reaching"): [0.2], ("normal", "velocity_tracking"): [0.4]}
    write_record(tmp_path, "sac/a1_seed0", method="sac", robot="a1", seed=0, costs=costs,
                 factors={"high_level_frames": 2000}, overrides=["sac.total_frames=2000"])
    write_record(tmp_path, "sac_sac/a1_seed0", method="sac_sac", robot="a1", seed=0, costs=costs,
                 factors={"high_level_frames": 10000})
    write_record(tmp_path, "sac_sac_2x512/a1_seed0", method="sac_sac", robot="a1", seed=0, costs=costs,
                 factors={"high_level_frames": 10000}, overrides=["low_level.hidden=512"])
    runs = read_records(tmp_path, variants=VARIANTS)
    assert {(r.method, r.task, r.factor("high_level_frames")) for r in runs} == {
        (m, t, frames) for m, frames in (("sac", 2000), ("sac_sac", 10000), ("sac_sac_2x512", 10000))
        for t in ("goal_reaching", "velocity_tracking")}
    assert {r.options for r in runs if r.method == "sac_sac_2x512"} == {()}  # the variant's override is its name


def test_seed_values_pool_a_seeds_runs_and_count_a_repeated_run_once(tmp_path):
    key = {("legs_disabled", "velocity_tracking"): "cccccccccccc"}
    for folder, seed, cost in (("a", 0, 0.51), ("a", 1, 1.01), ("b", 1, 0.80), ("b", 0, 0.51)):
        write_record(tmp_path / folder, f"ik/paper/daisy_seed{seed}", method="ik", robot="daisy", seed=seed,
                     costs={("legs_disabled", "velocity_tracking"): [cost]},
                     keys={k: f"{v[:-1]}{seed}" for k, v in key.items()})
    runs = read_records(tmp_path / "a", folder="a") + read_records(tmp_path / "b", folder="b")
    seeds, values, counts = seed_values(runs)
    assert seeds.tolist() == [0, 1] and values.tolist() == pytest.approx([0.51, 0.905]) and counts.tolist() == [1, 2]
    assert len(distinct(runs)) == 3  # seed 0's run is in both folders, to the last digit
    [group] = replicates(runs)
    assert sorted(r.cost for r in group) == [0.80, 1.01] and {r.folder for r in group} == {"a", "b"}
    rows = rows_of(runs)
    assert len(rows) == 3 and len({r["run"] for r in rows if r["seed"] == 1}) == 2


def test_a_table_adopts_the_configuration_of_the_records_it_was_made_like(tmp_path):
    write_record(tmp_path / "records", "lat/paper/a1_seed0", method="lat", robot="a1", seed=0,
                 costs={("normal", "goal_reaching"): [0.10, 0.12]}, keys={("normal", "goal_reaching"): "dddddddddddd"},
                 factors={"latent_dim": 3, "num_experts": 50})
    table = tmp_path / "comparison.csv"
    table.write_text(COLUMNS + "lat,a1,normal,goal_reaching,0,0,0.2,1.0,0.0,,\nlat,a1,normal,goal_reaching,0,1,0.3,"
                     "1.0,0.0,,\nlib,a1,normal,goal_reaching,0,0,0.5,1.0,0.0,,\n")
    runs = read_table(table, folder="old")
    assert [r.config for r in runs] == ["", ""] and runs[0].cost == pytest.approx(0.25)
    adopted = adopt_configs(runs, read_records(tmp_path / "records"))
    lat = select(adopted, method="lat")[0]
    assert lat.config == "dddddddddddd" and lat.factor("latent_dim") == 3
    assert select(adopted, method="lib")[0].config == ""  # nothing to adopt
    assert len(replicates(read_records(tmp_path / "records") + adopted)) == 1


def test_findings_are_read(tmp_path):
    from hierloco.pipeline import records

    place = tmp_path / "lat" / "paper" / "a1_seed2_rear_limp"
    signature = {"method": "lat", "overrides": ["robot=a1", "seed=2", "robot_profile=own", "settings=[rear_limp]"]}
    finding = {"stage": "dynamics_data_rear_limp", "key": {},
               "error": "a1: 500 of 500 random actions ended in a fall\nmore"}
    records.save(records.make_record(signature, [], finding=finding), place)
    [found] = read_findings(tmp_path)
    assert (found["method"], found["robot"], found["seed"], found["settings"]) == ("lat", "a1", 2, "[rear_limp]")
    assert found["error"] == "a1: 500 of 500 random actions ended in a fall"
    assert read_records(tmp_path) == []


def test_the_docstring_examples_run():
    import doctest

    import hierloco.evidence

    assert doctest.testmod(hierloco.evidence).failed == 0
