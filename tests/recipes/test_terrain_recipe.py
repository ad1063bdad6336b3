"""Terrain, pushes and randomised dynamics in the recipes and the terrain study (``docs/terrain.md``): flat ground keeps
every key and a non-flat world changes exactly the keys of the stages it affects; a tiny trained LAT run evaluated
on mild rough ground still reaches most goals, a push is survived or counted as a fall, a user's terrain file works
and a broken one is one line; the terrain study runs end to end on one robot and one method, training nothing."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.recipes.stage_plans import changed, plan
from tests.runner import run_in_process, run_subprocess




def evaluations(stages) -> set[str]:
    return {name for name in stages if name.startswith("evaluation_")}


def heightmap(path: Path, waves: float = 2.0) -> Path:
    """A 32 x 32 PNG of gentle bumps (white = the terrain's height_m)."""
    from matplotlib import pyplot as plt

    x, y = np.meshgrid(np.linspace(0, 2 * waves * np.pi, 32), np.linspace(0, 2 * waves * np.pi, 32))
    plt.imsave(path, 0.5 + 0.5 * np.sin(x) * np.cos(y), cmap="gray", vmin=0, vmax=1)
    return path


# ---------------------------------------------------------------------------------------------------- keys
def test_flat_ground_nominal_dynamics_and_no_pushes_keep_every_key():
    for recipe in ("lat", "sac", "sac_sac"):
        assert not changed(recipe, "terrain=flat", "randomization=nominal", "eval.terrain=flat",
                           "eval.pushes={magnitude_mps: 0.0}", "eval.randomization={}"), recipe


def test_a_non_flat_world_changes_the_keys_of_the_stages_it_affects():
    lat = plan("lat")
    data = {"dynamics_data_normal", "dynamics_model_normal"}
    # the run's terrain and randomised dynamics: its dynamics data (and model) and its evaluations, not its experts
    assert changed("lat", "terrain=rough", "terrain.difficulty=0.2") == data | evaluations(lat)
    assert changed("lat", "randomization=standard") == data | evaluations(lat)
    assert changed("lib", "terrain=stairs") == data | evaluations(plan("lib"))
    # the evaluations' own world: the evaluations alone
    assert changed("lat", "eval.terrain={name: rough, difficulty: 0.2}") == evaluations(lat)
    assert changed("lat", "eval.pushes={magnitude_mps: 0.5}") == evaluations(lat)
    assert changed("lat", "eval.randomization=standard") == evaluations(lat)
    # a task's own world: that task's evaluation alone
    assert changed("lat", "+eval.tasks.goal_reaching.terrain={name: blocks, difficulty: 0.3}") == {
        "evaluation_normal_goal_reaching"}
    keyed = plan("lat", "terrain=rough", "terrain.difficulty=0.2", "seed=3")
    assert keyed["dynamics_data_normal"].params["terrain"] == {"name": "rough", "difficulty": 0.2, "seed": 3}
    assert keyed["evaluation_normal_goal_reaching"].params["task"] == plan("lat")[
        "evaluation_normal_goal_reaching"].params["task"]  # the task's options without its world
    # SAC: its agents (trained in the run's world) and their evaluations; SAC-SAC also its low level
    sac = plan("sac")
    agents = {name for name in sac if name.startswith("sac_")}
    assert changed("sac", "terrain=slope") == agents | evaluations(sac)
    assert changed("sac", "eval.terrain=slope") == evaluations(sac)
    sac_sac = plan("sac_sac")
    assert changed("sac_sac", "randomization=standard") == set(sac_sac)  # the low level is trained first


def test_a_user_terrain_file_is_keyed_by_its_bytes_and_a_broken_one_is_one_line(tmp_path):
    image = heightmap(tmp_path / "ground.png")
    first = plan("lat", "terrain=heightmap", f"terrain.path={image}")["dynamics_data_normal"]
    assert first.params["terrain"]["sha256"] and "path" not in first.params["terrain"]
    moved = shutil.copy(image, tmp_path / "moved.png")
    assert plan("lat", "terrain=heightmap", f"terrain.path={moved}")["dynamics_data_normal"].digest == first.digest
    heightmap(image, waves=3.0)  # the same file edited: another ground
    assert plan("lat", "terrain=heightmap", f"terrain.path={image}")["dynamics_data_normal"].digest != first.digest
    broken = tmp_path / "scene.xml"
    broken.write_text("<mujoco><worldbody><geom type='plane' size='1 1 0.1'</worldbody></mujoco>")
    for overrides, said in ((["terrain=mjcf", f"terrain.path={broken}"], "cannot load"),
                            (["terrain=heightmap", f"terrain.path={tmp_path / 'missing.png'}"], "no terrain file"),
                            (["terrain=rough", "terrain.difficulty=1.5"], "difficulty must be in [0.0, 1.0]"),
                            (["+eval.pushes.magnitude=1.0"], "eval.pushes has no option 'magnitude'")):
        run_dir = tmp_path / "run"
        result = run_in_process("lat", "preset=tiny", f"run_dir={run_dir}", *overrides)
        assert result.returncode == 2, result.stderr[-2000:]
        assert len(result.lines) == 1 and result.lines[0].startswith("error:") and said in result.lines[0]
        assert not run_dir.exists()  # before any work


# ---------------------------------------------------------------------------------------------------- evaluation
@pytest.fixture(scope="module")
def off_the_floor(tiny_lat_run, tmp_path_factory):
    """The tiny LAT run evaluated (training nothing) on mild rough ground (every task), with a pushed velocity-tracking
    task on flat ground, a goal-reaching task on a user's heightfield image and a navigation arena on blocks."""
    tmp = tmp_path_factory.mktemp("terrain")
    run_dir = tmp / "run"
    shutil.copytree(tiny_lat_run, run_dir, ignore=shutil.ignore_patterns(".lock"))
    image = heightmap(tmp / "ground.png")
    pushed = ("pushed: {task: velocity_tracking, velocities: [[0.0, 0.2], [0.2, 0.0], [0.0, -0.2], [-0.2, 0.0]], "
              "steps_per_target: 1, rounds: 1, terrain: flat, pushes: {magnitude_mps: 1.0, interval_s: [1.0, 1.5]}}")
    on_image = (f"on_image: {{task: goal_reaching, radius: 0.6, num_steps: 4, terrain: {{name: heightmap, "
                f"path: '{image}', height_m: 0.03}}}}")
    arena = ("arena_on_blocks: {task: navigation, arena_seed: 0, num_obstacles: 3, speed: 1.0, extra_steps: 1, "
             "terrain: {name: blocks, difficulty: 0.3}}")
    extra = "{" + ", ".join((pushed, on_image, arena)) + "}"
    builds = json.loads((run_dir / "builds.json").read_text())
    result = run_in_process("evaluate.py", f"run_dir={run_dir}", "name=rough", "progress=false", "eval.videos=[]",
                            "eval.figures=false", "eval.terrain={name: rough, difficulty: 0.2}",
                            "~eval.generalization", f"+eval.generalization={extra}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    trained = {name for name in builds if not name.startswith("evaluation_")}
    after = json.loads((run_dir / "builds.json").read_text())
    assert {name: after[name] for name in trained} == {name: builds[name] for name in trained}  # nothing trained
    rows = list(csv.DictReader((run_dir / "evaluations" / "rough" / "episodes.csv").open()))
    from hierloco.results import TaskEvaluation

    found = {}
    for path in (run_dir / "evaluation" / "normal").glob("*.npz"):
        evaluation = TaskEvaluation.load(path)
        if "world" in evaluation.metadata:
            found[evaluation.metadata["task"]] = evaluation
    return {"rows": rows, "evaluations": found}


def test_a_tiny_lat_run_on_mild_rough_ground_still_reaches_most_goals(off_the_floor):
    goal = off_the_floor["evaluations"]["goal_reaching"]
    assert goal.metadata["terrain"] == {"name": "rough", "difficulty": 0.2, "seed": 0}
    assert goal.metadata["world"] == "rough (difficulty=0.2, seed=0)"
    reached = [row["success"] for row in goal.rows]
    assert len(reached) == 8 and sum(reached) >= 5, reached  # most of the 8 goals 0.6 m away
    assert goal.metrics["fall_rate"] == 0.0 and all(row["fell"] == 0.0 for row in goal.rows)
    assert {r["task"] for r in off_the_floor["rows"]} >= {"goal_reaching", "velocity_tracking", "trajectory_tracking"}


def test_a_push_at_the_tiny_preset_is_survived_or_counted_as_a_fall(off_the_floor):
    pushed = off_the_floor["evaluations"]["pushed"]
    assert pushed.metadata["pushes"]["magnitude_mps"] == 1.0 and "terrain" not in pushed.metadata
    (row,) = pushed.rows
    assert row["pushes"] >= 1  # the first push comes 1 to 1.5 s into a 4 s episode
    assert row["push_falls"] == row["fell"]  # it fell after a push (and then took no more), or survived them all
    assert row["pushes_recovered"] <= row["pushes"] - row["push_falls"]
    assert pushed.metrics["push_fall_rate"] == row["push_falls"] / row["pushes"]
    if row["pushes_recovered"]:
        assert 0.0 <= row["recovery_s"] < 4.0
    else:
        assert np.isnan(row["recovery_s"])


def test_a_user_heightfield_and_a_navigation_arena_on_terrain_are_evaluated(off_the_floor):
    on_image = off_the_floor["evaluations"]["on_image"]
    assert on_image.metadata["terrain"]["name"] == "heightmap" and len(on_image.metadata["terrain"]["sha256"]) == 64
    assert len(on_image.rows) == 8 and np.all(np.isfinite([r["normalized_cost"] for r in on_image.rows]))
    arena = off_the_floor["evaluations"]["arena_on_blocks"]
    assert arena.metadata["terrain"] == {"name": "blocks", "difficulty": 0.3, "seed": 0}
    (row,) = arena.rows
    assert np.isfinite(row["clearance"]) and row["fell"] in (0.0, 1.0)


# ---------------------------------------------------------------------------------------------------- the study
def trained_runs(tiny_lat_run, tmp_path: Path) -> str:
    target = tmp_path / "trained" / "lat" / "a1_seed0"
    shutil.copytree(tiny_lat_run, target, ignore=shutil.ignore_patterns(".lock", "evaluations"))
    return str(tmp_path / "trained" / "{method}" / "{robot}_seed{seed}")


def test_the_terrain_study_tiny_runs_end_to_end_training_nothing(tiny_lat_run, tmp_path):
    out, records, runs = tmp_path / "out", tmp_path / "records", tmp_path / "runs"
    arguments = ["preset=tiny", "robots=[a1]", "seeds=[0]", "methods=[lat]", "terrains=[stairs]", "levels=[0.0,0.5]",
                 "tasks=[goal_reaching]", "pushes.magnitudes_mps=[0.5,3.0]",
                 f"trained_runs='{trained_runs(tiny_lat_run, tmp_path)}'", f"runs_dir={runs}", f"out_dir={out}",
                 f"records={records}"]
    result = run_subprocess("terrain", *arguments, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = list(csv.DictReader((out / "terrain.csv").open()))
    stairs = [r for r in rows if r["terrain"] == "stairs"]
    assert {(r["task"], r["level"]) for r in stairs} == {("goal_reaching_stairs000", "0.0"),
                                                        ("goal_reaching_stairs050", "0.5")}
    assert all(r["fell"] in ("0.0", "1.0") and r["method"] == "lat" for r in stairs) and len(stairs) == 16
    pushed = [r for r in rows if float(r["push_mps"]) > 0]
    assert {r["task"] for r in pushed} == {"velocity_tracking_push050", "velocity_tracking_push300"}
    table = (out / "terrain.md").read_text()
    assert "| a1 | lat | stairs | 0.5 | 10 cm steps |" in table and "## Flat ground" in table
    assert "largest push survived" in (out / "pushes.md").read_text()
    for figure in ("success_a1.png", "pushes_a1.png"):
        assert (out / figure).read_bytes()[:4] == b"\x89PNG"
    assert (out / "terrains.png").is_file() or "no terrains.png: " in result.stdout  # rendered where it can be
    log = (runs / "lat" / "a1_seed0.log").read_text()
    for stage in ("experts", "gait_policy", "dynamics_data_normal", "dynamics_model_normal"):
        assert f"stage {stage}: cached" in log and f"stage {stage}: building" not in log
    assert len(list(records.rglob("record.json"))) == 1  # a study in parts: the job's record


def test_the_terrain_study_refuses_bad_configs_and_missing_trained_runs_before_any_work(tmp_path):
    runs = tmp_path / "runs"
    bad = run_in_process("terrain", "preset=tiny", "robots=[a1]", "terrains=[heightmap,stairs]", "levels=[0.5,1.5]",
                         f"runs_dir={runs}")
    assert bad.returncode == 2 and len(bad.lines) == 1 and bad.lines[0].startswith("error:"), bad.stderr
    assert "'heightmap' is not a terrain with a difficulty" in bad.lines[0] and "levels: 1.5" in bad.lines[0]
    missing = run_in_process("terrain", "preset=tiny", "robots=[a1]", "seeds=[0]", "methods=[lat]",
                             "terrains=[rough]", "levels=[0.5]", "pushes.magnitudes_mps=[]",
                             f"trained_runs='{tmp_path / 'none' / '{method}' / '{robot}_seed{seed}'}'",
                             f"runs_dir={runs}")
    assert missing.returncode == 2 and len(missing.lines) == 1, missing.stderr
    assert "the terrain study trains nothing" in missing.lines[0] and "no finished experts" in missing.lines[0]
    assert not runs.exists()


# ---------------------------------------------------------------------------------------------------- LAT made for terrain
def test_lat_made_for_terrain_keys_exactly_the_stages_it_changes():
    """The experts' foot lift and ground change every stage (all stand on the experts), a CoM model that reads the
    body state changes the model and the evaluations; their defaults change nothing."""
    lat = plan("lat")
    assert not changed("lat", "experts.swing_height_m=null", "dynamics.body_state=false")
    assert changed("lat", "experts.swing_height_m=0.1") == set(lat)
    assert changed("lat", "dynamics.body_state=true") == {"dynamics_model_normal"} | evaluations(lat)
    keyed = plan("lat", "experts.swing_height_m=0.1", "dynamics.body_state=true")
    assert keyed["experts"].params["swing_height_m"] == 0.1
    assert keyed["dynamics_model_normal"].params["body_state"] is True


@pytest.mark.parametrize("override, said", [
    ("experts.swing_height_m=0.5", "experts.swing_height_m must be a foot lift in m"),
    ("dynamics.body_state=sometimes", "dynamics.body_state must be true or false"),
])
def test_lat_made_for_terrain_refuses_bad_options_in_one_line(tmp_path, override, said):
    run_dir = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", f"run_dir={run_dir}", override)
    assert result.returncode == 2 and len(result.lines) == 1 and said in result.lines[0], result.lines
    assert not run_dir.exists()


def test_a_tiny_lat_run_made_for_terrain_plans_with_the_body_state_on_mild_rough_ground(tmp_path):
    """Experts with a higher foot lift, a CoM model that reads roll, pitch and height:
    trained and evaluated on mild rough ground, it plans with the body state the env measures, reaches goals and
    does not fall; the exporter refuses the model in one line rather than export it without its inputs."""
    from hierloco.trained import load_run

    run_dir = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", f"run_dir={run_dir}", "progress=false", "eval.videos=[]",
                            "eval.figures=false", "logger.backends=[csv]", "experts.swing_height_m=0.1",
                            "dynamics.body_state=true",
                            "terrain=rough", "terrain.difficulty=0.2")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    run = load_run(run_dir)
    model = run.com_model("normal")
    assert model.metadata["context"] == {"body_state": 3}
    assert model.model.action_dim == run.low_level().action_dim + 3
    assert run.world_model().measured_keys[-1] == "body_state"
    # the trained model's prediction depends on the pitch it is given
    world = run.world_model()
    start = world.initial_state(torch.zeros(2, 5)).set("action", torch.full((2, run.low_level().action_dim), 0.5))
    start["body_state"] = torch.tensor([[0.0, 0.0, 0.27], [0.0, 0.3, 0.15]])
    moved = world.step(start)["next", "com_state"]
    assert not torch.allclose(moved[0], moved[1])
    rows = list(csv.DictReader((run_dir / "episodes.csv").open()))
    goals = [r for r in rows if r["task"] == "goal_reaching"]
    costs = [float(r["normalized_cost"]) for r in goals]
    # it walks towards the goals at this tiny scale (8 experts, 1,000 transitions): well below standing still's cost
    # on average (0.67 when written), some goals reached (3 of 8 then), no fall
    assert len(goals) == 8 and np.mean(costs) < 0.85 and sum(float(r["success"]) for r in goals) >= 2, costs
    from hierloco.results import TaskEvaluation

    evaluated = [TaskEvaluation.load(path) for path in (run_dir / "evaluation" / "normal").glob("goal_reaching-*.npz")]
    assert len(evaluated) == 1 and evaluated[0].metadata["terrain"]["name"] == "rough"
    assert evaluated[0].metrics["fall_rate"] == 0.0
    from hierloco.exporting import export_run
    from hierloco.io import ArtifactError

    with pytest.raises(ArtifactError, match="does not carry such a model yet"):
        export_run(run_dir, tmp_path / "export")
    assert not (tmp_path / "export").exists()


def test_the_terrain_study_judges_each_lat_variant_against_plain_lat_paired_by_seed():
    """``variants.md``: a variant of the ``lat`` recipe against plain LAT at each terrain and difficulty, by the
    paired test over seeds; other methods are not variants of LAT; the small preset's null generalisation tasks are
    set, not deleted (the jobs' overrides compose)."""
    from hierloco.pipeline.config import compose_recipe
    from hierloco.recipes.terrain import run as terrain
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(Path(terrain.__file__).parent), version_base=None):
        cfg = compose("config", overrides=["preset=small", "methods=[lat,lat_body,lat_clearance,lib]"])
    assert terrain.lat_variants(cfg) == ["lat_body", "lat_clearance"]
    rows = []
    for seed, base in enumerate([0.50, 0.62, 0.41]):
        for method, cost in (("lat", base), ("lat_body", base - 0.15), ("lat_clearance", base + 0.002)):
            rows += [{"method": method, "robot": "a1", "setting": "normal", "task": "goal_reaching_rough075",
                      "seed": seed, "episode": e, "normalized_cost": cost, "push_mps": 0.0} for e in range(2)]
    text = terrain.variants_markdown(rows, cfg, title="small preset")
    line = {cells.split(" | ")[3]: cells for cells in text.splitlines() if cells.startswith("| a1 | normal | ")}
    assert line["lat_body"].split(" | ")[4].startswith("holds")            # 0.15 lower at every seed
    assert line["lat_clearance"].split(" | ")[5].startswith("holds")       # within the margin at every seed
    assert "`lat_body`: dynamics.body_state=true" in text
    jobs = terrain.generalization_overrides("lat", "small", {"x_rough050": {"task": "goal_reaching"}})
    assert jobs == ["eval.generalization={x_rough050: {task: goal_reaching}}"]
    assert compose_recipe("lat", ["preset=small", *jobs]).eval.generalization.x_rough050.task == "goal_reaching"
    assert terrain.generalization_overrides("lat", "paper", {"x": {"task": "goal_reaching"}})[0] == "~eval.generalization"


def test_a_variant_that_changes_only_its_evaluations_starts_from_plain_lat_s_trained_runs():
    """``lat_replan`` (re-planning at 5 Hz on A1) is trained as plain LAT: its jobs reuse plain LAT's trained runs
    (``trained_as``) and its plan differs from plain LAT's in the evaluations alone."""
    from hierloco.envs.robots import get_robot
    from hierloco.recipes.terrain import run as terrain
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(Path(terrain.__file__).parent), version_base=None):
        cfg = compose("config", overrides=["preset=small", "methods=[lat,lat_replan]", "seeds=[0]"])
    plain, replan = terrain.jobs(cfg, [get_robot("a1")])
    assert replan.reuse_from == plain.reuse_from == "outputs/lat/small/a1_seed0"
    assert replan.run_dir.endswith("lat_replan/a1_seed0") and "eval.replan_steps=20" in replan.overrides
    assert "lat_replan" in terrain.lat_variants(cfg)
