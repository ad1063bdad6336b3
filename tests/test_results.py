"""Results tables (results.csv, episodes.csv, results.md) and artifact I/O (atomic writes, array files)."""

import csv
import math
import os

import numpy as np
import pytest

from hierloco.io import ArtifactError, atomic_path, load_arrays, save_arrays, write_text
from hierloco.results import (
    RESULT_COLUMNS,
    markdown_table,
    read_csv,
    summarize_seeds,
    write_results,
)

# 2 seeds x 3 episodes of goal reaching, 2 seeds x 1 episode of velocity tracking (no success), one other method
GOAL_COSTS = {0: [0.2, 0.4, 0.6], 1: [0.3, 0.5, 1.0]}
GOAL_SUCCESS = {0: [1.0, 1.0, 0.0], 1: [1.0, 0.0, 0.0]}
GOAL_ERRORS = {0: [0.1, 0.15, 0.5], 1: [0.05, 0.3, 1.2]}


def episodes():
    rows = []
    for seed in (0, 1):
        for e in range(3):
            rows.append(dict(method="lat", robot="a1", setting="normal", task="goal_reaching", seed=seed, episode=e,
                             normalized_cost=GOAL_COSTS[seed][e], success=GOAL_SUCCESS[seed][e],
                             final_error=GOAL_ERRORS[seed][e]))
        rows.append(dict(method="lat", robot="a1", setting="normal", task="velocity_tracking", seed=seed, episode=0,
                         normalized_cost=0.1 + 0.1 * seed, success=math.nan, final_error=0.02))
    rows.append(dict(method="ik", robot="a1", setting="legs_disabled", task="goal_reaching", seed=0, episode=0,
                     normalized_cost=0.9, success=0.0, final_error=1.5))
    return rows


def test_results_csv(tmp_path):
    write_results(tmp_path, episodes())
    with open(tmp_path / "results.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == ["method", "robot", "setting", "task", "seed", "normalized_cost",
                                     "success_rate", "final_error"] == RESULT_COLUMNS
        raw = list(reader)
    assert len(raw) == 5  # (lat, goal) x 2 seeds, (lat, velocity) x 2 seeds, (ik, goal) x 1 seed
    rows = read_csv(tmp_path / "results.csv")
    by_key = {(r["method"], r["setting"], r["task"], r["seed"]): r for r in rows}
    assert len(by_key) == 5
    for seed in (0, 1):
        row = by_key["lat", "normal", "goal_reaching", seed]
        assert row["robot"] == "a1"
        assert row["normalized_cost"] == pytest.approx(np.mean(GOAL_COSTS[seed]))
        assert row["success_rate"] == pytest.approx(np.mean(GOAL_SUCCESS[seed]))
        assert row["final_error"] == pytest.approx(np.mean(GOAL_ERRORS[seed]))
        assert isinstance(row["seed"], int)
        velocity = by_key["lat", "normal", "velocity_tracking", seed]
        assert velocity["normalized_cost"] == pytest.approx(0.1 + 0.1 * seed)
        assert math.isnan(velocity["success_rate"])
    assert by_key["ik", "legs_disabled", "goal_reaching", 0]["normalized_cost"] == pytest.approx(0.9)


def test_read_csv_round_trip(tmp_path):
    rows = episodes()
    write_results(tmp_path, rows)
    back = read_csv(tmp_path / "episodes.csv")
    assert len(back) == len(rows)
    for original, read in zip(rows, back):
        assert set(read) == set(original) | {"path_distance", "steps_to_goal"}
        assert math.isnan(read["path_distance"])  # only trajectory tracking rows carry a path distance
        assert math.isnan(read["steps_to_goal"])  # and only goal reaching rows steps to the goal
        for key, value in original.items():
            if isinstance(value, float) and math.isnan(value):
                assert math.isnan(read[key])
            else:
                assert read[key] == value and type(read[key]) is type(value)
    summary = read_csv(tmp_path / "results.csv")
    for expected, read in zip(summarize_seeds(rows), summary):
        for key, value in expected.items():
            assert read[key] == value or (isinstance(value, float) and math.isnan(value) and math.isnan(read[key]))


def _line(table, method, setting, task):
    matches = [line for line in table.splitlines() if line.startswith(f"| {method} | a1 | {setting} | {task} |")]
    assert len(matches) == 1, table
    return [cell.strip() for cell in matches[0].strip("|").split("|")]


