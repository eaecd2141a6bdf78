"""The settings a stored study (or campaign) selected, and the files that carry them: a ppo
config file for later commands (``./conf/ppo/NAME.yaml``) or an rl-zoo3 hyperparameter file
(``./zoo/NAME.yml``) for rl-zoo3's trainer."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kraby_study.api.config import Config, with_default
from kraby_study.errors import ConfigError, StoreError

ZOO_DIR = "zoo"
"""Where rl-zoo3 hyperparameter files are written, in the working folder."""


@dataclass(frozen=True)
class Best:
    """Selected settings and where they come from.

    Attributes:
        description: A sentence saying what was selected, by which rule.
        settings: The ``env`` and ``ppo`` settings it trained with.
        env_keys: The env settings the study varied (written with the ppo settings).
        source: What was read, e.g. ``study 'gamma'``.
        steps: Env steps of each of its runs (None when not stored).
        front: A two-objective search's front, one line per trial (empty otherwise).
        name: The default name of its config file.
    """

    description: str
    settings: dict[str, Any]
    env_keys: list[str]
    source: str
    steps: int | None = None
    front: list[str] = field(default_factory=list)
    name: str = "best"


@dataclass(frozen=True)
class ZooFile:
    """A written rl-zoo3 hyperparameter file and the command that trains it."""

    path: Path
    train_command: str


def checked_name(name: str) -> str:
    """A config file's name, refused in one line unless made of letters, digits, _ and -."""
    if not name.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"--name {name!r}: use letters, digits, _ and -")
    return name


def default_name(config: Config, study: str | None = None, campaign: str | None = None
                 ) -> str:
    """The name `best`'s settings are saved under by default: ``campaign_NAME``, or
    ``best_STUDY`` (the search's name when no study is named)."""
    if campaign:
        return f"campaign_{campaign}"
    return f"best_{study or config.cfg.search.name}"


def best(config: Config, study: str | None = None, campaign: str | None = None) -> Best:
    """The settings a stored study's rule selected, or those a finished campaign ends with
    (its last stage's selected value, with every earlier winner).

    Args:
        config: A composed config: its ``storage``, ``compare.margin`` and, when set,
            ``compare.select`` (a rule applied instead of the stored one).
        study: The stored study (default: the search's name, ``search.name``).
        campaign: A campaign instead of a study.

    Returns:
        The `Best`.

    Raises:
        ConfigError: Both a study and a campaign; one line.
        StoreError: No store, no such study, or nothing selected yet; one line.

    Examples:
        >>> import kraby_study as ks
        >>> chosen = ks.best(ks.compose(["storage=sqlite:///example.db"], command="best"),
        ...                  study="clip_range")
        >>> chosen.description.startswith("clip_range=")
        True
    """
    from kraby_study.api.answers import read_selection

    if study and campaign:
        raise ConfigError("give --campaign NAME or --study-name NAME, not both")
    cfg = config.cfg
    name = study or str(cfg.search.name)
    chosen = read_selection(str(cfg.storage), name, campaign, cfg.compare.margin,
                            cfg.compare.select, int(cfg.report.min_seeds))
    return Best(description=chosen.description, settings=chosen.settings,
                env_keys=list(chosen.env_keys),
                source=f"campaign {campaign!r}" if campaign else f"study {name!r}",
                steps=chosen.steps, front=list(chosen.front),
                name=default_name(config, study, campaign))


