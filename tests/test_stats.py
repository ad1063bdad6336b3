"""hierloco.stats: the t distribution against known values, and each verdict of each kind of claim on synthetic
per-seed costs."""

import math

import numpy as np
import pytest
import scipy.stats

from hierloco.stats import (DOES_NOT_HOLD, HOLDS, INCONCLUSIVE, NOT_TESTABLE, bootstrap_interval, decide_all,
                            decide_better, decide_close, power, seeds_needed, t_cdf, t_ppf, t_two_sided_p, welch,
                            welch_t_test)


# --- the t distribution: known values -------------------------------------------------------------------------------

@pytest.mark.parametrize("t, df, p", [
    (2.0, 10, 0.0734),      # the example
    (2.228, 10, 0.0500),    # the 97.5 % point of t(10), from any t table
    (12.706, 1, 0.0500),    # t(1)
    (4.303, 2, 0.0500),     # t(2)
    (2.571, 5, 0.0500),     # t(5)
    (1.960, 1e9, 0.0500),   # the normal limit
    (0.0, 3, 1.0),
])
def test_two_sided_p_matches_t_tables(t, df, p):
    assert t_two_sided_p(t, df) == pytest.approx(p, abs=5e-5)


def test_t_cdf_closed_forms_for_one_and_two_degrees_of_freedom():
    for t in (-7.5, -1.0, -0.2, 0.3, 1.0, 4.0, 30.0):
        assert t_cdf(t, 1) == pytest.approx(0.5 + math.atan(t) / math.pi, abs=1e-12)           # Cauchy
        assert t_cdf(t, 2) == pytest.approx(0.5 + t / (2 * math.sqrt(2 + t * t)), abs=1e-12)
    assert t_cdf(math.inf, 4) == 1.0 and t_cdf(-math.inf, 4) == 0.0
    assert t_cdf(1.3, 7.5) + t_cdf(-1.3, 7.5) == pytest.approx(1.0, abs=1e-14)  # symmetric, any real df


def test_t_ppf_inverts_the_cdf():
    assert t_ppf(0.975, 10) == pytest.approx(2.228, abs=5e-4)
    assert t_ppf(0.95, 3) == pytest.approx(2.353, abs=5e-4)
    for p in (0.01, 0.2, 0.5, 0.9, 0.999):
        for df in (1.5, 4.0, 30.0):
            assert t_cdf(t_ppf(p, df), df) == pytest.approx(p, abs=1e-10)
    with pytest.raises(ValueError, match="0 < p < 1"):
        t_ppf(1.0, 3)


def test_t_cdf_closed_forms_for_three_four_and_infinite_degrees_of_freedom():
    for t in (-7.5, -1.0, -0.2, 0.3, 1.0, 4.0, 30.0):
        u = t / math.sqrt(3)
        assert t_cdf(t, 3) == pytest.approx(0.5 + (math.atan(u) + u / (1 + u * u)) / math.pi, abs=1e-12)
        s = 1 + t * t / 4
        assert t_cdf(t, 4) == pytest.approx(0.5 + 0.375 * t / math.sqrt(s) * (1 - t * t / (12 * s)), abs=1e-12)
        assert t_cdf(t, math.inf) == pytest.approx(0.5 * math.erfc(-t / math.sqrt(2)), abs=1e-12)   # the normal
    assert t_ppf(0.975, math.inf) == pytest.approx(1.959964, abs=1e-6)
    for bad in (0.0, -2.0):
        with pytest.raises(ValueError, match="df > 0"):
            t_cdf(1.0, bad)
        with pytest.raises(ValueError, match="df > 0"):
            t_ppf(0.9, bad)


