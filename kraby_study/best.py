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
from kraby_study.records import (
    best_trial,
    best_value,
    counted,
    param_name,
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
    if attrs.kind == "sweep":
        parameter = str(definition["parameter"])
        name = param_name(parameter)
        best = best_value(trials, name, definition.get("values", []))
        if best is None:
            return None
        label = f"{name}={value_label(best.value)}"
        seeds = len(best.trials)
        env_keys = [parameter.split(".", 1)[1]] if parameter.startswith("env.") else []
        return Best(short=f"{label} (mean {best.mean:.4g}, {seeds} seeds)",
                    description=f"{label} of sweep {ledger.name!r}: mean final score "
                                f"{best.mean:.4g} over {seeds} seed(s)",
                    settings=best.trials[0].user_attrs.get("settings", {}), env_keys=env_keys)
    trial = best_trial(trials, ledger.maximize)
    if trial is None:
        return None
    space = definition.get("search", {}).get("params", {})
    env_keys = [str(p["path"]).split(".", 1)[1] for p in space.values()
                if str(p["path"]).startswith("env.")]
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
