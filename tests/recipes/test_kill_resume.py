"""SIGKILL in every stage, then the same command: every artifact byte-identical to an uninterrupted run.

Each recipe runs as a chain: started, killed (SIGKILL, the whole process group) the moment one more stage has
finished, i.e. while the next stage is under way, started again, and so on until it ends. The finished run
directory must then hold exactly the uninterrupted run's artifacts, byte for byte, and no temporary file.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "WANDB_MODE": "offline"}
# what a run writes that may differ run to run: the holder of the lock, logs, wall-clock timings
VOLATILE = ("run.json", ".lock", "report.json", "builds.json")

RECIPES = {
    "lat": ["preset=tiny", "settings=[normal,legs_disabled]", "eval.videos=[]"],
    "sac": ["preset=tiny", "eval.videos=[]"],
    "sac_sac": ["preset=tiny", "eval.videos=[]"],
}


def command(recipe: str, run_dir: Path) -> list[str]:
    return [sys.executable, str(ROOT / "recipes" / recipe / "train.py"), "progress=false", f"run_dir={run_dir}",
            *RECIPES[recipe]]


def finished_stages(run_dir: Path) -> set[str]:
    return {p.name for p in run_dir.rglob("*.key.json")} if run_dir.exists() else set()


def artifacts(run_dir: Path) -> dict[str, bytes]:
    """Every file of the run by relative path (the run directory's own path, as ``config.yaml`` records it, as
    ``RUN_DIR``)."""
    return {str(p.relative_to(run_dir)): p.read_bytes().replace(str(run_dir).encode(), b"RUN_DIR")
            for p in sorted(run_dir.rglob("*"))
            if p.is_file() and p.name not in VOLATILE and not str(p.relative_to(run_dir)).startswith("logs")}


def run_killing_after_each_stage(cmd: list[str], run_dir: Path, timeout: float = 900) -> int:
    """Runs ``cmd`` to the end, SIGKILLing it each time one more stage has finished; returns the number of kills."""
    kills = 0
    deadline = time.monotonic() + timeout
    while True:
        before = finished_stages(run_dir)
        process = subprocess.Popen(cmd, cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                   start_new_session=True)
        while process.poll() is None and finished_stages(run_dir) == before:
            assert time.monotonic() < deadline, "the chain of runs took too long"
            time.sleep(0.02)
        if process.poll() is not None:  # it ended before finishing one more stage: the run is complete
            assert process.returncode == 0, process.stderr.read().decode()[-3000:]
            return kills
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        process.stderr.close()
        kills += 1


@pytest.mark.slow
@pytest.mark.parametrize("recipe", list(RECIPES))
def test_sigkill_in_every_stage_then_resume_is_byte_identical(recipe, tmp_path):
    reference = tmp_path / "reference"
    done = subprocess.run(command(recipe, reference), cwd=ROOT, env=ENV, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    stages = finished_stages(reference)

    killed = tmp_path / "killed"
    kills = run_killing_after_each_stage(command(recipe, killed), killed)
    print(f"{recipe}: killed {kills} times over {len(stages)} stages")
    assert kills >= 1 and stages, (kills, stages)
    assert artifacts(killed).keys() == artifacts(reference).keys()
    different = [name for name, content in artifacts(reference).items() if artifacts(killed)[name] != content]
    assert not different, different
    assert not [p for p in killed.rglob("*") if ".tmp" in p.name], "a killed write's temporary file was left"


@pytest.mark.slow
def test_a_study_killed_mid_way_reuses_its_finished_jobs_and_gives_the_same_table(tmp_path):
    small = '["eval.generalization=null","eval.videos=[]","eval.figures=false"]'
    study = [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny", "robots=[a1]",
             "methods=[lib,ik]", "seeds=[0,1]", "settings=[normal]", f"overrides={small}"]
    reference = subprocess.run([*study, f"out_dir={tmp_path / 'reference'}"], cwd=tmp_path, env=ENV,
                               capture_output=True, text=True, timeout=900)
    assert reference.returncode == 0, reference.stderr[-3000:]

    work = tmp_path / "killed"
    work.mkdir()
    process = subprocess.Popen([*study, f"out_dir={work / 'out'}"], cwd=work, env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 900
    while process.poll() is None and not list(work.rglob("job.json")):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert process.poll() is None, "the study ended before it could be killed"
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    finished = len(list(work.rglob("job.json")))
    again = subprocess.run([*study, f"out_dir={work / 'out'}"], cwd=work, env=ENV, capture_output=True, text=True,
                           timeout=900)
    assert again.returncode == 0, again.stderr[-3000:]
    # a job already running on a Ray worker may still finish after its driver was killed: at least those done
    reused = int(again.stdout.split("study: 4 jobs, ")[1].split()[0])
    assert finished <= reused < 4, again.stdout[-2000:]
    reference_table = (tmp_path / "reference" / "comparison.csv").read_bytes()
    assert (work / "out" / "comparison.csv").read_bytes() == reference_table
