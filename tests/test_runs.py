"""Run directories: stages cached with their config, mismatches refused, failures leave nothing behind
(``docs/index.md``, Runs and artifacts)."""

import json

import numpy as np
import pytest

from hierloco.io import ArtifactError
from hierloco.pipeline.rundir import ConfigMismatchError, RunDirectory

CONFIG = {"robot": "a1", "experts": {"num": 3, "seed": 0}, "lr": 1e-3, "dims": (2, 3)}


class Stage:
    """A stage whose build, save and load calls are counted."""

    def __init__(self, value=(1, 2, 3)):
        self.value = list(value)
        self.builds = self.loads = 0

    def build(self):
        self.builds += 1
        return list(self.value)

    @staticmethod
    def save(obj, path):
        path.write_text(json.dumps(obj))

    def load(self, path):
        self.loads += 1
        return json.loads(path.read_text())

    def run(self, run, config=CONFIG, name="numbers", filename="numbers.json"):
        return run.stage(name, config, self.build, self.save, self.load, filename)


def snapshot(directory):
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def test_built_once_then_loaded(tmp_path):
    stage = Stage()
    run = RunDirectory(tmp_path)
    assert stage.run(run) == [1, 2, 3]
    assert (stage.builds, stage.loads) == (1, 0)
    assert run.reused == {"numbers": False} and run.timings["numbers"] >= 0
    assert json.loads((tmp_path / "numbers.json.key.json").read_text()) == json.loads(json.dumps(CONFIG))
    # same directory object, then a fresh one (a re-run)
    assert stage.run(run) == [1, 2, 3]
    rerun = RunDirectory(tmp_path)
    assert stage.run(rerun) == [1, 2, 3]
    assert (stage.builds, stage.loads) == (1, 2)
    assert rerun.reused == {"numbers": True} and "numbers" in rerun.timings


def test_a_build_s_wall_clock_is_recorded_and_reported_when_reused(tmp_path):
    import time

    def slow():
        time.sleep(0.2)
        return [7]

    run = RunDirectory(tmp_path)
    run.stage("slow", CONFIG, slow, Stage.save, Stage().load, "slow.json")
    recorded = json.loads((tmp_path / "builds.json").read_text())["slow"]
    assert 0.2 <= recorded["seconds"] < 5 and recorded["threads"] >= 1 and recorded["host"]
    assert recorded["cpu"].endswith(")") and "(" in recorded["cpu"]  # the CPU and the instruction set torch uses
    rerun = RunDirectory(tmp_path)
    rerun.stage("slow", CONFIG, lambda: 1 / 0, Stage.save, Stage().load, "slow.json")
    assert rerun.reused["slow"] and rerun.timings["slow"] < 0.2, "loading is not building"
    assert rerun.build_seconds["slow"] == recorded["seconds"], "a reused stage reports what building it took"
    with pytest.raises(ZeroDivisionError):
        rerun.stage("broken", {"b": 1}, lambda: 1 / 0, Stage.save, Stage().load, "broken.json")
    assert set(json.loads((tmp_path / "builds.json").read_text())) == {"slow"}, "a failed build records nothing"


def test_a_resumed_build_counts_the_time_of_the_builds_killed_before_it(tmp_path):
    """A build that resumed from its checkpoint adds what the killed builds took: builds.json holds the whole time
    and that part; the next stage's build starts from zero; a negative time is refused."""
    run = RunDirectory(tmp_path)

    def resumed():
        run.count_interrupted_seconds(600.0)
        return [1]

    run.stage("resumed", CONFIG, resumed, Stage.save, Stage().load, "resumed.json")
    run.stage("fresh", {"f": 1}, lambda: [2], Stage.save, Stage().load, "fresh.json")
    builds = json.loads((tmp_path / "builds.json").read_text())
    assert 600.0 <= builds["resumed"]["seconds"] < 605 and builds["resumed"]["interrupted_seconds"] == 600.0
    assert builds["fresh"]["seconds"] < 5 and "interrupted_seconds" not in builds["fresh"]
    assert run.build_seconds["resumed"] == pytest.approx(builds["resumed"]["seconds"], abs=1e-3)
    with pytest.raises(ValueError, match=">= 0"):
        run.count_interrupted_seconds(-1.0)


