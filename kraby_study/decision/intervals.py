"""The interval of a mean over seeds behind every band and error bar of a report.

From 5 seeds on, the 95 % equal-tailed studentised bootstrap (bootstrap-t) interval
([`bootstrap_t_interval`][kraby_study.decision.intervals.bootstrap_t_interval]; Efron 1982, Hall
1988), seeded so that a report is reproducible. With 2 to 4 seeds, the 95 % Hall skewness-corrected
t interval ([`hall_interval`][kraby_study.decision.intervals.hall_interval]; Hall 1992). The
learning-curve bands, hundreds of intervals a value, are Hall's intervals at every n
([`describe`][kraby_study.decision.intervals.describe]). The interquartile mean (IQM) has the
Tukey-McLaughlin trimmed-t interval. See docs/reference/statistics.md for why each was chosen."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy

if TYPE_CHECKING:
    import pandas as pd

LEVEL = 0.95
MIN_BOOTSTRAP_SEEDS = 5
"""From this many values on, the interval of a mean is the bootstrap-t interval; below, Hall's."""
BOOTSTRAP_SEED = 20240522
"""Seed of the bootstrap-t's resamples, with the sample's values: the same sample always gives
the same interval."""
BAND_NAME = ("95 % Hall skewness-corrected t interval of the mean over seeds (Hall 1992; the "
             "Student-t interval when the seeds' skewness is 0)")

BOOTSTRAP_REPETITIONS = 2000
"""Default of the report option ``report.bootstrap``: the resamples of the bootstrap-t interval of
a mean ([`bootstrap_t_interval`][kraby_study.decision.intervals.bootstrap_t_interval]). Its coverage
is measured at this number."""


def interval_name(resamples: int = BOOTSTRAP_REPETITIONS, level: float = LEVEL) -> str:
    """The caption of [`mean_interval`][kraby_study.decision.intervals.mean_interval] at a number of
    resamples and a level."""
    return (f"{level * 100:g} % interval of the mean over seeds: from {MIN_BOOTSTRAP_SEEDS} "
            "seeds on, the equal-tailed studentised bootstrap (bootstrap-t) interval "
            f"({resamples:,} resamples seeded by the values; Efron 1982, Hall 1988); with 2 to "
            f"{MIN_BOOTSTRAP_SEEDS - 1} seeds, Hall's skewness-corrected t interval (Hall 1992)")


INTERVAL_NAME = interval_name()
SHORT_INTERVAL_NAME = (f"95 % interval of the mean (bootstrap-t from {MIN_BOOTSTRAP_SEEDS} seeds, "
                       "Hall's skewness-corrected t below)")
"""The interval of a mean in figure captions and legends."""


def iqm_interval_name(level: float = LEVEL) -> str:
    """The caption of [`iqm_interval`][kraby_study.decision.intervals.iqm_interval] at a level."""
    return (f"{level * 100:g} % Tukey-McLaughlin trimmed-t interval of the interquartile mean "
            "over seeds (winsorised sd; the plain t-interval below 4 seeds)")


IQM_INTERVAL_NAME = iqm_interval_name()
SHORT_IQM_INTERVAL_NAME = "95 % trimmed-t interval (Tukey-McLaughlin)"
"""The interval of an IQM in figure legends."""


