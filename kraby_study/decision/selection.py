"""Which value of a finished sweep is selected: the rules a campaign carries forward.

"Best" is the highest IQM final score only (the interquartile mean; the mean below 4 seeds);
"selected" is what a rule picks. Every rule is a named [`Rule`][kraby_study.decision.selection.Rule]
that reads one [`Comparison`][kraby_study.decision.comparison.Comparison] (the report's answers, the
same object its table column shows) and the values' mean AUC and training time:

- ``final_score``: the best value.
- ``auc``: the highest mean AUC over the seeds with a curve (the most sample-efficient).
- ``fastest_equivalent``: among the best and the values shown equivalent to it (within the
  margin, [`compare`][kraby_study.decision.comparison.compare]), the lowest mean training time: a
  slower value is not worth its time when a faster one is shown as good within the margin, and a
  value needs evidence to be selected, so spread cannot buy a place.

A study stored with the retired rule name ``fastest_tied`` selects by ``fastest_equivalent``
([`of`][kraby_study.records.attributes.SelectRule.of]).

Every rule considers only the comparison's family: values with at least ``min_seeds``
complete seeds (``report.min_seeds``, default 2), so one lucky seed is never selected. Ties
inside a rule go to the first value in order; NaN never wins.

In a raced study ([`kraby_study.decision.race`][]) every rule considers only the values the race did
not drop as worse: they are left out of the comparison, and the others are compared by the same
procedure on all their seeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from kraby_study.decision.comparison import Comparison
from kraby_study.records.attributes import SelectRule
from kraby_study.records.values import best_group

K = TypeVar("K", bound=Hashable)


def _lowest(candidates: Sequence[K], values: Mapping[K, float], fallback: K) -> K:
    """The candidate with the lowest value (first in order on ties, NaN never wins)."""
    known = {g: [-values[g]] for g in candidates if g in values and not math.isnan(values[g])}
    chosen = best_group(known)
    return chosen if chosen is not None else fallback


def _final_score(comparison: Comparison[K], aucs: Mapping[K, float],
                 times: Mapping[K, float]) -> K | None:
    return comparison.best


def _auc(comparison: Comparison[K], aucs: Mapping[K, float],
         times: Mapping[K, float]) -> K | None:
    return best_group({g: [aucs[g]] for g in comparison.family
                       if g in aucs and not math.isnan(aucs[g])})


def _fastest_equivalent(comparison: Comparison[K], aucs: Mapping[K, float],
                        times: Mapping[K, float]) -> K | None:
    if comparison.best is None:
        return None
    return _lowest([comparison.best, *comparison.equivalent], times, comparison.best)


@dataclass(frozen=True)
class Rule:
    """A selection rule: its name, what it selects in words, and the function that selects."""

    name: SelectRule
    description: str
    pick: Callable[[Comparison[Any], Mapping[Any, float], Mapping[Any, float]], Any]
    """(comparison, mean AUC by value, mean training time by value) -> the selected value."""
    tests: bool = True
    """Whether it reads the comparison's tests (False: the best and the family suffice)."""

    def select(self, comparison: Comparison[K], aucs: Mapping[K, float],
               times: Mapping[K, float]) -> K | None:
        """The value this rule selects; None when the comparison has no best."""
        return self.pick(comparison, aucs, times) if comparison.best is not None else None


_TIME = "mean training time (wall-clock seconds; CPU seconds on a confirm study)"
RULES: dict[SelectRule, Rule] = {r.name: r for r in (
    Rule(SelectRule.FINAL_SCORE, "highest IQM final score (the best)", _final_score, False),
    Rule(SelectRule.AUC, "highest mean AUC (sample efficiency)", _auc, False),
    Rule(SelectRule.FASTEST_EQUIVALENT,
         f"lowest {_TIME} among the best and the values shown equivalent to it (within the "
         "margin; multiple comparisons with the best, alpha 0.05)", _fastest_equivalent),
)}
RULE_TEXT = {name: rule.description for name, rule in RULES.items()}


def rule_of(name: str, where: str = "study.select") -> Rule:
    """The rule named ``name``; ConfigError naming the known ones."""
    return RULES[SelectRule.check(name, where)]


def mean_by_value(groups: Mapping[K, Sequence[float]]) -> dict[K, float]:
    """Each group's mean over its values (NaN ignored); a group without one is left out."""
    out = {}
    for group, values in groups.items():
        kept = [float(v) for v in values if not math.isnan(float(v))]
        if kept:
            out[group] = math.fsum(kept) / len(kept)
    return out


def select(rule: str, comparison: Comparison[K], aucs: Mapping[K, Sequence[float]],
           seconds: Mapping[K, Sequence[float]]) -> K | None:
    """The value ``rule`` selects from the study's one ``comparison`` (whose family excludes
    the values a race dropped) and each value's AUCs and training times (their means are
    compared); None when the comparison has no best.

    Args:
        rule: final_score, auc or fastest_equivalent.
        comparison: The study's comparison of its complete seeds' final scores.
        aucs: AUC of each complete seed with a curve, by value.
        seconds: Training time of each complete seed, by value.
    """
    return rule_of(rule).select(comparison, mean_by_value(aucs), mean_by_value(seconds))
