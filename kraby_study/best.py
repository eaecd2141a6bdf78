"""The best of a stored study, and its settings written back as a config file the commands use.

A sweep's best is its value with the highest mean final score over complete seeds; a search's
its complete trial with the highest score (:mod:`kraby_study.records` holds both rules).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import yaml
from optuna.trial import FrozenTrial

from kraby_study.errors import StoreError
from kraby_study.plan.confirm import Arm, Source
from kraby_study.records import (
    SWEPT_KINDS,
    Outcome,
    Tally,
    best_trial,
    counted,
    outcome,
    param_name,
    search_key,
    swept_value,
    tally,
    value_key,
    value_label,
)
from kraby_study.selection import DEFAULT_RULE, RULES, selected_index, swept_values
from kraby_study.store.connection import Store
from kraby_study.store.ledger import StudyLedger


@dataclass(frozen=True)
class Best:
    """The winner of a study and the settings it trained with."""

    short: str
    """One line for ``list``: ``gamma=0.8 (mean -0.0123, 10 seeds)`` or ``trial 7 (-0.0123)``."""
    description: str
    """A sentence for ``best`` and config files."""
    settings: dict[str, Any]
    """The env and ppo settings it trained with."""
    env_keys: list[str]
    """Env settings the study varied: written with the ppo settings so they travel together."""


def find_best(ledger: StudyLedger) -> Best | None:
    """A sweep's best value or another study's best trial; None when no trial is complete."""
    attrs = ledger.attrs
    definition = attrs.definition
    trials = counted(ledger.trials())
    if attrs.kind in SWEPT_KINDS:
        parameter = str(definition["parameter"])
        chosen = selection_of(ledger)
        if chosen is None:
            return None
        # A confirm study's values are already labels (t12, ppo=tuned, gamma=0.8).
        label = (value_label(chosen.value) if attrs.kind == "confirm"
                 else f"{param_name(parameter)}={value_label(chosen.value)}")
        seeds = len(chosen.trials)
        rule = "" if chosen.rule == DEFAULT_RULE else f", selected by {chosen.rule}"
        env_keys = ([parameter.split(".", 1)[1]] if parameter.startswith("env.")
                    else list(definition.get("env_keys", [])))
        return Best(short=f"{label} (mean {chosen.mean:.4g}, {seeds} seeds{rule})",
                    description=f"{label} of {attrs.kind} {ledger.name!r}: mean final score "
                                f"{chosen.mean:.4g} over {seeds} seed(s){rule}",
                    settings=chosen.trials[0].user_attrs.get("settings", {}), env_keys=env_keys)
    trial = best_trial(trials, ledger.maximize)
    if trial is None:
        return None
    env_keys = searched_env_keys(definition)
    params = ", ".join(f"{k}={value_label(v)}" for k, v in trial.params.items())
    return Best(short=f"trial {trial.number} ({float(trial.value):.4g})",  # type: ignore[arg-type]
                description=f"trial {trial.number} of {attrs.kind or 'study'} {ledger.name!r}: "
                            f"score {float(trial.value):.4g} ({params})",  # type: ignore[arg-type]
                settings=trial.user_attrs.get("settings", {}), env_keys=env_keys)


@dataclass(frozen=True)
class Selected:
    """The value a stored sweep's selection rule picks."""

    value: Any
    rule: str
    mean: float
    """Its mean final score."""
    trials: list[FrozenTrial]
    """Its complete counted trials."""
    tally: Tally
    """Outcomes of the study's counted trials."""
    planned: int
    """Runs planned."""

    @property
    def finished(self) -> bool:
        """No planned run is still to come."""
        return self.tally.ended >= self.planned