def test_other_stages_are_independent(tmp_path):
    run = RunDirectory(tmp_path)
    first, second = Stage([1]), Stage([2])
    first.run(run, name="a", filename="a.json")
    second.run(run, {"other": 1}, name="b", filename="b.json")
    assert run.reused == {"a": False, "b": False}
    assert first.run(RunDirectory(tmp_path), name="a", filename="a.json") == [1]
    assert first.builds == 1


@pytest.mark.parametrize("change, key", [
    ({"lr": 2e-3}, "lr"),
    ({"experts": {"num": 5, "seed": 0}}, "experts.num"),
    ({"extra": True}, "extra"),
])
def test_config_mismatch(tmp_path, change, key):
    stage = Stage()
    stage.run(RunDirectory(tmp_path))
    before = snapshot(tmp_path)
    other = Stage([9, 9])
    with pytest.raises(ConfigMismatchError, match=key) as info:
        other.run(RunDirectory(tmp_path), {**CONFIG, **change})
    assert "numbers" in str(info.value)
    assert other.builds == 0 and other.loads == 0
    assert snapshot(tmp_path) == before  # artifact and config file byte-identical


def test_missing_key_is_named(tmp_path):
    Stage().run(RunDirectory(tmp_path))
    config = {k: v for k, v in CONFIG.items() if k != "lr"}
    with pytest.raises(ConfigMismatchError, match="lr"):
        Stage().run(RunDirectory(tmp_path), config)


def test_tuples_and_numpy_scalars_match_their_json_form(tmp_path):
    config = {**CONFIG, "num": np.int64(3), "scale": np.float32(0.5), "shape": np.array([2, 3])}
    stage = Stage()
    stage.run(RunDirectory(tmp_path), config)
    stored = json.loads((tmp_path / "numbers.json.key.json").read_text())
    assert stored["num"] == 3 and stored["scale"] == 0.5 and stored["shape"] == [2, 3] and stored["dims"] == [2, 3]
    assert stage.run(RunDirectory(tmp_path), config) == [1, 2, 3]  # the re-run reuses it
    assert stage.run(RunDirectory(tmp_path), {**config, "num": 3, "dims": [2, 3]}) == [1, 2, 3]
    assert stage.builds == 1
    with pytest.raises(ConfigMismatchError, match="num"):
        stage.run(RunDirectory(tmp_path), {**config, "num": np.int64(4)})


def test_artifact_without_config_raises(tmp_path):
    (tmp_path / "numbers.json").write_text("[1]")
    stage = Stage()
    with pytest.raises(ConfigMismatchError, match="numbers.json.key.json"):
        stage.run(RunDirectory(tmp_path))
    assert stage.builds == 0
    assert (tmp_path / "numbers.json").read_text() == "[1]"
    assert not (tmp_path / "numbers.json.key.json").exists()


@pytest.mark.parametrize("content", [b'{"robot": "a1", ', b"\xff\xfe\x00garbage", b"[1, 2]", b"3"])
def test_corrupted_config_raises(tmp_path, content):
    Stage().run(RunDirectory(tmp_path))
    (tmp_path / "numbers.json.key.json").write_bytes(content)
    before = snapshot(tmp_path)
    stage = Stage()
    with pytest.raises(ArtifactError, match="numbers.json.key.json"):
        stage.run(RunDirectory(tmp_path))
    assert stage.builds == 0
    assert snapshot(tmp_path) == before


