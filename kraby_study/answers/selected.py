"""The settings a stored study selected: a sweep's value under its rule, a search's best trial.

"Best" is the statistics' word: the highest interquartile mean (IQM) of the final scores (a
sweep's value; below 4 seeds the IQM is the mean) or the highest score (a search's trial).
"Selected" is what a study's rule picks ([`kraby_study.decision.selection`][]): under
``final_score`` the best value, under ``fastest_equivalent`` the fastest value shown equivalent to
it. Every function takes the command's
[`CompareOptions`][kraby_study.decision.comparison.CompareOptions] (margin, ``report.min_seeds`` and
``compare.select``, a rule read instead of the stored one); the defaults without one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from kraby_study.answers.raced import dropped_indices
from kraby_study.answers.racing_search import RacingSearch, racing_rules, racing_search
from kraby_study.answers.search_front import (
    front_lines,
    front_rule,
    front_short,
    search_front,
)
from kraby_study.answers.seed_scores import (
    samples,
    sweep_comparison,
    swept_values,
    time_measure,
)
from kraby_study.decision.comparison import CompareOptions, seeds_needed
from kraby_study.decision.selection import RULES, select
from kraby_study.errors import StoreError
from kraby_study.records.attributes import SelectRule, StudyAttrs, StudyKind, TrialAttrs
from kraby_study.records.definition import stored_floor, two_objectives
from kraby_study.records.stored import (
    Outcome,
    StoredTrial,
    Tally,
    counted,
    known_number,
    outcome,
    tally,
)
from kraby_study.records.values import (
    best_trial,
    param_name,
    score,
    swept_value,
    value_key,
    value_label,
)

if TYPE_CHECKING:
    import pandas as pd

    from kraby_study.store.ledger import StudyLedger

Curves = Callable[[list[int]], "pd.DataFrame"]
"""Reads the learning curves of a study's trials by number (only the auc rule calls it)."""


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
    front: list[str] = field(default_factory=list)
    """A two-objective search's front, one line per trial, for ``best`` to print first."""
    steps: int | None = None
    """Env steps of each of its runs (the budget it trained at; None for trials stored
    without it)."""


def selection_of(ledger: StudyLedger, options: CompareOptions | None = None
                 ) -> Selection | None:
    """A sweep's value its rule selects, or another study's best trial; None when no trial is
    complete."""
    attrs = ledger.attrs
    definition = attrs.definition
    trials = counted(ledger.trials())
    if StudyKind.of(attrs.kind).swept:
        parameter = str(definition["parameter"])
        chosen = selected_value(attrs, trials, ledger.curves, options)
        if chosen is None:
            return None
        env_keys = ([parameter.split(".", 1)[1]] if parameter.startswith("env.")
                    else list(definition.get("env_keys", [])))
        return Selection(short=sweep_short(attrs, chosen),
                         description=f"{value_text(attrs, chosen)} of {attrs.kind} "
                                     f"{ledger.name!r}: mean final score {chosen.mean:.4g} over "
                                     f"{len(chosen.trials)} seed(s){rule_text(chosen)}"
                                     f"{answer_text(chosen)}",
                         settings=chosen.trials[0].user_attrs.get("settings", {}),
                         env_keys=env_keys, steps=chosen.trials[0].user_attrs.get("steps"))
    if attrs.kind == StudyKind.SEARCH and two_objectives(definition):
        return front_selection(ledger.name, definition, trials, attrs.select, options)
    if racing_rules(attrs.kind, definition) is not None:
        return racing_selection(ledger.name, definition, racing_search(definition, trials))
    trial = best_trial(trials, ledger.maximize)
    if trial is None:
        return None
    env_keys = searched_env_keys(definition)
    params = ", ".join(f"{k}={value_label(v)}" for k, v in trial.params.items())
    value = float(score(trial))  # type: ignore[arg-type]
    trial_attrs = TrialAttrs.of(trial)
    seeds = (f" over {len(trial_attrs.scores or [])} seeds (rechecked)"
             if trial_attrs.recheck_of is not None else "")
    return Selection(short=trial_short(trial),
                     description=f"trial {known_number(trial)} of {attrs.kind or 'study'} "
                                 f"{ledger.name!r}: score {value:.4g}{seeds} ({params})",
                     settings=trial.user_attrs.get("settings", {}), env_keys=env_keys,
                     steps=trial.user_attrs.get("steps"))