def zoo_best(overrides: Sequence[str] = (), fmt: str = "ppo") -> Best:
    """rl-zoo3's published PPO settings for ``env.id``, as ``ppo=zoo`` reads them (with the
    overrides' own ppo settings), at ``budget=zoo`` (its n_timesteps) unless the overrides
    choose a budget and ``fmt`` is ``zoo``.

    Args:
        overrides: Overrides with ``env=gym env.id=ID``.
        fmt: ``ppo`` to save them as a ppo config file, ``zoo`` as an rl-zoo3 file.

    Examples:
        With the ``[zoo]`` extra installed, ``zoo_best(["env=gym", "env.id=CartPole-v1"])``
        holds rl-zoo3's settings for CartPole-v1, saved by default as ``zoo_CartPole-v1``.
    """
    from kraby_study.config.compose import compose_config
    from kraby_study.config.validate import to_container
    from kraby_study.config.zoo import zoo_settings

    chosen = [*(o for o in overrides if not o.startswith("ppo=")), "ppo=zoo"]
    cfg = compose_config(with_default(chosen, "budget", "zoo") if fmt == "zoo" else chosen)
    read = zoo_settings(str(cfg.env.id))
    settings = {"env": to_container(cfg.env), "ppo": to_container(cfg.ppo)}
    if fmt == "zoo":
        description = (f"rl-zoo3 {read.version}'s PPO settings for {read.env_id}, as ppo=zoo "
                       "reads them")
    else:
        description = (f"rl-zoo3 {read.version}'s PPO settings for {read.env_id} (its budget, "
                       f"n_timesteps {read.n_timesteps:,}, is budget=zoo)")
    return Best(description=description, settings=settings, env_keys=[],
                source=f"ppo=zoo for {read.env_id}", steps=int(cfg.budget.steps),
                name="zoo_" + re.sub(r"[^A-Za-z0-9_-]+", "_", read.env_id))


def save_ppo_config(chosen: Best, name: str | None = None) -> Path:
    """Write the settings as ``./conf/ppo/NAME.yaml``, a ppo config later commands take as
    ``ppo=NAME``.

    Args:
        chosen: The settings (`best`).
        name: The file's name (default ``chosen.name``).

    Returns:
        The file written.

    Examples:
        >>> import kraby_study as ks
        >>> from kraby_study.api.settings_files import save_ppo_config
        >>> chosen = ks.best(ks.compose(["storage=sqlite:///example.db"], command="best"),
        ...                  study="clip_range")
        >>> save_ppo_config(chosen).as_posix()
        'conf/ppo/best_clip_range.yaml'
    """
    from kraby_study.config.conf_dirs import USER_CONF_DIR
    from kraby_study.config.ppo_file import write_ppo_config

    path = Path(USER_CONF_DIR) / "ppo" / f"{checked_name(name or chosen.name)}.yaml"
    write_ppo_config(chosen.settings, chosen.env_keys, chosen.description, path)
    return path


def save_zoo_file(chosen: Best, name: str | None = None) -> ZooFile:
    """Write the settings as ``./zoo/NAME.yml``, an rl-zoo3 hyperparameter file for their
    Gymnasium id in rl-zoo3's keys, ``n_timesteps`` the budget steps; refused in one line,
    before anything is written, when they are not a Gymnasium id's.

    Args:
        chosen: The settings (`best` or `zoo_best`).
        name: The file's name (default ``chosen.name``).

    Returns:
        The file written and the command that trains it (`ZooFile`).

    Examples:
        A study on ``env=gym env.id=Pendulum-v1`` saved as ``pendulum`` gives
        ``./zoo/pendulum.yml`` and ``python -m rl_zoo3.train --algo ppo --env Pendulum-v1
        -conf zoo/pendulum.yml``; the leg's settings are refused (no Gymnasium id).
    """
    from kraby_study.config.zoo import study_settings, train_command, write_hyperparams
    from kraby_study.plan.spec import OPTIONAL_PPO

    config_name = checked_name(name or chosen.name)
    if chosen.steps is None:
        raise StoreError(f"{chosen.source} stores no budget steps for its selected trial, "
                         "which an rl-zoo3 file needs as n_timesteps")
    complete = {"env": chosen.settings.get("env", {}),
                "ppo": {**OPTIONAL_PPO, **chosen.settings.get("ppo", {})}}
    read = study_settings(complete, chosen.steps, chosen.source)
    path = Path(ZOO_DIR) / f"{config_name}.yml"
    packages = [str(p) for p in complete["env"].get("packages", [])]
    write_hyperparams(read, chosen.description, path, packages)
    return ZooFile(path, train_command(read.env_id, path, packages))
