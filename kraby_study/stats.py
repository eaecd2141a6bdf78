"""The statistics behind every band, error bar, "best" mark and verdict of a report.

Every statistic is over seeds: one value per complete seed (its final score, its AUC, ...).
See docs/statistics.md for what each one means and why it was chosen.

- Interval of a mean over seeds (final score, AUC, training time, time to threshold):
  :func:`mean_interval`. From 5 seeds on, the 95 % equal-tailed studentised bootstrap
  (bootstrap-t) interval (:func:`bootstrap_t_interval`; Efron 1982, Hall 1988), seeded, so a
  report is reproducible. With 2 to 4 seeds, the 95 % Hall skewness-corrected t interval
  (:func:`hall_interval`; Hall 1992), the Student-t interval moved and stretched by the
  sample's skewness. It needs at least two seeds; with one it is left empty. The
  learning-curve bands, hundreds of intervals a value, are Hall's intervals at every n
  (:func:`describe` without ``bootstrap``).
- Robust summary: the interquartile mean (IQM) over seeds with its 95 % Tukey-McLaughlin
  trimmed-t interval, and the probability of improvement of the best value over another, after
  Agarwal et al., "Deep Reinforcement Learning at the Edge of the Statistical Precipice"
  (NeurIPS 2021), with Newcombe's (2006) 95 % score-type interval.
- Best value: the highest mean final score among the values with at least ``min_seeds``
  complete seeds (:func:`kraby_study.comparison.compare`).
- Every other value's answer at the margin, equivalent, worse or undecided:
  :func:`kraby_study.comparison.compare`, one comparison the verdict (:func:`verdict`), the
  table and the selection rules read; "worse" is a closed Holm step-down over one-sided Welch
  t-tests whose family-wise error holds although the best is chosen from the same data.
  :func:`compare_to_best` gives the raw two-sided Welch p-values against the best, for
  information only.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import TYPE_CHECKING

import numpy as np
import scipy

from kraby_study.comparison import (
    ALPHA,
    MIN_SEEDS,
    PROCEDURE,
    Comparison,
    best_with_evidence,
    compare,
    compare_with_best,
    procedure_name,
    welch_two_sided_p,
)
from kraby_study.records import best_group

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
TEST_NAME = ("two-sided Welch's t-test against the best value, uncorrected (for information: "
             "the ties do not use it)")
HOLM_NAME = (f"{PROCEDURE}, alpha = {ALPHA}: the adjusted p of 'this value is a best'; "
             f"< {ALPHA} means worse than the best")
PROCEDURE_NAME = procedure_name(ALPHA)
AUC_NAME = ("sample efficiency (AUC): the mean of a seed's binned mean episode rewards over the"
            " whole run, the normalised area under its learning curve")

BOOTSTRAP_REPETITIONS = 2000
"""Default of the report option ``report.bootstrap``: the resamples of the bootstrap-t interval of
a mean (:func:`bootstrap_t_interval`). Its coverage is measured at this number."""


def interval_name(resamples: int = BOOTSTRAP_REPETITIONS, level: float = LEVEL) -> str:
    """The caption of :func:`mean_interval` at a number of resamples and a level."""
    return (f"{level * 100:g} % interval of the mean over seeds: from {MIN_BOOTSTRAP_SEEDS} "
            "seeds on, the equal-tailed studentised bootstrap (bootstrap-t) interval "
            f"({resamples:,} resamples seeded by the values; Efron 1982, Hall 1988); with 2 to "
            f"{MIN_BOOTSTRAP_SEEDS - 1} seeds, Hall's skewness-corrected t interval (Hall 1992)")


INTERVAL_NAME = interval_name()
SHORT_INTERVAL_NAME = (f"95 % interval of the mean (bootstrap-t from {MIN_BOOTSTRAP_SEEDS} seeds, "
                       "Hall's skewness-corrected t below)")
"""The interval of a mean in figure captions and legends."""


def iqm_interval_name(level: float = LEVEL) -> str:
    """The caption of :func:`iqm_interval` at a level."""
    return (f"{level * 100:g} % Tukey-McLaughlin trimmed-t interval of the interquartile mean "
            "over seeds (winsorised sd; the plain t-interval below 4 seeds)")


def p_improvement_name(level: float = LEVEL) -> str:
    """The caption of :func:`p_improvement` and its interval at a level."""
    return ("probability of improvement P(best > this value) over all pairs of seeds, ties"
            f" counted half, with its {level * 100:g} % Newcombe score-type interval"
            " (Newcombe 2006, method 5)")


IQM_INTERVAL_NAME = iqm_interval_name()
P_IMPROVEMENT_NAME = p_improvement_name()


def t_interval(mean: np.ndarray | pd.Series | float, sd: np.ndarray | pd.Series | float,
               n: np.ndarray | pd.Series | float,
               level: float = LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Student-t confidence interval of a mean, elementwise; NaN where n < 2.

    The report's intervals of a mean use :func:`hall_interval`, which is this one when the
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


def welch_p(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Welch's t-test p-value of two samples; NaN when either has fewer than 2.

    Two samples without spread, relative to the scale of the scores
    (:data:`kraby_study.comparison.CONSTANT_RTOL`), are identical (p = 1) when their means
    agree within that tolerance, else certainly different (p = 0).
    """
    return welch_two_sided_p(a, b)


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
    (:func:`t_interval`), which it also falls back to where gamma is NaN (s = 0).

    Args:
        mean: Sample means.
        sd: Sample standard deviations (ddof 1).
        n: Sample sizes.
        skewness: Sample skewnesses, the biased moment estimator m3 / m2^1.5
            (:func:`sample_skewness`).
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
    """:func:`sample_skewness` of ``column`` per ``group``, vectorised (NaN values skipped)."""
    dev = samples[column].astype(float) - samples.groupby(group, sort=True)[column].transform(
        "mean")
    moments = samples.assign(_m2=dev ** 2, _m3=dev ** 3).groupby(group, sort=True)[
        ["_m2", "_m3"]].mean()
    return (moments["_m3"] / moments["_m2"] ** 1.5).where(moments["_m2"] > 0)


