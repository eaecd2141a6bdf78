"""Per-seed measures beside the final score: sample efficiency (AUC), time to a threshold,
repeatability (an IQR comparable across seed counts) and the probability of improvement of one
value over another (Agarwal et al. 2021, with Newcombe's 2006 score-type interval)."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from statistics import NormalDist
from typing import TYPE_CHECKING

import numpy as np
import scipy

from kraby_study.decision.intervals import LEVEL, _array

if TYPE_CHECKING:
    import pandas as pd

AUC_NAME = ("sample efficiency (AUC): the mean of a seed's binned mean episode rewards over the"
            " whole run, the normalised area under its learning curve")


def p_improvement_name(level: float = LEVEL) -> str:
    """The caption of [`p_improvement`][kraby_study.decision.measures.p_improvement] and its
    interval at a level."""
    return ("probability of improvement P(best > this value) over all pairs of seeds, ties"
            f" counted half, with its {level * 100:g} % Newcombe score-type interval"
            " (Newcombe 2006, method 5)")
P_IMPROVEMENT_NAME = p_improvement_name()


def auc(rewards: Sequence[float]) -> float:
    """Sample efficiency of one seed: the mean of its binned mean episode rewards over the run.

    With bins of equal width this is the area under the learning curve divided by its length.

    Returns:
        The mean reward of the curve's points; NaN for an empty curve.
    """
    x = _array(rewards)
    return float(np.mean(x)) if len(x) else math.nan


SeedScores = dict[int, list[float]]
"""One number per complete seed, by value index (in value order), each in run order."""


def curve_rewards(curves: pd.DataFrame) -> dict[int, np.ndarray]:
    """Each run's binned mean episode rewards in step order, by trial number (columns number,
    step, mean_reward): what [`auc`][kraby_study.decision.measures.auc] reads."""
    ordered = curves.sort_values(["number", "step"], kind="stable")
    return {int(n): g["mean_reward"].to_numpy(dtype=float)
            for n, g in ordered.groupby("number", sort=False)}


def seed_samples(runs: Iterable[tuple[int, int, float, float]],
                 rewards: Mapping[int, np.ndarray]) -> tuple[SeedScores, SeedScores, SeedScores]:
    """The seed scores every decision reads, from the complete runs (value index, trial
    number, final score, training time; NaN: no time stored) in run order, with their curves'
    rewards ([`curve_rewards`][kraby_study.decision.measures.curve_rewards]): per value with a run,
    in value order, the final scores, the AUCs of the runs with a curve and the training times."""
    final: SeedScores = {}
    aucs: SeedScores = {}
    seconds: SeedScores = {}
    for value_index, number, score, spent in runs:
        final.setdefault(value_index, []).append(score)
        if number in rewards:
            aucs.setdefault(value_index, []).append(auc(rewards[number]))
        if not math.isnan(spent):
            seconds.setdefault(value_index, []).append(spent)
    order = sorted(final)
    return ({i: final[i] for i in order}, {i: aucs.get(i, []) for i in order},
            {value_index: seconds.get(value_index, []) for value_index in order})


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
    """Newcombe's score-type confidence interval of
    [`p_improvement`][kraby_study.decision.measures.p_improvement] (Newcombe, "Confidence intervals
    for an effect size measure based on the Mann-Whitney statistic. Part 2: asymptotic methods and
    evaluation", Statistics in Medicine 25(4), 2006, method 5).

    With theta_hat = [`p_improvement`][kraby_study.decision.measures.p_improvement] of m values
    against n, the bounds are the two solutions in [0, 1] of |theta_hat - theta| = z sqrt(V(theta)),
    z = Phi^-1(0.5 + level / 2),

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
    """Expected sample IQR ([`iqr`][kraby_study.decision.measures.iqr], linear quartiles) of n
    standard normal values.

    The quartiles interpolate between order statistics, so their expectation is the same mix of
    the expected normal order statistics, each integrated numerically. 0.564 at n = 2 (true IQR
    1.349): a sample's IQR shrinks with n, which is why
    [`iqr_unbiased`][kraby_study.decision.measures.iqr_unbiased] divides by this.
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
    every n: IQR * 1.349 / E[IQR of n standard normals]
    ([`expected_normal_iqr`][kraby_study.decision.measures.expected_normal_iqr]).

    The raw sample IQR averages 0.42, 0.63 and 0.87 of the truth at n = 2, 3, 10, so the value
    that lost seeds looked the most repeatable; rescaled, the comparison across unequal n is
    fair in expectation. NaN with fewer than 2 values.
    """
    x = _array(values)
    if len(x) < 2:
        return math.nan
    return iqr(x) * NORMAL_IQR / expected_normal_iqr(len(x))
