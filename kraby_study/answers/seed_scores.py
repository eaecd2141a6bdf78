"""The seed scores of a stored sweep, read once from its trials: each value's final scores, AUCs
and training times ([`Samples`][kraby_study.answers.seed_scores.Samples]), the numbers every
decision reads, and the study's one comparison of them
([`sweep_comparison`][kraby_study.answers.seed_scores.sweep_comparison]): the only place a sweep,
confirm or single-run study is compared, whoever reads its answers (the report, ``best``, ``list``,
``${winner:...}``, campaigns)."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from kraby_study.decision.comparison import CompareOptions, Comparison, compare
from kraby_study.decision.measures import curve_rewards, seed_samples
from kraby_study.records.attributes import StudyKind, TrialAttrs
from kraby_study.records.stored import Outcome, StoredTrial, outcome
from kraby_study.records.values import (
    ordered_values,
    param_name,
    swept_value,
    value_key,
)

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class Samples:
    """Per-seed numbers of a sweep's complete runs, grouped by value (in the study's order)."""

    values: list[Any]
    final: dict[int, list[float]]
    aucs: dict[int, list[float]]
    seconds: dict[int, list[float]]


def time_measure(kind: str | None) -> str:
    """The training time fastest_equivalent compares, as a trial attribute: CPU seconds on a confirm
    study (a two-objective search's cost is CPU seconds per seed, and other work on the
    machine moves it little), wall-clock seconds on a sweep (as the documented studies
    compared them)."""
    return "cpu_time" if kind == StudyKind.CONFIRM else "wall_time"


def samples(trials: Sequence[StoredTrial], curves: pd.DataFrame | None, name: str,
            values: Sequence[Any], time_attr: str = "wall_time") -> Samples:
    """The samples of a sweep's counted trials; ``curves`` holds their curve points (columns
    number, step, mean_reward), None when no AUC is needed. A trial whose value is not in
    ``values`` is left out. ``time_attr``: the trial attribute read as its training time
    ([`time_measure`][kraby_study.answers.seed_scores.time_measure])."""
    index = {value_key(v): i for i, v in enumerate(values)}
    runs = []
    for trial in trials:
        if outcome(trial) != Outcome.COMPLETE or trial.value is None:
            continue
        value_index = index.get(value_key(swept_value(trial, name, values)))
        if value_index is None:
            continue
        spent = getattr(TrialAttrs.of(trial), time_attr)
        runs.append((value_index, trial.number, float(trial.value),
                     math.nan if spent is None else float(spent)))
    final, aucs, seconds = seed_samples(runs, curve_rewards(curves) if curves is not None else {})
    return Samples(values=list(values), final=final, aucs=aucs, seconds=seconds)


def swept_values(kind: str, definition: Mapping[str, Any],
                 trials: Sequence[StoredTrial]) -> tuple[str, list[Any]]:
    """A swept study's parameter name and its values in the order reports list them: the
    planned values and any other found, numbers ascending (a confirm study keeps its order)."""
    name = param_name(str(definition["parameter"]))
    planned = list(definition.get("values", []))
    found = [swept_value(t, name, planned) for t in trials]
    return name, ordered_values(planned, found, sort=kind != "confirm")


def sweep_comparison(final: Mapping[int, Sequence[float]], dropped: Collection[int],
                     options: CompareOptions, tests: bool = True) -> Comparison[int]:
    """A swept or single-run study's one comparison of its values' final scores (by index),
    the values a race dropped as worse (``dropped``) left out, under the command's margin,
    alpha and seeds; ``tests`` False: the best and the family only, for a rule that reads no
    test ([`tests`][kraby_study.decision.selection.Rule.tests])."""
    return compare({i: v for i, v in final.items() if i not in dropped}, options.margin,
                   alpha=options.alpha, min_seeds=options.min_seeds, tests=tests)