def test_failed_build_leaves_no_artifact(tmp_path):
    run = RunDirectory(tmp_path)

    def broken():
        raise RuntimeError("killed")

    with pytest.raises(RuntimeError, match="killed"):
        run.stage("numbers", CONFIG, broken, Stage.save, Stage().load, "numbers.json")
    assert not (tmp_path / "numbers.json").exists()
    assert "numbers" not in run.reused
    stage = Stage()
    assert stage.run(RunDirectory(tmp_path)) == [1, 2, 3]  # the re-run builds it
    assert stage.builds == 1
    # and a re-run after a failed build with another config builds too (nothing finished to protect)
    with pytest.raises(RuntimeError):
        run.stage("other", {"a": 1}, broken, Stage.save, Stage().load, "other.json")
    other = Stage([4])
    assert other.run(RunDirectory(tmp_path), {"a": 2}, name="other", filename="other.json") == [4]
    assert json.loads((tmp_path / "other.json.key.json").read_text()) == {"a": 2}


def test_config_mismatch_is_an_artifact_error():
    assert issubclass(ConfigMismatchError, ArtifactError)
    assert issubclass(ArtifactError, ValueError)


LOCKER = """
import sys, time
from hierloco.pipeline.rundir import RunDirectory
run = RunDirectory(sys.argv[1])
run.acquire("policy.epochs=20")
print("locked", flush=True)
time.sleep(60)
"""


def _locker(tmp_path):
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-c", LOCKER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "locked"
    return process


def test_a_second_process_is_refused_naming_the_holder(tmp_path):
    from hierloco.pipeline.rundir import RunLockedError

    holder = _locker(tmp_path)
    try:
        with pytest.raises(RunLockedError, match=rf"in use by pid {holder.pid} .*policy.epochs=20"):
            RunDirectory(tmp_path).acquire()
    finally:
        holder.kill()
        holder.wait()


def test_a_killed_holder_s_lock_is_taken_over(tmp_path):
    holder = _locker(tmp_path)
    holder.kill()  # SIGKILL: no clean-up, the lock file stays
    holder.wait()
    assert (tmp_path / ".lock").exists()
    run = RunDirectory(tmp_path)
    run.acquire()  # the kernel released the dead process's flock
    assert json.loads((tmp_path / ".lock").read_text())["pid"] == __import__("os").getpid()
    run.release()


def test_verify_checks_a_whole_plan_before_any_work(tmp_path):
    from hierloco.pipeline.rundir import StageSpec

    Stage().run(RunDirectory(tmp_path))
    Stage([2]).run(RunDirectory(tmp_path), {"b": 1}, name="b", filename="b.json")
    plan = [StageSpec("numbers", {**CONFIG, "lr": 5.0}, "numbers.json"), StageSpec("b", {"b": 2}, "b.json"),
            StageSpec("c", {}, "c.json")]
    before = snapshot(tmp_path)
    with pytest.raises(ConfigMismatchError) as info:
        RunDirectory(tmp_path).verify(plan)
    assert "'numbers'" in str(info.value) and "'b'" in str(info.value)  # every mismatch at once
    assert snapshot(tmp_path) == before
    assert RunDirectory(tmp_path).verify(plan[2:]) == {"c": False}


def test_a_read_only_directory_is_read_but_never_written(tmp_path):
    import os

    from hierloco.pipeline.rundir import ReadOnlyRunError, StageSpec

    stage = Stage()
    stage.run(RunDirectory(tmp_path))
    os.chmod(tmp_path, 0o555)
    try:
        run = RunDirectory(tmp_path)
        if not run.readonly:
            pytest.skip("running as a user who may write anywhere (root)")
        run.acquire()  # no lock file on a read-only directory
        assert stage.run(run) == [1, 2, 3] and stage.loads == 1
        with pytest.raises(ReadOnlyRunError, match="'c'"):
            run.verify([StageSpec("c", {}, "c.json")])
    finally:
        os.chmod(tmp_path, 0o755)


def test_readonly_can_be_forced(tmp_path):
    from hierloco.pipeline.rundir import ReadOnlyRunError

    with pytest.raises(ReadOnlyRunError, match="numbers"):
        Stage().run(RunDirectory(tmp_path, readonly=True))
    assert not list(tmp_path.iterdir())
