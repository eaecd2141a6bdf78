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

A run that diverged (NaN) has no score, so the comparison cannot see it. Each look therefore
also compares each value's diverged runs among its first r seeds with the look's best's
(one-sided Fisher exact test, Holm over the values, at the look's level) and drops a value
shown to diverge more often ([`diverging`][kraby_study.decision.race.diverging]). A run that
failed with an error is not counted: it says nothing of the value.

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
from collections.abc import Collection, Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Generic, TypeVar

import numpy as np

from kraby_study.decision.comparison import (
    Answer,
    Comparison,
    compare,
    holm,
    margin_weights,
    p_text,
)
from kraby_study.decision.robust import iqm, iqm_pairs
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
    diverged: int = 0
    """Runs of its first ``round`` seeds that diverged, when their count dropped it (0 when
    its scores did); ``p`` is then the Holm-adjusted p of the diverged counts' test."""

    def why(self) -> str:
        """``adjusted p 0.004``, or ``5 of 5 runs diverged, adjusted p 0.02``."""
        head = f"{self.diverged} of {self.round} runs diverged, " if self.diverged else ""
        return f"{head}adjusted p {p_text(self.p)}"


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


def take_look(scores: Mapping[K, Sequence[float]], rules: RaceRules) -> Comparison[K]:
    """One look of a race (or of a racing search's challenger): the report's comparison at
    the race's margin, at the look's level (alpha spent over the looks)."""
    return compare(scores, rules.margin, alpha=rules.look_alpha, min_seeds=2,
                   paired=rules.paired)


def race(values: Sequence[K], runs: Mapping[K, Mapping[int, float]], rules: RaceRules,
         diverged: Mapping[K, Collection[int]] | None = None) -> Race[K]:
    """Replay a race on the runs that have ended.

    Args:
        values: Every value, in the study's order.
        runs: Per value, the ended seeds by index (0 is the first seed): the final score, NaN
            for a run that ended without one (failed). Seeds beyond a round still running may
            be present (a round's tail): a look reads only each value's first r seeds.
        rules: The race's settings.
        diverged: Per value, the seed indices of its failed runs that diverged (the others
            failed with an error); a look drops a value shown to diverge more often than the
            look's best ([`diverging`][kraby_study.decision.race.diverging]).

    Returns:
        The [`Race`][kraby_study.decision.race.Race] after every round whose seeds have all ended.
    """
    dropped: dict[K, Drop] = {}
    settled: dict[K, Drop] = {}
    diverged = diverged or {}
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
        look = take_look(scores, rules)
        firsts = {v: {i for i in diverged.get(v, ()) if i < r} for v in alive}
        for v, (p, count) in diverging(firsts, r, look.best, rules.look_alpha).items():
            dropped[v] = Drop(round=r, p=p, diverged=count)
        for v in look.worse:
            dropped.setdefault(v, Drop(round=r, p=look.p_worse[v]))
        for v in look.equivalent:
            if v not in dropped:
                settled[v] = Drop(round=r, p=look.p_equivalent[v], answer=Answer.EQUIVALENT)
    return Race(values=list(values), rules=rules, rounds=rounds, dropped=dropped,
                settled=settled)


def diverging(diverged: Mapping[K, Collection[int]], r: int, best: K | None, level: float
              ) -> dict[K, tuple[float, int]]:
    """The values of a look shown to diverge more often than its best, with their adjusted p
    and diverged count.

    A diverged run has no score, so the look's IQMs cannot see it; its count can. Each value's
    diverged runs among its first ``r`` seeds against the best's: one-sided Fisher exact test
    (scipy), Holm-adjusted over the values compared (the look's family), shown where the
    adjusted p is below ``level`` (the look's). Nothing is compared without a best (no value
    has scores enough) or when no run of the look diverged.

    Args:
        diverged: Per value racing at this look, the seed indices below ``r`` that diverged.
        r: The look's round: each value's first ``r`` seeds.
        best: The look's best, the reference (None: nothing is compared).
        level: The look's level (alpha spent over the looks).
    """
    if best is None or not any(diverged.values()):
        return {}
    from scipy import stats  # only here: reading where studies stand loads no scipy.stats

    others = [v for v in diverged if v != best]
    held = len(diverged.get(best, ()))
    p = [float(stats.fisher_exact([[len(diverged[v]), r - len(diverged[v])], [held, r - held]],
                                  alternative="greater").pvalue) for v in others]
    return {v: (adjusted, len(diverged[v])) for v, adjusted in zip(others, holm(p), strict=True)
            if adjusted < level}


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
    diverged: Mapping[int, Collection[int]] = field(default_factory=dict)
    """Per planned value, the seed indices of its runs that diverged."""

    def replayed(self) -> StudyRace:
        """The race of the planned values (by their index in the study file) replayed on these
        runs, its dropped and settled values mapped to the caller's indices (a value the
        caller does not list is left out)."""
        state = race(list(range(self.planned)), self.runs, self.rules, self.diverged)

        def mapped(left: Mapping[int, Drop]) -> dict[int, Drop]:
            return {at: drop for v, drop in left.items() if (at := self.index[v]) is not None}

        return StudyRace(rules=self.rules, dropped=mapped(state.dropped),
                         runs=sum(len(r) for r in self.runs.values()),
                         fixed_runs=self.planned * self.rules.seeds, rounds=state.rounds,
                         over=state.over, settled=mapped(state.settled))


# A racing search: challengers raced over seeds against an incumbent -----------------------------
#
# SMAC's intensification (Hutter, Hoos and Leyton-Brown, LION 2011; Lindauer et al., JMLR 2022)
# decided by this project's comparison: a challenger asked from the sampler trains its first
# ``min_seeds`` seeds side by side, then one seed at a time; after each seed (from ``min_seeds``
# on) its first k seeds are compared with the incumbent's seeds by
# [`compare`][kraby_study.decision.comparison.compare] at the margin, at the look's level (alpha
# spent equally over the ``seeds - min_seeds + 1`` looks a configuration can take, as a race
# spends it). It leaves once shown worse (by more than the margin); it replaces the incumbent
# once shown better (the incumbent shown worse than it), or shown equivalent (within the
# margin) and cheaper in CPU seconds per run; shown equivalent and not cheaper, it leaves. A
# challenger that reaches the incumbent's seed count undecided replaces it only if its IQM on
# their common seeds (the same seed indices) is higher, else it leaves (SMAC's rule on the
# common instances). The incumbent earns one more seed whenever no challenger wants one, up to
# ``seeds`` (the cap). The pick is the incumbent, on all its seeds.


class Left(StrEnum):
    """Where a configuration of a racing search stands, or how it left."""

    INCUMBENT = "incumbent"
    RACING = "racing"
    """Still racing against the incumbent (or the search ended before it was decided)."""
    WORSE = "worse"
    """Shown worse than the incumbent by more than the margin."""
    EQUIVALENT = "equivalent"
    """Shown within the margin of the incumbent, and not cheaper."""
    BELOW = "below"
    """Undecided at the incumbent's seed count, its IQM on the common seeds not higher."""
    REPLACED = "replaced"
    """The incumbent until a challenger replaced it."""
    REFUSED = "refused"
    """Its settings could not run (refused before training)."""


@dataclass(frozen=True)
class RunEnd(Generic[K]):
    """One ended run of a racing search, in the order the runs ended."""

    config: K
    index: int
    """Its seed index (0: the configuration's first seed)."""
    score: float
    """Its final score; NaN for a run that ended without one (failed)."""
    cpu: float = math.nan
    """Its CPU seconds."""
    diverged: bool = False
    """It failed because training diverged (not an error, which says nothing of its
    settings)."""


@dataclass(frozen=True)
class Standing(Generic[K]):
    """A configuration's standing: how it left (or that it has not), at how many seeds."""

    left: Left
    seeds: int = 0
    """Seeds it had ended when it left (0 while it has not)."""
    p: float = math.nan
    """The p of the answer that moved it (the look's Holm-adjusted p of worse, or the
    Bonferroni p of equivalent); NaN where the IQM rule or no test decided."""
    by: K | None = None
    """The configuration it lost to: the incumbent it was compared with, or the challenger
    that replaced it."""
    cheaper: bool = False
    """It replaced the incumbent as equivalent and cheaper."""
    diverged: int = 0
    """Runs of its first ``seeds`` that diverged, when their count decided (0 otherwise)."""


@dataclass
class Intensification(Generic[K]):
    """A racing search's state: the incumbent, every configuration's standing and runs."""

    rules: RaceRules
    order: list[K]
    """The configurations in the order they were asked for."""
    incumbent: K | None
    standings: dict[K, Standing[K]]
    scores: dict[K, dict[int, float]]
    """Per configuration, its ended runs' final scores by seed index (NaN: failed)."""
    cpu: dict[K, list[float]]
    """Per configuration, its ended runs' CPU seconds."""
    diverged: dict[K, set[int]] = field(default_factory=dict)
    """Per configuration, the seed indices whose runs diverged."""
    looks: dict[K, int] = field(default_factory=dict)
    """Per configuration, the leading seeds its latest look read."""

    def ended(self, config: K) -> int:
        """Its leading ended seeds: 0, 1, ... k - 1 all ended (a look reads only these)."""
        runs = self.scores.get(config, {})
        k = 0
        while k in runs:
            k += 1
        return k

    @property
    def racing(self) -> list[K]:
        """Challengers still racing, in the order they were asked for."""
        return [c for c in self.order if self.standings[c].left == Left.RACING]

    def challenge_open(self) -> bool:
        """Whether a new challenger may start: the incumbent has ended its first
        ``min_seeds`` seeds (there is something to compare with)."""
        return self.incumbent is not None and self.ended(self.incumbent) >= self.rules.min_seeds

    def next_run(self, started: Mapping[K, Collection[int]]) -> tuple[K, int] | None:
        """The run (configuration, seed index) the race wants now, given the seed indices each
        configuration has started (ended, running or queued); None when it wants none of a
        known configuration (a new challenger may be asked, if
        [`challenge_open`][kraby_study.decision.race.Intensification.challenge_open]).

        In order: the incumbent's first ``min_seeds`` seeds side by side; a racing challenger's
        first ``min_seeds`` side by side, then its next seed once none of its runs is in flight
        and it has fewer than the incumbent; else, with no challenger wanting one, the
        incumbent's next seed (one at a time, up to the cap)."""
        inc = self.incumbent
        if inc is None:
            return None
        first = self.rules.min_seeds

        def following(config: K) -> int:
            have = set(started.get(config, ()))
            return next(i for i in range(len(have) + 1) if i not in have)

        inc_started = len(started.get(inc, ()))
        if inc_started < first:
            return inc, following(inc)
        inc_ended = self.ended(inc)
        if inc_ended < first:
            return None
        for config in self.racing:
            count = len(started.get(config, ()))
            if count < first or (count == self.ended(config) and count < inc_ended):
                return config, following(config)
        if inc_started == inc_ended and inc_ended < self.rules.seeds:
            return inc, following(inc)
        return None


def challenge(incumbent: Sequence[float], challenger: Sequence[float], rules: RaceRules
              ) -> tuple[Answer, Answer, float]:
    """One look: the challenger's first seeds against the incumbent's, at the look's level.

    Returns:
        The challenger's answer and the incumbent's ([`Answer`][Answer]; the higher IQM is
        best, undecided where no answer holds), and the p of the answer that decides (NaN when
        undecided). With ``rules.paired`` both are read on their common seed indices.
    """
    look = take_look(_look_scores(incumbent, challenger, rules), rules)
    ch = look.answers.get(1, Answer.UNDECIDED)
    inc = look.answers.get(0, Answer.UNDECIDED)
    loser = 1 if ch in (Answer.WORSE, Answer.EQUIVALENT) else 0
    answer = look.answers.get(loser)
    p = (look.p_worse.get(loser, math.nan) if answer == Answer.WORSE
         else look.p_equivalent.get(loser, math.nan) if answer == Answer.EQUIVALENT
         else math.nan)
    return ch, inc, p


def _look_scores(incumbent: Sequence[float], challenger: Sequence[float], rules: RaceRules
                 ) -> dict[int, list[float]]:
    """A look's samples, the incumbent's as 0 and the challenger's as 1: with
    ``rules.paired`` their common seed indices only."""
    if rules.paired:
        n = min(len(incumbent), len(challenger))
        return {0: list(incumbent[:n]), 1: list(challenger[:n])}
    return {0: list(incumbent), 1: list(challenger)}


def within_margin(incumbent: Sequence[float], challenger: Sequence[float], rules: RaceRules
                  ) -> float:
    """The p of "the challenger's IQM is within the margin of the incumbent's" (one-sided:
    above the incumbent's IQM less ``rules.margin`` x its |IQM|), by the comparison's own
    tests ([`iqm_pairs`][kraby_study.decision.robust.iqm_pairs]: the larger p of the
    percentile bootstrap and Yuen's test; with ``rules.paired`` on the common seeds). 1 where
    either side has too few seeds to test, or at margin 0.

    [`challenge`][kraby_study.decision.race.challenge] tests only the lower IQM against the
    higher: when the challenger's IQM is the higher, "the incumbent is within the margin of
    the challenger" says nothing of how far below the incumbent the challenger may be (a
    challenger whose one failure in four seeds its IQM trims, say). A cheaper challenger
    replaces the incumbent as equivalent only with this test too."""
    if rules.margin <= 0:
        return 1.0
    scores = _look_scores(incumbent, challenger, rules)
    samples = [np.asarray(scores[i], dtype=float) for i in (0, 1)]
    if not rules.paired:
        samples = [x[~np.isnan(x)] for x in samples]
    locations = np.array([_iqm(x) for x in samples])
    if not np.all(np.isfinite(locations)):
        return 1.0
    tests = iqm_pairs(samples, margin_weights(locations, rules.margin), rules.look_alpha,
                      paired=rules.paired)
    p = float(tests.less[0, 1])
    return p if math.isfinite(p) else 1.0


def _iqm(scores: Sequence[float]) -> float:
    """The IQM of the complete scores; -inf with none (it never beats anything)."""
    clean = np.asarray([s for s in scores if not math.isnan(s)], dtype=float)
    return float(iqm(clean)) if len(clean) else -math.inf


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return math.fsum(finite) / len(finite) if finite else math.nan


def intensify(order: Sequence[K], ends: Sequence[RunEnd[K]], rules: RaceRules,
              refused: Collection[K] = ()) -> Intensification[K]:
    """Replay a racing search on its ended runs, in the order they ended.

    Args:
        order: Every configuration, in the order it was asked for; the first is the incumbent
            from its start.
        ends: The ended runs in the order they ended (a run of an unknown configuration is
            ignored; a run of a configuration that has left is kept but decides nothing).
        rules: ``seeds`` is the cap on the incumbent's seeds, ``min_seeds`` the first look,
            ``alpha`` spent over the looks, ``margin`` and ``paired`` the comparison's.
        refused: Configurations whose settings could not run: they leave at once.

    Returns:
        The [`Intensification`][kraby_study.decision.race.Intensification] after every run.
    """
    state: Intensification[K] = Intensification(
        rules=rules, order=list(order), incumbent=order[0] if order else None,
        standings={c: Standing(Left.RACING) for c in order},
        scores={c: {} for c in order}, cpu={c: [] for c in order})
    if state.incumbent is not None:
        state.standings[state.incumbent] = Standing(Left.INCUMBENT)
    for config in refused:
        if config in state.standings and config != state.incumbent:
            state.standings[config] = Standing(Left.REFUSED)
    for end in ends:
        if end.config not in state.scores:
            continue
        state.scores[end.config][end.index] = end.score
        state.cpu[end.config].append(end.cpu)
        if end.diverged:
            state.diverged.setdefault(end.config, set()).add(end.index)
        else:
            state.diverged.get(end.config, set()).discard(end.index)
        if state.standings[end.config].left == Left.RACING:
            _look(state, end.config)
    return state


def _look(state: Intensification[K], config: K) -> None:
    """Compare a racing challenger with the incumbent when its leading seeds have grown past
    ``min_seeds``, and move it (or the incumbent) as the answers say."""
    inc = state.incumbent
    assert inc is not None
    k = state.ended(config)
    if k < state.rules.min_seeds or k <= state.looks.get(config, 0):
        return
    state.looks[config] = k
    m = state.ended(inc)
    if _diverging(state, config, k, inc, m):
        return
    ch_scores = [state.scores[config][i] for i in range(k)]
    inc_scores = [state.scores[inc][i] for i in range(m)]
    ch, inc_answer, p = challenge(inc_scores, ch_scores, state.rules)
    cheaper = _mean(state.cpu[config]) < _mean(state.cpu[inc])
    if cheaper and inc_answer == Answer.EQUIVALENT:
        # The challenger has the higher IQM and the incumbent is within the margin of it; to
        # replace the incumbent the challenger must be within the margin of the incumbent.
        p = within_margin(inc_scores, ch_scores, state.rules)
        ch = Answer.EQUIVALENT if p < state.rules.look_alpha else Answer.UNDECIDED
    if ch == Answer.WORSE:
        state.standings[config] = Standing(Left.WORSE, seeds=k, p=p, by=inc)
    elif inc_answer == Answer.WORSE:
        _replace(state, config, p)
    elif cheaper and ch == Answer.EQUIVALENT:
        _replace(state, config, p, cheaper=True)
    elif Answer.EQUIVALENT in (ch, inc_answer) and not cheaper:
        state.standings[config] = Standing(Left.EQUIVALENT, seeds=k, p=p, by=inc)
    elif k >= m or state.rules.below == "look":
        n = min(k, m)
        if _iqm(ch_scores[:n]) <= _iqm(inc_scores[:n]):
            state.standings[config] = Standing(Left.BELOW, seeds=k, by=inc)
        elif k >= m:
            _replace(state, config, math.nan)


def _diverging(state: Intensification[K], config: K, k: int, inc: K, m: int) -> bool:
    """Whether the diverged runs decide this look: the configuration whose runs diverge more
    often (one-sided Fisher exact test on the diverged counts of the challenger's first ``k``
    and the incumbent's first ``m`` runs, at the look's level) loses, the challenger as worse,
    the incumbent replaced. A diverged run has no score, so the IQMs cannot see it."""
    from scipy import stats  # only here: reading where studies stand loads no scipy.stats
    ch = len({i for i in state.diverged.get(config, set()) if i < k})
    held = len({i for i in state.diverged.get(inc, set()) if i < m})
    if not ch and not held:
        return False
    table = [[ch, k - ch], [held, m - held]]
    p_ch = float(stats.fisher_exact(table, alternative="greater").pvalue)
    if p_ch < state.rules.look_alpha:
        state.standings[config] = Standing(Left.WORSE, seeds=k, p=p_ch, by=inc, diverged=ch)
        return True
    p_inc = float(stats.fisher_exact(table, alternative="less").pvalue)
    if p_inc < state.rules.look_alpha:
        _replace(state, config, p_inc)
        return True
    return False


def _replace(state: Intensification[K], config: K, p: float, cheaper: bool = False) -> None:
    """The challenger becomes the incumbent; every challenger still racing with at least the
    new incumbent's seeds takes a look against it at once (it would get no more seeds)."""
    old = state.incumbent
    assert old is not None
    state.standings[old] = Standing(Left.REPLACED, seeds=state.ended(old), p=p, by=config)
    state.standings[config] = Standing(Left.INCUMBENT, cheaper=cheaper)
    state.incumbent = config
    for other in state.racing:
        if state.ended(other) >= state.ended(config):
            state.looks.pop(other, None)
            _look(state, other)