def t_interval(mean: np.ndarray | pd.Series | float, sd: np.ndarray | pd.Series | float,
               n: np.ndarray | pd.Series | float,
               level: float = LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Student-t confidence interval of a mean, elementwise; NaN where n < 2.

    The report's intervals of a mean use
    [`hall_interval`][kraby_study.decision.intervals.hall_interval], which is this one when the
    skewness is 0; the IQM's interval uses this one below 4 seeds.

    Args:
        mean: Sample means.
        sd: Sample standard deviations (ddof 1).
        n: Sample sizes.
        level: Confidence level.

    Returns:
        Lower and upper bounds, as float arrays.
    """
    mean_a = np.asarray(mean, dtype=float)
    sd_a = np.asarray(sd, dtype=float)
    n_a = np.asarray(n, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        dof = np.where(n_a >= 2, n_a - 1, np.nan)
        half = scipy.stats.t.ppf(0.5 + level / 2, dof) * sd_a / np.sqrt(n_a)
    half = np.where(n_a >= 2, half, np.nan)
    return mean_a - half, mean_a + half


def hall_interval(mean: np.ndarray | pd.Series | float, sd: np.ndarray | pd.Series | float,
                  n: np.ndarray | pd.Series | float,
                  skewness: np.ndarray | pd.Series | float,
                  level: float = LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Hall's skewness-corrected t interval of a mean, elementwise; NaN where n < 2.

    Peter Hall, "On the removal of skewness by transformation", Journal of the Royal
    Statistical Society B 54(1), 1992, 221-228 (see also Zhou and Dinh, "Nonparametric
    confidence intervals for the one- and two-sample problems", Biostatistics 6(2), 2005).
    With T = (mean - mu) / (s / sqrt(n)), gamma the sample skewness and b = gamma / (3 sqrt(n)),
    the monotone transform

        g(T) = T + b T^2 + (b^2 / 3) T^3 + b / 2 = ((1 + b T)^3 - 1) / (3 b) + b / 2

    removes T's skewness to first order, and is taken to follow t(n - 1). With
    q = t(0.5 + level / 2, n - 1) the interval is

        [mean - g^-1(q) s / sqrt(n), mean - g^-1(-q) s / sqrt(n)],

    g^-1(v) = ((1 + 3 b (v - b / 2))^(1/3) - 1) / b with the real cube root, computed here as
    3 (v - b / 2) / (c^2 + c + 1), c = (1 + 3 b (v - b / 2))^(1/3) (the same number, and
    v - b / 2 at b = 0 without dividing by b). With gamma = 0 it is the Student-t interval
    ([`t_interval`][kraby_study.decision.intervals.t_interval]), which it also falls back to where
    gamma is NaN (s = 0).

    Args:
        mean: Sample means.
        sd: Sample standard deviations (ddof 1).
        n: Sample sizes.
        skewness: Sample skewnesses, the biased moment estimator m3 / m2^1.5
            ([`sample_skewness`][kraby_study.decision.intervals.sample_skewness]).
        level: Confidence level.

    Returns:
        Lower and upper bounds, as float arrays.
    """
    mean_a = np.asarray(mean, dtype=float)
    sd_a = np.asarray(sd, dtype=float)
    n_a = np.asarray(n, dtype=float)
    gamma = np.asarray(skewness, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        dof = np.where(n_a >= 2, n_a - 1, np.nan)
        q = scipy.stats.t.ppf(0.5 + level / 2, dof)
        b = np.where(np.isfinite(gamma) & (sd_a > 0), gamma, 0.0) / (3 * np.sqrt(n_a))

        def inverse(v: np.ndarray) -> np.ndarray:
            shifted = v - b / 2
            c = np.cbrt(1 + 3 * b * shifted)
            return 3 * shifted / (c * c + c + 1)

        se = sd_a / np.sqrt(n_a)
        low = mean_a - inverse(q) * se
        high = mean_a - inverse(-q) * se
    keep = n_a >= 2
    return np.where(keep, low, np.nan), np.where(keep, high, np.nan)


def sample_skewness(values: Sequence[float]) -> float:
    """The biased moment estimator of skewness, m3 / m2^1.5 (m_k the k-th central moment with
    divisor n, as ``scipy.stats.skew(bias=True)``); NaN with fewer than 2 values or no spread.
    0 for any 2 values."""
    x = _array(values)
    if len(x) < 2:
        return math.nan
    dev = x - np.mean(x)
    m2 = float(np.mean(dev ** 2))
    return float(np.mean(dev ** 3)) / m2 ** 1.5 if m2 > 0 else math.nan


def _grouped_skewness(samples: pd.DataFrame, group: str | list[str], column: str
                      ) -> pd.Series:
    """[`sample_skewness`][kraby_study.decision.intervals.sample_skewness] of ``column`` per
    ``group``, vectorised (NaN values skipped)."""
    dev = samples[column].astype(float) - samples.groupby(group, sort=True)[column].transform(
        "mean")
    moments = samples.assign(_m2=dev ** 2, _m3=dev ** 3).groupby(group, sort=True)[
        ["_m2", "_m3"]].mean()
    return (moments["_m3"] / moments["_m2"] ** 1.5).where(moments["_m2"] > 0)


def describe(samples: pd.DataFrame, group: str | list[str], column: str,
             bootstrap: int | None = None) -> pd.DataFrame:
    """Count, mean, sd, skewness and interval of the mean of ``column`` per ``group``; NaN
    values are skipped.

    With ``bootstrap`` (resamples), the interval is
    [`mean_interval`][kraby_study.decision.intervals.mean_interval]'s: the bootstrap-t interval for
    groups of [`MIN_BOOTSTRAP_SEEDS`][kraby_study.decision.intervals.MIN_BOOTSTRAP_SEEDS] values or
    more, Hall's below (the summary's final score and training time). Without it, Hall's interval
    ([`hall_interval`][kraby_study.decision.intervals.hall_interval]) for every group, vectorised:
    the learning-curve bands, hundreds of groups a value, where a bootstrap per group would cost
    seconds.

    Returns:
        A frame indexed by group with columns n, mean, sd, skewness, low, high.
    """
    grouped = samples.groupby(group, sort=True)[column].agg(["count", "mean", "std"])
    grouped = grouped.rename(columns={"count": "n", "std": "sd"})
    grouped["skewness"] = _grouped_skewness(samples, group, column)
    low, high = hall_interval(grouped["mean"], grouped["sd"], grouped["n"],
                              grouped["skewness"])
    grouped["low"], grouped["high"] = low, high
    if bootstrap is not None and (grouped["n"] >= MIN_BOOTSTRAP_SEEDS).any():
        for key, values in samples.groupby(group, sort=True)[column]:
            x = values.dropna().to_numpy(dtype=float)
            if len(x) >= MIN_BOOTSTRAP_SEEDS:
                _, grouped.loc[key, "low"], grouped.loc[key, "high"] = mean_interval(
                    x, resamples=bootstrap)
    return grouped


# Robust and multiple-comparison statistics ------------------------------------------------------


def _array(values: Sequence[float]) -> np.ndarray:
    return np.asarray(values, dtype=float).ravel()


def mean_interval(values: Sequence[float], level: float = LEVEL,
                  resamples: int = BOOTSTRAP_REPETITIONS) -> tuple[float, float, float]:
    """Mean of a sample with its interval: the bootstrap-t interval
    ([`bootstrap_t_interval`][kraby_study.decision.intervals.bootstrap_t_interval]) from
    [`MIN_BOOTSTRAP_SEEDS`][kraby_study.decision.intervals.MIN_BOOTSTRAP_SEEDS] values on, Hall's
    skewness-corrected t interval ([`hall_interval`][kraby_study.decision.intervals.hall_interval])
    with 2 to 4 values.

    Below 5 values the bootstrap-t has too few distinct resamples (with 3 values, a ninth of
    them have no spread and an infinite t); Hall's interval stays finite there and its
    measured coverage is printed beside it. Where ties leave the bootstrap-t interval unbounded
    (three equal values of five, say), Hall's interval is given instead.

    Returns:
        (mean, low, high); low and high are NaN with fewer than 2 values, all three with none.
    """
    x = _array(values)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    mean, low, high = mean_intervals(x[None, :], level, resamples)
    return float(mean[0]), float(low[0]), float(high[0])


def mean_intervals(samples: np.ndarray, level: float = LEVEL,
                   resamples: int = BOOTSTRAP_REPETITIONS
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[`mean_interval`][kraby_study.decision.intervals.mean_interval] of every row of a (k, n)
    array without NaN, n >= 1, vectorised (``benchmarks/bench_error_rates.py`` measures its coverage
    through this).

    Returns:
        Means, lows and highs, as float arrays.
    """
    x = np.asarray(samples, dtype=float)
    k, n = x.shape
    mean = x.mean(axis=1)
    if n < 2:
        return mean, np.full(k, math.nan), np.full(k, math.nan)
    dev = x - mean[:, None]
    m2 = np.mean(dev ** 2, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        skewness = np.where(m2 > 0, np.mean(dev ** 3, axis=1) / m2 ** 1.5, math.nan)
    low, high = hall_interval(mean, x.std(axis=1, ddof=1), n, skewness, level)
    if n >= MIN_BOOTSTRAP_SEEDS:
        boot_low, boot_high = bootstrap_t_intervals(x, level, resamples)
        bounded = np.isfinite(boot_low) & np.isfinite(boot_high)
        low, high = np.where(bounded, boot_low, low), np.where(bounded, boot_high, high)
    return mean, low, high


_HUGE = 1e300
_INFINITE = 1e200
"""A quantile interpolated with any weight toward +-_HUGE is beyond this: an infinite t."""


def _resample_plan(x: np.ndarray, resamples: int, seed: int) -> np.ndarray:
    """Indices (2 ceil(resamples / 2), n) into the sorted sample ``x``: half drawn uniformly with
    replacement, half their antithetic mirror n - 1 - i (Hall 1989). The generator is seeded
    with ``seed`` and a SHA-256 digest of the sample's values, so a sample always gets the same
    resamples and different samples independent ones."""
    digest = hashlib.sha256(np.ascontiguousarray(x, dtype="<f8").tobytes()).digest()
    words = [int.from_bytes(digest[i:i + 8], "little") for i in range(0, len(digest), 8)]
    rng = np.random.default_rng([seed, *words])
    n = len(x)
    drawn = rng.integers(0, n, size=((resamples + 1) // 2, n), dtype=np.int32)
    return np.concatenate([drawn, n - 1 - drawn])


def bootstrap_t_interval(values: Sequence[float], level: float = LEVEL,
                         resamples: int = BOOTSTRAP_REPETITIONS,
                         seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """The equal-tailed studentised bootstrap (bootstrap-t, percentile-t) interval of a mean.

    Bradley Efron, *The Jackknife, the Bootstrap and Other Resampling Plans*, SIAM 1982;
    Peter Hall, "Theoretical comparison of bootstrap confidence intervals",
    Annals of Statistics 16(3), 1988, 927-953 (second-order correct); Efron and Tibshirani,
    *An Introduction to the Bootstrap*, 1993, ch. 12. With mean m, sd s and se = s / sqrt(n),
    each resample (n values drawn with replacement) gives T* = (m* - m) / (s* / sqrt(n)); with
    t_lo and t_hi the (1 - level) / 2 and (1 + level) / 2 quantiles of the T* (linear
    interpolation), the interval is

        [m - t_hi se, m - t_lo se].

    Unlike the t-interval it learns the skewness of T from the sample: a right-skewed sample
    gives a long lower tail of T*, so the interval reaches further up. SciPy's
    ``scipy.stats.bootstrap`` offers the percentile, basic and BCa intervals, not this one.

    Reproducible: the sample is sorted, and the resamples are drawn from a generator seeded
    with ``seed`` and the sorted values (`_resample_plan`), so the interval is a function of the
    sample, whatever its order. One plan for every sample would not do: its own
    Monte-Carlo error in the tails would bias every interval at that n alike (measured: a
    coverage 0.005 to 0.010 low at some n with 2,000 resamples). Half the resamples are the
    antithetic mirrors of the other half (index i of the sorted sample for n - 1 - i; Hall,
    "Antithetic resampling for the bootstrap", Biometrika 76(4), 1989): on a sample symmetric
    about its mean the T* are symmetric, and so is the interval.

    A resample without spread (every value the same) has T* = +-inf (0 on the mean). With 5
    distinct values that is 0.16 % of resamples, far inside the tails; where ties make it more
    than (1 - level) / 2 on a side, that bound is infinite
    ([`mean_interval`][kraby_study.decision.intervals.mean_interval] then gives Hall's interval).
    Below 5 values the interval is erratic (infinite with 3 values) and the report does not use it.

    Args:
        values: The sample.
        level: Confidence level.
        resamples: Bootstrap resamples (rounded up to an even number).
        seed: Seed of the resampling, with the sample's values.

    Returns:
        (low, high); (NaN, NaN) with fewer than 2 values, (v, v) when every value is v.
    """
    x = _array(values)
    if len(x) < 2:
        return math.nan, math.nan
    low, high = bootstrap_t_intervals(x[None, :], level, resamples, seed)
    return float(low[0]), float(high[0])


def bootstrap_t_intervals(samples: np.ndarray, level: float = LEVEL,
                          resamples: int = BOOTSTRAP_REPETITIONS,
                          seed: int = BOOTSTRAP_SEED) -> tuple[np.ndarray, np.ndarray]:
    """[`bootstrap_t_interval`][kraby_study.decision.intervals.bootstrap_t_interval] of every row of
    a (k, n) array without NaN, n >= 2: each row its own resamples (`_resample_plan`), the
    arithmetic vectorised over rows.

    Returns:
        Lows and highs, as float arrays.
    """
    x = np.sort(np.asarray(samples, dtype=float), axis=1)
    k, n = x.shape
    low, high = x[:, 0].copy(), x[:, 0].copy()  # rows without spread: the one point
    spread = np.flatnonzero(x[:, 0] != x[:, -1])
    tails = [(1 - level) / 2, (1 + level) / 2]
    chunk = max(1, 4_000_000 // (2 * ((resamples + 1) // 2) * n))  # about 32 MB of draws
    for start in range(0, len(spread), chunk):
        rows = spread[start:start + chunk]
        part = x[rows]
        mean, sd = part.mean(axis=1), part.std(axis=1, ddof=1)
        z = (part - mean[:, None]) / sd[:, None]  # standardised: T* does not change
        plans = np.stack([_resample_plan(row, resamples, seed) for row in part])
        plans += (n * np.arange(len(rows), dtype=np.int32))[:, None, None]  # into z.ravel()
        drawn = np.take(z.ravel(), plans)
        total = drawn.sum(axis=2)
        # The resample's variance from its sums: no cancellation to fear, z has mean 0, sd 1.
        variance = (np.einsum("rbi,rbi->rb", drawn, drawn) - total * total / n) / (n - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (total / n) / np.sqrt(np.maximum(variance, 0.0) / n)
        # A resample without spread (every value the same): +-inf, or 0 on the mean. Its
        # variance is 0 to rounding; only those near 0 are checked value by value.
        near = np.flatnonzero(variance.ravel() <= 1e-6)
        if len(near):
            candidates = drawn.reshape(-1, n)[near]
            flat = near[candidates.min(axis=1) == candidates.max(axis=1)]
            one = drawn.reshape(-1, n)[flat, 0]
            np.put(t, flat, np.where(one == 0, 0.0, np.copysign(np.inf, one)))
        # Interpolating against inf gives NaN: quantiles of +-_HUGE, then back to +-inf.
        t_low, t_high = np.quantile(np.clip(t, -_HUGE, _HUGE), tails, axis=1)
        t_low = np.where(np.abs(t_low) >= _INFINITE, np.sign(t_low) * np.inf, t_low)
        t_high = np.where(np.abs(t_high) >= _INFINITE, np.sign(t_high) * np.inf, t_high)
        se = sd / math.sqrt(n)
        low[rows], high[rows] = mean - t_high * se, mean - t_low * se
    return low, high


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: the mean of the middle half of the sorted values; NaN if empty.

    ``scipy.stats.trim_mean(values, 0.25)``: floor(n / 4) values are cut from each end, so with
    fewer than 4 values it is the plain mean.
    """
    x = _array(values)
    return float(scipy.stats.trim_mean(x, 0.25)) if len(x) else math.nan


def iqm_interval(values: Sequence[float], level: float = LEVEL) -> tuple[float, float]:
    """Tukey-McLaughlin confidence interval of the interquartile mean over seeds.

    With g = floor(n / 4) values trimmed from each end (as
    [`iqm`][kraby_study.decision.intervals.iqm]) and h = n - 2 g left, the interval is
    IQM +- t(0.5 + level / 2, h - 1) * s_w / ((1 - 2 * 0.25) sqrt(n)), s_w the sd (ddof 1) of the
    sample winsorised at g (Tukey and McLaughlin 1963; Wilcox, *Introduction to Robust Estimation
    and Hypothesis Testing*, 4th ed. 2017, sec. 4.4). With n < 4 nothing is trimmed and it is the
    Student-t interval of the mean. Its coverage is measured in
    ``benchmarks/bench_error_rates.py`` (docs/reference/statistics.md).

    Returns:
        (low, high); (NaN, NaN) with fewer than 2 values, (v, v) when every value is v.
    """
    x = np.sort(_array(values))
    n = len(x)
    if n < 2:
        return math.nan, math.nan
    if np.all(x == x[0]):
        return float(x[0]), float(x[0])
    g = n // 4
    if g == 0:
        low, high = t_interval(float(np.mean(x)), float(np.std(x, ddof=1)), n, level)
        return float(low), float(high)
    winsorised = np.clip(x, x[g], x[n - g - 1])
    se = float(np.std(winsorised, ddof=1)) / ((1 - 2 * 0.25) * math.sqrt(n))
    half = float(scipy.stats.t.ppf(0.5 + level / 2, n - 2 * g - 1)) * se
    centre = iqm(x)
    return centre - half, centre + half
