"""The ensemble study (issue of the research API): LAT's MLP against a probabilistic ensemble and risk-aware
planning, each variant judged against the MLP by the stated tests paired by seed, and the ensemble's disagreement
set against its error on fresh transitions in every setting."""

import pytest

from hierloco.results import read_csv
from hierloco.recipes.ensemble.run import calibration_markdown, verdict_table
from tests.runner import run_in_process, run_subprocess


def rows(method: str, costs: dict) -> list[dict]:
    return [{"robot": "a1", "setting": setting, "task": "goal_reaching", "method": method, "seed": seed,
             "episode": 0, "normalized_cost": cost}
            for setting, per_seed in costs.items() for seed, cost in enumerate(per_seed)]


def test_each_variant_is_judged_against_the_mlp_paired_by_seed():
    mlp = rows("mlp", {"normal": [0.30, 0.50, 0.40], "hardware_unadapted": [0.30, 0.50, 0.40],
                       "legs_disabled": [0.95, 0.97, 0.99]})
    # the same seeds' runs 0.1 lower (better), 0.001 off (close), both at standing still (not testable)
    ensemble = rows("ensemble", {"normal": [0.20, 0.40, 0.30], "hardware_unadapted": [0.301, 0.499, 0.401],
                                 "legs_disabled": [0.96, 0.98, 0.97]})
    text = verdict_table(mlp + ensemble, ["mlp", "ensemble"], ("goal_reaching",))
    line = {cells.split(" | ")[1]: cells for cells in text.splitlines() if cells.startswith("| a1 | ")}
    assert line["normal"].split(" | ")[4].startswith("holds")  # paired: the seeds' spread does not hide it
    assert line["hardware_unadapted"].split(" | ")[5].startswith("holds")
    assert "not testable" in line["legs_disabled"]
    assert "| ensemble | 1 | 1 | 0 | 1 | 0 |" in text


def test_the_calibration_table_averages_seeds_per_setting():
    found = [{"robot": "a1", "seed": seed, "setting": "hardware_unadapted", "model": "normal", "output": output,
              "error": 0.1 * (seed + 1), "spread": 0.01, "noise": 0.02, "coverage": 0.5}
             for seed in (0, 1) for output in ("dx", "dy", "dyaw", "vx", "vy")]
    text = calibration_markdown(found)
    assert "| a1 | hardware_unadapted (normal) | 0.150 / 0.010 / 0.020 |" in text and "| 50 % | 2 |" in text


def test_a_bad_calibration_size_is_one_line_before_any_work(tmp_path):
    result = run_in_process("ensemble", "preset=tiny", "calibration_transitions=-1", cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "calibration_transitions must be an integer >= 0, got -1" in result.lines[0]
    assert not (tmp_path / "outputs").exists()


@pytest.mark.slow  # six tiny LAT jobs through Ray (~4 min)
def test_the_tiny_ensemble_study_writes_its_verdicts_and_calibration(tmp_path):
    out = tmp_path / "out"
    result = run_subprocess("ensemble", "preset=tiny", "robots=[a1]", "seeds=[0,1]", "risks=[none,mean_std]",
                            "settings=[normal,hardware_unadapted]", "members=2", "calibration_transitions=40",
                            f"out_dir={out}", cwd=tmp_path)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    costs = read_csv(out / "ensemble.csv")
    assert {r["method"] for r in costs} == {"mlp", "ensemble", "ensemble_mean_std"}
    verdicts = (out / "verdicts.md").read_text()
    assert "| a1 | hardware_unadapted | goal_reaching | ensemble_mean_std |" in verdicts
    found = read_csv(out / "calibration.csv")
    assert {(r["setting"], r["model"]) for r in found} == {("normal", "normal"), ("hardware_unadapted", "normal")}
    assert {int(r["seed"]) for r in found} == {0, 1} and len(found) == 2 * 2 * 5
    assert all(float(r["spread"]) > 0 and 0 <= float(r["coverage"]) <= 1 for r in found)
