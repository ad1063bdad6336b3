"""The sample-efficiency study: LAT's and SAC's costs against their task layer's samples, the full budgets taken from
the comparison's runs or records, the claims decided over seeds."""

import shutil

import pytest

from hierloco.results import read_csv
from hierloco.recipes.sample_efficiency.run import check_claims, samples_in_all
from tests.runner import ROOT, run_in_process, run_subprocess

COMPARE_RECORDS = ROOT / "results" / "compare_full" / "records"


def test_the_full_budgets_are_the_comparisons_jobs_taken_from_its_records(tmp_path):
    """At the paper preset the preset's own budgets are the comparison's LAT and SAC jobs: with no run directory here
    the plan takes both from the committed comparison records (read only), and plans only the smaller budgets."""
    result = run_in_process("sample_efficiency", "robots=[a1]", "seeds=[0]", f"compare_records={COMPARE_RECORDS}",
                            "dry_run=true", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "7 jobs, 2 finished, 5 to run" in result.stdout, result.stdout
    for method in ("lat", "sac"):
        assert f"from its record ({COMPARE_RECORDS / method / 'paper' / 'a1_seed0'})" in result.stdout
    for run in ("lat_5000", "lat_2000", "lat_1000", "sac_5000", "sac_2000"):
        assert f"sample_efficiency/paper/a1_seed0/{run} | to run" in result.stdout
    assert not (tmp_path / "outputs").exists()  # a dry run writes nothing


@pytest.mark.parametrize("override, message", [
    ("sac_samples=[1000]", "sac_samples: 1000 is not an integer in [1001, 10000)"),
    ("lat_samples=[10000]", "lat_samples: 10000 is not an integer in [1, 10000)"),
    ("compare_records=[x]", "compare_records must be a directory path or null"),
])
def test_a_budget_the_study_cannot_run_is_one_line(tmp_path, override, message):
    result = run_in_process("sample_efficiency", "robots=[a1]", "seeds=[0]", override, cwd=tmp_path)
    assert result.returncode == 2 and len(result.lines) == 1 and result.lines[0].startswith("error: "), result.stderr
    assert message in result.lines[0], result.lines[0]
    assert not (tmp_path / "outputs").exists()


def test_the_claims_compare_equal_budgets_and_the_saturation(tmp_path):
    def curve(method, samples, costs):
        return [{"robot": "a1", "method": method, "task": "goal_reaching", "samples_per_task": samples, "seed": s,
                 "cost": c} for s, c in enumerate(costs)]

    curves = [*curve("lat", 1000, [0.30, 0.32, 0.31]), *curve("lat", 2000, [0.20, 0.21, 0.19]),
              *curve("lat", 10000, [0.20, 0.20, 0.21]), *curve("sac", 2000, [0.60, 0.62, 0.58]),
              *curve("sac", 10000, [0.19, 0.21, 0.20])]
    claims = {c.claim: c.verdict for c in check_claims(curves, 10000)}
    assert claims == {
        "LAT with 2000 samples in all is better than SAC with 2000 per task": "holds",
        "LAT with 10000 samples in all is better than SAC with 10000 per task": "does not hold",
        "LAT with 1000 samples is close to LAT with 10000": "does not hold",
        "LAT with 2000 samples is close to LAT with 10000": "holds",
    }
    assert samples_in_all("sac", 2000, 3) == 6000 and samples_in_all("lat", 2000, 3) == 2000


@pytest.mark.slow  # two tiny studies through Ray (~2 min)
def test_tiny_study_reuses_the_low_level_and_takes_full_budgets_from_another_study_s_records(tmp_path):
    first, again = tmp_path / "first", tmp_path / "again"
    first.mkdir(), again.mkdir()
    common = ["preset=tiny", "robots=[a1]", "seeds=[0]", "lat_samples=[200]", "sac_samples=[48]"]
    result = run_subprocess("sample_efficiency", *common, "compare_records=null", f"records={tmp_path / 'records'}",
                            f"out_dir={first / 'out'}", cwd=first)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    rows = read_csv(first / "out" / "sample_efficiency.csv")
    assert {r["method"] for r in rows} == {"lat 200", "lat 500", "sac 48", "sac 64"}
    assert {r["setting"] for r in rows} == {"normal"}  # the comparison's LAT job also ran legs_disabled: not here
    curves = read_csv(first / "out" / "curves.csv")
    assert {(r["method"], r["samples_in_all"]) for r in curves} == {("lat", "200"), ("lat", "500"), ("sac", "144"),
                                                                    ("sac", "192")}
    assert (first / "out" / "sample_efficiency.png").read_bytes()[:4] == b"\x89PNG"
    assert "LAT with 200 samples is close to LAT with 500" in (first / "out" / "paper_check.md").read_text()
    # a smaller budget starts from the low level of the run before it: only its task layer is new
    smaller = first / "outputs" / "sample_efficiency" / "tiny" / "a1_seed0" / "lat_200"
    full = first / "outputs" / "lat" / "tiny" / "a1_seed0"
    assert (smaller / "gait_policy.pt").read_bytes() == (full / "gait_policy.pt").read_bytes()
    assert (smaller / "dynamics_data_normal.npz").read_bytes() != (full / "dynamics_data_normal.npz").read_bytes()
    # elsewhere, the full budgets come from the first study's records (read only), the smaller ones run again
    borrowed = tmp_path / "borrowed"
    shutil.copytree(tmp_path / "records", borrowed)
    before = sorted(p.relative_to(borrowed) for p in borrowed.rglob("*"))
    result = run_subprocess("sample_efficiency", *common, f"compare_records={borrowed}", f"out_dir={again / 'out'}",
                            cwd=again)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert f"2 from the records in {borrowed}" in result.stdout, result.stdout[-2000:]
    assert not (again / "outputs" / "lat").exists() and not (again / "outputs" / "sac").exists()
    assert sorted(p.relative_to(borrowed) for p in borrowed.rglob("*")) == before  # nothing written there
    assert read_csv(again / "out" / "curves.csv") == curves  # the same numbers
