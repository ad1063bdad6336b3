"""Deciding a claim about costs from a few seeds: Welch's t-test, a seeded bootstrap, equivalence, power.

The paper's claims compare mean normalised costs (Li et al., RA-L 2021, Sec. IV): one method is *better* (a lower
cost) than another, or *close* to it. With a handful of seeds per method a fixed margin cannot tell a difference
from the spread between seeds, so each claim is decided by a test over the seeds' mean costs (each seed's mean over
its episodes first) and gets one of four verdicts (``docs/statistics.md``):

- :data:`HOLDS`: the data establish the claim at level :data:`ALPHA`;
- :data:`DOES_NOT_HOLD`: the data establish the opposite (for "better": the improvement is significantly smaller than
  the minimum effect, which includes a significantly *higher* cost; for "close": the difference is significantly
  outside the equivalence margin);
- :data:`INCONCLUSIVE`: neither, at this many seeds (:func:`seeds_needed` estimates how many would decide it);
- :data:`NOT_TESTABLE`: every method compared is no better than standing still (mean normalised cost >=
  :data:`NOT_TESTABLE_COST`), so an ordering between them says nothing about the claim.

Both decisions read a confidence interval of the difference ``d`` (Welch's t interval by default, a percentile
bootstrap on request), at ``1 - 2 alpha`` for the one-sided tests that establish a claim:

- **better** (``a`` lower than ``b``), ``d = mean(b) - mean(a)``, minimum effect ``delta = max(MIN_EFFECT_REL *
  mean(b), MIN_EFFECT_ABS)``: holds when the interval's lower end is above 0 (a one-sided test at ``alpha``) and
  ``d >= delta``; does not hold when its upper end is below ``delta``.
- **close** (``a`` within a margin of ``ref``), ``d = mean(a) - mean(ref)``, margin ``m = max(EQUIV_MARGIN_REL *
  mean(ref), EQUIV_MARGIN_ABS)``: two one-sided tests (TOST) — holds when the ``1 - 2 alpha`` interval lies inside
  ``(-m, m)``; does not hold when the ``1 - alpha`` interval lies wholly outside ``[-m, m]``.

The t distribution's CDF and quantiles come from ``scipy.stats.t``; the bootstrap resamples with numpy.

Example (three seeds each; LAT's cost against a baseline's):
    >>> lat, lib = [0.12, 0.11, 0.13], [0.45, 0.49, 0.44]
    >>> decide_better(lat, lib).verdict
    'holds'
    >>> decide_close([0.16, 0.16, 0.17], [0.10, 0.11, 0.09]).verdict   # 60 % above: not close
    'does not hold'
    >>> round(t_two_sided_p(2.0, 10), 4)
    0.0734
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

ALPHA = 0.05              # the level of every test (one-sided for "better", each side of TOST for "close")
MIN_EFFECT_REL = 0.10     # "better": the lower cost at least 10 % below the other's mean ...
MIN_EFFECT_ABS = 0.01     # ... and at least 0.01 normalised cost (1 % of standing still's cost)
EQUIV_MARGIN_REL = 0.20   # "close": within 20 % of the reference's mean cost ...
EQUIV_MARGIN_ABS = 0.01   # ... or within 0.01 normalised cost, whichever is wider
NOT_TESTABLE_COST = 0.9   # a method at or above this mean normalised cost is (close to) no better than standing still
POWER = 0.8               # the chance of reaching a verdict that seeds_needed asks for
BOOTSTRAP_SAMPLES = 10_000

HOLDS, DOES_NOT_HOLD, INCONCLUSIVE, NOT_TESTABLE = "holds", "does not hold", "inconclusive", "not testable here"
VERDICTS = (HOLDS, DOES_NOT_HOLD, INCONCLUSIVE, NOT_TESTABLE)


# --- the t distribution (scipy.stats) ---------------------------------------------------------------------------------

def _student_t():
    """``scipy.stats.t``, imported on first use: ``scipy.stats`` takes about a second to import, and the study
    drivers and ``recipes.verdicts`` import this module before they parse their command line."""
    from scipy.stats import t

    return t


def t_cdf(t: float, df: float) -> float:
    """``P(T <= t)`` for Student's t with ``df > 0`` degrees of freedom (not necessarily whole; ``inf``: the normal
    distribution), from ``scipy.stats.t``.

        >>> round(t_cdf(2.228, 10), 3)        # the 97.5 % point of t(10) is 2.228
        0.975
        >>> t_cdf(0.0, 3)
        0.5
    """
    if not df > 0:
        raise ValueError(f"t_cdf needs df > 0, got {df}")
    return float(_student_t().cdf(t, df))


def t_two_sided_p(t: float, df: float) -> float:
    """The two-sided p-value ``P(|T| >= |t|)`` of Student's t with ``df`` degrees of freedom.

        >>> round(t_two_sided_p(2.0, 10), 4)
        0.0734
    """
    return 2.0 * t_cdf(-abs(t), df)


def t_ppf(p: float, df: float) -> float:
    """The quantile ``t`` with ``t_cdf(t, df) = p`` (``0 < p < 1``), from ``scipy.stats.t``.

        >>> round(t_ppf(0.975, 10), 3)
        2.228
    """
    if not 0.0 < p < 1.0:
        raise ValueError(f"t_ppf needs 0 < p < 1, got {p}")
    if not df > 0:
        raise ValueError(f"t_ppf needs df > 0, got {df}")
    return float(_student_t().ppf(p, df))


# --- the difference of two means -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Difference:
    """``estimate = mean(x) - mean(y)`` with its standard error ``se`` and degrees of freedom ``df`` (Welch-
    Satterthwaite for two groups; ``n - 1`` for one group against a constant or for paired differences)."""

    estimate: float
    se: float
    df: float

    def interval(self, level: float) -> tuple[float, float]:
        """The two-sided ``level`` confidence interval of the difference (Welch's t interval)."""
        if self.se == 0.0:
            return self.estimate, self.estimate
        half = t_ppf(0.5 + level / 2.0, self.df) * self.se
        return self.estimate - half, self.estimate + half

    @property
    def t(self) -> float:
        return math.copysign(math.inf, self.estimate) if self.se == 0.0 else self.estimate / self.se

    def p_greater(self, value: float = 0.0) -> float:
        """The one-sided p-value of ``H0: difference <= value`` against ``difference > value``."""
        if self.se == 0.0:
            return 0.0 if self.estimate > value else 1.0
        return 1.0 - t_cdf((self.estimate - value) / self.se, self.df)

    def p_less(self, value: float = 0.0) -> float:
        """The one-sided p-value of ``H0: difference >= value`` against ``difference < value``."""
        if self.se == 0.0:
            return 0.0 if self.estimate < value else 1.0
        return t_cdf((self.estimate - value) / self.se, self.df)


def _values(x, name: str) -> np.ndarray:
    values = np.asarray(x, dtype=float).ravel()
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name}: every value must be finite, got {values.tolist()}")
    return values


