"""The damage study on tiny settings: fault models through the study engine, their table with achievable speeds,
LAT's videos under each fault, few-sample re-learning that reuses the trained low level, and a fault nothing can be
learned in (A1 sits down on unpowered rear legs: every random action ends in a fall) reported without stopping the
others."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # a study through Ray (~85 s)
def test_adverse_tiny(tmp_path):
    out = tmp_path / "adverse"
    command = [sys.executable, str(ROOT / "recipes" / "adverse" / "run.py"), "preset=tiny", "robots=[a1]", "seeds=[0]",
               "methods=[lat]", "profiles=[own]", "faults.own=[normal,legs_disabled,rear_limp,one_leg_locked]",
               "samples=[50,500]",
               "sample_methods=[lat]", f"out_dir={out}", 'overrides=["eval.generalization=null","eval.figures=false"]',
               '+method_overrides.lat=["checks.min_expert_reach=0.3"]', f"records={tmp_path / 'records'}"]
    result = subprocess.run(command, cwd=tmp_path, env={**os.environ, "WANDB_MODE": "offline"}, capture_output=True,
                            text=True, timeout=1200)
    # A1 on unpowered rear legs is a finding about the fault, not a failed study: reported, recorded, exit 0
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "not evaluable: lat in" in result.stderr and "a1_seed0_rear_limp" in result.stderr
    assert "ended in a fall" in result.stderr
    from hierloco.pipeline import records

    failure = records.read(tmp_path / "records" / "lat" / "tiny" / "a1_seed0_rear_limp")["finding"]
    assert failure["stage"] == "dynamics_data_rear_limp" and "ended in a fall" in failure["error"]
    runs = tmp_path / "outputs" / "adverse" / "tiny"  # the few-sample runs: in runs_dir, whatever out_dir is
    rows = read_csv(out / "adverse.csv")
    assert {r["setting"] for r in rows} == {"normal", "legs_disabled", "one_leg_locked"}
    table = (out / "adverse.md").read_text()
    assert "| lat | a1 | own | one_leg_locked |" in table  # the speeds the fault leaves
    assert "## Runs that could not be evaluated" in table and "limp legs ['RR', 'RL']" in table
    # the summary: one row per fault, LAT's three task costs and goals reached, or why there are none
    assert "| a1 | own | rear_limp | not evaluable |" in table
    legs_disabled = next(line for line in table.splitlines() if line.startswith("| a1 | own | legs_disabled | "))
    velocity = [r["normalized_cost"] for r in rows if r["setting"] == "legs_disabled" and r["task"] ==
                "velocity_tracking"]
    assert legs_disabled.split(" | ")[3].startswith(f"{sum(velocity) / len(velocity):.2f} +- "), legs_disabled
    # how well LAT's low level reproduces its experts, per profile (one row per trained low level)
    low_levels = table.split("## LAT's low level: its experts reproduced in simulation")[1]
    assert low_levels.count("| a1 | own |") == 1, low_levels
    # the per-method overrides reach every run of that method
    assert all("checks.min_expert_reach=0.3" in log.read_text() for log in
               [tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0.log", runs / "samples" / "lat" / "a1_seed0_n50.log"])
    assert {p.name for p in (out / "videos").iterdir()} == {f"a1_seed0_{s}_goal_reaching.mp4" for s in
                                                            ("normal", "legs_disabled", "one_leg_locked")}
    samples = read_csv(out / "samples.csv")
    assert {r["setting"] for r in samples} == {"legs_disabled"} and {int(r["samples"]) for r in samples} == {50, 500}
    trained = tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0"
    reused = runs / "samples" / "lat" / "a1_seed0_n50"
    assert (reused / "gait_policy.pt").read_bytes() == (trained / "gait_policy.pt").read_bytes()
    assert (reused / "dynamics_data_legs_disabled.npz").read_bytes() != (
        trained / "dynamics_data_legs_disabled.npz").read_bytes()
    # at the run's own count (the tiny preset's 500) the re-learned dynamics are the run's: taken, not built again
    same = runs / "samples" / "lat" / "a1_seed0_n500"
    assert (same / "dynamics_data_legs_disabled.npz").read_bytes() == (
        trained / "dynamics_data_legs_disabled.npz").read_bytes()
    cost = lambda of: sorted(r["normalized_cost"] for r in of if r["setting"] == "legs_disabled")  # noqa: E731
    assert cost(r for r in samples if int(r["samples"]) == 500) == cost(rows)
    assert (out / "samples.png").read_bytes()[:4] == b"\x89PNG"
    # the tables written elsewhere (results/...) reuse every finished run: nothing to run
    elsewhere = subprocess.run([c for c in command if not c.startswith("out_dir=")] + [
        f"out_dir={tmp_path / 'elsewhere'}", "dry_run=true"], cwd=tmp_path, env={**os.environ, "WANDB_MODE": "offline"},
        capture_output=True, text=True, timeout=600)
    assert "5 jobs, 5 finished (1 not evaluable: a finding), 0 to run" in elsewhere.stdout, elsewhere.stdout[-2000:]


    # a later session with the records alone (no run directory): the same speeds and low-level checks, from each
    # job's report.json in its record, and the fault that cannot be learned reported from its record, not run again
    shutil.move(tmp_path / "outputs", tmp_path / "outputs_of_an_earlier_machine")
    later = [c for c in command if not c.startswith(("faults.own=", "samples=", "out_dir="))]
    again = subprocess.run(later + ["faults.own=[normal,legs_disabled,rear_limp,one_leg_locked]", "samples=[]",
                                    f"out_dir={tmp_path / 'again'}"], cwd=tmp_path,
                           env={**os.environ, "WANDB_MODE": "offline"}, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stdout[-3000:] + again.stderr[-3000:]
    assert ("0 reused from their run directories, 2 from their records in " in again.stdout
            and ", 1 not evaluable (an earlier run's finding)" in again.stdout), again.stdout[-2000:]
    assert not (tmp_path / "outputs" / "lat" / "tiny" / "a1_seed0_rear_limp").exists()  # not run again
    section = lambda text, title: text.split(title)[1].split("\n## ")[0]  # noqa: E731
    later_table = (tmp_path / "again" / "adverse.md").read_text()
    speeds = "## Speeds each fault leaves (random-action dynamics data)"
    assert section(later_table, speeds) == section(table, speeds) and "| lat | a1 | own | legs_disabled |" in table
    checks = "## LAT's low level: its experts reproduced in simulation"
    assert section(later_table, checks).count("| a1 | own | ") == 1, later_table
    unusable = section(later_table, "## Runs that could not be evaluated")
    assert "a1_seed0_rear_limp" in unusable and "ended in a fall" in unusable, later_table
    planned = subprocess.run(later + ["faults.own=[normal,legs_disabled,rear_limp,one_leg_locked]", "samples=[]",
                                      "dry_run=true"], cwd=tmp_path, env={**os.environ, "WANDB_MODE": "offline"},
                             capture_output=True, text=True, timeout=600)
    assert "3 finished (1 not evaluable: a finding), 0 to run" in planned.stdout, planned.stdout[-2000:]


def adverse_config(*overrides):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(ROOT / "recipes" / "adverse"), version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def test_profile_overrides_reach_only_that_profiles_runs_of_that_method():
    from hierloco.recipes.adverse import run

    cfg = adverse_config("robots=[a1]", "seeds=[0]", "profiles=[own,stiff]", "samples=[]")
    main, extra = run.fault_jobs(cfg, run.check(cfg))
    bar = "checks.min_reproduced_fraction=0.25"
    with_bar = {(job.labels["method"], job.labels["profile"]) for job in main + extra if bar in job.overrides}
    assert with_bar == {("lat", "stiff")}


def test_bad_profile_overrides_are_refused_before_any_job():
    import pytest

    from hierloco.recipes.adverse import run
    from hierloco.pipeline.config import ConfigError

    with pytest.raises(ConfigError, match="unknown robot profile 'sticky' in profile_overrides"):
        run.check(adverse_config("robots=[a1]", "+profile_overrides.sticky={lat: []}"))
    with pytest.raises(ConfigError, match="profile_overrides.stiff names 'sac', which is not in methods"):
        run.check(adverse_config("robots=[a1]", "+profile_overrides.stiff.sac=[]"))


def test_sample_counts_build_the_low_level_once_when_the_paper_run_is_not_on_disk(tmp_path, monkeypatch):
    from hierloco.recipes.adverse import run
    from hierloco.pipeline import studies

    monkeypatch.chdir(tmp_path)
    cfg = adverse_config("robots=[a1]", "seeds=[0]", "sample_methods=[lat]", "samples=[200,500,2000]")
    robots = run.check(cfg)
    paper_run = str(run.run_dir("lat", cfg.preset_name, robots[0], "own", 0))
    # the paper's run is not on disk (to run, or from its record): the first count starts from it, the rest from
    # the first count's run directory
    first, *rest = run.sample_jobs(cfg, robots)
    assert first.reuse_from == paper_run and [job.reuse_from for job in rest] == [first.run_dir] * 2
    # finished in its run directory: every count starts from it (its dynamics too, at its own count)
    (tmp_path / paper_run).mkdir(parents=True)
    (tmp_path / paper_run / studies.DONE).write_text("{}")
    assert [job.reuse_from for job in run.sample_jobs(cfg, robots)] == [paper_run] * 3