def describe(samples: pd.DataFrame, group: str | list[str], column: str,
             bootstrap: int | None = None) -> pd.DataFrame:
    """Count, mean, sd, skewness and interval of the mean of ``column`` per ``group``; NaN
    values are skipped.

    With ``bootstrap`` (resamples), the interval is :func:`mean_interval`'s: the bootstrap-t
    interval for groups of :data:`MIN_BOOTSTRAP_SEEDS` values or more, Hall's below (the
    summary's final score and training time). Without it, Hall's interval
    (:func:`hall_interval`) for every group, vectorised: the learning-curve bands, hundreds of
    groups a value, where a bootstrap per group would cost seconds.

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


def compare_to_best(scores: dict[int, list[float]],
                    min_seeds: int = MIN_SEEDS) -> tuple[int | None, dict[int, float]]:
    """The best group (:func:`kraby_study.comparison.compare_with_best`), and every group's raw
    two-sided Welch p-value against it, uncorrected: for information, never for a tie.

    Args:
        scores: Final scores by group (groups without scores are ignored).
        min_seeds: Fewest complete seeds a group needs to be best.

    Returns:
        The best group (None if none has enough seeds) and p-values by group (NaN for the best
        itself or when a test is impossible).
    """
    best = best_with_evidence(scores, min_seeds)
    if best is None:
        return None, {}
    pvalues = {g: (math.nan if g == best else welch_p(scores[best], v))
               for g, v in scores.items() if len(v)}
    return best, pvalues


# Robust and multiple-comparison statistics ------------------------------------------------------


def _array(values: Sequence[float]) -> np.ndarray:
    return np.asarray(values, dtype=float).ravel()


def mean_interval(values: Sequence[float], level: float = LEVEL,
                  resamples: int = BOOTSTRAP_REPETITIONS) -> tuple[float, float, float]:
    """Mean of a sample with its interval: the bootstrap-t interval (:func:`bootstrap_t_interval`)
    from :data:`MIN_BOOTSTRAP_SEEDS` values on, Hall's skewness-corrected t interval
    (:func:`hall_interval`) with 2 to 4 values.

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
    """:func:`mean_interval` of every row of a (k, n) array without NaN, n >= 1, vectorised
    (``benchmarks/bench_error_rates.py`` measures its coverage through this).

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
    with ``seed`` and the sorted values (:func:`_resample_plan`), so the interval is a function
    of the sample, whatever its order. One plan for every sample would not do: its own
    Monte-Carlo error in the tails would bias every interval at that n alike (measured: a
    coverage 0.005 to 0.010 low at some n with 2,000 resamples). Half the resamples are the
    antithetic mirrors of the other half (index i of the sorted sample for n - 1 - i; Hall,
    "Antithetic resampling for the bootstrap", Biometrika 76(4), 1989): on a sample symmetric
    about its mean the T* are symmetric, and so is the interval.

    A resample without spread (every value the same) has T* = +-inf (0 on the mean). With 5
    distinct values that is 0.16 % of resamples, far inside the tails; where ties make it more
    than (1 - level) / 2 on a side, that bound is infinite (:func:`mean_interval` then gives
    Hall's interval). Below 5 values the interval is erratic (infinite with 3 values) and the
    report does not use it.

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
    """:func:`bootstrap_t_interval` of every row of a (k, n) array without NaN, n >= 2: each
    row its own resamples (:func:`_resample_plan`), the arithmetic vectorised over rows.

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

    With g = floor(n / 4) values trimmed from each end (as :func:`iqm`) and h = n - 2 g left,
    the interval is IQM +- t(0.5 + level / 2, h - 1) * s_w / ((1 - 2 * 0.25) sqrt(n)), s_w the
    sd (ddof 1) of the sample winsorised at g (Tukey and McLaughlin 1963; Wilcox,
    *Introduction to Robust Estimation and Hypothesis Testing*, 4th ed. 2017, sec. 4.4). With
    n < 4 nothing is trimmed and it is the Student-t interval of the mean. The percentile
    bootstrap it replaces covered the IQM 0.74 of the time at n = 3 and 0.90 at n = 5 (normal
    data); this one's coverage is measured in ``benchmarks/bench_error_rates.py``.

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


