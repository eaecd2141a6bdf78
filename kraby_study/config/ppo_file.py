"""A ``ppo`` config file written from settings, for ``train ppo=NAME`` and ``run ppo=NAME``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml


def write_ppo_config(settings: dict[str, Any], env_keys: list[str], description: str,
                     path: Path) -> None:
    """A ppo config file (global package) holding the ppo settings and the env settings named
    in ``env_keys`` (those a study varied: they travel with the ppo settings)."""
    body: dict[str, Any] = {}
    if env_keys:
        body["env"] = {key: settings["env"][key] for key in env_keys}
    body["ppo"] = dict(settings["ppo"])
    text = (f"# @package _global_\n# Written by kraby-study best: {description}.\n"
            + yaml.safe_dump(body, sort_keys=False))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
