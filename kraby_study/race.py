"""Racing: seeds run in rounds, and a value significantly worse than the best stops getting any.

Round r gives every value still in the race its r-th seed. From round ``min_seeds`` on, after
each round the values' first r seeds are compared with the best by the report's procedure
(:func:`kraby_study.comparison.compare_with_best`, the closed Holm step-down), and the values it
calls worse are dropped: their later seeds are never run. The race ends when one value is left
or every value left has ``seeds`` seeds.

Every value runs the same seeds, and a seed can move the scores of all values together (the
same initial weights and action-noise stream). With ``RaceRules.paired`` (``racing.paired``)
each pair of values is compared by a paired t-test on the seeds both have ended: seeds are
blocks, as instances are in F-Race (Birattari et al. 2002), whose Friedman test blocks on them.
It pays only where that shared part is large: on the four quick studies of docs/benchmarks.md
it saved no run, so the default stays Welch's unpaired tests, the report's own.

Each look is one more chance of a false "worse", so the looks share the family-wise error:
alpha is spent in equal parts over the ``seeds - min_seeds + 1`` looks the race can take
(Bonferroni's inequality over the looks, the simplest alpha-spending rule; see Jennison and
Turnbull, "Group Sequential Methods", 2000, ch. 1 and 7, and the Pocock-type constant boundary it
approximates). Under the global null, the chance that any look drops any value is then at most
the sum of the per-look levels, alpha; ``benchmarks/bench_error_rates.py`` measures it.

A function of the stored results only: the same results give the same race, whichever command
computes it, so a race resumes after a crash and is shared by commands on one database.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from kraby_study.comparison import compare_with_best
from kraby_study.plan.spec import RaceRules

K = TypeVar("K", bound=Hashable)

@dataclass(frozen=True)
class Drop:
    """When and why a value left the race."""

    round: int
    """The round after which it was dropped (its first ``round`` seeds were compared)."""
    p: float
    """Its Holm-adjusted p at that look (below the look's level)."""


@dataclass(frozen=True)
class Race(Generic[K]):
    """Where a race stands."""

    values: list[K]
    """Every value, in the study's order."""
    rules: RaceRules
    rounds: int
    """Rounds decided: every value still in the race has ended its first ``rounds`` seeds, and
    each look up to that round has been taken."""
    dropped: dict[K, Drop] = field(default_factory=dict)

    @property
    def survivors(self) -> list[K]:
        """Values still in the race, in the study's order."""
        return [v for v in self.values if v not in self.dropped]

    @property
    def over(self) -> bool:
        """One value is left, or every value left has all its seeds."""
        return len(self.survivors) <= 1 or self.rounds >= self.rules.seeds

    def wanted(self, value: K, index: int) -> bool:
        """Whether seed ``index`` (from 0) of ``value`` is still to be run: the value is in the
        race and the race is not over. A run already made is kept either way."""
        return value not in self.dropped and index < self.rules.seeds and not self.over


def race(values: Sequence[K], runs: Mapping[K, Mapping[int, float]], rules: RaceRules
         ) -> Race[K]:
    """Replay a race on the runs that have ended.

    Args:
        values: Every value, in the study's order.
        runs: Per value, the ended seeds by index (0 is the first seed): the final score, NaN
            for a run that ended without one (failed). Seeds beyond a round still running may
            be present (a round's tail): a look reads only each value's first r seeds.
        rules: The race's settings.

    Returns:
        The :class:`Race` after every round whose seeds have all ended.
    """
    dropped: dict[K, Drop] = {}
    rounds = 0
    for r in range(1, rules.seeds + 1):
        alive = [v for v in values if v not in dropped]
        if len(alive) <= 1:
            break
        if any(i not in runs.get(v, {}) for v in alive for i in range(r)):
            break
        rounds = r
        if r < rules.min_seeds:
            continue
        # Aligned by seed (NaN where a run failed): a paired look pairs position i of each.
        scores = {v: [runs[v][i] for i in range(r)] for v in alive}
        look = compare_with_best(scores, alpha=rules.look_alpha, min_seeds=2,
                                 paired=rules.paired)
        for v in look.worse:
            dropped[v] = Drop(round=r, p=look.p_adjusted[v])
    return Race(values=list(values), rules=rules, rounds=rounds, dropped=dropped)
