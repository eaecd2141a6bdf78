"""The settings of one run: resolved from a config, changed one at a time, and where its model goes.

Shared by every plan (sweeps, searches, confirm studies, train runs); pure.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from kraby_study.config.compose import compose_config
from kraby_study.config.validate import resolved_batch_size, to_container
from kraby_study.errors import ConfigError, first_line
from kraby_study.store.url import sqlite_path

SWEEPABLE_ROOTS = ("env", "ppo")


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


def settings_with_ppo(name: str, overrides: Sequence[str]) -> dict[str, Any]:
    """The resolved settings of a command's overrides with the ppo config ``NAME`` chosen
    instead of the command's own (a search's warm start, a confirm baseline)."""
    kept = [o for o in overrides if not o.startswith("ppo=")]
    return resolved_settings(compose_config([*kept, f"ppo={name}"]))
