"""The best settings of a stored study, written back as a config file the commands can use."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import optuna
import yaml
from optuna.trial import TrialState

from kraby_study.ledger import attempts_by_key, value_label
from kraby_study.store import DEFINITION, KIND, StoreError


@dataclass(frozen=True)
class Best:
    """The winner of a study and the settings it trained with."""

    description: str
    settings: dict[str, Any]
    env_keys: list[str]
    """Env settings the study varied: written with the ppo settings so they travel together."""


def find_best(study: optuna.Study) -> Best:
    """A search's best trial, or a sweep's value with the best mean final score."""
    trials = [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]
    if not trials:
        raise StoreError(f"study {study.study_name!r} has no complete trial yet")
    definition = study.user_attrs.get(DEFINITION, {})
    kind = study.user_attrs.get(KIND)
    if kind == "sweep":
        name = str(definition["parameter"]).split(".")[-1]
        latest = [t for t in attempts_by_key(trials).values() if t.state == TrialState.COMPLETE]
        groups: dict[str, list[optuna.trial.FrozenTrial]] = {}
        for trial in latest:
            groups.setdefault(repr(trial.params[name]), []).append(trial)
        group = max(groups.values(), key=lambda g: np.mean([float(t.value) for t in g]))
        mean = float(np.mean([float(t.value) for t in group]))
        value = group[0].params[name]
        description = (f"{name}={value_label(value)} of sweep {study.study_name!r}: mean final "
                       f"score {mean:.4g} over {len(group)} seed(s)")
        env_keys = [str(definition["parameter"]).split(".", 1)[1]] if str(
            definition["parameter"]).startswith("env.") else []
        return Best(description, group[0].user_attrs["settings"], env_keys)
    best = max(trials, key=lambda t: float(t.value))
    space = definition.get("search", {}).get("params", {})
    env_keys = [str(p["path"]).split(".", 1)[1] for p in space.values()
                if str(p["path"]).startswith("env.")]
    params = ", ".join(f"{k}={value_label(v)}" for k, v in best.params.items())
    description = (f"trial {best.number} of {kind or 'study'} {study.study_name!r}: score "
                   f"{float(best.value):.4g} ({params})")
    return Best(description, best.user_attrs["settings"], env_keys)


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
