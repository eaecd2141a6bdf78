"""Reading a study's trials: one attempt per planned run, progress, the best value so far."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
import optuna
from optuna.trial import FrozenTrial, TrialState

from kraby_study.store import DEFINITION, INTERRUPTED, KIND, PLANNED, RETRY_OF


def attempts_by_key(trials: list[FrozenTrial]) -> dict[str, FrozenTrial]:
    """The attempt that counts for each planned run: the latest trial with its key."""
    latest: dict[str, FrozenTrial] = {}
    for trial in sorted(trials, key=lambda t: t.number):
        key = trial.user_attrs.get("key")
        if key is not None:
            latest[key] = trial
    return latest


def superseded(trials: list[FrozenTrial]) -> set[int]:
    """Numbers of the trials that a later attempt of the same run replaced."""
    return {int(t.user_attrs[RETRY_OF]) for t in trials if RETRY_OF in t.user_attrs}


def was_interrupted(trial: FrozenTrial) -> bool:
    """A trial given back unfinished (its command or worker stopped), not a result."""
    return (trial.state == TrialState.FAIL
            and str(trial.user_attrs.get("failure", INTERRUPTED)).startswith(INTERRUPTED))


def is_final_failure(trial: FrozenTrial) -> bool:
    """A failed trial that is a result (diverged, errored), not an interruption."""
    return trial.state == TrialState.FAIL and not was_interrupted(trial)


def value_label(value: Any) -> str:
    """How a swept value is written in tables and legends."""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass(frozen=True)
class StudyProgress:
    """Where a study stands."""

    name: str
    kind: str
    total: int
    complete: int
    failed: int
    pruned: int
    running: int
    best: str


def study_progress(study: optuna.Study) -> StudyProgress:
    """Counts and the best value so far of a stored study."""
    kind = study.user_attrs.get(KIND, "optuna")
    trials = study.get_trials(deepcopy=False)
    if kind == "search":
        replaced = superseded(trials)
        counted = [t for t in trials if t.number not in replaced]
    else:
        counted = list(attempts_by_key(trials).values())
    states = [t.state for t in counted]
    complete = states.count(TrialState.COMPLETE)
    total = int(study.user_attrs.get(PLANNED, len(counted)))
    return StudyProgress(
        name=study.study_name, kind=kind, total=total, complete=complete,
        failed=sum(1 for t in counted if is_final_failure(t)),
        pruned=states.count(TrialState.PRUNED), running=states.count(TrialState.RUNNING),
        best=best_description(study, counted))


def best_description(study: optuna.Study, trials: list[FrozenTrial]) -> str:
    """The best value of a sweep (highest mean final score) or the best trial of a search."""
    done = [t for t in trials if t.state == TrialState.COMPLETE and t.value is not None]
    if not done:
        return "-"
    definition = study.user_attrs.get(DEFINITION, {})
    if definition.get("kind") == "sweep":
        name = str(definition["parameter"]).split(".")[-1]
        scores: dict[str, list[float]] = {}
        for trial in done:
            scores.setdefault(json.dumps(trial.params.get(name)), []).append(float(trial.value))
        best_value, best_scores = max(scores.items(), key=lambda kv: np.mean(kv[1]))
        return (f"{name}={value_label(json.loads(best_value))} "
                f"(mean {np.mean(best_scores):.4g}, {len(best_scores)} seeds)")
    best = max(done, key=lambda t: float(t.value))
    return f"trial {best.number} ({float(best.value):.4g})"
