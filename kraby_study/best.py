"""The best of a stored study, and its settings written back as a config file the commands use.

A sweep's best is its value with the highest mean final score over complete seeds; a search's
its complete trial with the highest score (:mod:`kraby_study.records` holds both rules).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from kraby_study.errors import StoreError
from kraby_study.plan.confirm import Arm, Source
from kraby_study.records import (
    SWEPT_KINDS,
    Outcome,
    best_trial,
    best_value,
    counted,
    outcome,
    param_name,
    search_key,
    swept_value,
    value_key,
    value_label,
)
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
        name = param_name(parameter)
        best = best_value(trials, name, definition.get("values", []))
        if best is None:
            return None
        # A confirm study's values are already labels (t12, ppo=tuned, gamma=0.8).
        label = (value_label(best.value) if attrs.kind == "confirm"
                 else f"{name}={value_label(best.value)}")
        seeds = len(best.trials)
        env_keys = ([parameter.split(".", 1)[1]] if parameter.startswith("env.")
                    else list(definition.get("env_keys", [])))
        return Best(short=f"{label} (mean {best.mean:.4g}, {seeds} seeds)",
                    description=f"{label} of {attrs.kind} {ledger.name!r}: mean final score "
                                f"{best.mean:.4g} over {seeds} seed(s)",
                    settings=best.trials[0].user_attrs.get("settings", {}), env_keys=env_keys)
    trial = best_trial(trials, ledger.maximize)
    if trial is None:
        return None
    env_keys = searched_env_keys(definition)
    params = ", ".join(f"{k}={value_label(v)}" for k, v in trial.params.items())
    return Best(short=f"trial {trial.number} ({float(trial.value):.4g})",  # type: ignore[arg-type]
                description=f"trial {trial.number} of {attrs.kind or 'study'} {ledger.name!r}: "
                            f"score {float(trial.value):.4g} ({params})",  # type: ignore[arg-type]
                settings=trial.user_attrs.get("settings", {}), env_keys=env_keys)


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