def welch(x: Sequence[float], y: Sequence[float] | float, *, paired: bool = False) -> Difference:
    """``mean(x) - mean(y)`` for independent samples (Welch), paired samples (``paired``: the mean of ``x - y``,
    one per seed), or ``y`` a constant (a one-sample t). Each sample needs at least 2 values.

        >>> d = welch([1.0, 2.0, 3.0, 4.0], [2.0, 4.0, 6.0, 8.0])
        >>> round(d.estimate, 2), round(d.se, 4), round(d.df, 3)
        (-2.5, 1.4434, 4.412)
    """
    x = _values(x, "x")
    if np.ndim(y) == 0:
        if x.size < 2:
            raise ValueError(f"a one-sample t needs 2 or more values, got {x.size}")
        return Difference(float(x.mean() - float(y)), float(x.std(ddof=1) / math.sqrt(x.size)), float(x.size - 1))
    y = _values(y, "y")
    if paired:
        if x.size != y.size:
            raise ValueError(f"paired samples need the same number of values, got {x.size} and {y.size}")
        return welch(x - y, 0.0)
    if x.size < 2 or y.size < 2:
        raise ValueError(f"Welch's t needs 2 or more values per sample, got {x.size} and {y.size}")
    vx, vy = x.var(ddof=1) / x.size, y.var(ddof=1) / y.size
    se2 = vx + vy
    if se2 == 0.0:
        df = float(x.size + y.size - 2)
    else:
        df = se2 ** 2 / (vx ** 2 / (x.size - 1) + vy ** 2 / (y.size - 1))
    return Difference(float(x.mean() - y.mean()), math.sqrt(se2), float(df))


