"""The statistics of a report, each against values worked out by hand on small samples."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from conftest import bootstrap_t_reference, hall_bounds, newcombe_bounds
from scipy import stats

from kraby_study.decision.comparison import compare, holm
from kraby_study.decision.intervals import (
    BAND_NAME,
    INTERVAL_NAME,
    IQM_INTERVAL_NAME,
    bootstrap_t_interval,
    describe,
    hall_interval,
    iqm,
    iqm_interval,
    mean_interval,
    sample_skewness,
    t_interval,
)
from kraby_study.decision.measures import (
    auc,
    default_threshold,
    first_reach,
    iqr,
    p_improvement,
    p_improvement_interval,
)
from kraby_study.decision.verdict import Verdict, empty_verdict, verdict

NAN = math.nan
SPREAD = [3.1, 0.4, 2.2, 5.9, 1.7, 4.4, 2.8, 3.6, 0.9, 5.1]
"""Ten distinct values, enough for intervals of some width."""


def nan_pair(pair: tuple[float, float]) -> bool:
    return math.isnan(pair[0]) and math.isnan(pair[1])


# IQM and its interval -----------------------------------------------------------------------------


def test_iqm_is_the_mean_of_the_middle_half() -> None:
    # n = 8: cut 2 from each end, the middle four 3, 4, 5, 6 average 4.5; order does not matter.
    assert iqm([1, 2, 3, 4, 5, 6, 7, 8]) == pytest.approx(4.5)
    assert iqm([8, 1, 7, 2, 6, 3, 5, 4]) == pytest.approx(4.5)
    # n = 5: cut floor(5 / 4) = 1 from each end: (2 + 3 + 4) / 3 = 3, the outlier 100 ignored.
    assert iqm([1, 2, 3, 4, 100]) == pytest.approx(3.0)
    # n = 3: nothing to cut, the plain mean.
    assert iqm([1, 2, 6]) == pytest.approx(3.0)
    assert math.isnan(iqm([]))


def test_iqm_interval_on_a_hand_worked_trimmed_t() -> None:
    # [1, 2, 3, 4, 10]: g = 1 cut from each end, IQM = mean(2, 3, 4) = 3. Winsorised at g:
    # [2, 2, 3, 4, 4], sd 1 (squares 1+1+0+1+1 over 4). se = 1 / (0.5 sqrt 5); t(0.975, 2).
    half = 4.302652729911275 * 1 / (0.5 * math.sqrt(5))
    assert iqm_interval([10.0, 1.0, 3.0, 2.0, 4.0]) == pytest.approx((3 - half, 3 + half))
    # n < 4: nothing cut, the Student-t interval of the mean (not Hall's: [0, 1, 5] is skewed).
    assert iqm_interval([0.0, 1.0]) == pytest.approx(mean_interval([0.0, 1.0])[1:])
    half = stats.t.ppf(0.975, 2) * stats.sem([0.0, 1.0, 5.0])
    assert iqm_interval([0.0, 1.0, 5.0]) == pytest.approx((2 - half, 2 + half))


def test_iqm_interval_contains_the_estimate_and_narrows_with_the_level() -> None:
    low, high = iqm_interval(SPREAD)
    assert low < iqm(SPREAD) < high
    narrow = iqm_interval(SPREAD, level=0.5)
    assert low < narrow[0] < narrow[1] < high


def test_iqm_interval_edge_cases_without_warnings() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert nan_pair(iqm_interval([]))
        assert nan_pair(iqm_interval([4.0]))
        assert iqm_interval([2.5, 2.5, 2.5]) == (2.5, 2.5)


def test_interval_names_name_the_method_and_the_procedure() -> None:
    assert IQM_INTERVAL_NAME.startswith("95 % Tukey-McLaughlin trimmed-t interval")
    assert INTERVAL_NAME.startswith("95 % interval of the mean over seeds: from 5 seeds on, the "
                                    "equal-tailed studentised bootstrap (bootstrap-t)")
    assert "2,000 resamples" in INTERVAL_NAME and "Hall's skewness-corrected t" in INTERVAL_NAME
    assert BAND_NAME.startswith("95 % Hall skewness-corrected t interval of the mean")


# Sample efficiency and time to a threshold -----------------------------------------------------


def test_auc_is_the_mean_of_the_curve() -> None:
    # Five bins rising 2, 4, 6, 8, 10: area 30 bin-widths over 5 bins = 6.
    assert auc([2.0, 4.0, 6.0, 8.0, 10.0]) == pytest.approx(6.0)
    # Same final reward, reached sooner: more area.
    assert auc([2.0, 10.0, 10.0, 10.0, 10.0]) == pytest.approx(8.4)
    assert math.isnan(auc([]))


def test_first_reach() -> None:
    steps, times = [100, 200, 300, 400, 500], [1.5, 2.5, 3.5, 4.5, 5.5]
    rewards = [0.0, 5.0, 9.0, 7.0, 12.0]
    assert first_reach(steps, rewards, times, 9.0) == (300.0, 3.5)  # equal counts as reached
    assert first_reach(steps, rewards, times, 8.0) == (300.0, 3.5)  # the first, not the last
    assert first_reach(steps, rewards, times, -1.0) == (100.0, 1.5)
    assert nan_pair(first_reach(steps, rewards, times, 12.5))
    assert nan_pair(first_reach(steps, rewards, times, NAN))
    assert nan_pair(first_reach([], [], [], 0.0))


def test_default_threshold() -> None:
    assert default_threshold(10.0, 110.0) == pytest.approx(100.0)
    assert default_threshold(10.0, 110.0, fraction=0.5) == pytest.approx(60.0)
    # Negative rewards: -200 + 0.9 * (-20 - -200) = -200 + 162 = -38.
    assert default_threshold(-200.0, -20.0) == pytest.approx(-38.0)


# Spread ------------------------------------------------------------------------------------------


def test_iqr() -> None:
    # Linear interpolation: [1..5] has Q1 = 2 and Q3 = 4; [1..4] has Q1 = 1.75, Q3 = 3.25.
    assert iqr([5, 1, 4, 2, 3]) == pytest.approx(2.0)
    assert iqr([1, 2, 3, 4]) == pytest.approx(1.5)
    assert iqr([7.0]) == 0.0
    assert math.isnan(iqr([]))


def test_mean_interval() -> None:
    # [1, 2, 3]: mean 2, sd 1, skewness 0, so Hall's interval is the Student-t one: half-width
    # t(0.975, 2) / sqrt(3) = 4.3027 / 1.7321 = 2.4841.
    mean, low, high = mean_interval([1.0, 2.0, 3.0])
    half = stats.t.ppf(0.975, 2) / math.sqrt(3)
    assert half == pytest.approx(2.4841, abs=1e-4)
    assert (mean, low, high) == pytest.approx((2.0, 2.0 - half, 2.0 + half))
    mean, low, high = mean_interval([4.0])
    assert mean == 4.0 and math.isnan(low) and math.isnan(high)
    assert all(math.isnan(v) for v in mean_interval([]))


def test_mean_interval_is_halls_on_a_hand_worked_skewed_sample() -> None:
    # [1, 2, 3, 10]: mean 4, deviations -3, -2, -1, 6; m2 = 50 / 4 = 12.5, m3 = 180 / 4 = 45,
    # skewness 45 / 12.5^1.5 = 1.01823; s = sqrt(50 / 3), b = 1.01823 / (3 * 2) = 0.169706.
    x = [1.0, 2.0, 3.0, 10.0]
    assert sample_skewness(x) == pytest.approx(45 / 12.5 ** 1.5, rel=1e-12)
    assert sample_skewness(x) == pytest.approx(stats.skew(x, bias=True), rel=1e-12)
    mean, low, high = mean_interval(x)
    # The inverse by another route: the real root of the cubic g(T) = v (numpy.roots).
    assert (mean, low, high) == pytest.approx(hall_bounds(x), rel=1e-9)
    # By hand: g^-1(v) = ((1 + 3 b (v - b / 2))^(1/3) - 1) / b at v = +-q, q = t(0.975, 3).
    b, q, se = 45 / 12.5 ** 1.5 / 6, stats.t.ppf(0.975, 3), math.sqrt(50 / 3) / 2
    def inverse(v: float) -> float:
        w = 1 + 3 * b * (v - b / 2)
        return (math.copysign(abs(w) ** (1 / 3), w) - 1) / b
    assert (low, high) == pytest.approx((4 - inverse(q) * se, 4 - inverse(-q) * se), rel=1e-9)
    # Right skew moves the interval up: the upper bound is further from the mean than the
    # Student-t one, the lower bound nearer.
    t_low, t_high = 4 - q * se, 4 + q * se
    assert t_low < low < mean < t_high < high


def _hall(x: list[float], level: float = 0.95) -> tuple[float, float, float]:
    """Hall's interval through the package's closed form, at any n."""
    mean = float(np.mean(x))
    low, high = hall_interval(mean, float(np.std(x, ddof=1)), len(x), sample_skewness(x), level)
    return mean, float(low), float(high)


@pytest.mark.parametrize("x", [SPREAD, [0.1, 0.5, 0.2, 3.0, 0.3], [-5.0, 0.0, 0.2, 0.1, 0.3, -0.1],
                               [1e6 + 1.0, 1e6 + 1.5, 1e6 + 7.0]])
def test_hall_interval_against_the_cubic_roots(x: list[float]) -> None:
    assert _hall(x) == pytest.approx(hall_bounds(x), rel=1e-9)
    assert _hall(x, level=0.8) == pytest.approx(hall_bounds(x, level=0.8), rel=1e-9)
    if len(x) < 5:  # the summary's interval below 5 seeds
        assert mean_interval(x) == pytest.approx(hall_bounds(x), rel=1e-9)


def test_hall_interval_reduces_to_scipys_t_interval_without_skewness() -> None:
    # Symmetric samples, and any 2 values (whose skewness is 0): SciPy's t interval.
    for x in ([1.0, 2.0, 3.0], [0.0, 1.0], [3.0, -7.5], [1.0, 2.0, 4.0, 5.0], SPREAD[:2]):
        expected = stats.t.interval(0.95, len(x) - 1, loc=np.mean(x), scale=stats.sem(x))
        assert mean_interval(x)[1:] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert sample_skewness([3.0, -7.5]) == pytest.approx(0.0, abs=1e-12)
    # Skewness exactly 0 in the vectorised form gives t_interval elementwise.
    means, sds, ns = np.array([1.0, -2.0]), np.array([0.5, 3.0]), np.array([3, 10])
    hall = hall_interval(means, sds, ns, np.zeros(2))
    plain = t_interval(means, sds, ns)
    assert np.allclose(hall, plain, rtol=1e-14, atol=0)


def test_hall_interval_edge_cases_without_warnings() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # No spread: the skewness is undefined and the interval is the one point.
        assert mean_interval([2.5, 2.5, 2.5]) == (2.5, 2.5, 2.5)
        assert math.isnan(sample_skewness([2.5, 2.5, 2.5]))
        assert math.isnan(sample_skewness([1.0]))
        # NaN skewness with a spread: the Student-t interval; n < 2: NaN.
        low, high = hall_interval([1.0, 1.0, 1.0], [0.5, 0.5, 0.0], [1, 4, 3],
                                  [math.nan, math.nan, math.nan])
        assert math.isnan(low[0]) and math.isnan(high[0])
        assert (low[1], high[1]) == pytest.approx(
            (1 - stats.t.ppf(0.975, 3) * 0.25, 1 + stats.t.ppf(0.975, 3) * 0.25))
        assert (low[2], high[2]) == (1.0, 1.0)


def test_describe_gives_the_same_interval_as_mean_interval() -> None:
    # describe with a bootstrap (final score, training time) and mean_interval (AUC, the
    # benchmark) print one interval; NaN values are skipped as mean_interval would never see
    # them. Without a bootstrap (the learning-curve bands), Hall's interval at every n.
    import pandas as pd

    groups = {0: [1.0, 2.0, 3.0, 10.0], 1: [5.0, 5.0, 5.0], 2: [7.0], 3: [1.0, 2.0],
              4: SPREAD, 5: [0.1, 0.5, 0.2, 3.0, 0.3]}
    frame = pd.DataFrame([(g, v) for g, vs in groups.items() for v in vs]
                         + [(3, math.nan), (5, math.nan)], columns=["g", "v"])
    summarised = describe(frame, "g", "v", bootstrap=2000)
    bands = describe(frame, "g", "v")
    for g, values in groups.items():
        mean, low, high = mean_interval(values, resamples=2000)
        for described in (summarised, bands):
            row = described.loc[g]
            assert row["n"] == len(values) and row["mean"] == pytest.approx(mean)
        if len(values) < 2:
            assert nan_pair((summarised.loc[g, "low"], summarised.loc[g, "high"]))
            assert nan_pair((bands.loc[g, "low"], bands.loc[g, "high"]))
            continue
        row = summarised.loc[g]
        assert (row["low"], row["high"]) == pytest.approx((low, high), rel=1e-12)
        hall = (5.0, 5.0) if g == 1 else hall_bounds(values)[1:]
        assert (bands.loc[g, "low"], bands.loc[g, "high"]) == pytest.approx(hall, rel=1e-9)
    # From 5 values on, the summary's interval is the bootstrap-t, not Hall's.
    for g in (4, 5):
        assert (summarised.loc[g, "low"], summarised.loc[g, "high"]) == pytest.approx(
            bootstrap_t_interval(groups[g]), rel=1e-12)
        assert summarised.loc[g, "high"] != pytest.approx(bands.loc[g, "high"], rel=1e-3)


# The bootstrap-t interval of a mean, from 5 values on ------------------------------------------


SKEWED = [1.0, 2.0, 3.0, 4.0, 20.0]
"""Five values with one far above: right-skewed (mean 6, sd 7.906)."""


def test_bootstrap_t_interval_against_a_slow_reference() -> None:
    # The same resamples, each resample's t computed one at a time with np.std (ddof 1), the
    # flat ones set to +-inf by hand, and np.quantile's linear interpolation.
    for x in (SKEWED, SPREAD, [0.1, 0.5, 0.2, 3.0, 0.3, 0.2], [1e6 + 1.0, 1e6 + 1.5, 1e6 + 7.0,
                                                                1e6 + 2.0, 1e6 + 2.5]):
        assert bootstrap_t_interval(x) == pytest.approx(bootstrap_t_reference(x), rel=1e-9)
        assert bootstrap_t_interval(x, level=0.8, resamples=300) == pytest.approx(
            bootstrap_t_reference(x, level=0.8, resamples=300), rel=1e-9)


def test_bootstrap_t_interval_converges_to_the_exact_bootstrap() -> None:
    # Five values have 5^5 = 3,125 equally likely ordered resamples: the exact ("ideal")
    # bootstrap-t interval enumerates them all. 400,000 resamples land within 1 % of it.
    x = np.array(SKEWED)
    grid = np.array(np.meshgrid(*[range(5)] * 5, indexing="ij")).reshape(5, -1).T
    draws = x[grid]
    spread = draws.std(axis=1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (draws.mean(axis=1) - x.mean()) / (spread / math.sqrt(5))
    t[spread == 0] = np.copysign(np.inf, draws[spread == 0, 0] - x.mean())
    t_low, t_high = np.quantile(t, [0.025, 0.975])
    se = x.std(ddof=1) / math.sqrt(5)
    exact = (x.mean() - t_high * se, x.mean() - t_low * se)
    assert bootstrap_t_interval(x, resamples=400_000) == pytest.approx(exact, rel=0.01)
    # Right skew: T* has a long lower tail, so the interval reaches further above the mean than
    # below, and above the Student-t interval's upper bound (6 + 2.776 * 3.536 = 15.82).
    low, high = bootstrap_t_interval(x)
    t_half = stats.t.ppf(0.975, 4) * se
    assert high - 6.0 > 6.0 - low and high > 6.0 + t_half


def test_bootstrap_t_interval_is_symmetric_on_symmetric_data() -> None:
    # Antithetic resamples: on a sample symmetric about its mean the T* are symmetric, and so
    # is the interval, to rounding.
    for x in ([1.0, 2.0, 3.0, 4.0, 5.0], [0.0, 2.0, 3.0, 4.5, 5.0, 5.0, 5.5, 7.0, 8.0, 10.0]):
        mean = float(np.mean(x))
        low, high = bootstrap_t_interval(x)
        assert high - mean == pytest.approx(mean - low, rel=1e-12)
        # Wider than the Student-t interval at 5 values (the t of a resample has heavier tails).
        if len(x) == 5:
            assert high - mean > stats.t.ppf(0.975, 4) * stats.sem(x)


def test_bootstrap_t_interval_is_deterministic_and_order_free() -> None:
    first = bootstrap_t_interval(SPREAD)
    assert bootstrap_t_interval(SPREAD) == first
    assert bootstrap_t_interval(list(reversed(SPREAD))) == first
    assert bootstrap_t_interval(sorted(SPREAD)) == first
    # Another seed: other resamples, nearly the same interval.
    other = bootstrap_t_interval(SPREAD, seed=1)
    assert other != first and other == pytest.approx(first, rel=0.05)
    assert mean_interval(SPREAD)[1:] == first


def test_bootstrap_t_interval_edge_cases_without_warnings() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert nan_pair(bootstrap_t_interval([]))
        assert nan_pair(bootstrap_t_interval([4.0]))
        assert bootstrap_t_interval([2.5] * 6) == (2.5, 2.5)
        assert bootstrap_t_interval([0.1] * 7) == (0.1, 0.1)  # np.std may give 1e-17 here
        assert mean_interval([0.1] * 7) == pytest.approx((0.1, 0.1, 0.1))
        # Three tied values of 5: a resample of the three alone, (3/5)^5 = 7.8 % of them, has
        # no spread and T* = -inf, more than the 2.5 % tail: the upper bound is infinite.
        low, high = bootstrap_t_interval([1.0, 1.0, 1.0, 2.0, 3.0])
        assert math.isfinite(low) and high == math.inf
        # The summary then gives Hall's interval.
        assert mean_interval([1.0, 1.0, 1.0, 2.0, 3.0]) == pytest.approx(
            hall_bounds([1.0, 1.0, 1.0, 2.0, 3.0]), rel=1e-9)
        # A flat resample on the mean (all 2s of [1, 2, 2, 2, 3]) has T* = 0, not NaN.
        low, high = bootstrap_t_interval([1.0, 2.0, 2.0, 2.0, 3.0])
        assert math.isfinite(low) and math.isfinite(high) and low < 2.0 < high
        # Below 5 values the bootstrap-t is erratic: with 3, a ninth of resamples are flat.
        assert bootstrap_t_interval([1.0, 2.0, 4.0]) == (-math.inf, math.inf)
        assert mean_interval([1.0, 2.0, 4.0]) == pytest.approx(hall_bounds([1.0, 2.0, 4.0]))


# Comparisons -------------------------------------------------------------------------------------


def test_holm_on_a_known_example() -> None:
    # p = [0.01, 0.04, 0.03, 0.005], m = 4. Sorted up: 0.005, 0.01, 0.03, 0.04, times
    # m, m - 1, ...: 4 * 0.005 = 0.02, 3 * 0.01 = 0.03, 2 * 0.03 = 0.06, 1 * 0.04 = 0.04.
    # Running maximum: 0.02, 0.03, 0.06, 0.06. Back in the given order: 0.03, 0.06, 0.06, 0.02.
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])


def test_holm_nan_cap_and_empty() -> None:
    # NaN is not counted: m = 2, so 2 * 0.01 = 0.02 and max(0.02, 1 * 0.02) = 0.02 (not 0.03).
    adjusted = holm([0.01, NAN, 0.02])
    assert adjusted[0] == pytest.approx(0.02) and adjusted[2] == pytest.approx(0.02)
    assert math.isnan(adjusted[1])
    # 2 * 0.5 = 1.0, then 1 * 0.6 = 0.6 is raised to the running maximum 1.0; 2 * 0.7 is capped.
    assert holm([0.5, 0.6]) == pytest.approx([1.0, 1.0])
    assert holm([0.7, 0.9]) == pytest.approx([1.0, 1.0])
    assert holm([0.03]) == pytest.approx([0.03])
    assert holm([]) == []


def test_holm_is_monotone_and_never_below_the_raw_p() -> None:
    raw = np.random.default_rng(3).uniform(0.0, 0.3, size=12)
    adjusted = np.array(holm(list(raw)))
    order = np.argsort(raw)
    assert np.all(np.diff(adjusted[order]) >= 0.0)
    assert np.all(adjusted >= raw) and np.all(adjusted <= 1.0)


def test_p_improvement_counts_pairs() -> None:
    assert p_improvement([3, 4], [1, 2]) == pytest.approx(1.0)
    # Pairs of [1, 2] and [1, 2]: tie, lose, win, tie: (0.5 + 0 + 1 + 0.5) / 4 = 0.5.
    assert p_improvement([1, 2], [1, 2]) == pytest.approx(0.5)
    assert p_improvement([1, 2], [3, 4]) == pytest.approx(0.0)
    # [2, 4] against [1, 3, 4]: 2 beats 1; 4 beats 1 and 3 and ties 4: 3.5 of 6 pairs.
    assert p_improvement([2, 4], [1, 3, 4]) == pytest.approx(3.5 / 6)
    assert p_improvement([1, 3, 4], [2, 4]) == pytest.approx(2.5 / 6)
    assert math.isnan(p_improvement([], [1.0]))
    assert math.isnan(p_improvement([1.0], []))


def test_p_improvement_interval_on_newcombe_hand_worked_bounds() -> None:
    # Every seed of x beats every seed of y (estimate 1, m = n = 2, N* = 2): the upper bound is
    # 1, the lower the root below 1 of (1 - t)^2 = z^2 t (1 - t) / 4 [1 + (1 - t) / (2 - t)
    # + t / (1 + t)]; at t = 0.38564 both sides are 0.3774.
    low, high = p_improvement_interval([3.0, 4.0], [1.0, 2.0])
    assert high == 1.0 and low == pytest.approx(0.38564, abs=1e-5)
    assert (low, high) == pytest.approx(newcombe_bounds(1.0, 2, 2), abs=1e-9)
    # Estimate 1/2 at m = n = 2 is symmetric about 1/2; with 5 against 3 seeds, 10 of 15 pairs.
    assert p_improvement_interval([0.0, 1.0], [0.5, 0.5]) == pytest.approx(
        newcombe_bounds(0.5, 2, 2), abs=1e-9)
    five, three = [1.0, 2.0, 3.0, 4.0, 5.0], [0.5, 2.5, 3.5]
    assert p_improvement(five, three) == pytest.approx(10 / 15)
    assert p_improvement_interval(five, three) == pytest.approx(
        newcombe_bounds(10 / 15, 5, 3), abs=1e-9)


def test_p_improvement_interval_contains_the_estimate_and_narrows_with_seeds() -> None:
    other = [v + 1.0 for v in SPREAD[:8]]
    low, high = p_improvement_interval(SPREAD, other)
    assert 0.0 < low < p_improvement(SPREAD, other) < high < 1.0
    # The same estimate from more seeds, or at a lower level, gives a narrower interval.
    few = p_improvement_interval([1.0, 3.0], [2.0, 0.0])
    many = p_improvement_interval([1.0, 3.0] * 5, [2.0, 0.0] * 5)
    assert few[0] < many[0] < 0.75 < many[1] < few[1]
    narrow = p_improvement_interval(SPREAD, other, level=0.5)
    assert low < narrow[0] < narrow[1] < high
    # Swapping the samples mirrors the interval about 1/2: V(t) = V(1 - t).
    swapped = p_improvement_interval(other, SPREAD)
    assert swapped == pytest.approx((1 - high, 1 - low), abs=1e-9)


def test_p_improvement_interval_edge_cases_without_warnings() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert nan_pair(p_improvement_interval([1.0], [1.0, 2.0]))
        assert nan_pair(p_improvement_interval([1.0, 2.0], []))
        # Never one point, even without spread: two seeds a side cannot rule out much.
        low, high = p_improvement_interval([1.0, 1.0], [2.0, 2.0])
        assert low == 0.0 and high == pytest.approx(newcombe_bounds(0.0, 2, 2)[1], abs=1e-9)
        assert p_improvement_interval([2.0, 2.0], [2.0, 2.0]) == pytest.approx(
            newcombe_bounds(0.5, 2, 2), abs=1e-9)


# The verdict -------------------------------------------------------------------------------------


def test_verdict_on_constructed_groups() -> None:
    final = {0: [1.0, 2.0, 3.0], 1: [4.0, 5.0, 6.0], 2: [4.5, 5.0, 5.5], 3: [5.0]}
    result = verdict(
        compare(final, 0.0),
        auc_means={0: 1.0, 1: 3.0, 2: 3.0, 3: 2.0},
        seconds={0: NAN, 1: 50.0, 2: 40.0, 3: 40.0},
        iqrs={0: 1.0, 1: 1.0, 2: 0.5, 3: 0.0},
    )
    # IQMs 2, 5, 5 (group 3 has one seed, out of the family): group 1 is the first best.
    assert result.best == 1
    assert result.most_sample_efficient == 1  # 3.0 twice: the first
    assert result.fastest == 2  # 40 s twice: the first; group 0 never reached (NaN)
    assert result.most_repeatable == 2  # group 3's IQR 0 is from one seed only
    assert result == Verdict(best=1, most_sample_efficient=1, fastest=2, most_repeatable=2)


def test_verdict_ties_go_to_the_first_group() -> None:
    result = verdict(compare({5: [1.0, 2.0], 2: [1.5, 1.5]}, 0.0), auc_means={5: 1.0, 2: 1.0},
                     seconds={5: 9.0, 2: 9.0}, iqrs={5: 0.5, 2: 0.5})
    assert result == Verdict(best=5, most_sample_efficient=5, fastest=5, most_repeatable=5)


def test_verdict_ignores_nan() -> None:
    final = {0: [NAN, NAN], 1: [1.0, NAN, 2.0], 2: [0.0, NAN]}
    result = verdict(compare(final, 0.0), auc_means={0: NAN, 1: NAN},
                     seconds={0: NAN, 1: NAN, 2: NAN}, iqrs={0: NAN, 1: 0.5, 2: 0.0})
    assert result.best == 1  # mean 1.5 over its two complete seeds
    assert result.most_sample_efficient is None
    assert result.fastest is None
    assert result.most_repeatable == 1  # group 2 has one complete seed
    empty = verdict(compare({}, 0.0), {}, {}, {})
    assert empty == Verdict(best=None, most_sample_efficient=None, fastest=None,
                            most_repeatable=None)
    assert empty_verdict() == empty


def test_verdict_is_frozen() -> None:
    result = verdict(compare({0: [1.0]}, 0.0), {}, {}, {})
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.best = 1  # type: ignore[misc]
