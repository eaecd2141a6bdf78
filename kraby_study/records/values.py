"""A trial's swept value, score and cost, read the same way by every command."""

from __future__ import annotations

import json
import math
from collections.abc import Hashable, Iterable, Mapping, Sequence
from typing import Any, TypeVar

from kraby_study.records.attributes import TrialAttrs
from kraby_study.records.stored import Outcome, StoredTrial, T, outcome, parse_sweep_key

ANSWER_FROM = 4
"""Fewest complete seeds a value (and the best) needs for any answer at a margin, worse or
equivalent: at 3 seeds the interquartile mean is the mean, and no test measured holds its error
rate there on skewed scores of unequal spreads (``kraby_study.decision.robust``; a false
"equivalent" of 0.10 at 2 values x 3 seeds). A race's first look comes no sooner."""

# Values and the best one --------------------------------------------------------------------------


def value_key(value: Any) -> Hashable:
    """The equality rule for swept values: numbers by value (1 == 1.0), also inside lists and
    dicts ([64, 64] == [64.0, 64.0]); the rest by JSON."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return ("number", float(value))
    return ("other", json.dumps(_numbers_as_floats(value), sort_keys=True, default=str))


def _numbers_as_floats(value: Any) -> Any:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, list | tuple):
        return [_numbers_as_floats(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _numbers_as_floats(v) for k, v in value.items()}
    return value


def value_label(value: Any) -> str:
    """How a swept value is written in tables, legends and messages."""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def param_name(parameter: str) -> str:
    """The Optuna parameter name of a swept setting: its last part (ppo.gamma -> gamma)."""
    return parameter.split(".")[-1]


def is_numeric(values: Sequence[Any]) -> bool:
    """True when every value is a real number (bools are not)."""
    return bool(values) and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def ordered_values(planned: list[Any], found: list[Any], sort: bool = True) -> list[Any]:
    """Planned values plus any other value found, sorted when all are numbers (and ``sort``)."""
    values = list(planned)
    known = {value_key(v) for v in values}
    for value in found:
        if value is not None and value_key(value) not in known:
            known.add(value_key(value))
            values.append(value)
    if sort and is_numeric(values):
        values.sort(key=float)
    return values


K = TypeVar("K", bound=Hashable)


def best_group(scores: Mapping[K, Sequence[float]]) -> K | None:
    """The group with the highest mean score (the first such in order); None if none has one."""
    best: K | None = None
    best_mean = -math.inf
    for group, values in scores.items():
        if len(values) and (mean := math.fsum(values) / len(values)) > best_mean:
            best, best_mean = group, mean
    return best


def swept_value(trial: StoredTrial, name: str, planned: Sequence[Any]) -> Any:
    """A sweep trial's value: its parameter, its queued parameter, or its key's value index."""
    if name in trial.params:
        return trial.params[name]
    fixed = trial.system_attrs.get("fixed_params") or {}
    if name in fixed:
        return fixed[name]
    parsed = parse_sweep_key(trial.user_attrs.get("key"))
    if parsed is not None and parsed[0] < len(planned):
        return planned[parsed[0]]
    return None


def score(trial: StoredTrial) -> float | None:
    """A trial's score: its value, or its first objective's (a two-objective search's reward);
    None without one. (Optuna's ``FrozenTrial.value`` raises on a trial of two objectives.)"""
    values = trial.values
    return float(values[0]) if values else None


def cost(trial: StoredTrial) -> float | None:
    """A two-objective search trial's cost (its second objective); None for one objective."""
    values = trial.values
    return float(values[1]) if values and len(values) > 1 else None


def ranking(trial: StoredTrial, maximize: bool = True) -> tuple[float, int, float, int]:
    """Where a complete search trial ranks, as a sort key (the smallest ranks first): by its
    score, the best first; among equal scores the one scored on more seeds (a recheck's
    trial, ``search.recheck``), then the cheaper, by training time (CPU seconds per seed; one
    without it after those with it); then the earlier.

    Where the reward has a ceiling many trials tie at it on their search seeds, and those seeds
    do not tell them apart; a tie that held on more seeds is surer, and of ties alike the tool
    takes the one that costs less to train.
    """
    value = float(score(trial))  # type: ignore[arg-type]
    attrs = TrialAttrs.of(trial)
    time = attrs.training_time()
    return (-value if maximize else value, -len(attrs.scores or []),
            math.inf if time is None else time, trial.number)


def best_trial(trials: Iterable[T], maximize: bool = True, objectives: int = 1) -> T | None:
    """The complete trial with the best score (a search's best); of equal scores the one on
    more seeds, then the cheaper ([`ranking`][ranking]); None when none is complete.

    kraby-study maximises; ``maximize=False`` serves foreign studies that minimise. Trials
    count when they have ``objectives`` values, by the first: 2 for a two-objective search's
    best score; a foreign study of several objectives has no single best.
    """
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and t.values
            and len(t.values) == objectives]
    return min(done, key=lambda t: ranking(t, maximize), default=None)