def welch_t_test(x: Sequence[float], y: Sequence[float]) -> tuple[float, float, float]:
    """Welch's two-sample t-test: ``(t, df, two-sided p)`` of ``mean(x) - mean(y)``.

        >>> t, df, p = welch_t_test([0.10, 0.12, 0.11], [0.20, 0.22, 0.19])
        >>> round(t, 2), round(df, 2), round(p, 4)
        (-8.85, 3.45, 0.0017)
    """
    d = welch(x, y)
    return d.t, d.df, (0.0 if d.se == 0.0 else t_two_sided_p(d.t, d.df))


def bootstrap_interval(x: Sequence[float], y: Sequence[float] | float, level: float, *, paired: bool = False,
                       samples: int = BOOTSTRAP_SAMPLES, seed: int = 0) -> tuple[float, float]:
    """The percentile bootstrap ``level`` interval of ``mean(x) - mean(y)``: each sample resampled with replacement
    on its own (both together when ``paired``; ``y`` a constant is not resampled), ``samples`` times, from
    ``numpy.random.default_rng(seed)``. At a few seeds it is too narrow (it has no small-sample correction):
    prefer Welch's interval below about 8 seeds per method.

        >>> low, high = bootstrap_interval([0.1, 0.2, 0.3, 0.2, 0.1, 0.3, 0.2, 0.2], 0.0, 0.9)
        >>> 0.15 < low < 0.2 < high < 0.25
        True
    """
    rng = np.random.default_rng(seed)
    x = _values(x, "x")
    if np.ndim(y) == 0:
        means = x[rng.integers(0, x.size, (samples, x.size))].mean(axis=1) - float(y)
    else:
        y = _values(y, "y")
        if paired:
            if x.size != y.size:
                raise ValueError(f"paired samples need the same number of values, got {x.size} and {y.size}")
            index = rng.integers(0, x.size, (samples, x.size))
            means = (x[index] - y[index]).mean(axis=1)
        else:
            means = (x[rng.integers(0, x.size, (samples, x.size))].mean(axis=1)
                     - y[rng.integers(0, y.size, (samples, y.size))].mean(axis=1))
    tail = (1.0 - level) / 2.0
    return float(np.quantile(means, tail)), float(np.quantile(means, 1.0 - tail))


# --- decisions -----------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Decision:
    """A claim decided: ``verdict`` (one of :data:`VERDICTS`), the ``kind`` of claim (``"better"`` or ``"close"``),
    the difference ``estimate`` (better: ``mean(b) - mean(a)``, the cost ``a`` saves; close: ``mean(a) -
    mean(ref)``), its ``1 - 2 alpha`` interval ``(low, high)``, ``p`` (the p-value of the test that would establish
    the claim: one-sided for better, the larger TOST p for close; ``None`` from the bootstrap), ``threshold`` (the
    minimum effect or the margin), the numbers of seeds ``n``, the ``method`` and a short ``reason``."""

    verdict: str
    kind: str
    estimate: float = math.nan
    low: float = math.nan
    high: float = math.nan
    p: float | None = None
    threshold: float = math.nan
    n: tuple[int, ...] = ()
    method: str = "welch"
    reason: str = ""
    p_refute: float | None = None   # the p-value of the test that would refute it (compared with refute_alpha)

    def text(self) -> str:
        """The verdict with its reason, e.g. ``"holds (d = 0.34 [0.29, 0.39], p = 0.0004, min effect 0.05)"``."""
        return f"{self.verdict} ({self.reason})" if self.reason else self.verdict


def _mean(x) -> float:
    return float(x) if np.ndim(x) == 0 else float(np.mean(_values(x, "sample")))


