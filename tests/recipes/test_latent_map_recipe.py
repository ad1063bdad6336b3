"""The latent-map study end to end on tiny settings: a 2-D LAT job per robot and seed measuring its latent space's
continuity, its record (the measurement comes back from it), the tables; a bad config refused in one line."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "recipes" / "latent_map" / "run.py"


def run(*arguments, timeout=900):
    return subprocess.run([sys.executable, str(SCRIPT), *arguments], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "WANDB_MODE": "offline"}, timeout=timeout)


@pytest.mark.slow  # a tiny LAT run through Ray (~40 s)
def test_latent_map_study_tiny(tmp_path):
    import shutil

    out, records, runs = tmp_path / "out", tmp_path / "records", tmp_path / "runs"
    arguments = ["preset=tiny", "robots=[daisy]", "seeds=[0]", "grid=4", f"runs_dir={runs}", f"records={records}",
                 f"out_dir={out}"]
    result = run(*arguments)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = list(csv.DictReader((out / "latent_map.csv").open()))
    assert [(r["robot"], r["seed"], r["latent_dim"], r["grid"]) for r in rows] == [("daisy", "0", "2", "4")]
    near, pair = float(rows[0]["neighbour_difference"]), float(rows[0]["pair_difference"])
    assert 0 < near and 0 < pair and abs(float(rows[0]["ratio"]) - near / pair) < 1e-9
    assert (runs / "daisy_seed0" / "latent_continuity.json").is_file()
    shutil.rmtree(runs)  # a fresh machine: the job and its measurement come back from the record, nothing runs
    again = run(*arguments, f"out_dir={tmp_path / 'again'}")
    assert again.returncode == 0 and "1 from their records" in again.stdout, again.stdout[-2000:]
    assert (tmp_path / "again" / "latent_map.csv").read_text() == (out / "latent_map.csv").read_text()


@pytest.mark.parametrize("argument, message", [("grid=1", "grid must be an integer >= 2, got 1"),
                                               ("robots=[spot]", "unknown robot 'spot'"),
                                               ("robot_overrides=3", "robot_overrides must map robot names")])
def test_a_bad_config_is_one_line_before_any_job(tmp_path, argument, message):
    result = run(argument, f"runs_dir={tmp_path / 'runs'}", f"out_dir={tmp_path / 'out'}")
    assert result.returncode == 2 and message in result.stderr, result.stderr[-2000:]
    assert result.stderr.strip().count("\n") == 0 and not (tmp_path / "runs").exists()