def racing_selection(name: str, definition: dict[str, Any], found: RacingSearch | None
                     ) -> Selection | None:
    """A racing search's pick: its incumbent, on all its seeds; None before it has a
    complete seed."""
    inc = found.incumbent if found is not None else None
    if inc is None or not math.isfinite(inc.iqm):
        return None
    params = ", ".join(f"{k}={value_label(v)}" for k, v in inc.params.items())
    return Selection(short=racing_short(found),
                     description=f"configuration {inc.key} of racing search {name!r}, its "
                                 f"incumbent: IQM final score {inc.iqm:.4g} over {inc.seeds} "
                                 f"seed(s){f', {inc.failed} failed' if inc.failed else ''} "
                                 f"({params})",
                     settings=inc.settings, env_keys=searched_env_keys(definition),
                     steps=definition.get("steps"))


def racing_short(found: RacingSearch | None) -> str:
    """A racing search's incumbent in a few words: ``c3 (IQM -0.0123, 8 seeds)``; ``-``
    before it has a complete seed."""
    inc = found.incumbent if found is not None else None
    if inc is None or not math.isfinite(inc.iqm):
        return "-"
    failed = f", {inc.failed} failed" if inc.failed else ""
    return f"{inc.key} (IQM {inc.iqm:.4g}, {inc.seeds} seeds{failed})"


def front_selection(name: str, definition: dict[str, Any], trials: Sequence[StoredTrial],
                    select: str | None = None,
                    options: CompareOptions | None = None) -> Selection | None:
    """A two-objective search's selection by its rule
    ([`front_rule`][kraby_study.answers.search_front.front_rule] of its stored ``select``;
    [`front_choice`][kraby_study.decision.front.front_choice]), with the front (above the search's
    floor, if it has one)."""
    found = search_front(trials, stored_floor(definition), front_rule(select, options), options)
    if found.choice is None:
        return None
    chosen = found.choice.chosen
    trial = next(t for t in trials if known_number(t) == chosen.key)
    params = ", ".join(f"{k}={value_label(v)}" for k, v in trial.params.items())
    return Selection(short=front_short(found),
                     description=f"trial {chosen.key} of search {name!r}: score "
                                 f"{chosen.score:.4g}, cost {chosen.cost:.3g} CPU s per seed "
                                 f"({params}); selected by {found.choice.rule_text}",
                     settings=trial.user_attrs.get("settings", {}),
                     env_keys=searched_env_keys(definition), front=front_lines(found),
                     steps=trial.user_attrs.get("steps"))


def selected_short(attrs: StudyAttrs, trials: Sequence[StoredTrial], maximize: bool,
                   curves: Curves, options: CompareOptions | None = None) -> str:
    """What a study selects so far, as ``list`` shows it
    ([`Selection.short`][kraby_study.answers.selected.Selection.short]), from its counted trials;
    ``-`` when it selects nothing yet."""
    if StudyKind.of(attrs.kind).swept:
        chosen = selected_value(attrs, trials, curves, options)
        return sweep_short(attrs, chosen) if chosen is not None else "-"
    if attrs.kind == StudyKind.SEARCH and two_objectives(attrs.definition):
        return front_short(search_front(trials, stored_floor(attrs.definition),
                                        front_rule(attrs.select, options), options))
    if racing_rules(attrs.kind, attrs.definition) is not None:
        return racing_short(racing_search(attrs.definition, trials))
    trial = best_trial(trials, maximize)
    return trial_short(trial) if trial is not None else "-"


@dataclass(frozen=True)
class SweepSelection:
    """The value a stored sweep's selection rule picks."""

    value: Any
    rule: str
    mean: float
    """Its mean final score."""
    trials: list[StoredTrial]
    """Its complete counted trials."""
    tally: Tally
    """Outcomes of the study's counted trials, and the runs planned."""
    margin: float = 0.0
    """The comparison's margin in score units."""
    answer: str = "best"
    """The selected value's answer against the best: best or equivalent (or, under the
    rules that need no evidence, undecided)."""
    warning: str | None = None
    """The comparison's warning when the margin is below what the seeds resolve (rules that
    read the answers only)."""

    @property
    def finished(self) -> bool:
        """No planned run is still to come."""
        return self.tally.finished


def sweep_selection(ledger: StudyLedger, options: CompareOptions | None = None
                    ) -> SweepSelection | None:
    """What a swept study's stored rule ([`kraby_study.decision.selection`][]) selects among its
    complete runs (of a raced study, among the values its race did not drop); None when none is
    complete."""
    return selected_value(ledger.attrs, counted(ledger.trials()), ledger.curves, options)