def test_welch_statistic_degrees_of_freedom_and_p():
    t, df, p = welch_t_test([1.0, 2.0, 3.0, 4.0], [2.0, 4.0, 6.0, 8.0])
    # by hand: means 2.5 and 5, variances 5/3 and 20/3, se^2 = 5/12 + 20/12, df = se^4 / sum((v/n)^2 / (n-1))
    assert t == pytest.approx(-2.5 / math.sqrt(25 / 12), abs=1e-12)
    assert df == pytest.approx((25 / 12) ** 2 / ((5 / 12) ** 2 / 3 + (20 / 12) ** 2 / 3), abs=1e-12)
    assert p == pytest.approx(t_two_sided_p(t, df)) and 0.1 < p < 0.2
    reference = scipy.stats.ttest_ind([1.0, 2.0, 3.0, 4.0], [2.0, 4.0, 6.0, 8.0], equal_var=False)
    assert (t, df, p) == (pytest.approx(reference.statistic, abs=1e-12), pytest.approx(reference.df, abs=1e-12),
                          pytest.approx(reference.pvalue, abs=1e-12))
    paired = welch([0.3, 0.5, 0.4], [0.2, 0.3, 0.3], paired=True)   # differences 0.1, 0.2, 0.1
    assert (paired.estimate, paired.df) == (pytest.approx(0.4 / 3), 2.0)
    assert paired.se == pytest.approx(np.std([0.1, 0.2, 0.1], ddof=1) / math.sqrt(3))
    constant = welch([0.8, 0.9, 0.7], 1.0)
    assert constant.estimate == pytest.approx(-0.2) and constant.df == 2.0
    with pytest.raises(ValueError, match="2 or more"):
        welch([0.1], [0.2, 0.3])


def test_bootstrap_is_seeded_and_brackets_the_difference():
    x, y = [0.31, 0.35, 0.29, 0.33, 0.30, 0.36, 0.32, 0.34], [0.21, 0.25, 0.20, 0.23, 0.22, 0.24, 0.19, 0.26]
    first = bootstrap_interval(x, y, 0.9, seed=3)
    assert first == bootstrap_interval(x, y, 0.9, seed=3) != bootstrap_interval(x, y, 0.9, seed=4)
    assert first[0] < np.mean(x) - np.mean(y) < first[1] and first[0] > 0.07
    low, high = bootstrap_interval(x, y, 0.9, paired=True, seed=0)
    assert low < 0.1 < high


# --- "better": each verdict --------------------------------------------------------------------------------------

def test_better_holds_when_significant_and_large_enough():
    decision = decide_better([0.12, 0.11, 0.13], [0.45, 0.49, 0.44])
    assert decision.verdict == HOLDS and decision.p < 0.001 and decision.low > 0
    assert decision.threshold == pytest.approx(0.1 * np.mean([0.45, 0.49, 0.44]))


def test_better_does_not_hold_when_the_cost_is_significantly_higher():
    decision = decide_better([0.86, 0.88, 0.84], [0.74, 0.73, 0.76])
    assert decision.verdict == DOES_NOT_HOLD and "significantly higher cost" in decision.reason


def test_better_does_not_hold_when_the_gain_is_significantly_below_the_minimum_effect():
    # 0.010 lower, tightly measured: significant, yet well under 10 % of 0.50
    decision = decide_better([0.490, 0.491, 0.489, 0.490], [0.500, 0.501, 0.499, 0.500])
    assert decision.verdict == DOES_NOT_HOLD and decision.p < 0.001 and decision.high < decision.threshold


def test_better_is_inconclusive_within_the_spread_of_the_seeds():
    # the audit's case: IK on damaged Daisy 0.51 / 1.01 / 0.54 per seed against LAT 0.62 / 0.87 / 0.54
    decision = decide_better([0.62, 0.87, 0.54], [0.51, 1.01, 0.54])
    assert decision.verdict == INCONCLUSIVE and decision.low < 0 < decision.high


def test_better_is_not_testable_when_both_are_no_better_than_standing_still():
    # the audit's case: A1 with its rear legs locked, LAT 0.93 against IK 1.01
    decision = decide_better([0.934, 0.907, 0.937], [1.014, 1.039, 0.969])
    assert decision.verdict == NOT_TESTABLE and "0.93, 1.01" in decision.reason
    # one of them at 0.9 or above is not enough to make it untestable
    assert decide_better([0.12, 0.11, 0.13], [0.95, 0.97, 0.96]).verdict == HOLDS