def _count(x) -> int:
    return 0 if np.ndim(x) == 0 else int(np.asarray(x).size)


def _not_testable(a, b, kind: str, limit: float) -> Decision | None:
    if np.ndim(b) == 0:
        return None  # against a constant (say standing still itself) the rule does not apply
    means = (_mean(a), _mean(b))
    if min(means) >= limit:
        return Decision(NOT_TESTABLE, kind, n=(_count(a), _count(b)),
                        reason=f"both at or above {limit} of standing still's cost: {means[0]:.2f}, {means[1]:.2f}")
    return None


def _difference_and_intervals(x, y, *, levels, paired, method, seed, sign=1.0):
    """``sign * (mean(x) - mean(y))`` and its intervals at ``levels``."""
    d = welch(x, y, paired=paired)
    d = Difference(sign * d.estimate, d.se, d.df)
    if method == "welch":
        return d, [d.interval(level) for level in levels]
    if method == "bootstrap":
        intervals = [bootstrap_interval(x, y, level, paired=paired, seed=seed) for level in levels]
        return d, [(low, high) if sign > 0 else (-high, -low) for low, high in intervals]
    raise ValueError(f"unknown method {method!r} (welch, bootstrap)")


def _too_few(a, b, kind) -> Decision | None:
    counts = (_count(a), _count(b))
    need = [c for c in counts if c != 0]
    if any(c < 2 for c in need) or not need:
        return Decision(INCONCLUSIVE, kind, n=counts, reason=f"fewer than 2 seeds ({counts[0]}, {counts[1]})")
    return None


def decide_better(a: Sequence[float], b: Sequence[float] | float, *, alpha: float = ALPHA,
                  min_effect_rel: float = MIN_EFFECT_REL, min_effect_abs: float = MIN_EFFECT_ABS,
                  method: str = "welch", paired: bool = False, refute_alpha: float | None = None,
                  not_testable: float = NOT_TESTABLE_COST, seed: int = 0) -> Decision:
    """"``a`` has a lower cost than ``b``", from per-seed mean costs ``a`` (``S_a``) and ``b`` (``S_b``, or a
    constant such as 1.0, standing still). Holds when ``d = mean(b) - mean(a)`` is significantly above 0 (one-sided,
    ``alpha``) and at least the minimum effect ``max(min_effect_rel * mean(b), min_effect_abs)``; does not hold when
    ``d`` is significantly below the minimum effect (one-sided, ``refute_alpha``, default ``alpha``); not testable
    when both means are at or above ``not_testable``; else inconclusive. ``paired``: ``a[i]`` and ``b[i]`` come from
    the same seed's run (a paired t on the differences).

        >>> decide_better([0.60, 0.62, 0.61], [0.90, 0.93, 0.91]).verdict
        'holds'
        >>> decide_better([0.93, 0.94, 0.92], [1.01, 1.04, 0.97]).verdict     # both no better than standing still
        'not testable here'
        >>> decide_better([0.68, 0.87, 0.54], [0.51, 1.01, 0.54]).verdict     # within the spread of the seeds
        'inconclusive'
    """
    refute_alpha = alpha if refute_alpha is None else refute_alpha
    if (found := _not_testable(a, b, "better", not_testable) or _too_few(a, b, "better")) is not None:
        return found
    delta = max(min_effect_rel * _mean(b), min_effect_abs)
    d, ((low, high), (_, refute_high)) = _difference_and_intervals(
        a, b, levels=(1 - 2 * alpha, 1 - 2 * refute_alpha), paired=paired, method=method, seed=seed, sign=-1.0)
    p = d.p_greater(0.0) if method == "welch" else None
    where = f"d = {d.estimate:.3f} [{low:.3f}, {high:.3f}]" + (f", p = {p:.3g}" if p is not None else "")
    p_refute = d.p_less(delta) if method == "welch" else None   # H0: d >= delta; refuted when the upper end < delta
    common = dict(kind="better", estimate=d.estimate, low=low, high=high, p=p, threshold=delta,
                  n=(_count(a), _count(b)), method=method, p_refute=p_refute)
    if low > 0 and d.estimate >= delta:
        return Decision(HOLDS, reason=f"{where}; min effect {delta:.3f}", **common)
    if refute_high < delta:
        why = "a significantly higher cost" if refute_high < 0 else f"a gain significantly below {delta:.3f}"
        return Decision(DOES_NOT_HOLD, reason=f"{where}; {why}", **common)
    return Decision(INCONCLUSIVE, reason=f"{where}; min effect {delta:.3f}", **common)


