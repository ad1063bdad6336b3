"""What SAC-SAC's low-level report says of its budget, from the learning curve."""

import subprocess
import sys
from pathlib import Path

from hierloco.recipes.sac_sac.report import budget_from_curve, budget_sentence

ROOT = Path(__file__).resolve().parents[2]


def curve(errors, step=20_000):
    return [{"frames": step * (i + 1), "tracking_error": e} for i, e in enumerate(errors)]


def test_a_curve_that_flattens_gives_the_frames_where_it_does():
    errors = [0.6, 0.5, 0.4, 0.3, 0.2, 0.15, 0.12, 0.1] + [0.07, 0.066, 0.064, 0.068, 0.065] * 4
    budget = budget_from_curve(curve(errors))
    assert not budget["still_improving"] and abs(budget["final_error"] - 0.066) < 0.002
    # the moving mean of 5 points stays within 10 % of 0.066 from the first window without the 0.1 point
    assert budget["plateau_frames"] == 20_000 * 9
    assert "flat from about 180,000 frames" in budget_sentence(budget)


def test_a_curve_still_falling_says_more_frames_would_help():
    errors = [1.0 - 0.03 * i for i in range(30)]
    budget = budget_from_curve(curve(errors))
    assert budget["still_improving"] and "still improving at the end" in budget_sentence(budget)


def test_a_short_curve_is_not_judged():
    budget = budget_from_curve(curve([0.5, 0.4, 0.3]))
    assert budget["plateau_frames"] is None and "too few log points" in budget_sentence(budget)


def test_the_report_refuses_a_run_without_a_low_level(tmp_path):
    result = subprocess.run([sys.executable, str(ROOT / "recipes" / "sac_sac" / "report.py"), str(tmp_path),
                             str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "missing sac_low_level.pt, sac_low_level_tracking.json" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