def selection_of(ledger: StudyLedger) -> Selected | None:
    """What a swept study's stored rule (:mod:`kraby_study.selection`) selects among its
    complete runs; None when none is complete."""
    attrs = ledger.attrs
    rule = attrs.select if attrs.select in RULES else DEFAULT_RULE
    trials = counted(ledger.trials())
    name, values = swept_values(str(attrs.kind), attrs.definition, trials)
    # Only the auc rule reads the curves.
    curves = (ledger.curves([t.number for t in trials]) if rule == "auc"
              else pd.DataFrame(columns=["number", "step", "mean_reward"]))
    index = selected_index(trials, curves, name, values, rule)
    if index is None:
        return None
    key = value_key(values[index])
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and t.value is not None
            and value_key(swept_value(t, name, values)) == key]
    counts = tally(trials)
    return Selected(value=values[index], rule=rule,
                    mean=sum(float(t.value) for t in done) / len(done),  # type: ignore[arg-type]
                    trials=done, tally=counts, planned=max(attrs.planned or 0, len(trials)))


def require_best(ledger: StudyLedger) -> Best:
    """The best of a study that must have one; StoreError otherwise."""
    best = find_best(ledger)
    if best is None:
        raise StoreError(f"study {ledger.name!r} has no complete trial yet")
    if not best.settings:
        raise StoreError(f"study {ledger.name!r} stores no settings for its best trial (not "
                         "made by kraby-study?)")
    return best


def write_config(best: Best, path: Path) -> None:
    """A ppo config file (global package) holding the ppo settings and the varied env ones."""
    body: dict[str, Any] = {}
    if best.env_keys:
        body["env"] = {key: best.settings["env"][key] for key in best.env_keys}
    body["ppo"] = dict(best.settings["ppo"])
    text = (f"# @package _global_\n# Written by kraby-study best: {best.description}.\n"
            + yaml.safe_dump(body, sort_keys=False))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def searched_env_keys(definition: dict[str, Any]) -> list[str]:
    """The env settings a search's space varies."""
    space = definition.get("search", {}).get("params", {})
    return [str(p["path"]).split(".", 1)[1] for p in space.values()
            if str(p["path"]).startswith("env.")]


def confirm_source(ledger: StudyLedger, top: int) -> Source:
    """The ``top`` best configurations of a search (distinct complete trials, best first) or
    of a sweep (values by mean final score), with the seeds its trials used.

    Raises:
        StoreError: The study is neither a search nor a sweep, or has fewer than ``top``
            complete configurations (the message says how many it has).
    """
    attrs = ledger.attrs
    definition = attrs.definition
    trials = counted(ledger.trials())
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and t.value is not None
            and t.user_attrs.get("settings")]
    if attrs.kind == "search":
        arms = _search_arms(ledger.name, done)
        per_trial = int(definition.get("seeds", 1))
        used = {int(t.user_attrs["seed"]) + i for t in trials if "seed" in t.user_attrs
                for i in range(per_trial)}
        env_keys = searched_env_keys(definition)
    elif attrs.kind == "sweep":
        arms = _sweep_arms(ledger.name, str(definition["parameter"]),
                           list(definition.get("values", [])), done)
        used = {int(t.user_attrs["seed"]) for t in trials if "seed" in t.user_attrs}
        parameter = str(definition["parameter"])
        env_keys = [parameter.split(".", 1)[1]] if parameter.startswith("env.") else []
    else:
        raise StoreError(f"confirm retrains a search or a sweep; study {ledger.name!r} is "
                         f"{'a ' + attrs.kind if attrs.kind else 'not made by kraby-study'}")
    if len(arms) < top:
        raise StoreError(f"study {ledger.name!r} has {len(arms)} complete configuration(s), "
                         f"fewer than --top {top}")
    return Source(name=ledger.name, arms=arms[:top], used_seeds=used,
                  steps=int(definition["steps"]), curve_every=int(definition["curve_every"]),
                  env_keys=env_keys)


