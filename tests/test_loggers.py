"""Run loggers: TorchRL's CSV logger always, wandb offline (never touching the network) or online (never hanging
without one), TensorBoard; one experiment folder per invocation; metric names that display correctly."""

import json
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from hierloco.loggers import RunLogger, flatten_config, metric_component, metric_name

FAKE_WANDB_KEY = "0" * 40  # a key of the right shape that no server accepts


def scalar_files(directory):
    return {p.relative_to(directory).as_posix(): p for p in Path(directory).rglob("*.csv")}


@pytest.fixture
def wandb_home(tmp_path, monkeypatch):
    """Everything wandb writes stays under tmp_path; no key, no server override (restored after the test)."""
    pytest.importorskip("wandb")  # skipped only when wandb cannot be imported
    home = tmp_path / "wandb_home"
    for var in ("WANDB_CONFIG_DIR", "WANDB_CACHE_DIR", "WANDB_DATA_DIR"):
        monkeypatch.setenv(var, str(home))
    for var in ("WANDB_API_KEY", "WANDB_BASE_URL", "WANDB_MODE", "WANDB_SILENT"):
        monkeypatch.delenv(var, raising=False)
    return home


@pytest.fixture
def loopback_server():
    """A TCP server on 127.0.0.1 that accepts connections and never answers; counts what connected."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    server.setblocking(False)

    def connections() -> int:
        count = 0
        while True:
            try:
                server.accept()[0].close()
                count += 1
            except BlockingIOError:
                return count

    yield f"http://127.0.0.1:{server.getsockname()[1]}", connections
    server.close()


# ---------------------------------------------------------------------------------------------------- CSV
def test_csv_logger_writes_scalars(tmp_path):
    logger = RunLogger("a1_seed3", tmp_path, prefix="lat", backends=("csv",), config={"robot": "a1", "seed": 3,
                                                                                       "planner": {"horizon": 2}})
    logger.log_scalar("eval/normalized_cost", 0.25, step=3)
    logger.log_metrics({"eval/success_rate": 0.5, "time/plan_seconds": 0.125}, step=7)
    logger.close()
    assert logger.exp_name.startswith("lat_a1_seed3_") and logger.experiment_dir == tmp_path / logger.exp_name
    files = scalar_files(logger.experiment_dir)
    assert files["scalars/eval/normalized_cost.csv"].read_text().splitlines() == ["3,0.25"]
    assert files["scalars/eval/success_rate.csv"].read_text().splitlines() == ["7,0.5"]
    assert files["scalars/time/plan_seconds.csv"].read_text().splitlines() == ["7,0.125"]
    hparams = list(logger.experiment_dir.rglob("hparams*.txt"))
    assert len(hparams) == 1 and "robot: a1" in hparams[0].read_text() and "planner/horizon: 2" in \
        hparams[0].read_text()
    assert not list(tmp_path.rglob("wandb"))


def test_every_invocation_gets_its_own_folder(tmp_path):
    """A re-run (resumed or refused) in the same log dir never appends to the first invocation's files."""
    loggers = []
    for value in (1.0, 2.0):
        logger = RunLogger("lat_a1_seed0", tmp_path, backends=("csv",), config={"seed": 0})
        logger.log_scalar("train/loss", value, step=0)
        logger.close()
        loggers.append(logger)
    first, second = loggers
    assert first.experiment_dir != second.experiment_dir
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([first.exp_name, second.exp_name])
    for logger, value in zip(loggers, (1.0, 2.0)):
        assert (logger.experiment_dir / "scalars/train/loss.csv").read_text().splitlines() == [f"0,{value}"]
        assert len(list(logger.experiment_dir.rglob("hparams*.txt"))) == 1


def test_csv_is_always_on(tmp_path):
    logger = RunLogger("exp", tmp_path, backends=())
    logger.log_scalar("train/loss", 1.5)
    assert logger.active_backends == ("csv",)
    assert (logger.experiment_dir / "scalars/train/loss.csv").read_text() == "0,1.5\n"
    logger.close()
    logger.close()  # closing twice is harmless