def test_better_against_a_constant_and_paired():
    assert decide_better([0.24, 0.25, 0.23], 1.0).verdict == HOLDS            # better than standing still
    assert decide_better([0.95, 0.99, 0.97], 1.0).verdict == DOES_NOT_HOLD    # not 10 % below it
    # the same seeds' runs: a consistent gain that the spread between seeds hides from Welch
    a, b = [0.10, 0.20, 0.30], [0.13, 0.235, 0.33]
    assert decide_better(a, b).verdict == INCONCLUSIVE
    assert decide_better(a, b, paired=True).verdict == HOLDS


def test_better_by_bootstrap():
    a = [0.30, 0.32, 0.29, 0.31, 0.33, 0.30, 0.28, 0.31]
    b = [0.45, 0.47, 0.44, 0.48, 0.46, 0.45, 0.43, 0.47]
    decision = decide_better(a, b, method="bootstrap")
    assert decision.verdict == HOLDS and decision.p is None and decision.method == "bootstrap"
    assert decide_better(a, a, method="bootstrap").verdict == DOES_NOT_HOLD
    with pytest.raises(ValueError, match="unknown method"):
        decide_better(a, b, method="permutation")


def test_fewer_than_two_seeds_is_inconclusive():
    assert decide_better([0.1], [0.5, 0.6]).verdict == INCONCLUSIVE
    assert decide_close([0.1, 0.1], [0.5]).verdict == INCONCLUSIVE


# --- "close": each verdict ---------------------------------------------------------------------------------------

def test_close_holds_inside_the_relative_margin():
    decision = decide_close([0.090, 0.088, 0.092], [0.091, 0.089, 0.090])
    assert decision.verdict == HOLDS and decision.p < 0.05
    assert decision.threshold == pytest.approx(0.2 * 0.09)
    assert decide_close([0.010, 0.012], [0.015, 0.016]).threshold == 0.01  # 20 % of 0.0155: below the floor


def test_close_does_not_hold_sixty_percent_above():
    # the audit's case: Daisy velocity tracking, LAT 0.16 against the tuned IK's 0.10 ("close" within 0.1 before)
    decision = decide_close([0.157, 0.162, 0.166], [0.109, 0.092, 0.089])
    assert decision.verdict == DOES_NOT_HOLD and "higher" in decision.reason
    assert decision.threshold == pytest.approx(0.2 * np.mean([0.109, 0.092, 0.089]))


def test_close_does_not_hold_far_below_either():
    decision = decide_close([0.12, 0.11, 0.12], [0.37, 0.38, 0.38])
    assert decision.verdict == DOES_NOT_HOLD and "lower" in decision.reason


def test_close_is_inconclusive_when_the_interval_straddles_the_margin():
    decision = decide_close([0.10, 0.16, 0.12], [0.10, 0.11, 0.09])
    assert decision.verdict == INCONCLUSIVE and decision.low < decision.threshold < decision.high


def test_close_is_not_testable_when_both_stand_still():
    assert decide_close([0.93, 0.94, 0.92], [0.92, 0.93, 0.93]).verdict == NOT_TESTABLE


# --- claims of several parts, and seeds -------------------------------------------------------------------------

def test_a_claim_of_several_parts():
    lat = [0.12, 0.11, 0.13]
    whole, _ = decide_all([(lat, [0.45, 0.49, 0.44]), (lat, [0.60, 0.66, 0.57])], decide_better)
    assert whole.verdict == HOLDS
    tight = [0.120, 0.121, 0.119]
    whole, parts = decide_all([(tight, [0.45, 0.49, 0.44]), (tight, [0.121, 0.120, 0.122])], decide_better)
    assert whole.verdict == DOES_NOT_HOLD and [p.verdict for p in parts] == [HOLDS, DOES_NOT_HOLD]
    whole, _ = decide_all([(lat, [0.45, 0.49, 0.44]), (lat, [0.10, 0.30, 0.16])], decide_better)
    assert whole.verdict == INCONCLUSIVE
    still = [0.95, 0.96, 0.94]
    assert decide_all([(still, [1.0, 1.1, 0.99])], decide_better)[0].verdict == NOT_TESTABLE
    # a refutation within alpha but not within alpha / parts (Bonferroni) leaves the claim undecided
    a, b = [0.50, 0.52, 0.51, 0.53], [0.53, 0.55, 0.54, 0.56]   # 0.03 lower; the minimum effect is 0.055
    alone = decide_better(a, b)
    assert alone.verdict == DOES_NOT_HOLD
    whole, parts = decide_all([(a, b)] * 20, decide_better)
    assert {p.verdict for p in parts} == {INCONCLUSIVE} and whole.verdict == INCONCLUSIVE


