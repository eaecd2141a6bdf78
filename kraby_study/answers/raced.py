"""Where a raced study stands, replayed from its stored runs (:mod:`kraby_study.race`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from optuna.trial import FrozenTrial

from kraby_study.plan.spec import RaceRules
from kraby_study.race import Race, race
from kraby_study.records import Outcome, latest_by_key, outcome, parse_sweep_key


def place(key: str, seeds: list[int]) -> tuple[int, int] | None:
    """(value index, seed index) of a run's key; None for a key of no round."""
    parsed = parse_sweep_key(key)
    if parsed is None or parsed[1] not in seeds:
        return None
    return parsed[0], seeds.index(parsed[1])


def ended_runs(latest: Mapping[str, FrozenTrial], seeds: list[int]
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


def study_race(definition: Mapping[str, Any], trials: list[FrozenTrial]) -> Race[int] | None:
    """The race of a stored study replayed on its runs (values by index); None for a study
    that did not race."""
    rules = RaceRules.of(dict(definition))
    if rules is None:
        return None
    runs = ended_runs(latest_by_key(trials), list(rules.round_seeds))
    return race(list(range(len(definition["values"]))), runs, rules)


def race_record(values: list[Any], state: Race[int], runs: dict[int, dict[int, float]]
                ) -> dict[str, Any]:
    """The race as stored on the study (``StudyAttrs.race``)."""
    return {
        "rounds": state.rounds, "over": state.over,
        "runs": sum(len(r) for r in runs.values()),
        "fixed_runs": len(values) * state.rules.seeds,
        "values": [{"value": values[v], "seeds": len(runs.get(v, {})),
                    "dropped_at": state.dropped[v].round if v in state.dropped else None,
                    "p": state.dropped[v].p if v in state.dropped else None}
                   for v in range(len(values))],
    }
