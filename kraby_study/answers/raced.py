"""Where a raced study stands, replayed from its stored runs (:mod:`kraby_study.decision.race`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from kraby_study.decision.race import Drop, Race, race
from kraby_study.plan.spec import RaceRules
from kraby_study.records.stored import Outcome, StoredTrial, latest_by_key, outcome, parse_sweep_key
from kraby_study.records.values import value_key


def place(key: str, seeds: list[int]) -> tuple[int, int] | None:
    """(value index, seed index) of a run's key; None for a key of no round."""
    parsed = parse_sweep_key(key)
    if parsed is None or parsed[1] not in seeds:
        return None
    return parsed[0], seeds.index(parsed[1])


def ended_runs(latest: Mapping[str, StoredTrial], seeds: list[int]
               ) -> dict[int, dict[int, float]]:
    """Per value, its ended runs by seed index: the final score of a complete run, NaN for one
    that ended without a score (failed)."""
    runs: dict[int, dict[int, float]] = {}
    for key, trial in latest.items():
        where = place(key, seeds)
        if where is None:
            continue
        ended = outcome(trial)
        if ended == Outcome.COMPLETE and trial.value is not None:
            runs.setdefault(where[0], {})[where[1]] = float(trial.value)
        elif ended == Outcome.FAILED:
            runs.setdefault(where[0], {})[where[1]] = math.nan
    return runs


def replay(rules: RaceRules, values: int, latest: Mapping[str, StoredTrial]
           ) -> tuple[Race[int], dict[int, dict[int, float]]]:
    """The race of ``values`` values (by index) replayed on the latest attempt of each run, and
    the ended runs it read (:func:`ended_runs`)."""
    runs = ended_runs(latest, list(rules.round_seeds))
    return race(list(range(values)), runs, rules), runs


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


def race_of(definition: Mapping[str, Any], trials: Sequence[StoredTrial],
            values: Sequence[Any]) -> StudyRace | None:
    """The race of a stored study with its dropped values mapped onto ``values`` (matched by
    :func:`kraby_study.records.value_key`, not by position); None for a study that did not
    race. A dropped value not in ``values`` is left out."""
    rules = RaceRules.of(dict(definition))
    if rules is None:
        return None
    planned = list(definition["values"])
    state, runs = replay(rules, len(planned), latest_by_key(trials))
    index = {value_key(v): i for i, v in enumerate(values)}
    def mapped(left: Mapping[int, Drop]) -> dict[int, Drop]:
        return {index[value_key(planned[v])]: drop for v, drop in left.items()
                if value_key(planned[v]) in index}

    return StudyRace(rules=rules, dropped=mapped(state.dropped),
                     runs=sum(len(r) for r in runs.values()),
                     fixed_runs=len(planned) * rules.seeds, rounds=state.rounds,
                     over=state.over, settled=mapped(state.settled))


def dropped_indices(definition: Mapping[str, Any], trials: Sequence[StoredTrial],
                    values: Sequence[Any]) -> list[int]:
    """Indices in ``values`` of the values a stored study's race dropped as worse (none for a
    study that did not race): the values no selection rule, best or answer may name."""
    found = race_of(definition, trials, values)
    return sorted(found.dropped) if found is not None else []


def race_record(values: list[Any], state: Race[int], runs: dict[int, dict[int, float]]
                ) -> dict[str, Any]:
    """The race as stored on the study (``StudyAttrs.race``)."""
    return {
        "rounds": state.rounds, "over": state.over,
        "runs": sum(len(r) for r in runs.values()),
        "fixed_runs": len(values) * state.rules.seeds,
        "values": [{"value": values[v], "seeds": len(runs.get(v, {})),
                    "dropped_at": state.dropped[v].round if v in state.dropped else None,
                    "p": state.dropped[v].p if v in state.dropped else None,
                    **({"settled_at": state.settled[v].round, "p_equivalent": state.settled[v].p}
                       if v in state.settled else {})}
                   for v in range(len(values))],
    }
