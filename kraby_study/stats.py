"""The statistics behind every band, error bar and "best" mark of a report.

- Interval: the 95 % Student-t confidence interval of the mean over seeds,
  mean +- t(0.975, n - 1) * s / sqrt(n), with s the sample standard deviation (ddof 1).
  It needs at least two seeds; with one it is left empty.
- Best value: the highest mean final score.
- "Not significantly different from the best": a two-sided Welch's t-test (unequal variances)
  of each value's final scores against the best value's gives p >= 0.05. No correction for
  multiple comparisons, so the set of values marked as ties is, if anything, too small.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

LEVEL = 0.95
ALPHA = 0.05
INTERVAL_NAME = "95 % Student-t confidence interval of the mean over seeds"
TEST_NAME = "two-sided Welch's t-test against the best value, alpha = 0.05"


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
    means = {g: float(np.mean(v)) for g, v in scores.items() if len(v)}
    if not means:
        return None, {}
    best = max(means, key=lambda g: means[g])
    pvalues = {g: (math.nan if g == best else welch_p(scores[best], scores[g])) for g in means}
    return best, pvalues
