"""Racing: seeds run in rounds, and a value leaves once its answer is settled.

Round r gives every value still in the race its r-th seed. From round ``min_seeds`` on, after
each round the values' first r seeds are compared by the report's procedure
([`compare`][kraby_study.decision.comparison.compare] at the race's margin): a value shown worse
than the look's best by more than the margin is dropped, and a value other than the look's best
shown equivalent to it (within the margin) is settled. Either way it gets no more seeds. The race
ends when one value is left racing, or every value left has ``seeds`` seeds. A settled value stays a
candidate: the selection compares every value the race did not drop, on all its seeds, by the
study's rule. At margin 0 no value is settled: the race stops only values shown worse.

The guarantee aimed at is Kim and Nelson's (2001) indifference zone: with probability at least
1 - alpha the race's selection is within the margin of the highest true mean. A look's false
"worse" and its false "equivalent" each have probability at most its level, and the levels sum
to alpha over the looks (below), but truncation at ``seeds`` and the selection's own noise
are not covered by that argument: ``benchmarks/bench_error_rates.py`` measures the
probability of a selection outside the margin, truncation included.

Every value runs the same seeds, and a seed can move the scores of all values together (the
same initial weights and action-noise stream). With ``RaceRules.paired`` (``racing.paired``)
each pair of values is compared on the seeds both have ended (the common seeds resampled
together, and Yuen's test for dependent trimmed means): seeds are blocks, as instances are in
F-Race (Birattari et al. 2002), whose Friedman test blocks on them. It pays only where that
shared part is large: on the four quick studies of docs/benchmarks/index.md it saved no run,
so the default stays the unpaired tests, the report's own.

Each look is one more chance of a false answer, so the looks share the error: alpha is spent
in equal parts over the ``seeds - min_seeds + 1`` looks the race can take (Bonferroni's
inequality over the looks, the simplest alpha-spending rule; see Jennison and Turnbull, "Group
Sequential Methods", 2000, ch. 1 and 7, and the Pocock-type constant boundary it
approximates). Under the global null, the chance that any look drops any value is then at most
the sum of the per-look levels, alpha; ``benchmarks/bench_error_rates.py`` and
``benchmarks/bench_racing.py`` measure it.

A function of the stored results only: the same results give the same race, whichever command
computes it, so a race resumes after a crash and is shared by commands on one database.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from kraby_study.decision.comparison import Answer, compare
from kraby_study.plan.spec import RaceRules

K = TypeVar("K", bound=Hashable)

@dataclass(frozen=True)
class Drop:
    """When and why a value left the race."""

    round: int
    """The round after which it left (its first ``round`` seeds were compared)."""
    p: float
    """The p of its answer at that look (below the look's level): the Holm-adjusted p of
    "within the margin" for a value dropped as worse, the Bonferroni p of "more than the
    margin below" for one settled as equivalent."""
    answer: Answer = Answer.WORSE
    """Why it left: worse (dropped) or equivalent (settled)."""


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
    """Values shown worse: never selected."""
    settled: dict[K, Drop] = field(default_factory=dict)
    """Values shown equivalent to a look's best: no more seeds, still candidates."""

    @property
    def survivors(self) -> list[K]:
        """Values still racing (neither dropped nor settled), in the study's order."""
        return [v for v in self.values if v not in self.dropped and v not in self.settled]

    @property
    def candidates(self) -> list[K]:
        """Values a selection may name: every value not dropped, in the study's order."""
        return [v for v in self.values if v not in self.dropped]

    @property
    def over(self) -> bool:
        """One value is left racing, or every value left has all its seeds."""
        return len(self.survivors) <= 1 or self.rounds >= self.rules.seeds

    def wanted(self, value: K, index: int) -> bool:
        """Whether seed ``index`` (from 0) of ``value`` is still to be run: the value is still
        racing and the race is not over. A run already made is kept either way."""
        return (value not in self.dropped and value not in self.settled
                and index < self.rules.seeds and not self.over)


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
        The [`Race`][kraby_study.decision.race.Race] after every round whose seeds have all ended.
    """
    dropped: dict[K, Drop] = {}
    settled: dict[K, Drop] = {}
    rounds = 0
    for r in range(1, rules.seeds + 1):
        alive = [v for v in values if v not in dropped and v not in settled]
        if len(alive) <= 1:
            break
        if any(i not in runs.get(v, {}) for v in alive for i in range(r)):
            break
        rounds = r
        if r < rules.min_seeds:
            continue
        # Aligned by seed (NaN where a run failed): a paired look pairs position i of each.
        scores = {v: [runs[v][i] for i in range(r)] for v in alive}
        look = compare(scores, rules.margin, alpha=rules.look_alpha, min_seeds=2,
                       paired=rules.paired)
        for v in look.worse:
            dropped[v] = Drop(round=r, p=look.p_worse[v])
        for v in look.equivalent:
            settled[v] = Drop(round=r, p=look.p_equivalent[v], answer=Answer.EQUIVALENT)
    return Race(values=list(values), rules=rules, rounds=rounds, dropped=dropped,
                settled=settled)


@dataclass(frozen=True)
class StudyRace:
    """A stored study's race as its answers and report read it, its values by their index in
    a list the caller gives (the report's order may differ from the study file's)."""

    rules: RaceRules
    dropped: dict[int, Drop]
    """The values dropped as worse by their index in the caller's list, each with its round
    and p."""
    runs: int
    """Runs the race made: ended complete or failed (a withdrawn retry is not a run)."""
    fixed_runs: int
    """Runs of the fixed design: every value with every seed."""
    rounds: int
    """Rounds decided so far."""
    over: bool
    """The race is over: one value is left racing, or every value left has all its seeds."""
    settled: dict[int, Drop] = field(default_factory=dict)
    """The values settled as equivalent, by their index in the caller's list: no more seeds,
    still candidates."""

    @property
    def share(self) -> float:
        """Runs made over the fixed design's runs."""
        return self.runs / self.fixed_runs if self.fixed_runs else math.nan

    def saved_text(self) -> str:
        """``raced: 31 of 60 runs (52 %)``."""
        return f"raced: {self.runs} of {self.fixed_runs} runs ({100 * self.share:.0f} %)"


@dataclass(frozen=True)
class RaceRuns:
    """A raced study's ended runs as its evidence holds them, to be replayed."""

    rules: RaceRules
    planned: int
    """Values in the study file."""
    runs: Mapping[int, Mapping[int, float]]
    """Per planned value, its ended runs' final scores by seed index (NaN: failed)."""
    index: Sequence[int | None]
    """The caller's index of each planned value, None where the caller does not list it."""

    def replayed(self) -> StudyRace:
        """The race of the planned values (by their index in the study file) replayed on these
        runs, its dropped and settled values mapped to the caller's indices (a value the
        caller does not list is left out)."""
        state = race(list(range(self.planned)), self.runs, self.rules)

        def mapped(left: Mapping[int, Drop]) -> dict[int, Drop]:
            return {at: drop for v, drop in left.items() if (at := self.index[v]) is not None}

        return StudyRace(rules=self.rules, dropped=mapped(state.dropped),
                         runs=sum(len(r) for r in self.runs.values()),
                         fixed_runs=self.planned * self.rules.seeds, rounds=state.rounds,
                         over=state.over, settled=mapped(state.settled))