def auc(rewards: Sequence[float]) -> float:
    """Sample efficiency of one seed: the mean of its binned mean episode rewards over the run.

    With bins of equal width this is the area under the learning curve divided by its length.

    Returns:
        The mean reward of the curve's points; NaN for an empty curve.
    """
    x = _array(rewards)
    return float(np.mean(x)) if len(x) else math.nan


def first_reach(steps: Sequence[float], rewards: Sequence[float], wall_times: Sequence[float],
                threshold: float) -> tuple[float, float]:
    """When a learning curve first reaches a reward.

    Args:
        steps: Env steps of each curve point, in order.
        rewards: Mean episode reward of each point.
        wall_times: Seconds since training started of each point.
        threshold: The reward to reach.

    Returns:
        (env steps, seconds) of the first point whose reward >= threshold; (NaN, NaN) if none.
    """
    for step, reward, seconds in zip(steps, rewards, wall_times, strict=True):
        if reward >= threshold:
            return float(step), float(seconds)
    return math.nan, math.nan


def default_threshold(untrained: float, best_final: float, fraction: float = 0.9) -> float:
    """The reward a curve must reach by default: ``fraction`` of the way from the untrained
    policy's reward to the best value's final score."""
    return untrained + fraction * (best_final - untrained)


def holm_vs_best(scores: Mapping[int, Sequence[float]],
                 min_seeds: int = MIN_SEEDS) -> tuple[int | None, dict[int, float]]:
    """The best group and every group's adjusted p of "this group is a best"
    (:func:`kraby_study.comparison.compare_with_best`: closed Holm step-down over one-sided
    Welch tests); NaN for the best itself and for groups with fewer than ``min_seeds`` seeds.
    A group tied with the best has p >= ALPHA."""
    result = compare_with_best(scores, min_seeds=min_seeds)
    return result.best, {g: result.p_adjusted.get(g, math.nan)
                         for g, v in scores.items() if len(v)}


def p_improvement(x: Sequence[float], y: Sequence[float]) -> float:
    """Probability of improvement of X over Y (Agarwal et al. 2021), over all pairs of seeds.

    P(X > Y) + 0.5 P(X = Y): the Mann-Whitney U statistic of x against y over len(x) len(y),
    counted pair by pair (seeds are few, and SciPy's ``mannwhitneyu`` costs more than the pairs
    inside the simulations of ``benchmarks/bench_error_rates.py``).

    Returns:
        A probability in [0, 1]; NaN if either sample is empty.
    """
    a, b = _array(x), _array(y)
    if len(a) == 0 or len(b) == 0:
        return math.nan
    wins = np.greater.outer(a, b) + 0.5 * np.equal.outer(a, b)
    return float(np.mean(wins))


