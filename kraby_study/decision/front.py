"""A two-objective search's front, and what is chosen from it by stated rules, never by eye.

A two-objective search maximises a score and minimises a cost (CPU seconds per seed). A trial
is on the front when no other complete trial is at least as good on both and better on one.
Two choices are made from it:

- [`front_choice`][kraby_study.decision.front.front_choice], the search's selection (``best``,
  ``list``, the report): the front's trials are compared on their seed scores
  ([`compare`][kraby_study.decision.comparison.compare]), and the search's rule picks the cheapest
  of the best score and the trials it admits: ``fastest_equivalent`` those shown within the margin
  of the best, ``final_score`` none. The family is the front, not every trial: the best score is
  always on it, every trial off it is matched or beaten on both objectives by one on it, and a
  family of 50 trials would leave the tests almost no power at 3 seeds. With fewer than
  ``min_seeds`` (2) seeds a trial there is no test, and the rule falls back to the best score.
- [`spread`][kraby_study.decision.front.spread], what ``confirm`` retrains: up to K trials
  spread along the front.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from kraby_study.decision.comparison import CompareOptions, Comparison, compare
from kraby_study.decision.selection import RULES
from kraby_study.records.attributes import SelectRule

K = TypeVar("K", bound=Hashable)

FRONT_RULES = (SelectRule.FASTEST_EQUIVALENT, SelectRule.FINAL_SCORE)
"""The rules a front can be selected by (the cost is the time they compare)."""
UNTESTED_TEXT = ("the best score: with fewer than 2 seeds a trial no comparison can be made, so "
                 "the rule falls back to final_score")
"""What the rule becomes when the trials have too few seeds for a test."""


@dataclass(frozen=True)
class Point(Generic[K]):
    """One complete trial of a two-objective search: its key (the trial's number), its score
    (higher is better) and its cost (lower is better)."""

    key: K
    score: float
    cost: float


def dominates(a: Point[K], b: Point[K]) -> bool:
    """``a`` is at least as good as ``b`` on both objectives and better on one."""
    return (a.score >= b.score and a.cost <= b.cost) and (a.score > b.score or a.cost < b.cost)


def pareto_front(points: Sequence[Point[K]]) -> list[Point[K]]:
    """The points no other point dominates, cheapest first (equal costs: higher score first,
    then in the given order). Equal points are both kept."""
    front = [p for p in points if not any(dominates(q, p) for q in points)]
    order = {id(p): i for i, p in enumerate(points)}
    return sorted(front, key=lambda p: (p.cost, -p.score, order[id(p)]))


def spread(front: Sequence[Point[K]], count: int) -> list[Point[K]]:
    """Up to ``count`` points spread along a front (as
    [`pareto_front`][kraby_study.decision.front.pareto_front] orders it, cheapest first): the best
    score first, then the cheapest, then the rest in cost order.

    With n points on the front and count < n, the points taken are those at the evenly spaced
    places round(i (n - 1) / (count - 1)), i = 0 .. count - 1, of the cost order: both ends
    and the rest as evenly as the front's points allow. With count >= n every point is taken;
    count 1 takes the best score alone.
    """
    n = len(front)
    if n == 0 or count < 1:
        return []
    if count >= n:
        places = list(range(n))
    elif count == 1:
        places = [n - 1]
    else:
        places = sorted({round(i * (n - 1) / (count - 1)) for i in range(count)})
    best = n - 1
    rest = [i for i in places if i not in (best, 0)]
    ordered = [best] + ([0] if 0 in places and n > 1 else []) + rest
    return [front[i] for i in ordered]


@dataclass(frozen=True)
class FrontChoice(Generic[K]):
    """The front's trial a rule chose, and what it was chosen among."""

    chosen: Point[K]
    best: Point[K]
    """The front's best score."""
    equivalent: list[K] = field(default_factory=list)
    """The front's trials the rule admitted beside the best (the best excluded): those shown
    equivalent to it under fastest_equivalent, none under final_score."""
    tested: bool = True
    """False when the trials had too few seeds for a test: the chosen is then the best."""
    rule: str = SelectRule.FASTEST_EQUIVALENT
    comparison: Comparison[K] | None = None
    """The comparison the rule read (None when untested)."""

    @property
    def rule_text(self) -> str:
        """The rule that chose, in words."""
        if not self.tested:
            return UNTESTED_TEXT
        if self.rule != SelectRule.FASTEST_EQUIVALENT:
            return f"{self.rule}: the front's best score"
        margin = f"; {self.comparison.margin_text()}" if self.comparison is not None else ""
        return (f"{self.rule}: the lowest cost (CPU s per seed) among the front's trials "
                f"shown equivalent to its best score (within the margin), on each trial's "
                f"seed scores{margin}")


def front_choice(front: Sequence[Point[K]], seed_scores: Mapping[K, Sequence[float]],
                 rule: str, options: CompareOptions) -> FrontChoice[K] | None:
    """The cheapest of the front's best score and the front's trials ``rule`` admits; None for
    an empty front.

    Args:
        front: The front ([`pareto_front`][kraby_study.decision.front.pareto_front]).
        seed_scores: Each trial's seed scores, by key; a trial with fewer than ``min_seeds``
            is in no test.
        rule: fastest_equivalent or final_score.
        options: The command's margin, alpha and seeds of the comparison.
    """
    if not front:
        return None
    best_score = max(front, key=lambda p: p.score)
    # Highest score first, so that the rule's "first in order" breaks a tie in cost by score.
    ordered = sorted(front, key=lambda p: -p.score)
    by_key = {p.key: p for p in ordered}
    comparison = compare({p.key: list(seed_scores.get(p.key, [])) for p in ordered},
                         options.margin, alpha=options.alpha, min_seeds=options.min_seeds)
    if comparison.best is None:
        return FrontChoice(chosen=best_score, best=best_score, tested=False, rule=rule)
    admitted = comparison.equivalent if rule == SelectRule.FASTEST_EQUIVALENT else []
    # The rules of a sweep's values, with the trials' cost as their time.
    chosen = RULES[SelectRule(rule)].select(comparison, {}, {p.key: p.cost for p in ordered})
    return FrontChoice(chosen=by_key[chosen], best=by_key[comparison.best],
                       equivalent=list(admitted), rule=rule, comparison=comparison)