def decide_close(a: Sequence[float], ref: Sequence[float] | float, *, alpha: float = ALPHA,
                 margin_rel: float = EQUIV_MARGIN_REL, margin_abs: float = EQUIV_MARGIN_ABS,
                 method: str = "welch", paired: bool = False, refute_alpha: float | None = None,
                 not_testable: float = NOT_TESTABLE_COST, seed: int = 0) -> Decision:
    """"``a`` is close to ``ref``": an equivalence test (two one-sided tests, TOST) of ``d = mean(a) - mean(ref)``
    against the margin ``m = max(margin_rel * mean(ref), margin_abs)``, from per-seed mean costs (``S_a``,
    ``S_ref``). Holds when the ``1 - 2 alpha`` interval of ``d`` lies inside ``(-m, m)``; does not hold when the
    ``1 - refute_alpha`` interval (default ``alpha``) lies wholly outside ``[-m, m]`` (either side: a much lower
    cost is not "close" either); not testable when both means are at or above ``not_testable``; else inconclusive.

        >>> decide_close([0.090, 0.088, 0.092], [0.091, 0.089, 0.090]).verdict
        'holds'
        >>> decide_close([0.16, 0.16, 0.17], [0.10, 0.11, 0.09]).verdict
        'does not hold'
        >>> decide_close([0.10, 0.16, 0.12], [0.10, 0.11, 0.09]).verdict
        'inconclusive'
    """
    refute_alpha = alpha if refute_alpha is None else refute_alpha
    if (found := _not_testable(a, ref, "close", not_testable) or _too_few(a, ref, "close")) is not None:
        return found
    margin = max(margin_rel * _mean(ref), margin_abs)
    d, ((low, high), (refute_low, refute_high)) = _difference_and_intervals(
        a, ref, levels=(1 - 2 * alpha, 1 - refute_alpha), paired=paired, method=method, seed=seed)
    p = max(d.p_greater(-margin), d.p_less(margin)) if method == "welch" else None
    where = f"d = {d.estimate:+.3f} [{low:+.3f}, {high:+.3f}]" + (f", TOST p = {p:.3g}" if p is not None else "")
    # refuted when the 1 - refute_alpha interval lies outside [-m, m]: either one-sided test at refute_alpha / 2
    p_refute = min(1.0, 2.0 * min(d.p_greater(margin), d.p_less(-margin))) if method == "welch" else None
    common = dict(kind="close", estimate=d.estimate, low=low, high=high, p=p, threshold=margin,
                  n=(_count(a), _count(ref)), method=method, p_refute=p_refute)
    if -margin < low and high < margin:
        return Decision(HOLDS, reason=f"{where}; margin {margin:.3f}", **common)
    if refute_low > margin or refute_high < -margin:
        side = "higher" if d.estimate > 0 else "lower"
        return Decision(DOES_NOT_HOLD, reason=f"{where}; significantly {side} than the margin {margin:.3f} allows",
                        **common)
    return Decision(INCONCLUSIVE, reason=f"{where}; margin {margin:.3f}", **common)


