"""A sweep's verdict: the best value and every other value's answer, read from the study's one
comparison ([`compare`][kraby_study.decision.comparison.compare]), with the most sample-efficient
(highest mean AUC), the fastest to a threshold (lowest restricted mean time) and the most repeatable
(lowest rescaled IQR) value among the comparison's family."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from kraby_study.decision.comparison import MIN_SEEDS, Comparison
from kraby_study.records.values import best_group


@dataclass(frozen=True)
class Verdict:
    """What a sweep's report concludes, group by group (a group is a swept value's index).

    Only groups in the comparison's family (at least ``min_seeds`` complete seeds) can be an
    answer.
    """

    best: int | None
    """The group with the highest IQM final score among the groups with enough seeds."""
    most_sample_efficient: int | None
    """The group with the highest mean AUC."""
    fastest: int | None
    """The group with the lowest restricted mean seconds to the threshold (a seed that never
    reached it counts at its run's end), among groups where a seed reached it."""
    most_repeatable: int | None
    """The group with the lowest rescaled IQR of its final scores."""
    min_seeds: int = MIN_SEEDS
    """Fewest complete seeds a group needed to be any of the above."""
    comparison: Comparison[int] | None = field(default=None, compare=False)
    """The comparison the best and the answers come from; None for an empty verdict."""


def _highest(values: Mapping[int, float]) -> int | None:
    """The group with the highest value (first in order on ties), ignoring NaN."""
    return best_group({g: [float(v)] for g, v in values.items() if not math.isnan(v)})


def verdict(comparison: Comparison[int], auc_means: Mapping[int, float],
            seconds: Mapping[int, float], iqrs: Mapping[int, float]) -> Verdict:
    """The verdict of a sweep; NaN values never win, ties go to the first group in order.

    Args:
        comparison: The study's one comparison
            ([`compare`][kraby_study.decision.comparison.compare]): the best is read from it, and
            its family is the groups that may be any answer.
        auc_means: Mean AUC by group.
        seconds: Restricted mean seconds to the threshold by group (a seed that never reached
            it at its run's end), NaN where no seed reached it.
        iqrs: Final-score IQR by group, comparable across n
            ([`iqr_unbiased`][kraby_study.decision.measures.iqr_unbiased]).

    Returns:
        The [`Verdict`][kraby_study.decision.verdict.Verdict].
    """
    enough = set(comparison.family)

    def among(values: Mapping[int, float], sign: float = 1.0) -> dict[int, float]:
        return {g: sign * float(v) for g, v in values.items() if g in enough}

    return Verdict(best=comparison.best,
                   most_sample_efficient=_highest(among(auc_means)),
                   fastest=_highest(among(seconds, -1.0)),
                   most_repeatable=_highest(among(iqrs, -1.0)), min_seeds=comparison.min_seeds,
                   comparison=comparison)


def empty_verdict() -> Verdict:
    """The verdict of a study with nothing to compare."""
    return Verdict(None, None, None, None)


