"""The statistics behind every band, error bar, "best" mark and verdict of a report.

Every statistic is over seeds: one value per complete seed (its final score, its AUC, ...).
See docs/statistics.md for what each one means and why it was chosen.

- Interval: the 95 % Student-t confidence interval of the mean over seeds,
  mean +- t(0.975, n - 1) * s / sqrt(n), with s the sample standard deviation (ddof 1).
  It needs at least two seeds; with one it is left empty.
- Robust summary: the interquartile mean (IQM) over seeds with its 95 % percentile-bootstrap
  interval, and the probability of improvement of the best value over another, both after
  Agarwal et al., "Deep Reinforcement Learning at the Edge of the Statistical Precipice"
  (NeurIPS 2021). Bootstraps use a fixed seed, so a report is reproducible.
- Best value: the highest mean final score (:func:`kraby_study.records.best_group`).
- "Not significantly different from the best": a two-sided Welch's t-test (unequal variances)
  of each value's final scores against the best value's gives p >= 0.05. :func:`compare_to_best`
  gives the raw p-values; :func:`holm` corrects them for the study's several comparisons
  (Holm 1979), and the verdict's ties use the corrected ones.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from kraby_study.records import best_group

LEVEL = 0.95
ALPHA = 0.05
INTERVAL_NAME = "95 % Student-t confidence interval of the mean over seeds"
TEST_NAME = "two-sided Welch's t-test against the best value, alpha = 0.05"
HOLM_NAME = ("Welch's t-test against the best value, Holm-corrected over the study's comparisons,"
             " alpha = 0.05")
AUC_NAME = ("sample efficiency (AUC): the mean of a seed's binned mean episode rewards over the"
            " whole run, the normalised area under its learning curve")

BOOTSTRAP_SEED = 20211206
"""Seed of every bootstrap, fixed so reports are reproducible."""
BOOTSTRAP_REPETITIONS = 2000
"""Resamples of every bootstrap."""


def iqm_interval_name(repetitions: int = BOOTSTRAP_REPETITIONS, level: float = LEVEL) -> str:
    """The caption of :func:`iqm_interval` for a number of resamples and a level."""
    return (f"{level * 100:g} % percentile-bootstrap interval of the interquartile mean over seeds"
            f" ({repetitions:,} resamples, fixed seed)")


def p_improvement_name(repetitions: int = BOOTSTRAP_REPETITIONS, level: float = LEVEL) -> str:
    """The caption of :func:`p_improvement` and its interval for a number of resamples."""
    return ("probability of improvement P(best > this value) over all pairs of seeds, ties"
            f" counted half, with its {level * 100:g} % percentile-bootstrap interval"
            f" ({repetitions:,} resamples of each value's seeds, fixed seed)")


IQM_INTERVAL_NAME = iqm_interval_name()
P_IMPROVEMENT_NAME = p_improvement_name()


def t_interval(mean: np.ndarray | pd.Series | float, sd: np.ndarray | pd.Series | float,
               n: np.ndarray | pd.Series | float,
               level: float = LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Student-t confidence interval of a mean, elementwise; NaN where n < 2.

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
        half = stats.t.ppf(0.5 + level / 2, dof) * sd_a / np.sqrt(n_a)
    half = np.where(n_a >= 2, half, np.nan)
    return mean_a - half, mean_a + half


def welch_p(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Welch's t-test p-value of two samples; NaN when either has fewer than 2.

    Two samples without any spread are identical (p = 1) or certainly different (p = 0).
    """
    x = np.asarray(a, dtype=float)
    y = np.asarray(b, dtype=float)
    if len(x) < 2 or len(y) < 2:
        return math.nan
    if np.var(x) == 0.0 and np.var(y) == 0.0:
        return 1.0 if float(np.mean(x)) == float(np.mean(y)) else 0.0
    return float(stats.ttest_ind(x, y, equal_var=False).pvalue)


def describe(samples: pd.DataFrame, group: str, column: str) -> pd.DataFrame:
    """Count, mean, sd and t interval of ``column`` per ``group``, vectorised.

    Returns:
        A frame indexed by group with columns n, mean, sd, low, high.
    """
    grouped = samples.groupby(group, sort=True)[column].agg(["count", "mean", "std"])
    grouped = grouped.rename(columns={"count": "n", "std": "sd"})
    low, high = t_interval(grouped["mean"], grouped["sd"], grouped["n"])
    grouped["low"], grouped["high"] = low, high
    return grouped


