"""Run loggers: TorchRL's CSV logger always, wandb offline without network."""

import pytest

from hierloco.loggers import RunLogger


def scalar_files(log_dir):
    return {p.relative_to(log_dir).as_posix(): p for p in log_dir.rglob("*.csv")}


def test_csv_logger_writes_scalars(tmp_path):
    logger = RunLogger("exp", tmp_path, backends=("csv",), config={"robot": "a1", "seed": 3})
    logger.log_scalar("eval/normalized_cost", 0.25, step=3)
    logger.log_metrics({"eval/success_rate": 0.5, "time/plan_seconds": 0.125}, step=7)
    logger.close()
    files = scalar_files(tmp_path)
    name = next(k for k in files if k.endswith("eval/normalized_cost.csv"))
    assert name.startswith("exp/")
    assert files[name].read_text().strip().splitlines() == ["3,0.25"]
    success = next(p for k, p in files.items() if k.endswith("eval/success_rate.csv"))
    assert success.read_text().strip() == "7,0.5"
    assert any(k.endswith("time/plan_seconds.csv") for k in files)
    hparams = list(tmp_path.rglob("hparams*.txt"))
    assert hparams and "a1" in hparams[0].read_text()
    assert not (tmp_path / "wandb").exists()


def test_csv_is_always_on(tmp_path):
    logger = RunLogger("exp", tmp_path, backends=())
    logger.log_scalar("train/loss", 1.5)
    assert [k for k in scalar_files(tmp_path) if k.endswith("train/loss.csv")]


def test_unknown_backend(tmp_path):
    with pytest.raises(ValueError, match="tensorboard"):
        RunLogger("exp", tmp_path, backends=("csv", "tensorboard"))
    with pytest.raises(ValueError, match="wandb_mode"):
        RunLogger("exp", tmp_path, backends=("csv",), wandb_mode="cloud")
    assert not list(tmp_path.rglob("*.csv"))


def test_wandb_offline(tmp_path, monkeypatch):
    pytest.importorskip("wandb")  # skipped only when wandb cannot be imported
    # offline, and everything wandb writes stays under tmp_path (restored after the test)
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    for var in ("WANDB_CONFIG_DIR", "WANDB_CACHE_DIR", "WANDB_DATA_DIR"):
        monkeypatch.setenv(var, str(tmp_path / "wandb_home"))
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    log_dir = tmp_path / "logs"
    logger = RunLogger("exp", log_dir, backends=("wandb",), config={"robot": "a1"})
    logger.log_scalar("eval/normalized_cost", 0.25, step=1)
    logger.close()
    runs = list((log_dir / "wandb").glob("offline-run-*"))
    assert len(runs) == 1, list(log_dir.rglob("*"))
    records = list(runs[0].glob("run-*.wandb"))
    assert records and b"eval/normalized_cost" in records[0].read_bytes()
    # the CSV logger runs beside it
    assert [k for k in scalar_files(log_dir) if k.endswith("eval/normalized_cost.csv")]