def test_markdown_mean_and_std_over_targets_and_seeds(tmp_path):
    table = write_results(tmp_path, episodes())
    assert (tmp_path / "results.md").read_text().endswith(table)
    costs = np.array(GOAL_COSTS[0] + GOAL_COSTS[1])  # 6 values: 3 targets x 2 seeds
    errors = np.array(GOAL_ERRORS[0] + GOAL_ERRORS[1])
    cells = _line(table, "lat", "normal", "goal_reaching")
    # population std (ddof=0) over the 6 (target, seed) values: 0.50 +- 0.26 and 0.38 +- 0.39
    # (a sample std, ddof=1, would give 0.28 and 0.43)
    assert cells[4] == f"{costs.mean():.2f} +- {costs.std():.2f}" == "0.50 +- 0.26"
    assert cells[5] == "50%"  # 3 of 6 episodes succeeded
    assert cells[6] == f"{errors.mean():.2f} +- {errors.std():.2f}" == "0.38 +- 0.39"
    assert cells[7] == "2"  # seeds
    velocity = _line(table, "lat", "normal", "velocity_tracking")
    assert velocity[4] == "0.15 +- 0.05" and velocity[5] == "-" and velocity[7] == "2"
    ik = _line(table, "ik", "legs_disabled", "goal_reaching")
    assert ik[4] == "0.90 +- 0.00" and ik[5] == "0%" and ik[7] == "1"
    lines = table.splitlines()
    assert lines[0].startswith("| method | robot | setting | task | normalized cost | success | final error")
    assert len(lines) == 2 + 3
    assert all(line.endswith("| - |") for line in lines[2:])  # no path distances in these rows


def test_path_distance_column(tmp_path):
    rows = [dict(method="lat", robot="a1", setting="normal", task="trajectory_tracking", seed=s, episode=0,
                 normalized_cost=0.1, success=1.0, final_error=0.05, path_distance=d) for s, d in ((0, 0.02), (1, 0.04))]
    table = write_results(tmp_path, rows)
    assert _line(table, "lat", "normal", "trajectory_tracking")[8] == "0.03 +- 0.01"
    assert [r["path_distance"] for r in read_csv(tmp_path / "episodes.csv")] == [0.02, 0.04]


def test_markdown_ignores_missing_success_of_some_episodes():
    rows = episodes()[:3]
    rows[1] = {**rows[1], "success": math.nan}
    cells = _line(markdown_table(rows), "lat", "normal", "goal_reaching")
    assert cells[5] == "50%"  # 1 of the 2 episodes that have a success flag


def test_writes_leave_no_temp_files(tmp_path):
    write_results(tmp_path, episodes())
    write_results(tmp_path, episodes())  # overwriting works too
    assert sorted(os.listdir(tmp_path)) == ["episodes.csv", "results.csv", "results.md"]
    save_arrays(tmp_path / "a.npz", {"x": np.arange(4)}, {"k": 1})
    write_text(tmp_path / "sub" / "t.txt", "hello")
    assert sorted(os.listdir(tmp_path)) == ["a.npz", "episodes.csv", "results.csv", "results.md", "sub"]
    assert os.listdir(tmp_path / "sub") == ["t.txt"]


def test_atomic_path_failure_keeps_the_previous_file(tmp_path):
    target = tmp_path / "results.md"
    write_text(target, "previous")
    with pytest.raises(RuntimeError, match="interrupted"):
        with atomic_path(target) as tmp:
            with open(tmp, "w") as f:
                f.write("half a new fi")
            assert target.read_text() == "previous"  # nothing under the final name until the end
            raise RuntimeError("interrupted")
    assert target.read_text() == "previous"
    assert os.listdir(tmp_path) == ["results.md"]
    # a failure before anything existed leaves nothing at all
    with pytest.raises(RuntimeError):
        with atomic_path(tmp_path / "new.npz"):
            raise RuntimeError("interrupted")
    assert os.listdir(tmp_path) == ["results.md"]


def test_atomic_files_have_normal_permissions(tmp_path):
    write_text(tmp_path / "a.txt", "x")
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o666 & ~umask


def test_arrays_round_trip(tmp_path):
    path = tmp_path / "data.npz"
    arrays = {"x": np.arange(6.0).reshape(2, 3), "i": np.array([1, 2], dtype=np.int64)}
    save_arrays(path, arrays, {"robot": "daisy", "n": 3})
    loaded, metadata = load_arrays(path)
    assert metadata == {"robot": "daisy", "n": 3}
    assert set(loaded) == {"x", "i"}
    for name in arrays:
        assert np.array_equal(loaded[name], arrays[name]) and loaded[name].dtype == arrays[name].dtype


@pytest.mark.parametrize("corrupt", ["truncated", "garbage", "empty", "no_metadata", "missing"])
def test_load_arrays_bad_file_names_it(tmp_path, corrupt):
    path = tmp_path / "dynamics_data_normal.npz"
    save_arrays(path, {"x": np.random.default_rng(0).normal(size=(200, 5))}, {"robot": "a1"})
    data = path.read_bytes()
    if corrupt == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif corrupt == "garbage":
        path.write_bytes(b"not a zip file at all" * 10)
    elif corrupt == "empty":
        path.write_bytes(b"")
    elif corrupt == "no_metadata":
        with open(path, "wb") as f:
            np.savez(f, x=np.zeros(3))
    else:
        path.unlink()
    with pytest.raises(ArtifactError, match="dynamics_data_normal.npz"):
        load_arrays(path)