def compare_to_best(scores: dict[int, list[float]]) -> tuple[int | None, dict[int, float]]:
    """The group with the highest mean score, and every group's Welch p-value against it.

    Args:
        scores: Final scores by group (groups without scores are ignored).

    Returns:
        The best group (None if no scores) and p-values by group (NaN for the best itself or
        when a test is impossible).
    """
    best = best_group(scores)
    if best is None:
        return None, {}
    pvalues = {g: (math.nan if g == best else welch_p(scores[best], v))
               for g, v in scores.items() if len(v)}
    return best, pvalues


# Robust and multiple-comparison statistics ------------------------------------------------------


def _array(values: Sequence[float]) -> np.ndarray:
    return np.asarray(values, dtype=float).ravel()


def mean_interval(values: Sequence[float], level: float = LEVEL) -> tuple[float, float, float]:
    """Mean of a sample with its Student-t interval (:func:`t_interval`).

    Returns:
        (mean, low, high); low and high are NaN with fewer than 2 values, all three with none.
    """
    x = _array(values)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    mean = float(np.mean(x))
    if len(x) < 2:
        return mean, math.nan, math.nan
    low, high = t_interval(mean, float(np.std(x, ddof=1)), len(x), level)
    return mean, float(low), float(high)


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: the mean of the middle half of the sorted values; NaN if empty.

    ``scipy.stats.trim_mean(values, 0.25)``: floor(n / 4) values are cut from each end, so with
    fewer than 4 values it is the plain mean.
    """
    x = _array(values)
    return float(stats.trim_mean(x, 0.25)) if len(x) else math.nan


def _iqm_along(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return stats.trim_mean(x, 0.25, axis=axis)


def iqm_interval(values: Sequence[float], repetitions: int = BOOTSTRAP_REPETITIONS,
                 level: float = LEVEL, seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of the interquartile mean over seeds.

    Agarwal et al. (2021) resample the runs of each task apart (a stratified bootstrap). A
    sweep value has one task, so its one stratum is its seeds: this resamples the seeds, with
    replacement, ``repetitions`` times (``scipy.stats.bootstrap``, method "percentile").

    Args:
        values: One value per seed.
        repetitions: Bootstrap resamples.
        level: Confidence level.
        seed: Seed of the resampling; the same seed gives the same interval.

    Returns:
        (low, high); (NaN, NaN) with fewer than 2 values, (v, v) when every value is v.
    """
    x = _array(values)
    if len(x) < 2:
        return math.nan, math.nan
    if np.all(x == x[0]):
        return float(x[0]), float(x[0])
    result = stats.bootstrap((x,), _iqm_along, n_resamples=repetitions, vectorized=True,
                             confidence_level=level, method="percentile",
                             rng=np.random.default_rng(seed))
    ci = result.confidence_interval
    return float(ci.low), float(ci.high)


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


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm (1979) step-down adjusted p-values, in the order given.

    With the m p-values sorted up, p(1) <= ... <= p(m), the i-th adjusted one is
    max over j <= i of min(1, (m - j + 1) p(j)). Reject where adjusted p < alpha: the chance of
    any false rejection stays <= alpha. SciPy has no Holm correction (only BH and BY).

    Returns:
        Adjusted p-values; NaN entries stay NaN and do not count in m.
    """
    p = _array(pvalues)
    adjusted = np.full(len(p), math.nan)
    present = np.flatnonzero(~np.isnan(p))
    order = present[np.argsort(p[present], kind="stable")]
    m = len(order)
    scaled = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adjusted[order] = np.maximum.accumulate(scaled)
    return [float(v) for v in adjusted]


def holm_vs_best(scores: Mapping[int, Sequence[float]]) -> tuple[int | None, dict[int, float]]:
    """The best group and every other group's Welch p-value against it, Holm-corrected over
    the study's comparisons (:func:`compare_to_best`, then :func:`holm`); NaN for the best
    itself and where no test is possible. A group tied with the best has p >= ALPHA."""
    best, pvalues = compare_to_best({g: list(v) for g, v in scores.items()})
    groups = list(pvalues)
    return best, dict(zip(groups, holm([pvalues[g] for g in groups]), strict=True))


def _p_improvement_along(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    u = stats.mannwhitneyu(x, y, axis=axis).statistic
    return u / (x.shape[axis] * y.shape[axis])


def p_improvement(x: Sequence[float], y: Sequence[float]) -> float:
    """Probability of improvement of X over Y (Agarwal et al. 2021), over all pairs of seeds.

    P(X > Y) + 0.5 P(X = Y): the Mann-Whitney U statistic of x against y over len(x) len(y).

    Returns:
        A probability in [0, 1]; NaN if either sample is empty.
    """
    a, b = _array(x), _array(y)
    if len(a) == 0 or len(b) == 0:
        return math.nan
    return float(_p_improvement_along(a, b))


def p_improvement_interval(x: Sequence[float], y: Sequence[float],
                           repetitions: int = BOOTSTRAP_REPETITIONS, level: float = LEVEL,
                           seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of :func:`p_improvement`.

    Each sample's seeds are resampled apart, with replacement (``scipy.stats.bootstrap`` with
    two unpaired samples, method "percentile").

    Args:
        x: One value per seed of the first sample.
        y: One value per seed of the second.
        repetitions: Bootstrap resamples.
        level: Confidence level.
        seed: Seed of the resampling; the same seed gives the same interval.

    Returns:
        (low, high); (NaN, NaN) if either sample has fewer than 2 values, (p, p) when neither
        has any spread.
    """
    a, b = _array(x), _array(y)
    if len(a) < 2 or len(b) < 2:
        return math.nan, math.nan
    if np.all(a == a[0]) and np.all(b == b[0]):
        p = p_improvement(a, b)
        return p, p
    result = stats.bootstrap((a, b), _p_improvement_along, n_resamples=repetitions,
                             vectorized=True, paired=False, confidence_level=level,
                             method="percentile", rng=np.random.default_rng(seed))
    ci = result.confidence_interval
    return float(ci.low), float(ci.high)


