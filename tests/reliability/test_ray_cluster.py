"""Studies on Ray whatever else runs on the machine, and on a real cluster (issue 42, item 1; docs/pipeline.md,
"Studies on a Ray cluster").

Every study here runs as a user runs it (a subprocess) with a temporary folder of its own (``TMPDIR``, where Ray
looks for the ``ray/ray_current_cluster`` file a ``ray start`` leaves), so no test reads or writes another user's
``/tmp/ray``. The cluster test starts its own head (its own ``--temp-dir`` and port), and stops only the processes
it started, by pid. Every Ray address is 127.0.0.1 (``LOOPBACK``).
"""

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from hierloco.results import read_csv

ROOT = Path(__file__).resolve().parents[2]
RAY = Path(sys.executable).with_name("ray")
# Ray's switch for a single machine: every address of a head, its workers and a driver is 127.0.0.1
LOOPBACK = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}
INTERRUPTED = ("interrupted: the study's jobs were stopped; their finished stages are kept: run the same command "
               "again to resume")
SMALL = '["eval.videos=[]","eval.figures=false"]'


@pytest.fixture
def private_tmp():
    """A temporary folder of the test's own, short (Ray's socket paths under it allow 107 bytes); removed after."""
    path = Path(tempfile.mkdtemp(prefix="hl-", dir="/tmp"))
    yield path
    shutil.rmtree(path, ignore_errors=True)


def environment(tmp: Path, **extra: str) -> dict:
    """The environment of a study or head under test: this one without Ray's variables, ``TMPDIR=tmp``."""
    env = {key: value for key, value in os.environ.items() if not key.startswith("RAY_")}
    return {**env, "TMPDIR": str(tmp), "WANDB_MODE": "offline", "PYTHONPATH": str(ROOT), **LOOPBACK, **extra}


def compare(out: Path, *overrides: str) -> list[str]:
    return [sys.executable, str(ROOT / "recipes" / "compare" / "run.py"), "preset=tiny", "robots=[a1]", "seeds=[0]",
            "settings=[normal]", f"out_dir={out}", *overrides]


