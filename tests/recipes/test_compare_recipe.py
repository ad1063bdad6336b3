"""The comparison study: method recipes as jobs on a real local Ray instance, then the comparison table and charts.
Through Ray it gives exactly what running the same jobs one by one gives; a re-run reuses every finished job."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["eval.generalization=null", "eval.videos=[]", "eval.figures=false"]


def compare(cwd, *overrides):
    env = {**os.environ, "WANDB_MODE": "offline"}
    command = [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny", "robots=[a1]",
               "methods=[lib,ik]", "seeds=[0,1]", "settings=[normal]", f"overrides={SMALL}".replace("'", '"'),
               *overrides]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=1200)


@pytest.mark.slow  # a study of 8 jobs through Ray (~170 s); the default suite's reliability tests cover reuse (case 1)
def test_compare_through_ray_equals_the_jobs_one_by_one(tmp_path):
    by_ray = tmp_path / "ray"
    by_ray.mkdir()
    records = tmp_path / "records"
    result = compare(by_ray, f"out_dir={by_ray / 'out'}", f"records={records}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "study: 4 jobs, 0 reused" in result.stdout and "study: 4 done, 0 running, 0 failed" in result.stdout

    one_by_one = []
    for method in ("lib", "ik"):
        for seed in (0, 1):
            run_dir = tmp_path / "single" / f"{method}_{seed}"
            done = subprocess.run([sys.executable, str(ROOT / "recipes" / method / "train.py"), "preset=tiny",
                                   "robot=a1", f"seed={seed}", "settings=[normal]", "progress=false",
                                   f"run_dir={run_dir}", *SMALL], cwd=tmp_path, capture_output=True, text=True,
                                  timeout=900)
            assert done.returncode == 0, done.stderr[-2000:]
            one_by_one += read_csv(run_dir / "episodes.csv")
    through_ray = read_csv(by_ray / "out" / "comparison.csv")
    key = lambda r: (r["method"], r["seed"], r["task"], r["episode"])  # noqa: E731
    comparable = lambda rows: [repr(sorted(r.items())) for r in sorted(rows, key=key)]  # noqa: E731  (NaN as text)
    assert comparable(through_ray) == comparable(one_by_one)
    table = (by_ray / "out" / "comparison.md").read_text()
    assert "| ik | a1 | normal | goal_reaching |" in table and "| lib | a1 | normal | goal_reaching |" in table
    assert (by_ray / "out" / "comparison_normal.png").read_bytes()[:4] == b"\x89PNG"
    # without LAT in the study, the paper's claims about LAT cannot be checked, and say so
    assert "| LIB is worse than LAT at velocity tracking | a1 | normal | velocity_tracking | - | " \
           "lat 0.16 +- 0.10, lib 0.58 +- 0.01 | not measured |" in (by_ray / "out" / "paper_check.md").read_text()
    assert (by_ray / "outputs" / "lib" / "tiny" / "a1_seed1" / "job.json").exists()

    # a re-run (say, after the study was killed) reuses every finished job without submitting it, and a job's
    # rows are those of the evaluations its plan names: a user's run of another planner into the study's LIB run
    # directory (its own table now in the run directory) changes nothing in the study's table
    import json

    from tests.runner import run_in_process

    lib_dir = by_ray / "outputs" / "lib" / "tiny" / "a1_seed0"
    signature = json.loads((lib_dir / "job.json").read_text())["signature"]
    assert run_in_process("lib", f"run_dir={lib_dir}", *signature["overrides"], "planner.horizon=2").returncode == 0
    horizon2 = read_csv(lib_dir / "episodes.csv")
    again = compare(by_ray, f"out_dir={by_ray / 'out'}")
    assert again.returncode == 0 and "study: 4 jobs, 4 reused" in again.stdout, again.stdout[-2000:]
    assert comparable(read_csv(by_ray / "out" / "comparison.csv")) == comparable(through_ray)
    costs = lambda rows: sorted((r["task"], r["episode"], r["normalized_cost"]) for r in rows)  # noqa: E731
    lib0 = [r for r in through_ray if r["method"] == "lib" and r["seed"] == 0]
    assert costs(horizon2) != costs(lib0)  # the horizon-2 numbers differ, and are not reported
    # reused jobs cost nothing now, and the wall-clock table still says what building their stages took
    wallclock = (by_ray / "out" / "wallclock.md").read_text()
    assert "| lib | a1 | 2 |" in wallclock and "| ik | a1 | 2 |" in wallclock, wallclock
    assert wallclock.count("| 0 | yes |") == 4, wallclock  # every job reused, no stage without its build time
    from hierloco.pipeline import records as job_records
    from hierloco.pipeline.report import job_compute

    ik_record = job_records.read(records / "ik" / "tiny" / "a1_seed0")
    stages = job_compute(ik_record["report"], ik_record["builds"])
    assert "dynamics_data_normal" in stages and all(v is not None and v > 0 for v in stages.values()), stages

    # the study left a record of every job: its rows, stage keys and timings, without the artifacts; on a machine
    # without the run directories (another session, a cluster without shared storage) the study takes every job from
    # its record and writes the same table
    record = records / "ik" / "tiny" / "a1_seed1"
    assert [p.name for p in record.iterdir()] == [job_records.RECORD]
    held = job_records.read(record)
    assert "dynamics_model_normal.pt" in held["stages"] and held["rows"] and held["builds"] and held["report"]
    assert not list(records.rglob("*.pt")) and not list(records.rglob("*.npz"))
    assert (record / job_records.RECORD).stat().st_size < 200_000
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    planned = compare(elsewhere, f"out_dir={elsewhere / 'out'}", f"records={records}", "dry_run=true")
    assert planned.returncode == 0, planned.stdout[-2000:] + planned.stderr[-2000:]
    assert "study plan: 4 jobs, 4 finished, 0 to run" in planned.stdout, planned.stdout
    assert planned.stdout.count("| from its record (") == 4 and not (elsewhere / "out").exists()
    # a seed no study has run yet is estimated from the recorded seeds of the same method and robot
    new_seed = compare(elsewhere, f"out_dir={elsewhere / 'out'}", f"records={records}", "seeds=[2]", "dry_run=true")
    assert "study plan: 2 jobs, 0 finished, 2 to run: about" in new_seed.stdout, new_seed.stdout
    assert "without an estimate" not in new_seed.stdout and new_seed.stdout.count("| to run | about ") == 2
    moved = compare(elsewhere, f"out_dir={elsewhere / 'out'}", f"records={records}")
    assert moved.returncode == 0, moved.stdout[-2000:] + moved.stderr[-2000:]
    assert "study: 4 jobs, 0 reused from their run directories, 4 from their records" in moved.stdout, moved.stdout
    assert not (elsewhere / "outputs").exists()
    assert comparable(read_csv(elsewhere / "out" / "comparison.csv")) == comparable(through_ray)
    moved_wallclock = (elsewhere / "out" / "wallclock.md").read_text()
    assert moved_wallclock.count("| 0 | from its record |") == 4 and "| ik | a1 | 2 |" in moved_wallclock, \
        moved_wallclock
    # a record is taken only while its keys are today's: a stage key that differs makes its job run again here,
    # and the job's new record replaces the stale one
    from hierloco.pipeline.rundir import StageSpec

    older = {filename: StageSpec(entry["name"], entry["key"], filename) for filename, entry in held["stages"].items()}
    changed = older["dynamics_model_normal.pt"].key
    changed["params"]["lr"] = 2 * changed["params"]["lr"]  # as an older version of the code keyed it
    job_records.save(job_records.make_record(held["signature"], older.values(), rows=held["rows"],
                                             report=held["report"], builds=held["builds"], seconds=held["seconds"]),
                     record)
    planned = compare(elsewhere, f"out_dir={elsewhere / 'out'}", f"records={records}", "dry_run=true")
    assert "study plan: 4 jobs, 3 finished, 1 to run: about" in planned.stdout, planned.stdout
    to_run = [line for line in planned.stdout.splitlines() if "| to run |" in line]
    assert len(to_run) == 1 and "ik/tiny/a1_seed1" in to_run[0] and "| about " in to_run[0], planned.stdout
    assert not (elsewhere / "outputs").exists()  # a dry run runs nothing
    rerun = compare(elsewhere, f"out_dir={elsewhere / 'out'}", f"records={records}")
    assert rerun.returncode == 0, rerun.stdout[-2000:] + rerun.stderr[-2000:]
    assert "study: 4 jobs, 0 reused from their run directories, 3 from their records" in rerun.stdout, rerun.stdout
    assert (elsewhere / "outputs" / "ik" / "tiny" / "a1_seed1" / "job.json").exists()
    assert job_records.read(record)["stages"]["dynamics_model_normal.pt"]["key"]["params"]["lr"] == \
        changed["params"]["lr"] / 2  # the job's new record replaced the stale one
    assert comparable(read_csv(elsewhere / "out" / "comparison.csv")) == comparable(through_ray)

    # a finished job is reused only while every stage its recipe plans today has the key on disk: a stage made
    # with another config (as after a changed default) makes it run again, and the run names that stage
    import json

    from hierloco.pipeline.studies import Job, finished

    run_dir = by_ray / "outputs" / "ik" / "tiny" / "a1_seed1"
    job = Job("ik", str(run_dir), json.loads((run_dir / "job.json").read_text())["signature"]["overrides"])
    assert finished(job)
    key_path = run_dir / "dynamics_model_normal.pt.key.json"
    key = json.loads(key_path.read_text())
    key["params"]["lr"] = 2 * key["params"]["lr"]
    key_path.write_text(json.dumps(key))
    assert not finished(job)
    stale = compare(by_ray, f"out_dir={by_ray / 'out'}")
    assert stale.returncode == 1 and "study: 4 jobs, 3 reused" in stale.stdout, stale.stdout[-2000:]
    assert "stage 'dynamics_model_normal'" in stale.stderr and "made with another config" in stale.stderr


@pytest.mark.slow
def test_a_failed_job_is_reported_and_the_others_go_on(tmp_path):
    result = compare(tmp_path, f"out_dir={tmp_path / 'out'}", "methods=[lib,ik]", "seeds=[0]",
                     '+method_overrides.ik=["dynamics.num_transitions=5"]')
    assert result.returncode == 1
    assert "failed: ik in" in result.stderr and "num_transitions" in result.stderr, result.stderr[-2000:]
    assert {r["method"] for r in read_csv(tmp_path / "out" / "comparison.csv")} == {"lib"}


def test_compare_refuses_unknown_method(tmp_path):
    command = [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "methods=[magic]",
               f"out_dir={tmp_path}"]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "unknown method 'magic'" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def compare_config(*overrides):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(ROOT / "recipes" / "compare"), version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def test_method_seeds_give_a_method_its_own_seeds():
    from hierloco.recipes.compare import run

    cfg = compare_config("methods=[lat,sac]", "robots=[a1]", "seeds=[0,1,2]", "+method_seeds.sac=[0]")
    planned = run.jobs(cfg, run.check(cfg))
    runs = sorted((job.labels["method"], Path(job.run_dir).name) for job in planned)
    assert runs == [("lat", "a1_seed0"), ("lat", "a1_seed1"), ("lat", "a1_seed2"), ("sac", "a1_seed0")]
    assert run.seeds_text(cfg) == "seeds [0, 1, 2] (sac: [0])"
    # under its name in the tables: the 2 x 256 SAC-SAC is shown as sac_sac_2x256 (names)
    cfg = compare_config("methods=[lat,sac_sac]", "robots=[a1]", "seeds=[0,1,2,3,4]", "+method_seeds.sac_sac=[0,1,2]")
    assert run.seeds_text(cfg) == "seeds [0, 1, 2, 3, 4] (sac_sac_2x256: [0, 1, 2])"


@pytest.mark.parametrize("method_seeds, message", [
    ("magic=[0]", "method_seeds names 'magic', which is not in methods"),
    ("sac=[]", "method_seeds.sac must be a non-empty list of seeds"),
    ("sac=[-1]", "method_seeds.sac: seed -1 is not an integer >= 0"),
    ("sac=0", "method_seeds.sac must be a non-empty list of seeds, got 0"),
])
def test_bad_method_seeds_are_refused_before_any_job(method_seeds, message):
    from hierloco.pipeline.config import ConfigError
    from hierloco.recipes.compare import run

    cfg = compare_config("methods=[lat,sac]", "robots=[a1]", f"+method_seeds.{method_seeds}")
    with pytest.raises(ConfigError, match=message.replace("[", r"\[")):
        run.check(cfg)


def test_a_bad_causes_file_is_refused_before_any_job(tmp_path):
    from hierloco.pipeline.config import ConfigError
    from hierloco.recipes.compare import run

    causes = tmp_path / "causes.yaml"
    causes.write_text("- {claims: [lat_is_great], cause: because}")
    with pytest.raises(ConfigError, match="unknown claim 'lat_is_great'"):
        run.check(compare_config("robots=[a1]", f"causes={causes}"))
    with pytest.raises(ConfigError, match="causes: no file"):
        run.check(compare_config("robots=[a1]", f"causes={tmp_path / 'missing.yaml'}"))
    causes.write_text("- {claims: [lib_worse], cause: because}")
    assert run.check(compare_config("robots=[a1]", f"causes={causes}"))[0].name == "a1"


def test_names_show_a_variant_under_the_methods_name_and_refuse_two_under_one():
    """``names`` puts SAC-SAC at the paper's 2 x 512 in the tables and claims as ``sac_sac`` (the 2 x 256 runs as a
    labelled variant); two methods under one name would be pooled as one, so that is refused before any job."""
    from hierloco.pipeline.config import ConfigError
    from hierloco.recipes.compare import run

    cfg = compare_config("methods=[sac_sac,sac_sac_2x512]", "robots=[a1]")  # the recipe's own names
    assert dict(cfg.names) == {"sac_sac_2x512": "sac_sac", "sac_sac": "sac_sac_2x256"}
    run.check(cfg)
    rows = [{"method": m, "normalized_cost": c} for m, c in (("sac_sac", 0.9), ("sac_sac_2x512", 0.5), ("lat", 0.1))]
    assert [(r["method"], r["normalized_cost"]) for r in run.renamed(rows, dict(cfg.names))] == [
        ("sac_sac_2x256", 0.9), ("sac_sac", 0.5), ("lat", 0.1)]
    with pytest.raises(ConfigError, match="two methods would be shown as 'sac_sac'"):
        run.check(compare_config("methods=[sac_sac,sac_sac_2x512]", "robots=[a1]", "names.sac_sac=sac_sac"))
