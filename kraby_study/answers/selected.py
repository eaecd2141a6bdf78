"""The settings a stored study selected: a sweep's value under its rule, a search's best trial.

"Best" is the statistics' word: the highest mean final score (a sweep's value) or the highest
score (a search's trial). "Selected" is what a study's rule picks (:mod:`kraby_study.selection`):
under ``final_score`` the best value, under ``fastest_tied`` the fastest value tied with it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from optuna.trial import FrozenTrial

from kraby_study.answers.raced import dropped_indices
from kraby_study.comparison import MIN_SEEDS
from kraby_study.errors import StoreError
from kraby_study.records import (
    Outcome,
    SelectRule,
    StudyKind,
    Tally,
    best_trial,
    counted,
    outcome,
    param_name,
    swept_value,
    tally,
    value_key,
    value_label,
)
from kraby_study.selection import selected_index, swept_values
from kraby_study.store.ledger import StudyLedger


@dataclass(frozen=True)
class Selection:
    """What a study selected and the settings it trained with."""

    short: str
    """One line for ``list``: ``gamma=0.8 (mean -0.0123, 10 seeds)`` or ``trial 7 (-0.0123)``."""
    description: str
    """A sentence for ``best`` and config files."""
    settings: dict[str, Any]
    """The env and ppo settings it trained with."""
    env_keys: list[str]
    """Env settings the study varied: written with the ppo settings so they travel together."""


def selection_of(ledger: StudyLedger) -> Selection | None:
    """A sweep's value its rule selects, or another study's best trial; None when no trial is
    complete."""
    attrs = ledger.attrs
    definition = attrs.definition
    trials = counted(ledger.trials())
    if StudyKind.of(attrs.kind).swept:
        parameter = str(definition["parameter"])
        chosen = sweep_selection(ledger)
        if chosen is None:
            return None
        # A confirm study's values are already labels (t12, ppo=tuned, gamma=0.8).
        label = (value_label(chosen.value) if attrs.kind == StudyKind.CONFIRM
                 else f"{param_name(parameter)}={value_label(chosen.value)}")
        seeds = len(chosen.trials)
        rule = "" if chosen.rule == SelectRule.FINAL_SCORE else f", selected by {chosen.rule}"
        env_keys = ([parameter.split(".", 1)[1]] if parameter.startswith("env.")
                    else list(definition.get("env_keys", [])))
        return Selection(short=f"{label} (mean {chosen.mean:.4g}, {seeds} seeds{rule})",
                         description=f"{label} of {attrs.kind} {ledger.name!r}: mean final score "
                                     f"{chosen.mean:.4g} over {seeds} seed(s){rule}",
                         settings=chosen.trials[0].user_attrs.get("settings", {}),
                         env_keys=env_keys)
    trial = best_trial(trials, ledger.maximize)
    if trial is None:
        return None
    env_keys = searched_env_keys(definition)
    params = ", ".join(f"{k}={value_label(v)}" for k, v in trial.params.items())
    score = float(trial.value)  # type: ignore[arg-type]
    return Selection(short=f"trial {trial.number} ({score:.4g})",
                     description=f"trial {trial.number} of {attrs.kind or 'study'} "
                                 f"{ledger.name!r}: score {score:.4g} ({params})",
                     settings=trial.user_attrs.get("settings", {}), env_keys=env_keys)


@dataclass(frozen=True)
class SweepSelection:
    """The value a stored sweep's selection rule picks."""

    value: Any
    rule: str
    mean: float
    """Its mean final score."""
    trials: list[FrozenTrial]
    """Its complete counted trials."""
    tally: Tally
    """Outcomes of the study's counted trials, and the runs planned."""

    @property
    def finished(self) -> bool:
        """No planned run is still to come."""
        return self.tally.finished


def sweep_selection(ledger: StudyLedger) -> SweepSelection | None:
    """What a swept study's stored rule (:mod:`kraby_study.selection`) selects among its
    complete runs (of a raced study, among the race's survivors); None when none is
    complete."""
    attrs = ledger.attrs
    rule = SelectRule.of(attrs.select)
    trials = counted(ledger.trials())
    name, values = swept_values(str(attrs.kind), attrs.definition, trials)
    # Only the auc rule reads the curves.
    curves = ledger.curves([t.number for t in trials]) if rule == SelectRule.AUC else None
    # A raced study selects among its survivors: a dropped value is never selected.
    dropped = dropped_indices(attrs.definition, trials, values)
    index = selected_index(trials, curves, name, values, rule, dropped=dropped)
    if index is None:
        return None
    key = value_key(values[index])
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and t.value is not None
            and value_key(swept_value(t, name, values)) == key]
    mean = sum(float(t.value) for t in done) / len(done)  # type: ignore[arg-type]
    return SweepSelection(value=values[index], rule=rule, mean=mean, trials=done,
                          tally=tally(trials, attrs.planned))


def require_selection(ledger: StudyLedger) -> Selection:
    """The selection of a study that must have one; StoreError otherwise."""
    best = selection_of(ledger)
    if best is None:
        done = tally(counted(ledger.trials())).complete
        if done and StudyKind.of(ledger.attrs.kind).swept:
            raise StoreError(f"study {ledger.name!r} selects nothing yet: no value has the "
                             f"{MIN_SEEDS} complete seeds a selection needs ({done} complete "
                             "trial(s) in all)")
        raise StoreError(f"study {ledger.name!r} has no complete trial yet")
    if not best.settings:
        raise StoreError(f"study {ledger.name!r} stores no settings for its best trial (not "
                         "made by kraby-study?)")
    return best


def searched_env_keys(definition: dict[str, Any]) -> list[str]:
    """The env settings a search's space varies."""
    space = definition.get("search", {}).get("params", {})
    return [str(p["path"]).split(".", 1)[1] for p in space.values()
            if str(p["path"]).startswith("env.")]


