"""A study's job subprocess dies with the worker that runs it, so a killed study leaves no recipe running on
(``hierloco.pipeline.studies.die_with_parent``, called by every recipe as it starts)."""

import os
import signal
import subprocess
import sys
import time

import pytest

CHILD = ("from hierloco.pipeline.studies import die_with_parent; die_with_parent(); print('armed', flush=True); "
         "import time; time.sleep(120)")  # says when its death signal is set: a loaded machine may import slowly
PARENT = f"""
import os, subprocess, sys, time
env = {{**os.environ, "HIERLOCO_PARENT_PID": str(os.getpid())}}
child = subprocess.Popen([sys.executable, "-c", {CHILD!r}], env=env)
print(child.pid, flush=True)
time.sleep(120)
"""


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_job_subprocess_ends_when_its_parent_is_killed():
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    assert parent.stdout.readline().strip() == "armed"  # the child shares the parent's stdout
    assert alive(child)
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child)