def iqr(values: Sequence[float]) -> float:
    """Interquartile range of a sample (``scipy.stats.iqr``), its repeatability; NaN if empty."""
    x = _array(values)
    return float(stats.iqr(x)) if len(x) else math.nan


# The verdict --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Verdict:
    """What a sweep's report concludes, group by group (a group is a swept value's index)."""

    best: int | None
    """The group with the best mean final score (:func:`kraby_study.records.best_group`)."""
    tied: list[int]
    """The other groups not significantly worse than the best: Holm-corrected Welch p >= ALPHA."""
    most_sample_efficient: int | None
    """The group with the highest mean AUC."""
    fastest: int | None
    """The group with the lowest mean seconds to the threshold, among groups where a seed
    reached it."""
    most_repeatable: int | None
    """The group with the lowest final-score IQR, among groups with >= 2 complete seeds."""


def _highest(values: Mapping[int, float]) -> int | None:
    """The group with the highest value (first in order on ties), ignoring NaN."""
    return best_group({g: [float(v)] for g, v in values.items() if not math.isnan(v)})


def verdict(final: Mapping[int, Sequence[float]], auc_means: Mapping[int, float],
            seconds: Mapping[int, float], iqrs: Mapping[int, float],
            p_holm: Mapping[int, float]) -> Verdict:
    """The verdict of a sweep; NaN values never win, ties go to the first group in order.

    Args:
        final: Final scores of the complete seeds, by group (NaN scores are ignored).
        auc_means: Mean AUC by group.
        seconds: Mean seconds to the threshold by group, NaN where no seed reached it.
        iqrs: Final-score IQR by group.
        p_holm: Holm-corrected Welch p against the best, by group (NaN for the best itself or
            where no test was possible: such a group is not tied).

    Returns:
        The :class:`Verdict`.
    """
    scores = {g: [float(v) for v in vs if not math.isnan(v)] for g, vs in final.items()}
    best = best_group(scores)
    # NaN >= ALPHA is False: a group without a test is not tied.
    tied = [g for g in scores if best is not None and g != best
            and float(p_holm.get(g, math.nan)) >= ALPHA]
    repeatable = {g: -float(v) for g, v in iqrs.items() if len(scores.get(g, [])) >= 2}
    return Verdict(best=best, tied=tied,
                   most_sample_efficient=_highest(auc_means),
                   fastest=_highest({g: -float(v) for g, v in seconds.items()}),
                   most_repeatable=_highest(repeatable))
