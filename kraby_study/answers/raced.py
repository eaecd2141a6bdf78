"""Where a raced study stands, replayed from its stored runs ([`kraby_study.decision.race`][])."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from kraby_study.decision.race import Race, RaceRuns, StudyRace, race
from kraby_study.plan.spec import RaceRules
from kraby_study.records.stored import (
    StoredTrial,
    diverged_runs,
    ended_runs,
    latest_by_key,
)
from kraby_study.records.values import value_key


def replay(rules: RaceRules, values: int, latest: Mapping[str, StoredTrial]
           ) -> tuple[Race[int], dict[int, dict[int, float]]]:
    """The race of ``values`` values (by index) replayed on the latest attempt of each run, and
    the ended runs it read ([`ended_runs`][kraby_study.records.stored.ended_runs])."""
    seeds = list(rules.round_seeds)
    runs = ended_runs(latest, seeds)
    return race(list(range(values)), runs, rules, diverged_runs(latest, seeds)), runs


def race_runs(definition: Mapping[str, Any], trials: Sequence[StoredTrial],
              values: Sequence[Any]) -> RaceRuns | None:
    """A stored study's race as its ended runs, each planned value placed in ``values``
    (matched by [`value_key`][kraby_study.records.values.value_key], not by position; a value not in
    ``values`` is left out); None for a study that did not race."""
    rules = RaceRules.of(dict(definition))
    if rules is None:
        return None
    planned = list(definition["values"])
    index = {value_key(v): i for i, v in enumerate(values)}
    latest, seeds = latest_by_key(trials), list(rules.round_seeds)
    return RaceRuns(rules=rules, planned=len(planned), runs=ended_runs(latest, seeds),
                    index=[index.get(value_key(v)) for v in planned],
                    diverged=diverged_runs(latest, seeds))


def race_of(definition: Mapping[str, Any], trials: Sequence[StoredTrial],
            values: Sequence[Any]) -> StudyRace | None:
    """The race of a stored study with its dropped values mapped onto ``values``
    ([`race_runs`][kraby_study.answers.raced.race_runs], replayed); None for a study that did not
    race."""
    runs = race_runs(definition, trials, values)
    return runs.replayed() if runs is not None else None


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
                    **({"diverged": state.dropped[v].diverged}
                       if v in state.dropped and state.dropped[v].diverged else {}),
                    **({"settled_at": state.settled[v].round, "p_equivalent": state.settled[v].p}
                       if v in state.settled else {})}
                   for v in range(len(values))],
    }
