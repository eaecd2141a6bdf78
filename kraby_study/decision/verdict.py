"""A sweep's verdict: the best value and every other value's answer, read from the study's one
comparison (:func:`kraby_study.decision.comparison.compare`), with the most sample-efficient,
the fastest and the most repeatable value; the raw Welch p-values against the best, for
information only."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from kraby_study.decision.comparison import (
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
from kraby_study.records.values import best_group

TEST_NAME = ("two-sided Welch's t-test against the best value, uncorrected (for information: "
             "the ties do not use it)")
HOLM_NAME = (f"{PROCEDURE}, alpha = {ALPHA}: the adjusted p of 'this value is a best'; "
             f"< {ALPHA} means worse than the best")
PROCEDURE_NAME = procedure_name(ALPHA)


def welch_p(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Welch's t-test p-value of two samples; NaN when either has fewer than 2.

    Two samples without spread, relative to the scale of the scores
    (:data:`kraby_study.decision.robust.CONSTANT_RTOL`), are identical (p = 1) when their means
    agree within that tolerance, else certainly different (p = 0).
    """
    return welch_two_sided_p(a, b)


def compare_to_best(scores: dict[int, list[float]],
                    min_seeds: int = MIN_SEEDS) -> tuple[int | None, dict[int, float]]:
    """The best group (:func:`kraby_study.decision.comparison.compare_with_best`), and every group's
    raw two-sided Welch p-value against it, uncorrected: for information, never for a tie.

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


def holm_vs_best(scores: Mapping[int, Sequence[float]],
                 min_seeds: int = MIN_SEEDS) -> tuple[int | None, dict[int, float]]:
    """The best group and every group's adjusted p of "this group is a best"
    (:func:`kraby_study.decision.comparison.compare_with_best`: closed Holm step-down over one-sided
    Welch tests); NaN for the best itself and for groups with fewer than ``min_seeds`` seeds.
    A group tied with the best has p >= ALPHA."""
    result = compare_with_best(scores, min_seeds=min_seeds)
    return result.best, {g: result.p_adjusted.get(g, math.nan)
                         for g, v in scores.items() if len(v)}


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
    (:func:`kraby_study.decision.comparison.compare_with_best`)."""
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
        comparison: The study's one comparison (:func:`kraby_study.decision.comparison.compare`):
        the
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
