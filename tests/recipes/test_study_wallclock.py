"""A study's ``wallclock.md``: each job's compute counts the stages it needs; the total says how much of it is stages
copied between runs (``Job.reuse_from``), so shared work is not read as spent twice."""

from hierloco.pipeline.report import wallclock_markdown
from hierloco.pipeline.studies import Job, JobResult


def result(run_dir: str, builds: dict) -> JobResult:
    report = {"stage_seconds": {name: 0.0 for name in builds}}
    return JobResult(Job("lat", run_dir, ["robot=a1", "seed=0"], labels={"method": "lat"}), ok=True, rows=[],
                     seconds=60.0, report=report, builds=builds)


def test_stages_copied_from_another_run_are_counted_once_in_the_total():
    trained = {"dynamics_model_normal": {"seconds": 600.0}, "evaluation_normal_goal_reaching": {"seconds": 120.0}}
    reused = {"dynamics_model_normal": {"seconds": 600.0, "copied_from": "/runs/a1_seed0"},
              "evaluation_normal_speed_profile": {"seconds": 60.0}}
    text = wallclock_markdown([result("/runs/a1_seed0", trained), result("/runs/a1_seed0_profile", reused)])
    assert "| lat | /runs/a1_seed0_profile | 1.0 | 11.0 |" in text  # the job's compute holds the stage it copied
    assert "In all 23.0 min of compute (13.0 min with each stage counted once: 10.0 min are stages copied" in text


def test_a_study_without_copies_keeps_its_one_line_total():
    text = wallclock_markdown([result("/runs/a1_seed0", {"experts": {"seconds": 90.0}})])
    assert text.rstrip().endswith("In all 1.5 min of compute.")