def _search_arms(name: str, done: list[Any]) -> list[Arm]:
    """Complete search trials, best first, one per distinct configuration."""
    arms: list[Arm] = []
    seen: set[Any] = set()
    for trial in sorted(done, key=lambda t: -float(t.value)):
        settings = trial.user_attrs["settings"]
        if value_key(settings) in seen:
            continue
        seen.add(value_key(settings))
        arms.append(Arm(label=str(trial.user_attrs.get("key", search_key(trial.number))),
                        settings=settings, origin=f"trial {trial.number} of search {name!r}",
                        source_score=float(trial.value)))
    return arms


def _sweep_arms(name: str, parameter: str, planned: list[Any], done: list[Any]) -> list[Arm]:
    """A sweep's values with complete seeds, best mean final score first."""
    short = param_name(parameter)
    groups: dict[Any, list[Any]] = {}
    values: dict[Any, Any] = {}
    for trial in done:
        value = swept_value(trial, short, planned)
        groups.setdefault(value_key(value), []).append(trial)
        values.setdefault(value_key(value), value)
    means = {k: sum(float(t.value) for t in g) / len(g) for k, g in groups.items()}
    order = sorted(groups, key=lambda k: -means[k])
    return [Arm(label=f"{short}={value_label(values[k])}",
                settings=groups[k][0].user_attrs["settings"],
                origin=f"{parameter} = {value_label(values[k])} in sweep {name!r} (mean final "
                       f"score over {len(groups[k])} seed(s))",
                source_score=means[k]) for k in order]


def campaign_best(store: Store, name: str) -> Best:
    """The settings a finished campaign ends with: its last stage's selected value's, with the
    env settings any stage or the start set.

    Raises:
        StoreError: No stage of that campaign is stored, or a stage is not finished (the
            message names the first one and its progress).
    """
    stages = campaign_stages(store, name)
    if not stages:
        known = sorted({str(r["name"]) for r in campaign_records(store).values()})
        raise StoreError(f"no campaign {name!r} in {store.url}"
                         + (f" (campaigns: {', '.join(known)})" if known else ""))
    chosen = None
    for number, stage in enumerate(stages, start=1):
        done = None
        if stage["name"] in store.study_names():
            done = selection_of(store.load(str(stage["name"])))
        if done is None or not done.finished:
            progress = (f"{done.tally.complete}/{done.planned} complete" if done is not None
                        else "not run yet")
            raise StoreError(f"campaign {name!r} is not finished: stage {number}/{len(stages)} "
                             f"{stage['name']} is {progress}; rerun `kraby-study run "
                             f"campaign={name}`")
        chosen = done
    assert chosen is not None
    last = stages[-1]
    record = next(iter(campaign_records(store, name).values()))
    env_keys = sorted({str(s["parameter"]).split(".", 1)[1] for s in stages
                       if str(s["parameter"]).startswith("env.")}
                      | {key.split(".", 1)[1] for key in record.get("start", {})
                         if key.startswith("env.")})
    label = f"{param_name(str(last['parameter']))}={value_label(chosen.value)}"
    return Best(short=f"campaign {name}: {label}",
                description=f"campaign {name!r} after its {len(stages)} stages (last: {label} "
                            f"in {last['name']}, mean final score {chosen.mean:.4g} over "
                            f"{len(chosen.trials)} seed(s), {chosen.rule})",
                settings=chosen.trials[0].user_attrs.get("settings", {}), env_keys=env_keys)


def campaign_records(store: Store, name: str | None = None) -> dict[str, dict[str, Any]]:
    """Stored study name -> its campaign record, for every campaign stage (of ``name``),
    latest stage first."""
    records = {}
    for study in store.study_names():
        record = store.load(study).attrs.campaign
        if record and (name is None or record.get("name") == name):
            records[study] = record
    return dict(sorted(records.items(), key=lambda item: -int(item[1].get("stage", 0))))


def campaign_stages(store: Store, name: str) -> list[dict[str, Any]]:
    """The stages of a stored campaign, as its latest stored stage records them."""
    records = campaign_records(store, name)
    return list(next(iter(records.values()))["stages"]) if records else []
