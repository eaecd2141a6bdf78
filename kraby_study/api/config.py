"""Compose a command's config from the overrides the command line takes.

Each command composes ``conf/config.yaml`` through Hydra's compose API with its own default
groups (``train`` trains ``ppo=tuned``; ``search`` and ``confirm`` take ``budget=quick``; a
search on ``env=gym`` takes ``search=gym``), then checks what it will write to, so a bad
setting is refused here, before anything runs. The heavy work (Hydra, the store) is imported
when a function runs: importing this module loads none of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from kraby_study.errors import ConfigError

if TYPE_CHECKING:
    from omegaconf import DictConfig

COMMANDS = ("run", "train", "search", "confirm", "report", "best", "list")
"""The commands a config is composed for."""

TRAINING = ("run", "train", "search", "confirm")
"""Commands that train, and so check the folders they write models and logs to."""


def with_default(overrides: Sequence[str], group: str, option: str) -> list[str]:
    """The overrides, choosing ``group=option`` first unless the user chose that group.

    Examples:
        >>> with_default(["ppo.gamma=0.9"], "budget", "quick")
        ['budget=quick', 'ppo.gamma=0.9']
    """
    chosen = any(o.startswith(f"{group}=") for o in overrides)
    return list(overrides) if chosen else [f"{group}={option}", *overrides]


def command_overrides(overrides: Sequence[str], command: str) -> list[str]:
    """The overrides with the command's own default groups placed first.

    Examples:
        >>> command_overrides(["env=gym"], "search")
        ['search=gym', 'budget=quick', 'env=gym']
    """
    if command not in COMMANDS:
        raise ConfigError(f"command {command!r}: one of {', '.join(COMMANDS)}")
    chosen = list(overrides)
    if command == "train":
        chosen = with_default(chosen, "ppo", "tuned")
    if command in ("search", "confirm"):
        chosen = with_default(chosen, "budget", "quick")
    if command == "search" and "env=gym" in chosen:
        # The default space searches the leg's observation too; a gym env's space has no env.
        chosen = with_default(chosen, "search", "gym")
    return chosen


@dataclass
class Config:
    """A config composed for one command, with the overrides it was composed from.

    Attributes:
        cfg: The composed, validated config (an OmegaConf ``DictConfig``):
            ``config.cfg.budget.steps``, ``config.cfg.storage``.
        overrides: The overrides as composed, the command's default groups first; a search
            and a confirm compose them again for each configuration they start from.
        command: The command it was composed for (``run``, ``train``, ``search``,
            ``confirm``, ``report``, ``best`` or ``list``).
        choices: The config group files Hydra chose (``ppo`` -> ``tuned``).
        inputs: For ``run``: each ``${winner:STUDY}`` value taken from a stored study.
    """

    cfg: DictConfig
    overrides: list[str]
    command: str
    choices: dict[str, str] = field(default_factory=dict)
    inputs: list[Any] = field(default_factory=list)

    def to_yaml(self) -> str:
        """The composed config as YAML (what ``--dry-run`` prints first)."""
        from omegaconf import OmegaConf

        return OmegaConf.to_yaml(self.cfg)

    def require(self, command: str) -> Config:
        """This config, when composed for ``command``; ConfigError otherwise (each command has
        its own default groups, so a config composed for another would train otherwise)."""
        if self.command != command:
            raise ConfigError(f"this config was composed for {self.command}, not {command}: "
                              f"compose(overrides, command={command!r})")
        return self


def compose(overrides: Sequence[str] = (), command: str = "run") -> Config:
    """Compose the config a command runs with, from the same overrides the CLI takes.

    Args:
        overrides: Hydra overrides, e.g. ``["study=ent_coef", "budget=smoke"]``.
        command: The command it is for: ``run`` (a sweep or a campaign), ``train``,
            ``search``, ``confirm``, ``report``, ``best`` or ``list``.

    Returns:
        The composed, validated `Config`.

    Raises:
        ConfigError: A setting is unknown, mistyped or out of range, or a folder the command
            writes to cannot be written; one line.

    Examples:
        >>> import kraby_study as ks
        >>> config = ks.compose(["study=ent_coef", "budget=smoke"])
        >>> config.cfg.study.parameter
        'ppo.ent_coef'
    """
    from kraby_study.config.compose import composed

    chosen = command_overrides(overrides, command)
    inputs: list[Any] = []
    if command == "run":
        # A study file may take a setting from a finished study (${winner:STUDY}).
        from kraby_study.answers.winners import StoreWinners
        from kraby_study.config.winner import winners_from

        lookup = StoreWinners()
        with winners_from(lookup):
            found = composed(chosen)
        inputs = lookup.inputs
    else:
        found = composed(chosen)
    if command in TRAINING:
        from kraby_study.plan.settings import validate_outputs

        validate_outputs(found.cfg)
    if command == "train" and found.cfg.racing.enabled:
        raise ConfigError("racing is for run, optuna and confirm: train makes one run")
    return Config(cfg=found.cfg, overrides=chosen, command=command, choices=found.choices,
                  inputs=inputs)