def decide_all(parts: Sequence[tuple], decide: Callable[..., Decision], **options) -> tuple[Decision, list[Decision]]:
    """A claim made of several parts, each ``(a, b)`` decided by ``decide`` (:func:`decide_better` or
    :func:`decide_close`): it holds when every part holds (an intersection-union test: each at ``alpha``, no
    correction needed); it does not hold when any part does not hold, each refuted at ``alpha / len(parts)``
    (Bonferroni, so the claim is not refuted by chance among many parts); not testable when every part is; else
    inconclusive. Returns the combined decision and the parts'.

        >>> lat = [0.12, 0.11, 0.13]
        >>> whole, parts = decide_all([(lat, [0.45, 0.49, 0.44]), (lat, [0.60, 0.66, 0.57])], decide_better)
        >>> whole.verdict, [p.verdict for p in parts]
        ('holds', ['holds', 'holds'])
    """
    if not parts:
        raise ValueError("decide_all needs at least one part")
    alpha = options.get("alpha", ALPHA)
    decisions = [decide(a, b, refute_alpha=alpha / len(parts), **options) for a, b in parts]
    verdicts = [d.verdict for d in decisions]
    kind = decisions[0].kind
    if all(v == NOT_TESTABLE for v in verdicts):
        return Decision(NOT_TESTABLE, kind, reason="every part not testable"), decisions
    if DOES_NOT_HOLD in verdicts:
        return Decision(DOES_NOT_HOLD, kind, reason=f"{verdicts.count(DOES_NOT_HOLD)} of {len(parts)} parts do not "
                        "hold"), decisions
    if all(v == HOLDS for v in verdicts):
        return Decision(HOLDS, kind, reason=f"all {len(parts)} parts hold"), decisions
    return Decision(INCONCLUSIVE, kind, reason=", ".join(f"{verdicts.count(v)} {v}" for v in VERDICTS
                                                          if verdicts.count(v))), decisions


# --- many claims: multiplicity, borderline verdicts -------------------------------------------------------------------