def processes_naming(text: str) -> list[int]:
    """The live processes whose command line holds ``text``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if text in (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace") and \
                    (entry / "stat").read_text().split(") ")[-1].split()[0] != "Z":
                found.append(int(entry.name))
        except OSError:
            continue
    return found


def wait_until(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"{what} within {timeout:.0f} s"
        time.sleep(0.1)


def comparable(rows: list[dict]) -> list[str]:
    key = lambda r: (r["method"], r["seed"], r["task"], r["episode"])  # noqa: E731
    return [repr(sorted(r.items())) for r in sorted(rows, key=key)]  # NaN compared as text


def test_the_study_skeleton_checks_the_ray_address_before_loading_ray_or_torch():
    """A dead ``RAY_ADDRESS`` is refused as soon as the study's config is composed (``study_main``); the skeleton
    and the jobs module load neither Ray nor torch, MuJoCo or TorchRL, so only a study's own imports come first."""
    code = ("import sys, hierloco.pipeline.study, hierloco.pipeline.studies; "
            "print(','.join(m for m in ('ray', 'torch', 'mujoco', 'torchrl') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == ""


def test_every_study_refuses_a_dead_ray_address_before_loading_torch():
    """Every registered study's script loads no torch, TorchRL or Ray as it is imported (what it needs of
    them is imported where a table is judged), so a dead ``RAY_ADDRESS`` is one line in about a second."""
    code = ("import importlib, sys\n"
            "from hierloco.pipeline.methods import STUDIES\n"
            "for name in STUDIES.names():\n"
            "    importlib.import_module(STUDIES[name].package + '.' + STUDIES[name].script_name.removesuffix('.py'))\n"
            "    heavy = [m for m in ('ray', 'torch', 'torchrl') if m in sys.modules]\n"
            "    print(name, ','.join(heavy))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    lines = out.stdout.splitlines()
    assert len(lines) >= 8 and all(line.split(" ")[1:] == [""] for line in lines), out.stdout


def test_what_a_job_on_a_cluster_sends_back_lands_where_no_other_run_lies(tmp_path):
    """A node's run directory and log come back to the driver's path for the job; once there (or on storage both
    share) nothing is written twice; a run directory of another run at that path is left as it is, in one line."""
    from hierloco.pipeline import studies

    node = tmp_path / "node" / "a1_seed0"
    (node / "evaluation").mkdir(parents=True)
    (node / "job.json").write_text('{"signature": {"method": "ik"}, "seconds": 12.5}')
    (node / "evaluation" / "goal_reaching.npz").write_bytes(b"\x00rows")
    sent = {"archive": studies.pack(node), "log": b"=== the run on the node\ndone\n"}
    job = studies.Job("ik", str(tmp_path / "driver" / "outputs" / "ik" / "a1_seed0"), [])
    here, log = Path(job.run_dir), studies.job_log(job)

    assert studies.bring_back(job, sent) is None
    assert sorted(str(p.relative_to(here)) for p in here.rglob("*")) == \
        ["evaluation", "evaluation/goal_reaching.npz", "job.json"]
    assert (here / "evaluation" / "goal_reaching.npz").read_bytes() == b"\x00rows"
    assert log.read_bytes() == sent["log"]
    assert not [p for p in here.parent.iterdir() if "incoming" in p.name]
    assert studies.bring_back(job, sent) is None  # already here (or shared storage): nothing written twice
    assert log.read_bytes() == sent["log"]

    (here / "job.json").write_text('{"signature": {"method": "ik"}, "seconds": 99.0}')  # another run of the path
    said = studies.bring_back(job, sent)
    assert said is not None and said.startswith(f"{here} here holds another run") and "not brought back" in said
    assert (here / "job.json").read_text().endswith("99.0}")


def stale_cluster_study(tmp: Path, private_tmp: Path, tiny_lat_run: Path) -> tuple[Path, Path, list[str]]:
    """A ``ray_current_cluster`` file left by a head killed without ``ray stop`` (its address dead), and a tiny
    comparison study of LAT whose job's run has every stage but its evaluations: the file, the run directory and the
    study's command."""
    stale = private_tmp / "ray" / "ray_current_cluster"
    stale.parent.mkdir()
    with socket.socket() as unused:  # a port nothing listens on once closed
        unused.bind(("127.0.0.1", 0))
        stale.write_text(f"127.0.0.1:{unused.getsockname()[1]}")
    run_dir = tmp / "outputs" / "lat" / "tiny" / "a1_seed0"
    shutil.copytree(tiny_lat_run, run_dir, ignore=shutil.ignore_patterns(".lock", "evaluation"))  # left to build
    return stale, run_dir, compare(tmp / "out", "methods=[lat]", f"overrides={SMALL}")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("moment", ["sockets/raylet", "logs/python-core-driver-*"])  # Ray's processes up; the study joining them
def test_a_study_ignores_a_stale_cluster_file_and_stops_in_one_line_on_sigterm_as_its_ray_starts(
        moment, tiny_lat_run, tmp_path, private_tmp):
    """A stale ``ray_current_cluster`` file made every local study stop with Ray's ValueError: the study starts its
    own instance. SIGTERM as that instance starts is one line, exit 130, and no process or folder of the study's
    Ray is left: as Ray's processes are up (it ended in Ray's C++ stack dump, exit 134) and as the study's own
    connection to them starts (it printed the line, then crashed as Python shut down: a segmentation fault, or no
    exit at all)."""
    stale, _, command = stale_cluster_study(tmp_path, private_tmp, tiny_lat_run)
    study = subprocess.Popen(command, cwd=tmp_path, env=environment(private_tmp), stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: list(private_tmp.glob(f"hierloco-ray-*/session_2*/{moment}")) or
                   study.poll() is not None, 300, f"the study's Ray wrote {moment}")
        assert study.poll() is None, study.communicate()
        study.send_signal(signal.SIGTERM)
        code, err = study.wait(timeout=120), study.stderr.read()
    finally:
        if study.poll() is None:
            study.kill()
    assert code == 130 and err.splitlines() == [INTERRUPTED], (code, err[-3000:])
    # no Ray process of the study is left, nor its folder (a process that ray.init had not yet registered when the
    # signal came is stopped too)
    assert not processes_naming(str(private_tmp / "hierloco-ray-")), "the study's Ray processes are stopped"
    assert not list(private_tmp.glob("hierloco-ray-*")), "the study's Ray folder is removed"
    assert stale.read_text().startswith("127.0.0.1:")  # left as it was


@pytest.mark.slow  # ~45 s: a study's job stopped and run again
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_study_stopped_by_sigterm_while_its_job_runs_stops_the_job_and_resumes(tiny_lat_run, tmp_path,
                                                                               private_tmp):
    """SIGTERM while the study's job runs (a stale cluster file beside it) is one line, exit 130, the job's recipe
    and the study's Ray stopped; the same command then resumes and gives the job's numbers."""
    stale, run_dir, command = stale_cluster_study(tmp_path, private_tmp, tiny_lat_run)
    study = subprocess.Popen(command, cwd=tmp_path, env=environment(private_tmp), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: processes_naming(f"run_dir={run_dir}") or study.poll() is not None, 300,
                   "the job's recipe started")
        assert study.poll() is None, study.communicate()
        recipe = processes_naming(f"run_dir={run_dir}")
        ray_processes = processes_naming(str(private_tmp / "hierloco-ray-"))
        assert ray_processes, "the study's own Ray instance, in its temporary folder"
        time.sleep(1.0)
        study.send_signal(signal.SIGTERM)
        out, err = study.communicate(timeout=120)
    finally:
        if study.poll() is None:
            study.kill()
    assert study.returncode == 130 and err.splitlines() == [INTERRUPTED], (study.returncode, err[-3000:])
    wait_until(lambda: not any(pid in processes_naming("") for pid in recipe + ray_processes), 30,
               "the job's recipe and the study's Ray stopped")
    assert not list(private_tmp.glob("hierloco-ray-*")), "the study's Ray folder is removed"
    assert not (run_dir / "job.json").exists()

    again = subprocess.run(command, cwd=tmp_path, env=environment(private_tmp), capture_output=True, text=True,
                           timeout=600)
    assert again.returncode == 0 and not again.stderr.strip(), again.stdout[-2000:] + again.stderr[-3000:]
    assert "study: 1 done, 0 running, 0 failed" in again.stdout
    assert stale.read_text().startswith("127.0.0.1:")  # left as it was
    episode = lambda r: (r["task"], r["episode"], r["normalized_cost"])  # noqa: E731
    reference = {episode(r) for r in read_csv(tiny_lat_run / "episodes.csv")}
    table = [episode(r) for r in read_csv(tmp_path / "out" / "comparison.csv")]
    assert table and set(table) <= reference, "the study's rows are the job's own evaluations"


def start_head(temp_dir: Path, port: int, env: dict, log: Path) -> subprocess.Popen:
    with open(log, "w") as out:
        return subprocess.Popen([str(RAY), "start", "--head", "--block", "--port", str(port), "--temp-dir",
                                 str(temp_dir), "--num-cpus", "2", "--include-dashboard", "false",
                                 "--disable-usage-stats"], env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)


def stop(head: subprocess.Popen, temp_dir: Path) -> None:
    """Stops the head this test started (``ray start --block`` stops its processes on SIGTERM), then any process
    of it still running (each names its ``--temp-dir``), by pid."""
    if head.poll() is None:
        head.terminate()
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()
    for pid in processes_naming(str(temp_dir)):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_study_through_a_ray_head_gives_the_local_table_and_brings_its_run_directories_back(tmp_path,
                                                                                                private_tmp):
    """A real ``ray start --head`` (token authentication, its own ``--temp-dir`` and port): a study without
    ``RAY_ADDRESS`` still runs on its own instance (the live head's address in ``$TMPDIR/ray/ray_current_cluster``
    made it fail); through ``RAY_ADDRESS=127.0.0.1:<port>`` without ``RAY_AUTH_MODE=token`` it is refused in one
    line; with it, its jobs run on the head in a copy of the project, their run directories, logs and records come
    back to the driver's folder, and the table equals the local run's; the study run again reuses them."""
    token = secrets.token_hex(16)
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    head_dir = private_tmp / "ray"  # where a default `ray start` of this TMPDIR writes: ray_current_cluster too
    head = start_head(head_dir, port, environment(private_tmp, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token),
                      tmp_path / "head.log")
    try:
        wait_until(lambda: (head_dir / "ray_current_cluster").exists() or head.poll() is not None, 180,
                   "the head started")
        assert head.poll() is None, (tmp_path / "head.log").read_text()[-3000:]
        assert (head_dir / "ray_current_cluster").read_text().strip() == f"127.0.0.1:{port}"
        small = [f"overrides={SMALL}", "methods=[ik]"]

        local = tmp_path / "local"
        local.mkdir()
        by_itself = subprocess.run(compare(local / "out", *small), cwd=local, env=environment(private_tmp),
                                   capture_output=True, text=True, timeout=900)
        assert by_itself.returncode == 0 and not by_itself.stderr.strip(), by_itself.stderr[-3000:]
        assert not list(head_dir.glob("session_2*/runtime_resources/working_dir_files/*/outputs")), \
            "the study without RAY_ADDRESS ran nothing on the head"

        cluster = tmp_path / "cluster"
        cluster.mkdir()
        address = {"RAY_ADDRESS": f"127.0.0.1:{port}", "RAY_AUTH_TOKEN": token}
        refused = subprocess.run(compare(cluster / "out", *small), cwd=cluster, env=environment(private_tmp, **address),
                                 capture_output=True, text=True, timeout=300)
        assert refused.returncode == 2 and len(refused.stderr.splitlines()) == 1, refused.stderr[-3000:]
        assert refused.stderr.startswith(f"error: the Ray cluster at 127.0.0.1:{port} refused this process") and \
            "RAY_AUTH_MODE=token" in refused.stderr
        assert not (cluster / "outputs").exists()

        records = cluster / "records"
        on_head = subprocess.run(compare(cluster / "out", *small, f"records={records}"), cwd=cluster,
                                 env=environment(private_tmp, RAY_AUTH_MODE="token", **address), capture_output=True,
                                 text=True, timeout=900)
        assert on_head.returncode == 0 and not on_head.stderr.strip(), on_head.stdout[-2000:] + on_head.stderr[-3000:]
        assert "study: 1 done, 0 running, 0 failed" in on_head.stdout
        assert comparable(read_csv(cluster / "out" / "comparison.csv")) == \
            comparable(read_csv(local / "out" / "comparison.csv"))
        # the job ran on the head, in the head's copy of the project, and its run directory, log and record came back
        ran = list(head_dir.glob("session_2*/runtime_resources/working_dir_files/*/outputs/ik/tiny/a1_seed0"))
        assert len(ran) == 1, ran
        back = cluster / "outputs" / "ik" / "tiny" / "a1_seed0"
        assert (back / "job.json").read_bytes() == (ran[0] / "job.json").read_bytes()
        assert sorted(p.name for p in back.iterdir()) == sorted(p.name for p in ran[0].iterdir())
        assert (cluster / "outputs" / "ik" / "tiny" / "a1_seed0.log").read_text().startswith("=== ")
        assert (records / "ik" / "tiny" / "a1_seed0" / "record.json").is_file()

        again = subprocess.run(compare(cluster / "out", *small), cwd=cluster,
                               env=environment(private_tmp, RAY_AUTH_MODE="token", **address), capture_output=True,
                               text=True, timeout=600)
        assert again.returncode == 0 and "study: 1 jobs, 1 reused from their run directories" in again.stdout, \
            again.stdout[-2000:] + again.stderr[-2000:]
    finally:
        stop(head, head_dir)
    assert not processes_naming(str(private_tmp)), "every process this test started has stopped"
