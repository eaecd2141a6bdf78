"""Rechecks: a search's leading trials retrained on more seeds before the search ends.

A search ranks trials by the mean score of a few seeds, and the best of many noisy means
overstates its trial: a setting that fails on some seeds can lead by doing well on the few it
was given. ``search.recheck = K`` answers this as racing methods do: once the search stops
exploring, each of its K leading trials is retrained on ``search.recheck_seeds`` more seeds,
and ranks by the mean over all its seeds. A rechecked trial that falls out of the top K lets
the next one in, which is rechecked in turn, until the top K are all rechecked (or the CPU
budget is used; past it, the best trial is still rechecked, so the search never picks a trial
on its search seeds alone). A recheck is an attempt of its trial (the same key), so everything that
reads a study's counted trials reads the trial by all its seeds.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from optuna.trial import FrozenTrial, TrialState

from kraby_study.records.attributes import RUN_MEASURES, TrialAttrs, TrialResult
from kraby_study.records.stored import Outcome, counted, outcome
from kraby_study.records.values import ranking, score


@dataclass(frozen=True)
class Leader:
    """One of a search's leading configurations, as its counted attempt."""

    trial: FrozenTrial
    """The complete trial, or the recheck of it that is queued or running."""
    score: float
    """Its score (a rechecked trial's over all its seeds; one being rechecked, its score
    before)."""
    rechecked: bool
    """Whether it is rechecked, or its recheck is queued or running."""


def leaders(trials: Sequence[FrozenTrial], count: int) -> list[Leader]:
    """The ``count`` best configurations of a search, best first, in the order a search's
    pick reads them ([`ranking`][kraby_study.records.values.ranking]: equal scores by seeds, then
    cost, then number); a recheck that is queued or running stands where its trial
    does."""
    by_number = {t.number: t for t in trials}
    ranked: list[tuple[tuple[float, int, float, int], Leader]] = []
    for trial in counted(trials):
        of = TrialAttrs.of(trial).recheck_of
        value = score(trial)
        if outcome(trial) == Outcome.COMPLETE and value is not None:
            ranked.append((ranking(trial), Leader(trial, value, of is not None)))
        elif (trial.state in (TrialState.WAITING, TrialState.RUNNING) and of is not None
              and of in by_number and (before := score(by_number[of])) is not None):
            ranked.append((ranking(by_number[of]), Leader(trial, before, True)))
    ranked.sort(key=lambda pair: pair[0])
    return [leader for _, leader in ranked[:count]]


def next_recheck(trials: Sequence[FrozenTrial], count: int) -> FrozenTrial | None:
    """The best of the top ``count`` trials not rechecked yet; None when all are."""
    return next((lead.trial for lead in leaders(trials, count) if not lead.rechecked), None)


def reserve(trials: Sequence[FrozenTrial], count: int, seeds: int) -> float:
    """CPU seconds the rechecks of today's leaders would use: each one not rechecked yet, its
    CPU seconds per seed (its training time; its whole CPU time if it stores no seed's score)
    times ``seeds``."""
    total = 0.0
    for lead in leaders(trials, count):
        if not lead.rechecked:
            attrs = TrialAttrs.of(lead.trial)
            per_seed = attrs.training_time()
            total += (float(attrs.cpu_time or 0.0) if per_seed is None else per_seed) * seeds
    return total


OWN_RATE_FROM = 0.1
"""Fraction of its env steps after which a running trial's own CPU seconds per step project
the rest of it; before, its start (making the env and the network) would inflate them."""


def cpu_per_step(trials: Sequence[FrozenTrial]) -> float | None:
    """The median CPU seconds per env step of the ended attempts that trained any; None
    when none has."""
    rates = [float(a.cpu_time) / a.env_steps for a in map(TrialAttrs.of, trials)
             if a.cpu_time is not None and a.env_steps]
    return statistics.median(rates) if rates else None


def to_spend(done: int, total: int, cpu: float, rate: float | None) -> float:
    """CPU seconds a running trial would still use to train its ``total`` env steps, having
    trained ``done`` of them in ``cpu`` seconds: at its own pace once it has trained
    [`OWN_RATE_FROM`][kraby_study.run.recheck.OWN_RATE_FROM] of them, before that at ``rate`` (the
    search's ended trials' pace; its own when there is none). A pruner may stop it sooner, so this
    is what it could use, not what it will."""
    own = cpu / done if done > 0 else None
    pace = own if own is not None and (done >= OWN_RATE_FROM * total or rate is None) else rate
    return (pace or 0.0) * max(0, total - done)


def first_seed(original: FrozenTrial) -> int:
    """The first seed a recheck of ``original`` trains: the one after the trial's own."""
    attrs = TrialAttrs.of(original)
    return int(attrs.seed or 0) + len(attrs.scores or [])


def combined(original: FrozenTrial, result: TrialResult) -> TrialResult:
    """A complete recheck's result with the original trial's seeds first: every seed's score,
    the score their mean (the training reward too), every per-seed measure both lists. Its CPU
    seconds, env steps and times stay its own, so the search's spending counts each seed once.
    A recheck that did not complete is returned as it is."""
    before = TrialAttrs.of(original)
    if result.outcome != Outcome.COMPLETE or not result.scores or not before.scores:
        return result
    scores = [*before.scores, *result.scores]
    rewards = [(r, len(s)) for r, s in ((before.train_reward, before.scores),
                                         (result.train_reward, result.scores)) if r is not None]
    train_reward = (math.fsum(r * n for r, n in rewards) / sum(n for _, n in rewards)
                    if rewards else None)
    # Every per-seed measure (the evaluation errors and sds) lists the original's seeds first.
    per_seed = {}
    for measure in RUN_MEASURES:
        if measure.per_seed:
            old, new = getattr(before, measure.attribute), getattr(result, measure.attribute)
            per_seed[measure.attribute] = [*old, *new] if old and new else new
    return dataclasses.replace(result, scores=scores, final_score=math.fsum(scores) / len(scores),
                               train_reward=train_reward, **per_seed)
