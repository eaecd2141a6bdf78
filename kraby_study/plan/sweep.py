"""Expand a study into trial specifications: pure, no training, no database."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from kraby_study.config.validate import (
    resolved_batch_size,
    to_container,
    validate_env,
    validate_ppo,
)
from kraby_study.errors import ConfigError, first_line
from kraby_study.plan.spec import TrialSpec
from kraby_study.records import StudyAttrs, param_name, sweep_key, train_key, value_key, value_label
from kraby_study.store.connection import sqlite_path

SWEEPABLE_ROOTS = ("env", "ppo")


@dataclass(frozen=True)
class StudyPlan:
    """A sweep laid out: its definition (for the store) and one spec per value and seed."""

    name: str
    parameter: str
    values: list[Any]
    specs: list[TrialSpec]
    definition: dict[str, Any]
    select: str | None = None
    """A sweep's selection rule (stored beside the definition, not in it)."""
    inputs: list[dict[str, Any]] = field(default_factory=list)
    """Settings taken from earlier studies' selected values (``Input.stored()``)."""
    campaign: dict[str, Any] | None = None
    """A campaign stage's place in its campaign (``Campaign.record``)."""

    def notes(self) -> StudyAttrs:
        """What is stored beside the definition: rule, inputs, campaign."""
        return StudyAttrs(select=self.select, inputs=self.inputs or None,
                          campaign=self.campaign)

    @property
    def fingerprint(self) -> str:
        """Hash of the definition: the same study name must always mean the same sweep."""
        return fingerprint(self.definition)


def fingerprint(definition: dict[str, Any]) -> str:
    """A short stable hash of a JSON-able definition."""
    text = json.dumps(definition, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def resolved_settings(cfg: DictConfig) -> dict[str, Any]:
    """The env and ppo settings of a config, with the batch size made explicit."""
    settings = {"env": to_container(cfg.env), "ppo": to_container(cfg.ppo)}
    settings["ppo"]["batch_size"] = resolved_batch_size(cfg.ppo)
    return settings


def models_dir(cfg: DictConfig) -> Path:
    """Folder for saved models: beside the SQLite file, or studies/models for a server."""
    if cfg.models_dir:
        return Path(cfg.models_dir)
    db = sqlite_path(cfg.storage)
    if db is None:
        return Path("studies") / "models"
    return db.parent / f"{db.stem}_models"


def model_path(cfg: DictConfig, study: str, key: str) -> str | None:
    """Where a trial's model is saved, or None when models are switched off."""
    if not cfg.save_models:
        return None
    return str(models_dir(cfg) / study / f"{key}.zip")


def with_value(cfg: DictConfig, parameter: str, value: Any) -> DictConfig:
    """A copy of cfg with one setting changed, type-checked by the schema."""
    root = parameter.split(".", 1)[0]
    if root not in SWEEPABLE_ROOTS or "." not in parameter:
        raise ConfigError(f"study.parameter {parameter!r} must name a setting under env. or ppo.")
    if OmegaConf.select(cfg, parameter, default="__missing__") == "__missing__":
        raise ConfigError(f"study.parameter {parameter!r} is not a setting of the config")
    trial_cfg = cfg.copy()
    try:
        OmegaConf.update(trial_cfg, parameter, value, merge=False)
    except OmegaConfBaseException as err:
        raise ConfigError(f"study value {value!r} for {parameter}: {first_line(err)}") from None
    return trial_cfg


def run_seeds(cfg: DictConfig) -> list[int]:
    """Seeds of a study's runs: seed, seed + 1, ... (fixed, so a rerun repeats them)."""
    return [int(cfg.seed) + i for i in range(int(cfg.budget.seeds))]


def expand_study(cfg: DictConfig) -> StudyPlan:
    """One TrialSpec per (value, seed) of the selected study; every trial config validated."""
    if cfg.study is None:
        raise ConfigError("no study selected: add study=NAME (e.g. study=ent_coef)")
    study = cfg.study
    values = list(to_container(study["values"]))
    if not values:
        raise ConfigError(f"study {study.name!r} lists no values")
    if len({value_key(v) for v in values}) != len(values):
        raise ConfigError(f"study {study.name!r} lists a value twice")
    specs = []
    for index, value in enumerate(values):
        trial_cfg = with_value(cfg, study.parameter, value)
        try:
            validate_env(trial_cfg.env)
            validate_ppo(trial_cfg.ppo)
        except ConfigError as err:
            raise ConfigError(f"study {study.name}, value {value!r}: {err}") from None
        settings = resolved_settings(trial_cfg)
        for seed in run_seeds(cfg):
            key = sweep_key(index, seed)
            specs.append(TrialSpec(
                study=str(study.name), key=key, seed=seed, steps=int(cfg.budget.steps),
                curve_every=int(cfg.budget.curve_every), settings=settings, value=value,
                model_path=model_path(cfg, str(study.name), key),
                label=f"{param_name(str(study.parameter))}={value_label(value)} seed {seed}"))
    base = resolved_settings(cfg)
    root, leaf = str(study.parameter).split(".", 1)
    base[root].pop(leaf, None)
    if study.parameter != "ppo.batch_size":
        base["ppo"].pop("batch_size", None)
        base["ppo"]["batch_size_setting"] = to_container(cfg.ppo).get("batch_size")
    definition = {
        "kind": "sweep",
        "parameter": str(study.parameter),
        "values": values,
        "settings": base,
        "steps": int(cfg.budget.steps),
        "curve_every": int(cfg.budget.curve_every),
    }
    return StudyPlan(name=str(study.name), parameter=str(study.parameter), values=values,
                     specs=specs, definition=definition, select=str(study.select))


def single_run(cfg: DictConfig) -> StudyPlan:
    """The plan of ``train``: one run at the configured settings and seed.

    Runs with the same settings and budget share one study named train-<hash>, one trial per seed.
    """
    validate_env(cfg.env)
    validate_ppo(cfg.ppo)
    settings = resolved_settings(cfg)
    definition = {"kind": "train", "settings": settings, "steps": int(cfg.budget.steps),
                  "curve_every": int(cfg.budget.curve_every)}
    name = f"train-{fingerprint(definition)[:8]}"
    seed = int(cfg.seed)
    key = train_key(seed)
    spec = TrialSpec(study=name, key=key, seed=seed, steps=int(cfg.budget.steps),
                     curve_every=int(cfg.budget.curve_every), settings=settings,
                     model_path=model_path(cfg, name, key), label=f"seed {seed}")
    return StudyPlan(name=name, parameter="seed", values=[seed], specs=[spec],
                     definition=definition)
