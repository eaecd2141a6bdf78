"""Seeds that failed to learn: counted apart, because a mean hides them.

A seed *failed* when its final score lies nearer the untrained policy's score than the best
value's mean: below the midpoint ``(untrained + best mean) / 2``, i.e. it learned less than
half of the gain the best value learns on average. The untrained score is the study's mean
first-curve-point reward (every complete seed's first bin: the policy before it learned
much). Half the learned gain is the natural cut of a two-component mixture (a seed that
learns, a seed that does not) whose components are the best value's runs and the untrained
policy, and it reads the same on any env and any reward scale; a seed that learned half of
what the best learns is not a failure of the setting, one that learned less is nearer to
never having trained.

A failed *run* (an error, a divergence to NaN) is another thing: it has no score, and is
counted in the ``failed`` column of the summary; failed seeds are complete runs.

The share of failed seeds of a value is a binomial rate over its complete seeds; its interval
is Clopper and Pearson's exact interval (1934), `scipy.stats.binomtest`'s
``proportion_ci(method="exact")``, whose coverage is at least the level for every rate and n.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

LEVEL = 0.95


def failure_line(untrained: float, best_mean: float) -> float:
    """The score below which a seed failed: halfway from the untrained score to the best
    value's mean; NaN when either is missing or the best learned nothing (its mean is not
    above the untrained score)."""
    if not (math.isfinite(untrained) and math.isfinite(best_mean)) or best_mean <= untrained:
        return math.nan
    return 0.5 * (untrained + best_mean)


@dataclass(frozen=True)
class FailedSeeds:
    """A value's failed seeds among its complete ones."""

    count: int
    """Seeds below the failure line."""
    seeds: int
    """Complete seeds looked at (0 when the line is not defined)."""
    low: float
    """Lower end of the exact interval of the failure rate (NaN without seeds)."""
    high: float
    """Upper end."""

    def text(self) -> str:
        """E.g. '2 of 10 (rate 95 % CI 0.03-0.56)'; '-' when not counted."""
        if not self.seeds:
            return "-"
        return (f"{self.count} of {self.seeds} (rate {LEVEL * 100:g} % CI "
                f"{self.low:.2f}-{self.high:.2f})")


def failed_seeds(scores: Sequence[float], line: float, level: float = LEVEL) -> FailedSeeds:
    """How many of ``scores`` (NaN ignored) lie below ``line``, with the Clopper-Pearson
    interval of the rate at ``level``; none counted when the line is NaN."""
    from scipy.stats import binomtest

    x = np.asarray(scores, dtype=float)
    x = x[~np.isnan(x)]
    if not len(x) or not math.isfinite(line):
        return FailedSeeds(0, 0, math.nan, math.nan)
    count = int(np.sum(x < line))
    interval = binomtest(count, len(x)).proportion_ci(confidence_level=level, method="exact")
    return FailedSeeds(count, len(x), float(interval.low), float(interval.high))


def definition_text(line: float, untrained: float) -> str:
    """How reports define a failed seed, with the line in score units."""
    return (f"a failed seed's final score is below {line:.4g}, halfway from the untrained "
            f"policy's {untrained:.4g} to the best value's mean (it learned less than half the "
            f"best's gain); rate interval: Clopper-Pearson exact, {LEVEL * 100:g} %")