def _newcombe_variance(theta: float, m: int, n: int) -> float:
    """Newcombe's (2006, Part 2, method 5) variance of U / (m n) at a true value ``theta``."""
    half = (m + n) / 2  # N*, the mean sample size
    return (theta * (1 - theta) / (m * n)
            * (1 + (half - 1) * (1 - theta) / (2 - theta) + (half - 1) * theta / (1 + theta)))


def _newcombe_upper(estimate: float, m: int, n: int, z: float) -> float:
    """The root above ``estimate`` of theta - estimate = z sqrt(V(theta)), or 1 at 1."""
    if estimate >= 1.0:
        return 1.0

    def distance(theta: float) -> float:
        return theta - estimate - z * math.sqrt(_newcombe_variance(theta, m, n))

    # Negative at the estimate (V > 0 inside (0, 1)) and 1 - estimate > 0 at 1. At an estimate
    # of 0 both terms vanish, so the bracket starts just above it, where sqrt(V) dominates.
    start = estimate if estimate > 0.0 else 1e-12
    return float(scipy.optimize.brentq(distance, start, 1.0, xtol=1e-12))


def p_improvement_interval(x: Sequence[float], y: Sequence[float],
                           level: float = LEVEL) -> tuple[float, float]:
    """Newcombe's score-type confidence interval of :func:`p_improvement` (Newcombe, "Confidence
    intervals for an effect size measure based on the Mann-Whitney statistic. Part 2:
    asymptotic methods and evaluation", Statistics in Medicine 25(4), 2006, method 5).

    With theta_hat = :func:`p_improvement` of m values against n, the bounds are the two
    solutions in [0, 1] of |theta_hat - theta| = z sqrt(V(theta)), z = Phi^-1(0.5 + level / 2),

        V(theta) = theta (1 - theta) / (m n)
                   * [1 + (N* - 1) (1 - theta) / (2 - theta) + (N* - 1) theta / (1 + theta)],

    N* = (m + n) / 2: Hanley and McNeil's variance of U / (m n) for exponential scores, with
    both sample sizes replaced by their mean, evaluated at the candidate theta as in Wilson's
    interval for a proportion. Like Wilson's, it stays inside [0, 1] and is never one point:
    the BCa bootstrap it replaced covered 0.64-0.74 at n = 3 and 0.88-0.92 at n = 5 a side,
    and printed [0, 1] or one-point intervals at n = 2 and 3; this one's coverage is measured
    in ``benchmarks/bench_error_rates.py``. Ties count half in theta_hat; V assumes none.
    V(theta) = V(1 - theta), so the lower bound is 1 minus the upper bound of 1 - theta_hat.

    Args:
        x: One value per seed of the first sample (m of them).
        y: One value per seed of the second (n of them).
        level: Confidence level.

    Returns:
        (low, high); (NaN, NaN) if either sample has fewer than 2 values.
    """
    a, b = _array(x), _array(y)
    m, n = len(a), len(b)
    if m < 2 or n < 2:
        return math.nan, math.nan
    estimate = p_improvement(a, b)
    z = float(scipy.stats.norm.ppf(0.5 + level / 2))
    return (1.0 - _newcombe_upper(1.0 - estimate, m, n, z),
            _newcombe_upper(estimate, m, n, z))


def iqr(values: Sequence[float]) -> float:
    """Interquartile range of a sample (``scipy.stats.iqr``), its repeatability; NaN if empty."""
    x = _array(values)
    return float(scipy.stats.iqr(x)) if len(x) else math.nan


@functools.lru_cache(maxsize=256)
def expected_normal_iqr(n: int) -> float:
    """Expected sample IQR (:func:`iqr`, linear quartiles) of n standard normal values.

    The quartiles interpolate between order statistics, so their expectation is the same mix of
    the expected normal order statistics, each integrated numerically. 0.564 at n = 2 (true IQR
    1.349): a sample's IQR shrinks with n, which is why :func:`iqr_unbiased` divides by this.
    """
    if n < 2:
        return math.nan

    def order_mean(r: int) -> float:  # E[X_(r:n)], r from 1
        log_c = math.lgamma(n + 1) - math.lgamma(r) - math.lgamma(n - r + 1)
        def density(z: float) -> float:
            norm = scipy.stats.norm
            return z * math.exp(log_c + (r - 1) * norm.logcdf(z) + (n - r) * norm.logsf(z)
                                + norm.logpdf(z))
        return float(scipy.integrate.quad(density, -12, 12, limit=200)[0])

    def quantile(p: float) -> float:
        h = (n - 1) * p
        lo = math.floor(h)
        frac = h - lo
        value = order_mean(lo + 1)
        return value + frac * (order_mean(lo + 2) - value) if frac else value

    return quantile(0.75) - quantile(0.25)