def study_rule(stored: str | None, options: CompareOptions | None = None) -> SelectRule:
    """The rule a swept study selects by: ``compare.select`` when given, else its stored one
    (final_score when none)."""
    if options is not None and options.select is not None:
        return SelectRule.check(options.select, "compare.select")
    return SelectRule.of(stored)


def selected_value(attrs: StudyAttrs, trials: Sequence[StoredTrial], curves: Curves,
                   options: CompareOptions | None = None) -> SweepSelection | None:
    """What a swept study's rule ([`study_rule`][kraby_study.answers.selected.study_rule]) selects
    among its counted trials; None when no value can be selected yet."""
    options = options or CompareOptions()
    rule = study_rule(attrs.select, options)
    name, values = swept_values(str(attrs.kind), attrs.definition, trials)
    # Only the auc rule reads the curves.
    frame = curves([t.number for t in trials]) if rule == SelectRule.AUC else None
    # A raced study selects among the values its race kept: one dropped as worse never is.
    dropped = dropped_indices(attrs.definition, trials, values)
    found = samples(trials, frame, name, values, time_measure(attrs.kind))
    comparison = sweep_comparison(found.final, dropped, options, tests=RULES[rule].tests)
    index = select(rule, comparison, found.aucs, found.seconds)
    if index is None:
        return None
    key = value_key(values[index])
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and t.value is not None
            and value_key(swept_value(t, name, values)) == key]
    mean = sum(float(t.value) for t in done) / len(done)  # type: ignore[arg-type]
    return SweepSelection(value=values[index], rule=rule, mean=mean, trials=done,
                          tally=tally(trials, attrs.planned), margin=comparison.margin,
                          answer=str(comparison.answers.get(index, "best")),
                          warning=comparison.resolution_text() if RULES[rule].tests else None)


def value_text(attrs: StudyAttrs, chosen: SweepSelection) -> str:
    """A selected value as ``gamma=0.8``; a confirm study's values are already labels (t12,
    ppo=tuned, gamma=0.8)."""
    if attrs.kind == StudyKind.CONFIRM:
        return value_label(chosen.value)
    return f"{param_name(str(attrs.definition['parameter']))}={value_label(chosen.value)}"


def answer_text(chosen: SweepSelection) -> str:
    """The selection's answer against the best with the margin in score units, for the rules
    that read the answers (``; the best itself (margin 0.0028 in score units)``), and the
    warning when the margin is below what the seeds resolve; empty for the other rules."""
    if chosen.rule != SelectRule.FASTEST_EQUIVALENT:
        return ""
    answer = ("the best itself" if chosen.answer == "best"
              else f"answered {chosen.answer} against the best")
    warning = f"; warning: {chosen.warning}" if chosen.warning else ""
    return f"; {answer} (margin {chosen.margin:.3g} in score units){warning}"


def rule_text(chosen: SweepSelection) -> str:
    """``, selected by RULE`` for a rule other than the default; empty for final_score."""
    return "" if chosen.rule == SelectRule.FINAL_SCORE else f", selected by {chosen.rule}"


def sweep_short(attrs: StudyAttrs, chosen: SweepSelection) -> str:
    """A sweep's selection in a few words: ``gamma=0.8 (mean -0.0123, 10 seeds)``."""
    return (f"{value_text(attrs, chosen)} (mean {chosen.mean:.4g}, {len(chosen.trials)} seeds"
            f"{rule_text(chosen)})")


def trial_short(trial: StoredTrial) -> str:
    """A search's best trial in a few words: ``trial 7 (-0.0123)``."""
    return f"trial {known_number(trial)} ({float(score(trial)):.4g})"  # type: ignore[arg-type]


def require_selection(ledger: StudyLedger, options: CompareOptions | None = None
                      ) -> Selection:
    """The selection of a study that must have one; StoreError otherwise."""
    options = options or CompareOptions()
    best = selection_of(ledger, options)
    if best is None:
        done = tally(counted(ledger.trials())).complete
        if done and StudyKind.of(ledger.attrs.kind).swept:
            raise StoreError(f"study {ledger.name!r} selects nothing yet: no value has the "
                             f"{seeds_needed(options.min_seeds)} complete seeds a selection needs "
                             f"({done} complete trial(s) in all)")
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