def test_power_grows_with_seeds_and_seeds_needed_decides():
    a, b = [0.30, 0.40, 0.35], [0.45, 0.55, 0.40]
    assert decide_better(a, b).verdict == INCONCLUSIVE
    chances = [power(a, b, n) for n in (3, 5, 10, 20)]
    assert chances == sorted(chances) and chances[0] < 0.8 <= chances[1]
    assert seeds_needed(a, b) == 5
    # an effect measured right at the minimum effect is never decided: no seed count is enough
    assert seeds_needed([0.90, 0.91, 0.89], [1.0, 1.01, 0.99]) is None
    close_a, close_b = [0.10, 0.13, 0.11], [0.10, 0.11, 0.09]
    assert decide_close(close_a, close_b).verdict == INCONCLUSIVE
    needed = seeds_needed(close_a, close_b, kind="close")
    assert needed is not None and needed > 3 and power(close_a, close_b, needed, kind="close") >= 0.8
    # one seed on a side: no spread to estimate a power from, said rather than guessed
    with pytest.raises(ValueError, match="at least 2 seeds per side"):
        seeds_needed([0.2], [0.5, 0.6, 0.55])


def test_the_example_of_docs_statistics_runs_as_printed(capsys):
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "statistics.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    exec(compile(code, "docs/statistics.md", "exec"), {})
    printed = capsys.readouterr().out.splitlines()
    expected = []
    for line in code.splitlines():  # what each print says: the comment on its line, or on the line after it
        if line.startswith("# ") and expected and expected[-1] is None:
            expected[-1] = line[2:]
        elif line.startswith("print("):
            expected.append(line.split("#", 1)[1].strip() if "#" in line else None)
    assert len(printed) == len(expected)
    for got, want in zip(printed, expected):
        assert want is None or got == want or want.startswith(got + ":"), (got, want)


def test_the_docstring_examples_run():
    import doctest

    import hierloco.stats

    assert doctest.testmod(hierloco.stats).failed == 0


def test_holm_and_benjamini_hochberg_give_the_known_adjusted_p_values_of_a_toy_family():
    from hierloco.stats import benjamini_hochberg, holm

    family = [0.01, 0.04, 0.03, 0.005]
    # Holm: sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 -> 0.02, 0.03, 0.06, 0.04 -> monotone 0.02, 0.03, 0.06, 0.06
    assert holm(family) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    # BH: m p / rank = 0.02, 0.02, 0.04, 0.04, then the running minimum from the largest down
    assert benjamini_hochberg(family) == pytest.approx([0.02, 0.04, 0.04, 0.02])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0]) and holm([]) == []
    assert benjamini_hochberg([0.001, 0.8, 0.9]) == pytest.approx([0.003, 0.9, 0.9])


def test_the_refuting_p_is_below_the_refuting_level_exactly_when_a_claim_is_refuted():
    from hierloco.stats import ALPHA, DOES_NOT_HOLD, borderline, decide_better, decide_close

    cases = [(decide_better, [0.50, 0.52, 0.51], [0.50, 0.51, 0.53]),
             (decide_better, [0.9, 0.95, 0.92], [0.6, 0.62, 0.61]),
             (decide_better, [0.40, 0.50, 0.45], [0.5, 0.55, 0.52]),
             (decide_close, [0.16, 0.16, 0.17], [0.10, 0.11, 0.09]),
             (decide_close, [0.10, 0.16, 0.12], [0.10, 0.11, 0.09]),
             (decide_close, [0.01, 0.012, 0.011], [0.2, 0.21, 0.2])]
    for decide, a, b in cases:
        decision = decide(a, b)
        assert (decision.verdict == DOES_NOT_HOLD) == (decision.p_refute < ALPHA), (decide.__name__, a, b, decision)
    assert borderline(0.0498) and borderline(0.01) and not borderline(0.0099) and not borderline(0.05)
