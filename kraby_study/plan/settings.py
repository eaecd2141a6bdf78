"""The settings of one run: resolved from a config, changed one at a time, and where its model
and its TensorBoard logs go.

Shared by every plan (sweeps, searches, confirm studies, train runs); pure.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from kraby_study.config.compose import compose_config
from kraby_study.config.validate import check_writable, resolved_batch_size, to_container
from kraby_study.errors import ConfigError, first_line
from kraby_study.plan.spec import OPTIONAL_PPO
from kraby_study.store.url import sqlite_path

SWEEPABLE_ROOTS = ("env", "ppo")

UNSAFE = re.compile(r"[^A-Za-z0-9._,=+-]+")
"""Characters a folder name avoids: path separators, spaces, brackets, quotes, ..."""


def resolved_settings(cfg: DictConfig) -> dict[str, Any]:
    """The env and ppo settings of a config, with the batch size made explicit.

    A ppo setting of [`OPTIONAL_PPO`][kraby_study.plan.spec.OPTIONAL_PPO] at its default is left
    out: stored settings that do not name it mean that default, and keep their fingerprints.
    """
    ppo = {key: value for key, value in to_container(cfg.ppo).items()
           if key not in OPTIONAL_PPO or value != OPTIONAL_PPO[key]}
    settings = {"env": to_container(cfg.env), "ppo": ppo}
    settings["ppo"]["batch_size"] = resolved_batch_size(cfg.ppo)
    return settings


def validate_outputs(cfg: DictConfig) -> None:
    """The folders a training command writes to can be written: TensorBoard logs (when asked
    for) and models (unless save_models is false); refused in one line before any run starts,
    so that no run fails on them. Nothing is left behind."""
    if cfg.tensorboard_dir is not None:
        check_writable(Path(str(cfg.tensorboard_dir)).expanduser(), "tensorboard_dir")
    if cfg.save_models:
        check_writable(models_dir(cfg), "models_dir")


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


def tensorboard_run(cfg: DictConfig, study: str, name: str) -> str | None:
    """Where a run's TensorBoard logs go, ``DIR/<study>/<name>`` (the trial adds ``-seed<n>``),
    both parts made safe as folder names; None when ``tensorboard_dir`` is null.

    A relative DIR is taken from the command's working folder, so every worker (and every
    node of a Ray cluster) is given the same absolute path.
    """
    if cfg.tensorboard_dir is None:
        return None
    root = Path(str(cfg.tensorboard_dir)).expanduser().absolute()
    return str(root / folder_name(study) / folder_name(name))


def folder_name(text: str) -> str:
    """A name as a folder name on any system: each run of characters other than letters,
    digits and ``. _ , = + -`` becomes one ``_`` (``t0 = ppo=tuned`` -> ``t0_=_ppo=tuned``)."""
    name = UNSAFE.sub("_", text).strip("_")
    return name if name.strip(".") else "_"


def with_value(cfg: DictConfig, parameter: str, value: Any) -> DictConfig:
    """A copy of cfg with one setting changed, type-checked by the schema."""
    root = parameter.split(".", 1)[0]
    if root not in SWEEPABLE_ROOTS or "." not in parameter:
        raise ConfigError(f"study.parameter {parameter!r} must name a setting under env. or ppo.")
    if OmegaConf.select(cfg, parameter, default="__missing__") == "__missing__":
        own = (f" (this env's settings: {', '.join(str(k) for k in cfg.env.keys())})"
               if root == "env" else "")
        raise ConfigError(f"study.parameter {parameter!r} is not a setting of the config{own}")
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
