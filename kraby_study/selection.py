"""Which value of a finished sweep is selected: the rules a campaign carries forward.

One implementation serves the report's ``selected`` column, ``${winner:...}`` and ``best``. The
rules read the same per-seed numbers the report shows, and the ties are the report's ties
(:func:`kraby_study.comparison.compare_with_best`, closed Holm-Welch step-down, alpha 0.05):

- ``final_score``: the highest mean final score (the report's "best").
- ``auc``: the highest mean AUC over the seeds with a curve (the most sample-efficient).
- ``fastest_tied``: among the best value and the values tied with it (not worse than the best
  under the closed Holm-Welch step-down, alpha 0.05), the lowest mean training time in
  seconds: the documented "good compromise" when a slower value is not measurably better.

Every rule considers only values with at least ``min_seeds`` complete seeds (default 2, the
report's ``report.min_seeds`` default), so one lucky seed is never selected. Ties inside a rule
go to the first group in order; NaN never wins.

In a raced study (:mod:`kraby_study.race`) every rule considers only the race's survivors: the
caller passes the dropped values (``dropped``), which are never best, tied or selected, and the
survivors are compared by the same procedure on all their seeds.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from kraby_study.comparison import (
    ALPHA,
    MIN_SEEDS,
    best_with_evidence,
    compare_with_best,
    evidence,
    procedure_name,
)
from kraby_study.records import (
    Outcome,
    SelectRule,
    StoredTrial,
    StudyKind,
    TrialAttrs,
    best_group,
    ordered_values,
    outcome,
    param_name,
    swept_value,
    value_key,
)
from kraby_study.stats import auc

if TYPE_CHECKING:
    import pandas as pd

RULE_TEXT = {
    SelectRule.FINAL_SCORE: "highest mean final score",
    SelectRule.AUC: "highest mean AUC (sample efficiency)",
    SelectRule.FASTEST_TIED: ("lowest mean training time (wall-clock seconds; CPU seconds on "
                              "a confirm study) among the values tied with the best final "
                              f"score (not worse under the {procedure_name(ALPHA)})"),
}

K = TypeVar("K", bound=Hashable)


def _means(groups: Mapping[K, Sequence[float]]) -> dict[K, float]:
    out = {}
    for group, values in groups.items():
        kept = [float(v) for v in values if not math.isnan(float(v))]
        if kept:
            out[group] = math.fsum(kept) / len(kept)
    return out


def select(rule: str, final: Mapping[K, Sequence[float]], aucs: Mapping[K, Sequence[float]],
           seconds: Mapping[K, Sequence[float]], min_seeds: int = MIN_SEEDS,
           dropped: Collection[K] = ()) -> K | None:
    """The selected group under ``rule``; None when no group can be selected.

    Args:
        rule: final_score, auc or fastest_tied.
        final: Final scores of the complete seeds, by group, in the study's order.
        aucs: AUC of each complete seed with a curve, by group.
        seconds: Training time of each complete seed, by group.
        min_seeds: Fewest complete seeds a group needs to be selected (at least 2).
        dropped: Groups a race dropped: left out of every rule, as if never run.
    """
    SelectRule.check(rule)
    if dropped:
        final = {g: vs for g, vs in final.items() if g not in dropped}
        aucs = {g: vs for g, vs in aucs.items() if g not in dropped}
        seconds = {g: vs for g, vs in seconds.items() if g not in dropped}
    scores = {g: [float(v) for v in vs if not math.isnan(float(v))] for g, vs in final.items()}
    if rule == SelectRule.FINAL_SCORE:
        return best_with_evidence(scores, min_seeds)
    if rule == SelectRule.AUC:
        need, _, _ = evidence(scores, min_seeds)
        return best_group({g: [m] for g, m in _means(aucs).items()
                           if len(scores.get(g, [])) >= need})
    comparison = compare_with_best(scores, min_seeds=min_seeds)
    best = comparison.best
    if best is None:
        return None
    tied = [best, *comparison.tied]
    times = _means(seconds)
    timed = {g: [-times[g]] for g in tied if g in times}
    return best_group(timed) if timed else best


@dataclass(frozen=True)
class Samples:
    """Per-seed numbers of a sweep's complete runs, grouped by value (in the study's order)."""

    values: list[Any]
    final: dict[int, list[float]]
    aucs: dict[int, list[float]]
    seconds: dict[int, list[float]]


def time_measure(kind: str | None) -> str:
    """The training time fastest_tied compares, as a trial attribute: CPU seconds on a confirm
    study (a two-objective search's cost is CPU seconds per seed, and other work on the
    machine moves it little), wall-clock seconds on a sweep (as the documented studies
    compared them)."""
    return "cpu_time" if kind == StudyKind.CONFIRM else "wall_time"


def samples(trials: Sequence[StoredTrial], curves: pd.DataFrame | None, name: str,
            values: Sequence[Any], time_attr: str = "wall_time") -> Samples:
    """The samples of a sweep's counted trials; ``curves`` holds their curve points (columns
    number, step, mean_reward), None when no AUC is needed. A trial whose value is not in
    ``values`` is left out. ``time_attr``: the trial attribute read as its training time
    (:func:`time_measure`)."""
    index = {value_key(v): i for i, v in enumerate(values)}
    final: dict[int, list[float]] = {}
    aucs: dict[int, list[float]] = {}
    seconds: dict[int, list[float]] = {}
    rewards = {}
    if curves is not None:
        ordered = curves.sort_values(["number", "step"], kind="stable")
        rewards = {int(n): g["mean_reward"].to_numpy(dtype=float)
                   for n, g in ordered.groupby("number", sort=False)}
    for trial in trials:
        if outcome(trial) != Outcome.COMPLETE or trial.value is None:
            continue
        vi = index.get(value_key(swept_value(trial, name, values)))
        if vi is None:
            continue
        final.setdefault(vi, []).append(float(trial.value))
        if trial.number in rewards:
            aucs.setdefault(vi, []).append(auc(rewards[trial.number]))
        spent = getattr(TrialAttrs.of(trial), time_attr)
        if spent is not None:
            seconds.setdefault(vi, []).append(float(spent))
    order = sorted(final)
    return Samples(values=list(values), final={vi: final[vi] for vi in order},
                   aucs={vi: aucs.get(vi, []) for vi in order},
                   seconds={vi: seconds.get(vi, []) for vi in order})


def swept_values(kind: str, definition: Mapping[str, Any],
                 trials: Sequence[StoredTrial]) -> tuple[str, list[Any]]:
    """A swept study's parameter name and its values in the order reports list them: the
    planned values and any other found, numbers ascending (a confirm study keeps its order)."""
    name = param_name(str(definition["parameter"]))
    planned = list(definition.get("values", []))
    found = [swept_value(t, name, planned) for t in trials]
    return name, ordered_values(planned, found, sort=kind != "confirm")


def selected_index(trials: Sequence[StoredTrial], curves: pd.DataFrame | None, name: str,
                   values: Sequence[Any], rule: str, min_seeds: int = MIN_SEEDS,
                   dropped: Collection[int] = (), time_attr: str = "wall_time") -> int | None:
    """Index in ``values`` of the value ``rule`` selects among the complete runs; None when
    no value has ``min_seeds`` complete seeds. ``dropped``: indices in ``values`` of the values
    a race dropped (:func:`kraby_study.answers.raced.dropped_indices`), never selected."""
    found = samples(trials, curves, name, values, time_attr)
    return select(rule, found.final, found.aucs, found.seconds, min_seeds, dropped)
