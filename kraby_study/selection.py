"""Which value of a finished sweep is selected: the rules a campaign carries forward.

"Best" is the highest mean final score only; "selected" is what a rule picks. Every rule is a
named :class:`Rule` that reads one :class:`kraby_study.comparison.Comparison` (the report's
answers, the same object its table column shows) and the values' mean AUC and training time:

- ``final_score``: the best value.
- ``auc``: the highest mean AUC over the seeds with a curve (the most sample-efficient).
- ``fastest_equivalent``: among the best and the values shown equivalent to it (within the
  margin, :func:`kraby_study.comparison.compare`), the lowest mean training time: a slower
  value is not worth its time when a faster one is shown as good within the margin, and a
  value needs evidence to be selected, so spread cannot buy a place.
- ``fastest_tied``: among the best and the values not shown worse at margin 0 (the closed
  Holm-Welch step-down, alpha 0.05), the lowest mean training time. The rule of earlier
  releases, kept so stored studies select as before: a noisy, cheap, truly worse value enters
  by its spread.

Every rule considers only the comparison's family: values with at least ``min_seeds``
complete seeds (``report.min_seeds``, default 2), so one lucky seed is never selected. Ties
inside a rule go to the first value in order; NaN never wins.

In a raced study (:mod:`kraby_study.race`) every rule considers only the values the race did
not drop as worse: the caller passes them (``dropped``), and the others are compared by the
same procedure on all their seeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from kraby_study.comparison import (
    ALPHA,
    MARGIN,
    MIN_SEEDS,
    Comparison,
    compare,
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

K = TypeVar("K", bound=Hashable)


def _lowest(candidates: Sequence[K], values: Mapping[K, float], fallback: K) -> K:
    """The candidate with the lowest value (first in order on ties, NaN never wins)."""
    known = {g: [-values[g]] for g in candidates if g in values and not math.isnan(values[g])}
    chosen = best_group(known)
    return chosen if chosen is not None else fallback


def _final_score(comparison: Comparison[K], aucs: Mapping[K, float],
                 times: Mapping[K, float]) -> K | None:
    return comparison.best


def _auc(comparison: Comparison[K], aucs: Mapping[K, float],
         times: Mapping[K, float]) -> K | None:
    return best_group({g: [aucs[g]] for g in comparison.family
                       if g in aucs and not math.isnan(aucs[g])})


def _fastest_equivalent(comparison: Comparison[K], aucs: Mapping[K, float],
                        times: Mapping[K, float]) -> K | None:
    if comparison.best is None:
        return None
    return _lowest([comparison.best, *comparison.equivalent], times, comparison.best)


def _fastest_tied(comparison: Comparison[K], aucs: Mapping[K, float],
                  times: Mapping[K, float]) -> K | None:
    if comparison.best is None:
        return None
    return _lowest([comparison.best, *comparison.tied], times, comparison.best)


@dataclass(frozen=True)
class Rule:
    """A selection rule: its name, what it selects in words, and the function that selects."""

    name: SelectRule
    description: str
    pick: Callable[[Comparison[Any], Mapping[Any, float], Mapping[Any, float]], Any]
    """(comparison, mean AUC by value, mean training time by value) -> the selected value."""
    tests: bool = True
    """Whether it reads the comparison's tests (False: the best and the family suffice)."""

    def select(self, comparison: Comparison[K], aucs: Mapping[K, float],
               times: Mapping[K, float]) -> K | None:
        """The value this rule selects; None when the comparison has no best."""
        return self.pick(comparison, aucs, times) if comparison.best is not None else None


_TIME = "mean training time (wall-clock seconds; CPU seconds on a confirm study)"
RULES: dict[SelectRule, Rule] = {r.name: r for r in (
    Rule(SelectRule.FINAL_SCORE, "highest mean final score (the best)", _final_score, False),
    Rule(SelectRule.AUC, "highest mean AUC (sample efficiency)", _auc, False),
    Rule(SelectRule.FASTEST_EQUIVALENT,
         f"lowest {_TIME} among the best and the values shown equivalent to it (within the "
         "margin; multiple comparisons with the best, alpha 0.05)", _fastest_equivalent),
    Rule(SelectRule.FASTEST_TIED,
         f"lowest {_TIME} among the best and the values not shown worse at margin 0 (the "
         f"{procedure_name(ALPHA)}; the rule of earlier releases: a noisy value ties by its "
         "spread)", _fastest_tied),
)}
RULE_TEXT = {name: rule.description for name, rule in RULES.items()}


def rule_of(name: str, where: str = "study.select") -> Rule:
    """The rule named ``name``; ConfigError naming the known ones."""
    return RULES[SelectRule.check(name, where)]


def mean_by_value(groups: Mapping[K, Sequence[float]]) -> dict[K, float]:
    """Each group's mean over its values (NaN ignored); a group without one is left out."""
    out = {}
    for group, values in groups.items():
        kept = [float(v) for v in values if not math.isnan(float(v))]
        if kept:
            out[group] = math.fsum(kept) / len(kept)
    return out


def select(rule: str, final: Mapping[K, Sequence[float]], aucs: Mapping[K, Sequence[float]],
           seconds: Mapping[K, Sequence[float]], min_seeds: int = MIN_SEEDS,
           dropped: Collection[K] = (), margin: float = MARGIN) -> K | None:
    """The selected group under ``rule``; None when no group can be selected.

    Args:
        rule: final_score, auc, fastest_equivalent or fastest_tied.
        final: Final scores of the complete seeds, by group, in the study's order.
        aucs: AUC of each complete seed with a curve, by group.
        seconds: Training time of each complete seed, by group.
        min_seeds: Fewest complete seeds a group needs to be selected.
        dropped: Groups a race dropped as worse: left out of every rule, as if never run.
        margin: ``compare.margin``, the margin as a fraction of the best's |mean|.
    """
    chosen = rule_of(rule)
    comparison = compare({g: vs for g, vs in final.items() if g not in dropped}, margin,
                         min_seeds=min_seeds, tests=chosen.tests)
    return chosen.select(comparison, mean_by_value(aucs), mean_by_value(seconds))


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
                   dropped: Collection[int] = (), time_attr: str = "wall_time",
                   margin: float = MARGIN) -> int | None:
    """Index in ``values`` of the value ``rule`` selects among the complete runs; None when
    no value has ``min_seeds`` complete seeds. ``dropped``: indices in ``values`` of the values
    a race dropped as worse (:func:`kraby_study.answers.raced.dropped_indices`), never
    selected."""
    found = samples(trials, curves, name, values, time_attr)
    return select(rule, found.final, found.aucs, found.seconds, min_seeds, dropped, margin)
