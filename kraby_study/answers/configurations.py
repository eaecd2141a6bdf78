"""The configurations ``confirm`` retrains, read from a stored search or sweep."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from kraby_study.answers.racing_search import RacingSearch, racing_rules, racing_search
from kraby_study.answers.search_front import search_front
from kraby_study.answers.selected import searched_env_keys
from kraby_study.decision.front import spread
from kraby_study.decision.robust import iqm
from kraby_study.errors import StoreError
from kraby_study.plan.confirm import Arm, ConfirmedStudy
from kraby_study.records.attributes import StudyKind
from kraby_study.records.definition import REWARDS, objective_names, stored_floor, two_objectives
from kraby_study.records.stored import (
    Outcome,
    counted,
    known_number,
    outcome,
    search_key,
    trial_seeds,
)
from kraby_study.records.values import (
    param_name,
    ranking,
    score,
    swept_value,
    value_key,
    value_label,
)
from kraby_study.store.ledger import StudyLedger


def confirmed_study(ledger: StudyLedger, top: int) -> ConfirmedStudy:
    """The ``top`` best configurations of a search (distinct complete trials, best first) or
    of a sweep (values by IQM final score, as the answers rank them), with the seeds its
    trials used. Of a
    two-objective search, up to ``top`` trials of its front spread along it
    ([`spread`][kraby_study.decision.front.spread]: the best score, the cheapest, the rest in cost
    order).

    Raises:
        StoreError: The study is neither a search nor a sweep, or has fewer than ``top``
            complete configurations (the message says how many it has).
    """
    attrs = ledger.attrs
    definition = attrs.definition
    trials = counted(ledger.trials())
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and score(t) is not None
            and t.user_attrs.get("settings")]
    front = attrs.kind == StudyKind.SEARCH and two_objectives(definition)
    raced = racing_search(definition, ledger.trials()) if racing_rules(
        attrs.kind, definition) is not None else None
    if raced is not None:
        arms = _racing_arms(ledger.name, raced)
        used = {seed for t in ledger.trials() for seed in trial_seeds(t)}
        env_keys = searched_env_keys(definition)
    elif attrs.kind == StudyKind.SEARCH:
        arms = (_front_arms(ledger.name, done, top, stored_floor(definition)) if front
                else _search_arms(ledger.name, done))
        used = _search_seeds(ledger.trials(), int(definition.get("seeds", 1)))
        env_keys = searched_env_keys(definition)
    elif attrs.kind == StudyKind.SWEEP:
        arms = _sweep_arms(ledger.name, str(definition["parameter"]),
                           list(definition.get("values", [])), done)
        used = {seed for t in trials for seed in trial_seeds(t)}
        parameter = str(definition["parameter"])
        env_keys = [parameter.split(".", 1)[1]] if parameter.startswith("env.") else []
    else:
        raise StoreError(f"confirm retrains a search or a sweep; study {ledger.name!r} is "
                         f"{'a ' + attrs.kind if attrs.kind else 'not made by kraby-study'}")
    if len(arms) < top and not front:
        raise StoreError(f"study {ledger.name!r} has {len(arms)} complete configuration(s), "
                         f"fewer than --top {top}")
    if not arms:
        raise StoreError(f"search {ledger.name!r} has no complete trial on its front yet")
    search = definition.get("search", {}) if attrs.kind == StudyKind.SEARCH else {}
    return ConfirmedStudy(name=ledger.name, arms=arms[:top], used_seeds=used,
                          steps=int(definition["steps"]),
                          curve_every=int(definition["curve_every"]), env_keys=env_keys,
                          two_objectives=front,
                          objective=objective_names(search.get("objective", REWARDS[0]))[0])


def _search_seeds(trials: list[Any], per_trial: int) -> set[int]:
    """The seeds a search's trials trained, every attempt's: a trial's ``per_trial`` seeds,
    a recheck's those after its trial's (as many as it added to the trial's scores)."""
    by_number = {t.number: t for t in trials}
    used: set[int] = set()
    for trial in trials:
        of = trial.user_attrs.get("recheck_of")
        if of is not None and of in by_number:
            added = (len(trial.user_attrs.get("scores") or [])
                     - len(by_number[of].user_attrs.get("scores") or []))
            used.update(trial_seeds(trial, max(added, 1)))
        else:
            used.update(trial_seeds(trial, per_trial))
    return used


def _front_arms(name: str, done: list[Any], top: int, floor: str | None) -> list[Arm]:
    """Up to ``top`` trials of a two-objective search's front (above its floor, if any),
    spread along it: the best score first, then the cheapest, then the rest by cost."""
    found = search_front(done, floor)
    by_number = {known_number(t): t for t in done}
    chosen = spread(found.front, top)
    places = {p.key: "best score" for p in chosen[:1]}
    places.update({p.key: "cheapest" for p in chosen[1:2]})
    arms = []
    for point in chosen:
        trial = by_number[point.key]
        place = places.get(point.key, "on the front")
        arms.append(Arm(label=str(trial.user_attrs.get("key", search_key(trial.number))),
                        settings=trial.user_attrs["settings"],
                        origin=f"trial {point.key} of search {name!r} ({place} of "
                               f"{len(found.front)} on the front: score {point.score:.4g}, "
                               f"{point.cost:.3g} CPU s/seed)",
                        source_score=point.score))
    return arms


def _search_arms(name: str, done: list[Any]) -> list[Arm]:
    """Complete search trials, best first (of equal scores the one on more seeds, then the
    cheaper: [`ranking`][kraby_study.records.values.ranking]), one per distinct configuration."""
    arms: list[Arm] = []
    seen: set[Any] = set()
    for trial in sorted(done, key=ranking):
        settings = trial.user_attrs["settings"]
        if value_key(settings) in seen:
            continue
        seen.add(value_key(settings))
        arms.append(Arm(label=str(trial.user_attrs.get("key", search_key(trial.number))),
                        settings=settings, origin=f"trial {trial.number} of search {name!r}",
                        source_score=float(score(trial))))  # type: ignore[arg-type]
    return arms


def _racing_arms(name: str, raced: RacingSearch) -> list[Arm]:
    """A racing search's configurations with a complete seed: the incumbent first, then by
    seeds ended (the evidence each earned), then by IQM."""
    inc = raced.incumbent
    done = [c for c in raced.configurations if math.isfinite(c.iqm) and c.settings]
    ordered = sorted(done, key=lambda c: (c is not inc, -c.seeds, -c.iqm))
    return [Arm(label=c.key, settings=c.settings,
                origin=f"configuration {c.key} of racing search {name!r} ({c.left_text()}; IQM "
                       f"over {c.seeds} seed(s))",
                source_score=c.iqm) for c in ordered]


def _sweep_arms(name: str, parameter: str, planned: list[Any], done: list[Any]) -> list[Arm]:
    """A sweep's values with complete seeds, best IQM final score first (the mean below 4
    seeds)."""
    short = param_name(parameter)
    groups: dict[Any, list[Any]] = {}
    values: dict[Any, Any] = {}
    for trial in done:
        value = swept_value(trial, short, planned)
        groups.setdefault(value_key(value), []).append(trial)
        values.setdefault(value_key(value), value)
    scores = {k: np.array([float(t.value) for t in g]) for k, g in groups.items()}
    order = sorted(groups, key=lambda k: -float(iqm(scores[k])))
    return [Arm(label=f"{short}={value_label(values[k])}",
                settings=groups[k][0].user_attrs["settings"],
                origin=f"{parameter} = {value_label(values[k])} in sweep {name!r} (mean final "
                       f"score over {len(groups[k])} seed(s))",
                source_score=sum(float(t.value) for t in groups[k]) / len(groups[k]))
            for k in order]