@pytest.mark.parametrize("kwargs, message", [
    ({"backends": ("csv", "mlflow")}, "mlflow"),
    ({"backends": "wandb"}, "list of names"),
    ({"wandb_mode": "cloud"}, "wandb_mode"),
    ({"group": ""}, "group"),
    ({"tags": "paper"}, "tags"),
    ({"wandb_init_timeout": 0}, "wandb_init_timeout"),
    ({"config": [("seed", 0)]}, "config"),
])
def test_bad_arguments_are_refused_before_any_work(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        RunLogger("exp", tmp_path, **kwargs)
    assert not list(tmp_path.iterdir())


def test_metric_names_display_in_wandb():
    assert metric_component("goal_reaching_1.5m") == "goal_reaching_1p5m"
    assert metric_component("v 0.2 m/s") == "v_0p2_m_s"
    assert metric_component("dynamics.normal") == "dynamics_normal"  # no dot survives: wandb would nest it
    assert metric_name("eval/", "normal//goal_reaching_3m", "final_error") == "eval/normal/goal_reaching_3m/final_error"
    for bad in ("", "...", "//"):
        with pytest.raises(ValueError, match="metric name"):
            metric_name(bad)
    assert flatten_config({"a": {"b": np.float32(0.5), "c": None}}) == {"a/b": 0.5, "a/c": "None"}


def test_task_names_are_cleaned_when_logged(tmp_path):
    with RunLogger("exp", tmp_path, backends=("csv",)) as logger:
        logger.log_metrics({"eval/normal/goal_reaching_1.5m/normalized_cost": 0.4}, step=0)
        with pytest.raises(ValueError, match="must be a number"):
            logger.log_scalar("eval/x", "high")
        with pytest.raises(ValueError, match="step"):
            logger.log_scalar("eval/x", 1.0, step=-1)
    assert list(scalar_files(logger.experiment_dir)) == ["scalars/eval/normal/goal_reaching_1p5m/normalized_cost.csv"]


def test_log_curve_puts_a_history_on_its_step_axis(tmp_path):
    with RunLogger("exp", tmp_path, backends=("csv",)) as logger:
        logger.log_curve("train/dynamics_normal", {"heldout_loss": [0.9, 0.5, 0.4], "train_loss": [1.0, 0.6]},
                         step_name="epoch")
        logger.log_curve("train/sac", {"reward": [-3.0, -1.0]}, step_name="frames", steps=[1000, 2000])
        for bad in ({"steps": [2, 1]}, {"steps": [0]}):
            with pytest.raises(ValueError, match="increasing"):
                logger.log_curve("train/x", {"y": [1.0, 2.0]}, **bad)
        with pytest.raises(ValueError, match="1-D"):
            logger.log_curve("train/x", {"y": [[1.0]]})
    files = scalar_files(logger.experiment_dir / "scalars")
    assert files["train/dynamics_normal/heldout_loss.csv"].read_text().splitlines() == ["1,0.9", "2,0.5", "3,0.4"]
    assert files["train/dynamics_normal/train_loss.csv"].read_text().splitlines() == ["1,1.0", "2,0.6"]
    assert files["train/sac/reward.csv"].read_text().splitlines() == ["1000,-3.0", "2000,-1.0"]


def test_tables_and_summary_on_csv(tmp_path):
    png = tmp_path / "figure.png"
    _write_png(png)
    with RunLogger("exp", tmp_path / "logs", backends=("csv",)) as logger:
        path = logger.log_table("eval/normal/episodes", [{"task": "goal_reaching_1.5m", "cost": 0.25},
                                                         {"task": "velocity_tracking", "cost": 0.5, "falls": 1}])
        logger.summary({"eval/normal/goal_reaching/normalized_cost": 0.25, "seed": np.int64(3)})
        logger.summary({"total_seconds": 12.5})
        logger.log_image("figures/latent_map", png)  # CSV keeps no images: nothing to write, nothing to fail
        with pytest.raises(ValueError, match="non-empty list of dicts"):
            logger.log_table("eval/empty", [])
        with pytest.raises(ValueError, match="no such image"):
            logger.log_image("figures/missing", tmp_path / "missing.png")
    assert path == logger.experiment_dir / "tables/eval/normal/episodes.csv"
    assert path.read_text().splitlines() == ["task,cost,falls", "goal_reaching_1.5m,0.25,", "velocity_tracking,0.5,1"]
    assert json.loads((logger.experiment_dir / "summary.json").read_text()) == {
        "eval/normal/goal_reaching/normalized_cost": 0.25, "seed": 3, "total_seconds": 12.5}


def _write_png(path, size=(24, 16)):
    from PIL import Image

    pixels = np.zeros((size[1], size[0], 3), np.uint8)
    pixels[:, : size[0] // 2, 0] = 255  # left half red
    Image.fromarray(pixels).save(path)
    return pixels


# ---------------------------------------------------------------------------------------------------- TensorBoard
def test_tensorboard_backend(tmp_path):
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    png = tmp_path / "figure.png"
    pixels = _write_png(png)
    with RunLogger("exp", tmp_path / "logs", backends=("tensorboard",), config={"robot": "a1"}) as logger:
        logger.log_scalar("eval/normal/goal_reaching_1.5m/normalized_cost", 0.3, step=2)
        logger.log_curve("train/dynamics", {"heldout_loss": [0.9, 0.5]}, step_name="epoch")
        logger.log_image("figures/latent_map", png, step=1)
        logger.log_table("eval/episodes", [{"task": "goal_reaching", "cost": 0.25}])
    assert logger.active_backends == ("csv", "tensorboard")
    events = EventAccumulator(str(logger.experiment_dir / "tensorboard"), size_guidance={"images": 0}).Reload()
    scalars = events.Scalars("eval/normal/goal_reaching_1p5m/normalized_cost")
    assert [(s.step, round(s.value, 6)) for s in scalars] == [(2, 0.3)]
    assert [(s.step, round(s.value, 6)) for s in events.Scalars("train/dynamics/heldout_loss")] == [(1, 0.9), (2, 0.5)]
    image = events.Images("figures/latent_map")[0]
    assert (image.step, image.width, image.height) == (1, pixels.shape[1], pixels.shape[0])
    assert "eval/episodes/text_summary" in events.Tags()["tensors"]
    assert (logger.experiment_dir / "scalars/train/dynamics/heldout_loss.csv").exists()  # CSV beside it


# ---------------------------------------------------------------------------------------------------- wandb
def test_wandb_offline_never_touches_the_network(tmp_path, wandb_home, monkeypatch, loopback_server):
    url, connections = loopback_server
    monkeypatch.setenv("WANDB_BASE_URL", url)  # any connection attempt to "the server" would arrive here
    monkeypatch.setenv("WANDB_API_KEY", FAKE_WANDB_KEY)
    png = tmp_path / "figure.png"
    _write_png(png)
    logger = RunLogger("a1_seed0", tmp_path / "logs", prefix="lat", backends=("wandb",), group="lat/a1/tiny",
                       tags=["tiny", "a1"], config={"robot": "a1"})
    assert logger.active_backends == ("csv", "wandb") and logger.wandb_problem is None
    logger.log_scalar("eval/normal/goal_reaching_1.5m/normalized_cost", 0.25, step=1)
    logger.log_curve("train/dynamics", {"heldout_loss": [0.9, 0.5]}, step_name="epoch")
    logger.log_image("figures/latent_map", png)
    logger.log_table("eval/episodes", [{"task": "goal_reaching", "cost": 0.25}])
    logger.summary({"eval/success_rate": 0.75})
    logger.log_video("eval/normal/goal_reaching/video", np.zeros((6, 16, 16, 3), np.uint8), fps=20)
    with pytest.raises(ValueError, match="T x H x W x 3 uint8"):
        logger.log_video("eval/normal/goal_reaching/video", np.zeros((6, 16, 16), np.uint8))
    checkpoint = tmp_path / "gait_policy.pt"
    checkpoint.write_bytes(b"weights")
    assert logger.log_artifact([checkpoint], "a1_seed0-run", "hierloco-run", {"gait_policy": "abc"})
    identity = logger.wandb_run
    assert identity["mode"] == "offline" and identity["group"] == "lat/a1/tiny" and identity["id"]
    logger.close()
    assert connections() == 0
    assert "WANDB_MODE" not in os.environ  # TorchRL's process-wide switch does not leak into later loggers
    runs = list((logger.experiment_dir / "wandb").glob("offline-run-*"))
    assert len(runs) == 1, list(logger.experiment_dir.rglob("*"))
    record = next(runs[0].glob("run-*.wandb")).read_bytes()
    for text in ("eval/normal/goal_reaching_1p5m/normalized_cost", "eval/normal/goal_reaching_1p5m/step",
                 "train/dynamics/heldout_loss", "train/dynamics/epoch", "figures/latent_map", "eval/episodes",
                 "eval/success_rate", "lat/a1/tiny", "tiny", logger.exp_name, "a1_seed0-run", "hierloco-run",
                 identity["id"]):
        assert text.encode() in record, text
    assert b"goal_reaching_1.5m" not in record
    assert list(runs[0].glob("files/media/videos/eval/normal/goal_reaching/video_*.mp4"))
    assert (logger.experiment_dir / "scalars/eval/normal/goal_reaching_1p5m/normalized_cost.csv").exists()


ONLINE_SCRIPT = textwrap.dedent("""
    import sys, time
    import wandb
    import torchrl.record.loggers
    from hierloco.loggers import RunLogger
    start = time.perf_counter()
    logger = RunLogger("a1_seed0", sys.argv[1], prefix="lat", wandb_mode="online", config={"robot": "a1"})
    seconds = time.perf_counter() - start
    logger.log_scalar("eval/normalized_cost", 0.5, step=2)
    logger.close()
    print(f"SECONDS {seconds:.2f} BACKENDS {','.join(logger.active_backends)} DIR {logger.experiment_dir}",
          flush=True)
    sys.stderr.flush()
    # not measured here: at exit wandb's own usage telemetry may wait up to 15 s more for a silent server
    import os; os._exit(0)
""")


def _run_online(tmp_path, wandb_home, base_url=None):
    """Starts an online RunLogger in a fresh process (as a recipe would); returns its stdout and stderr lines."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("WANDB_")}
    env.update(WANDB_API_KEY=FAKE_WANDB_KEY, WANDB_CONFIG_DIR=str(wandb_home), WANDB_CACHE_DIR=str(wandb_home),
               WANDB_DATA_DIR=str(wandb_home), PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    if base_url:
        env["WANDB_BASE_URL"] = base_url
    done = subprocess.run([sys.executable, "-c", ONLINE_SCRIPT, str(tmp_path / "logs")], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    out = done.stdout.strip().splitlines()
    words = out[-1].split()
    return float(words[1]), words[3].split(","), Path(words[5]), done.stderr.strip().splitlines()


def _check_fallback(seconds, backends, experiment_dir, stderr, reason):
    assert seconds < 15, seconds
    assert backends == ["csv"]
    assert len(stderr) == 1, stderr  # one line, no traceback
    assert stderr[0].startswith(f"wandb: {reason}") and stderr[0].endswith("; logging to CSV only"), stderr
    assert (experiment_dir / "scalars/eval/normalized_cost.csv").read_text() == "2,0.5\n"


def test_wandb_online_without_a_network(tmp_path, wandb_home):
    """Here the network reaches only package registries: the default wandb server cannot be reached."""
    seconds, backends, experiment_dir, stderr = _run_online(tmp_path, wandb_home)
    _check_fallback(seconds, backends, experiment_dir, stderr, reason="")


@pytest.mark.slow
def test_wandb_online_with_a_server_that_never_answers(tmp_path, wandb_home, loopback_server):
    """The server accepts the connection and then stays silent: wandb.init's timeout ends the wait."""
    url, connections = loopback_server
    seconds, backends, experiment_dir, stderr = _run_online(tmp_path, wandb_home, base_url=url)
    _check_fallback(seconds, backends, experiment_dir, stderr, reason="could not start")
    assert connections() >= 1  # it did try this server, and only this one


def test_a_recipe_run_records_its_wandb_run_and_logs_its_checkpoints(copy_run, wandb_home):
    """run.json names the wandb run (offline here) the run logged to, and the run's checkpoints go to it as one
    ``hierloco-run`` artifact; the CoM model's training loss is logged beside its held-out loss."""
    import json

    from tests.runner import run_in_process

    for stale in copy_run.glob("dynamics_model_normal.pt*"):  # trained again, so its curves are logged
        stale.unlink()
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "eval.videos=[]",
                            "logger.backends=[csv,wandb]", env={"WANDB_MODE": "offline"})
    assert result.returncode == 0, result.stderr[-3000:]
    identity = json.loads((copy_run / "run.json").read_text())["wandb"]
    assert identity["mode"] == "offline" and identity["group"] == "lat/a1/tiny"
    [record] = [p for p in (copy_run / "logs").rglob(f"run-{identity['id']}.wandb")]
    content = record.read_bytes()
    assert f"{copy_run.name}-run".encode() in content and b"hierloco-run" in content  # the checkpoints artifact
    assert b"train/dynamics_normal/train_loss" in content and b"train/dynamics_normal/heldout_loss" in content
