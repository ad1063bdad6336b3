"""LAT with experts over several gaits (``experts.gaits``): one gait policy and latent space over all of them."""

from pathlib import Path

import numpy as np
import pytest

from hierloco.components.expert_library import ExpertLibrary
from hierloco.results import read_csv
from hierloco.recipes.gaits.run import (
    action_speeds, decide_needed_gait, needed_at, needed_gait_shares, profile_markdown, segments,
)
from tests.recipes.test_device_keys import changed, plan
from tests.runner import ROOT, run_in_process, run_subprocess

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


def test_a_gait_s_own_box_is_in_the_experts_key_only_when_given():
    boxes = "experts.gait_boxes={pace: {command_low: [-0.1, -0.1, -0.2], command_high: [0.1, 0.1, 0.2]}}"
    assert "gait_boxes" not in plan("lat", GAITS)["experts"].params
    assert plan("lat", GAITS, boxes)["experts"].params["gait_boxes"]["pace"]["command_high"] == [0.1, 0.1, 0.2]
    assert changed("lat", GAITS, boxes) == changed("lat", GAITS)  # relative to the defaults: the same stages


BOX = "{command_high: [0.1, 0.1, 0.2]}"


@pytest.mark.parametrize("overrides, message", [
    ((f"experts.gait_boxes={{pace: {BOX}}}",), "set experts.gaits too"),
    ((GAITS, f"experts.gait_boxes={{gallop: {BOX}}}"), "experts.gait_boxes names 'gallop', which is not one of"),
])
def test_a_bad_gait_box_is_one_line_before_any_work(tmp_path, overrides, message):
    run = tmp_path / "run"
    result = run_in_process("lat", "preset=tiny", f"run_dir={run}", *overrides, cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert result.lines[0].startswith("error: ") and message in result.lines[0], result.lines[0]
    assert not run.exists()


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
    ("+profile.reach={task: goal_reaching}", "profile task 'reach' is a goal_reaching task"),
    ("profile.speed_profile.rounds=0", "profile task 'speed_profile': eval task 'speed_profile': rounds must be"),
    ("own_runs=runs/mlp", "own_runs must be a path holding {seed}"),
    ("+gait_boxes={gallop: {command_high: [0.1, 0.1, 0.2]}}", "gait_boxes names 'gallop', which is not one of"),
    ("+gait_boxes={pace: {command_high: [0.1, 0.1]}}", "gait_boxes.pace: command_high must be 3 finite numbers"),
    ("tag=a/b", "tag must be letters, digits and underscores"),
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
    # the speed profile: both libraries' trained runs evaluated on it alone, each action labelled
    profile = read_csv(out / "profile.csv")
    assert {r["method"] for r in profile} == {"own gait (trot)", "3 gaits"}
    assert [float(r["target_speed"]) for r in profile if r["method"] == "3 gaits"] == [0.05] * 5 + [0.15] * 5 + \
        [0.3] * 5 + [0.15] * 5 + [0.05] * 5
    assert {r["gait"] for r in profile if r["method"] == "3 gaits"} <= {"trot", "pace", "bound"}
    assert {r["gait"] for r in profile if r["method"] == "own gait (trot)"} == {""}
    assert "| 10-14 | 0.30 |" in (out / "profile.md").read_text()
    assert (out / "gait_speed_profile_profile.png").read_bytes()[:4] == b"\x89PNG"
    runs = tmp_path / "outputs" / "gaits" / "tiny"
    evaluated = {p.name.split("-")[0] for p in (runs / "a1_seed0_profile" / "evaluation" / "normal").glob("*.npz")}
    assert evaluated == {"speed_profile"}  # the profile alone, on the several-gait run's trained stages


def test_action_speeds_are_each_actions_mean_velocity_along_its_target():
    steps = 4
    # the CoM moves +y at 0.1 m/s for two 1 s actions, then +x at 0.2 m/s (paths sampled at the end of each step)
    time = np.arange(1, 3 * steps + 1) / steps
    y = np.minimum(time, 2.0) * 0.1
    x = np.maximum(time - 2.0, 0.0) * 0.2
    paths = np.stack([x, y], -1)[None]
    targets = np.array([[0.0, 0.1], [0.0, 0.3], [0.0, 0.3]])
    speeds = action_speeds(paths, targets, steps, 1.0)
    np.testing.assert_allclose(speeds, [[0.1, 0.1, 0.0]], atol=1e-12)  # the last action moves across its target


def test_the_profile_table_counts_gaits_per_target_and_where_the_switches_fall():
    targets = [0.05, 0.05, 0.3, 0.3]
    found = []
    for seed, gaits in ((0, ["trot", "trot", "bound", "bound"]), (1, ["trot", "pace", "pace", "bound"])):
        found += [{"seed": seed, "method": "3 gaits", "task": "speed_profile", "episode": 0, "action": a,
                   "target_speed": t, "speed": t / 2, "gait": g} for a, (t, g) in enumerate(zip(targets, gaits))]
        found += [{"seed": seed, "method": "own gait (trot)", "task": "speed_profile", "episode": 0, "action": a,
                   "target_speed": t, "speed": t, "gait": ""} for a, t in enumerate(targets)]
    costs = [{"robot": "a1", "setting": "normal", "task": "speed_profile", "method": m, "seed": s, "normalized_cost": c}
             for s in (0, 1) for m, c in (("3 gaits", 0.5), ("own gait (trot)", 0.2))]
    assert segments(targets) == [(0, 2), (2, 4)]
    text = profile_markdown(found, costs, {"trot": 0, "pace": 0, "bound": 0}, own="own gait (trot)",
                            several="3 gaits", title="a1")
    # per stretch: bound, pace, trot shares; switches inside; speeds with each library
    assert "| 0-1 | 0.05 | 0 % | 25 % | 75 % | 0.5 | 0.025 | 0.050 |" in text
    assert "| 2-3 | 0.30 | 75 % | 25 % | 0 % | 0.5 | 0.150 | 0.300 |" in text
    assert "Switches: 3 in all, 1 at the first action after a change of target (33 %; 33 % of" in text
    assert "| speed profile | 0.200 | 0.500 |" in text
    # per seed: share at the fastest target / at the others (bound, pace, trot)
    assert "| 0 | 100 % / 0 % | 0 % / 0 % | 0 % / 100 % |" in text
    assert "| 1 | 50 % / 0 % | 50 % / 50 % | 0 % / 50 % |" in text


def profile_found(shares_fast, shares_slow, *, needed_fast="tripod", every="ripple|tripod"):
    """Profile rows of one several-gait episode per seed: 10 actions at a target only tripod reaches, 10 at one any
    gait reaches, tripod picked in the given shares."""
    found = []
    for seed, (fast, slow) in enumerate(zip(shares_fast, shares_slow)):
        for a in range(20):
            at_fast = a < 10
            share = fast if at_fast else slow
            gait = "tripod" if (a % 10) < round(10 * share) else "ripple"
            found.append({"seed": seed, "method": "2 gaits", "task": "speed_profile", "episode": 0, "action": a,
                          "target_speed": 0.3 if at_fast else 0.05, "speed": 0.1, "gait": gait,
                          "needed": needed_fast if at_fast else every})
    return found


def test_the_gait_a_target_needs_is_the_one_whose_box_reaches_it():
    top = {"ripple": 0.141, "tripod": 0.5}
    assert needed_at(top, 0.05) == "ripple|tripod" and needed_at(top, 0.3) == "tripod" and needed_at(top, 0.6) == ""


@pytest.mark.parametrize("fast, slow, verdict", [
    ((1.0, 0.9, 1.0), (0.3, 0.4, 0.2), "holds"),             # tripod where only it reaches, either elsewhere
    ((0.5, 0.6, 0.5), (0.5, 0.5, 0.6), "does not hold"),     # the same share wherever the target is
    ((0.9, 0.3, 0.8), (0.4, 0.5, 0.3), "inconclusive"),      # within the spread of three seeds
])
def test_the_planner_picks_the_needed_gait_is_decided_over_seeds(fast, slow, verdict):
    shares = needed_gait_shares(profile_found(fast, slow), "2 gaits")
    assert [round(f, 1) for f, _ in shares.values()] == list(fast)
    assert [round(s, 1) for _, s in shares.values()] == list(slow)
    assert decide_needed_gait(shares).verdict == verdict


def test_the_profile_page_says_which_targets_need_a_gait_and_the_test():
    found = profile_found((1.0, 0.9, 1.0), (0.3, 0.4, 0.2))
    text = profile_markdown(found, [], {"ripple": 0, "tripod": 0}, own="own gait (tripod)", several="2 gaits",
                            title="daisy", top={"ripple": 0.141, "tripod": 0.5})
    assert "Each gait's fastest command (its box's corner farthest from standing): ripple 0.14 m/s, tripod 0.50" in text
    assert "Targets only some gaits reach: 0.30 m/s (tripod)." in text
    assert "| 1 | 90 % | 40 % |" in text and "**holds**" not in text
    assert 'The test "the planner picks the gait a target needs"' in text and "holds" in text.split("The test")[-1]
    # without gait boxes no target needs a gait: no such section
    assert "The gait the task needs" not in profile_markdown(found, [], {"ripple": 0, "tripod": 0},
                                                              own="own", several="2 gaits", title="daisy")
    assert needed_gait_shares([{**r, "needed": "ripple|tripod"} for r in found], "2 gaits") == {}


# --- the per-action table in a job's record (the gait claim rebuilt from records) -------------------------------------

PROFILE_GAITS = "+gaits={trot: [[FR, RL], [FL, RR]], pace: [[FR, RR], [FL, RL]]}"
SLOW_PACE = "+gait_boxes={pace: {command_low: [-0.1, -0.1, -0.2], command_high: [0.1, 0.1, 0.2]}}"


@pytest.fixture(scope="module")
def profiled(tmp_path_factory):
    """The gait study's several-gait profile job on A1 at the tiny preset (trot, and a pace that walks only up to
    0.14 m/s: the profile's 0.15 and 0.30 m/s targets need the trot), run once in this process and finished as a
    study's job leaves it; then taken by the study as it takes a finished job (:func:`studies.run_jobs`, no job to
    run: no Ray), which writes its record, and the study's ``profile.csv`` written from the result."""
    from hydra import compose, initialize_config_dir

    from hierloco.pipeline import studies
    from hierloco.recipes.gaits import run

    root = tmp_path_factory.mktemp("gait_records")
    with initialize_config_dir(config_dir=str(ROOT / "recipes" / "gaits"), version_base=None):
        cfg = compose(config_name="config", overrides=[
            "preset=tiny", "seeds=[0]", "compare_records=null", "~gaits", PROFILE_GAITS, SLOW_PACE, "tag=slow",
            f"runs_dir={root / 'outputs' / 'gaits' / 'tiny'}", f"records={root / 'records'}"])
    spec = run.check(cfg)
    _, profile_jobs = run.jobs(cfg, spec)
    job = next(j for j in profile_jobs if j.labels["method"] == "2 gaits")
    result = run_in_process("lat", f"run_dir={job.run_dir}", *job.overrides, cwd=root)
    assert result.returncode == 0, result.stderr[-3000:]
    (Path(job.run_dir) / studies.DONE).write_text(studies.done_text(job, 10.0))
    [taken] = studies.run_jobs([job], records=cfg.records)
    assert taken.ok and taken.reused and taken.actions is not None
    run.write_profile(cfg, spec, [taken], root / "out", own="own gait (trot)", several="2 gaits")
    return cfg, job, root


def test_a_gait_study_job_keeps_each_actions_gait_and_target_in_its_record(profiled):
    """The record holds, per action of the profile episode, the gait its foot contacts walked (as
    ``classify_actions`` reads them from the evaluation), its target speed and the gaits that reach it."""
    from hierloco.components.gaits import classify_actions
    from hierloco.pipeline import records
    from hierloco.recipes.gaits.run import evaluation_arrays, gait_context

    cfg, job, _ = profiled
    record = records.read(records.record_dir(cfg.records, job.run_dir))  # verified as it is read
    table = record["actions"]
    assert [(a["setting"], a["task"], a["episode"], a["action"]) for a in table] == [
        ("normal", "speed_profile", 0, a) for a in range(25)]
    assert [a["target_speed"] for a in table] == [0.05] * 5 + [0.15] * 5 + [0.3] * 5 + [0.15] * 5 + [0.05] * 5
    assert [a["needed"] for a in table] == ["pace|trot" if a["target_speed"] == 0.05 else "trot" for a in table]
    legs, steps = gait_context(job)
    contacts = evaluation_arrays(job, "speed_profile")["foot_contacts"][0]
    assert [a["gait"] for a in table] == classify_actions(contacts, steps, {"trot": [["FR", "RL"], ["FL", "RR"]],
                                                                            "pace": [["FR", "RR"], ["FL", "RL"]]}, legs)
    assert {a["gait"] for a in table} <= {"trot", "pace"}
    assert all(isinstance(a["speed"], float) for a in table)


def test_the_gait_claim_from_the_records_is_the_one_from_the_profile_table_the_run_wrote(profiled):
    """``hierloco verdicts`` reads the claim from the profile table made again from the records
    (``profile_from_records``): the same rows, and the same check, as from the ``profile.csv`` the study wrote."""
    from hierloco.recipes.gaits.claims import gait_checks
    from hierloco.recipes.gaits.run import profile_from_records

    cfg, _, root = profiled
    written = read_csv(root / "out" / "profile.csv")
    rebuilt, lacking = profile_from_records(cfg.records, robot="a1", tag="slow", preset="tiny")
    assert lacking == [] and len(rebuilt) == len(written) == 25
    assert [{k: str(v) for k, v in row.items()} for row in rebuilt] == [
        {k: str(v) for k, v in row.items()} for row in written]
    from_table = gait_checks([{**row, "robot": "a1"} for row in written])
    from_records = gait_checks([{**row, "robot": "a1"} for row in rebuilt])
    assert len(from_table) == 1 and from_records == from_table
    assert from_records[0].ours.startswith("the needed gaits' share") and "0.15 m/s: trot" in from_records[0].ours
    # another study's records (another tag, another preset) are not this one's
    assert profile_from_records(cfg.records, robot="a1", tag=None, preset="tiny") == ([], [])
    assert profile_from_records(cfg.records, robot="a1", tag="slow", preset="paper") == ([], [])


def test_a_job_is_taken_from_its_record_with_its_table_and_run_again_without_one(profiled, tmp_path, capsys):
    """Elsewhere (no run directory) the study takes the job from its record, per-action table and all; a record
    made before jobs kept the table (the same record without it: it verifies) is not taken: the job is to run."""
    import dataclasses
    import shutil

    from hierloco.pipeline import records, studies

    cfg, job, _ = profiled
    elsewhere = dataclasses.replace(job, run_dir=str(tmp_path / "gaits" / "tiny" / Path(job.run_dir).name),
                                    reuse_from=None)
    kept = records.read(records.record_dir(cfg.records, job.run_dir))
    [taken] = studies.run_jobs([dataclasses.replace(elsewhere)], records=cfg.records)
    assert taken.ok and taken.source != elsewhere.run_dir and taken.actions == kept["actions"]
    older = tmp_path / "records"
    shutil.copytree(cfg.records, older)
    where = records.record_dir(older, job.run_dir)
    records.save(records.make_record(kept["signature"], studies.planned_stages(job), rows=kept["rows"],
                                     report=kept["report"], builds=kept["builds"], seconds=kept["seconds"]), where)
    assert "actions" not in records.read(where)
    with pytest.raises(SystemExit):
        studies.run_jobs([dataclasses.replace(elsewhere)], records=str(older), dry_run=True)
    out = capsys.readouterr().out
    assert f"the record {where / records.RECORD} holds no per-action table" in out and "0 finished, 1 to run" in out
