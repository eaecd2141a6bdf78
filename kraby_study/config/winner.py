"""``${winner:STUDY}``: a setting taken from an earlier study's selected value.

The resolver only parses and routes: the value comes from a
[`Lookup`][kraby_study.config.winner.Lookup] the command installs for the time it composes
([`winners_from`][kraby_study.config.winner.winners_from]), which reads the store. Without one, a
``${winner:...}`` fails with one line. Composition resolves every interpolation at once, so the
config a command plans from holds plain values.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, Protocol

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from kraby_study.errors import ConfigError, StoreError, first_line

NAME = "winner"
REFERENCE = re.compile(r"\$\{\s*winner\s*:\s*([^}]*?)\s*\}")


class Lookup(Protocol):
    """Where ``${winner:...}`` values come from."""

    def __call__(self, study: str, setting: str, root: DictConfig) -> Any:
        """The selected value of ``study`` for the config key ``setting`` of ``root``.

        Raises:
            ConfigError or StoreError: The study cannot give a value; one line.
        """
        ...


_LOOKUP: ContextVar[Lookup | None] = ContextVar("kraby_winner_lookup", default=None)


@contextmanager
def winners_from(lookup: Lookup) -> Iterator[None]:
    """Resolve ``${winner:...}`` through ``lookup`` inside the block."""
    token = _LOOKUP.set(lookup)
    try:
        yield
    finally:
        _LOOKUP.reset(token)


def _resolve(study: str, *, _node_: Any, _root_: DictConfig) -> Any:
    setting = _node_._get_full_key(None)
    lookup = _LOOKUP.get()
    if lookup is None:
        raise ConfigError(f"{setting}: ${{winner:{study}}} is read by `kraby-study run` only "
                          "(a study or campaign); give a value here")
    if not str(study).strip():
        raise ConfigError(f"{setting}: ${{winner:}} needs a study name, e.g. ${{winner:gamma}}")
    return lookup(str(study).strip(), setting, _root_)


def register() -> None:
    """Register the resolver with OmegaConf (idempotent)."""
    if not OmegaConf.has_resolver(NAME):
        OmegaConf.register_new_resolver(NAME, _resolve)


def references(cfg: DictConfig) -> list[tuple[str, str]]:
    """Every ``${winner:STUDY}`` of a config, unresolved, as (setting, study) pairs."""
    found: list[tuple[str, str]] = []

    def walk(node: Any, path: str) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                walk(value, f"{path}.{key}" if path else str(key))
        elif isinstance(node, list):
            for index, value in enumerate(node):
                walk(value, f"{path}[{index}]")
        elif isinstance(node, str):
            found.extend((path, match) for match in REFERENCE.findall(node))

    walk(OmegaConf.to_container(cfg, resolve=False), "")
    return found


def resolve(cfg: DictConfig) -> None:
    """Resolve every interpolation of ``cfg`` in place.

    Raises:
        ConfigError or StoreError: A ``${winner:...}`` (or another interpolation) cannot be
            resolved; the lookup's own one-line message when it gave one.
    """
    try:
        OmegaConf.resolve(cfg)
    except OmegaConfBaseException as err:
        cause: BaseException | None = err
        while cause is not None:
            if isinstance(cause, ConfigError | StoreError):
                raise cause from None
            cause = cause.__cause__ or cause.__context__
        raise ConfigError(f"cannot resolve the config: {first_line(err)}") from None
