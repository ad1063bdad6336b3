"""Suite-wide set-up."""

import os
import sys

import absl.logging
import torch

# The suite's own networks are small: one torch thread trains them several times faster than two whenever the
# cores are shared (the simulation's threads, a Ray worker, a busy CI machine), because a parallel op waits for its
# slowest thread (benchmarks/bench_sac.py measures it). The recipe runs the tests start as subprocesses inherit the
# same setting (as a study's jobs do, hierloco/pipeline/studies.py); the simulation's threads still follow the cores.
torch.set_num_threads(1)
os.environ.setdefault("OMP_NUM_THREADS", "1")

# absl's log handler keeps the stream it was created with and closes it on ``logging.shutdown`` when that stream is
# no longer ``sys.stderr``. Imported under pytest's capture, that stream is pytest's capture file; a recipe run
# in-process with stderr redirected (tests/recipes/test_user_errors.py) lets Hydra's logging set-up shut the handler
# down, which closed pytest's capture file and lost every later test's output. The process's own stderr is never
# closed by absl.
absl.logging.get_absl_handler().python_handler.stream = sys.__stderr__


import shutil  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def tiny_lat_run(tmp_path_factory):
    """A tiny LAT run on A1 (normal setting, a video of goal reaching), made once per test session: the first
    pytest-xdist worker that asks for it builds it in the folder all workers share, the others wait on its lock and
    take it. Tests that change it take their own copy (:func:`copy_run`)."""
    from filelock import FileLock

    from tests.runner import run_in_process

    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent  # the session's folder, above each worker's own
    run_dir, done = shared / "shared_lat_tiny", shared / "shared_lat_tiny.done"
    with FileLock(str(shared / "shared_lat_tiny.lock")):
        if not done.exists():
            result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={run_dir}",
                                    env={"WANDB_MODE": "offline"})
            assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
            done.write_text("built\n")
    return run_dir


@pytest.fixture
def copy_run(tiny_lat_run, tmp_path):
    """A copy of the shared tiny LAT run, in this test's sandbox (``tmp_path/run``)."""
    target = tmp_path / "run"
    shutil.copytree(tiny_lat_run, target, ignore=shutil.ignore_patterns(".lock"))
    return target