NORMAL_IQR = NormalDist().inv_cdf(0.75) - NormalDist().inv_cdf(0.25)
"""The interquartile range of the standard normal distribution."""


def iqr_unbiased(values: Sequence[float]) -> float:
    """The sample IQR rescaled so that its expectation, for normal data, is the true IQR at
    every n: IQR * 1.349 / E[IQR of n standard normals] (:func:`expected_normal_iqr`).

    The raw sample IQR averages 0.42, 0.63 and 0.87 of the truth at n = 2, 3, 10, so the value
    that lost seeds looked the most repeatable; rescaled, the comparison across unequal n is
    fair in expectation. NaN with fewer than 2 values.
    """
    x = _array(values)
    if len(x) < 2:
        return math.nan
    return iqr(x) * NORMAL_IQR / expected_normal_iqr(len(x))


# The verdict --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Verdict:
    """What a sweep's report concludes, group by group (a group is a swept value's index).

    Only groups with at least ``min_seeds`` complete seeds can be an answer.
    """

    best: int | None
    """The group with the best mean final score among the groups with enough seeds."""
    tied: list[int]
    """The other groups not significantly worse than the best: adjusted p >= ALPHA
    (:func:`kraby_study.comparison.compare_with_best`)."""
    most_sample_efficient: int | None
    """The group with the highest mean AUC."""
    fastest: int | None
    """The group with the lowest restricted mean seconds to the threshold (a seed that never
    reached it counts at its run's end), among groups where a seed reached it."""
    most_repeatable: int | None
    """The group with the lowest :func:`iqr_unbiased` of its final scores."""
    min_seeds: int = MIN_SEEDS
    """Fewest complete seeds a group needed to be any of the above."""
    comparison: Comparison[int] | None = dataclasses.field(default=None, compare=False)
    """The comparison the best and the answers come from (None: the verdict compared at
    margin 0 itself)."""


def _highest(values: Mapping[int, float]) -> int | None:
    """The group with the highest value (first in order on ties), ignoring NaN."""
    return best_group({g: [float(v)] for g, v in values.items() if not math.isnan(v)})


def verdict(final: Mapping[int, Sequence[float]], auc_means: Mapping[int, float],
            seconds: Mapping[int, float], iqrs: Mapping[int, float],
            p_holm: Mapping[int, float] | None = None, min_seeds: int = MIN_SEEDS,
            comparison: Comparison[int] | None = None) -> Verdict:
    """The verdict of a sweep; NaN values never win, ties go to the first group in order.

    Args:
        final: Final scores of the complete seeds, by group (NaN scores are ignored).
        auc_means: Mean AUC by group.
        seconds: Restricted mean seconds to the threshold by group (a seed that never reached
            it at its run's end), NaN where no seed reached it.
        iqrs: Final-score IQR by group, comparable across n (:func:`iqr_unbiased`).
        p_holm: Unused when ``comparison`` is given; else the adjusted p against the best by
            group (:func:`holm_vs_best`; NaN for the best itself or a group outside the
            family: such a group is not tied).
        min_seeds: Fewest complete seeds a group needs to be any answer (at least 2).
        comparison: The study's one comparison (:func:`kraby_study.comparison.compare`): the
            best, the ties and the four answers are read from it, and its family is the
            groups that may be any answer.

    Returns:
        The :class:`Verdict`.
    """
    if comparison is None:
        comparison = compare(final, 0.0, min_seeds=min_seeds)
        if p_holm is not None:  # the caller's adjusted p (NaN is not tied: no test)
            comparison = dataclasses.replace(comparison, tied=[
                g for g in comparison.family if g != comparison.best
                and float(p_holm.get(g, math.nan)) >= ALPHA])
    need = comparison.min_seeds
    enough = set(comparison.family)
    best = comparison.best
    tied = list(comparison.tied)

    def among(values: Mapping[int, float], sign: float = 1.0) -> dict[int, float]:
        return {g: sign * float(v) for g, v in values.items() if g in enough}

    return Verdict(best=best, tied=tied,
                   most_sample_efficient=_highest(among(auc_means)),
                   fastest=_highest(among(seconds, -1.0)),
                   most_repeatable=_highest(among(iqrs, -1.0)), min_seeds=need,
                   comparison=comparison)