BORDERLINE = (0.01, ALPHA)   # a verdict whose deciding p-value lies in [0.01, alpha) is borderline


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values of a family of tests (controls the family-wise error rate): sorted
    ascending, the i-th (from 0) is ``max_{j <= i} min(1, (m - j) p_(j))``; returned in the order given. A test of the
    family is significant at ``alpha`` when its adjusted p-value is below ``alpha``.

        >>> holm([0.01, 0.04, 0.03, 0.005])
        [0.03, 0.06, 0.06, 0.02]
    """
    p = [float(x) for x in p_values]
    m, adjusted, running = len(p), [0.0] * len(p), 0.0
    for rank, i in enumerate(sorted(range(m), key=lambda i: p[i])):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adjusted[i] = round(running, 12)
    return adjusted


def benjamini_hochberg(p_values: Sequence[float]) -> list[float]:
    """Benjamini-Hochberg adjusted p-values (q-values; controls the false discovery rate): sorted ascending, the
    i-th (from 1) is ``min_{j >= i} min(1, m p_(j) / j)``; returned in the order given.

        >>> benjamini_hochberg([0.01, 0.04, 0.03, 0.005])
        [0.02, 0.04, 0.04, 0.02]
    """
    p = [float(x) for x in p_values]
    m, adjusted, running = len(p), [0.0] * len(p), 1.0
    order = sorted(range(m), key=lambda i: p[i])
    for rank in range(m, 0, -1):
        i = order[rank - 1]
        running = min(running, min(1.0, m * p[i] / rank))
        adjusted[i] = round(running, 12)
    return adjusted


def borderline(p: float | None, *, alpha: float = ALPHA, low: float = BORDERLINE[0]) -> bool:
    """Whether a verdict decided by p-value ``p`` at level ``alpha`` is borderline: ``low <= p < alpha``.

        >>> borderline(0.0498), borderline(0.004), borderline(0.2), borderline(None)
        (True, False, False, False)
    """
    return p is not None and low <= p < alpha


# --- how many seeds would decide it --------------------------------------------------------------------------------

def power(a: Sequence[float], b: Sequence[float] | float, n: int, *, kind: str = "better", alpha: float = ALPHA,
          min_effect_rel: float = MIN_EFFECT_REL, min_effect_abs: float = MIN_EFFECT_ABS,
          margin_rel: float = EQUIV_MARGIN_REL, margin_abs: float = EQUIV_MARGIN_ABS, paired: bool = False) -> float:
    """The chance that ``n`` seeds per method decide the claim in the direction the measured seeds point to, if the
    true means and standard deviations are the measured ones (``a``, ``b``: per-seed mean costs): for "better",
    holding when ``d >= delta`` and not holding when below; for "close", holding when ``|d| < m`` and not holding
    when above. The sampling distribution of ``d`` is taken as ``d + se_n T`` with ``T`` Student's t at the Welch
    degrees of freedom of ``n`` seeds each (a shifted central t: the usual approximation to the noncentral t).

        >>> round(power([0.30, 0.40, 0.35], [0.45, 0.55, 0.40], 3), 2)     # measured: inconclusive, p = 0.051
        0.49
        >>> round(power([0.30, 0.40, 0.35], [0.45, 0.55, 0.40], 5), 2)
        0.81
    """
    a_values = _values(a, "a")
    if np.ndim(b) == 0 or paired:
        spread = float((a_values - (0.0 if np.ndim(b) == 0 else _values(b, "b"))).std(ddof=1))
        se, df = spread / math.sqrt(n), float(n - 1)
        d_a_minus_b = float(a_values.mean()) - _mean(b)
    else:
        b_values = _values(b, "b")
        va, vb = float(a_values.var(ddof=1)) / n, float(b_values.var(ddof=1)) / n
        se = math.sqrt(va + vb)
        df = (va + vb) ** 2 / (va ** 2 / (n - 1) + vb ** 2 / (n - 1)) if va + vb > 0 else float(2 * n - 2)
        d_a_minus_b = float(a_values.mean() - b_values.mean())
    if se == 0.0:
        return 1.0
    ref = _mean(b)
    if kind == "better":
        d, delta = -d_a_minus_b, max(min_effect_rel * ref, min_effect_abs)
        t = t_ppf(1 - alpha, df)
        if d >= delta:  # holds: lower end above 0 and the estimate at least delta
            return 1.0 - t_cdf((max(t * se, delta) - d) / se, df)
        return t_cdf((delta - d) / se - t, df)  # does not hold: upper end below delta
    if kind == "close":
        d, margin = d_a_minus_b, max(margin_rel * ref, margin_abs)
        if abs(d) < margin:
            t = t_ppf(1 - alpha, df)
            return max(0.0, t_cdf((margin - d) / se - t, df) - t_cdf((-margin - d) / se + t, df))
        t = t_ppf(1 - alpha / 2, df)
        return 1.0 - t_cdf(t - (abs(d) - margin) / se, df)
    raise ValueError(f"unknown kind {kind!r} (better, close)")


def seeds_needed(a: Sequence[float], b: Sequence[float] | float, *, target: float = POWER, most: int = 100,
                 **options) -> int | None:
    """The fewest seeds per method (at least the ones measured) at which :func:`power` reaches ``target``, or
    ``None`` when not even ``most`` would (say, an effect measured right at the minimum effect). A side measured on
    one seed has no spread to go on: ``ValueError``.

        >>> seeds_needed([0.30, 0.40, 0.35], [0.45, 0.55, 0.40])     # inconclusive at 3 (p = 0.051)
        5
        >>> seeds_needed([0.68, 0.87, 0.54], [0.51, 1.01, 0.54]) is None   # 0.01 apart in a spread of 0.2
        True
    """
    if _count(a) < 2 or (np.ndim(b) and _count(b) < 2):
        raise ValueError(f"seeds_needed needs at least 2 seeds per side to measure the spread, got {_count(a)} and "
                         f"{_count(b) if np.ndim(b) else 'a constant'}")
    start = max(_count(a), _count(b) if np.ndim(b) else 0, 2)
    for n in range(start, most + 1):
        if power(a, b, n, **options) >= target:
            return n
    return None


__all__ = ["ALPHA", "BOOTSTRAP_SAMPLES", "BORDERLINE", "benjamini_hochberg", "borderline", "holm", "DOES_NOT_HOLD",
           "Decision", "Difference", "EQUIV_MARGIN_ABS",
           "EQUIV_MARGIN_REL", "HOLDS", "INCONCLUSIVE", "MIN_EFFECT_ABS", "MIN_EFFECT_REL", "NOT_TESTABLE",
           "NOT_TESTABLE_COST", "POWER", "VERDICTS", "bootstrap_interval", "decide_all", "decide_better",
           "decide_close", "power", "seeds_needed", "t_cdf", "t_ppf", "t_two_sided_p", "welch", "welch_t_test"]
