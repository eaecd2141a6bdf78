"""A ``ppo`` config file written from settings, for ``train ppo=NAME`` and ``run ppo=NAME``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

CARRIED_ENV_KEYS = ("normalize", "normalize_reward")
"""Env settings a ppo config carries (ppo=zoo sets them from rl-zoo3's normalize): a setting
trained with VecNormalize is not the same setting without it."""


def write_ppo_config(settings: dict[str, Any], env_keys: list[str], description: str,
                     path: Path) -> None:
    """A ppo config file (global package) holding the ppo settings, the env settings named in
    ``env_keys`` (those a study varied: they travel with the ppo settings) and any of
    [`CARRIED_ENV_KEYS`][kraby_study.config.ppo_file.CARRIED_ENV_KEYS] the settings hold (a
    Gymnasium env's normalisation)."""
    env = settings.get("env", {})
    keys = [*env_keys, *(key for key in CARRIED_ENV_KEYS if key in env and key not in env_keys)]
    body: dict[str, Any] = {}
    if keys:
        body["env"] = {key: env[key] for key in keys}
    body["ppo"] = dict(settings["ppo"])
    text = (f"# @package _global_\n# Written by kraby-study best: {description}.\n"
            + yaml.safe_dump(body, sort_keys=False))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
