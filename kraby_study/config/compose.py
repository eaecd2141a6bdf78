"""Compose the typed config: packaged tree, the user's own tree, command-line overrides."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from hydra import compose, initialize_config_module
from hydra.core.config_search_path import ConfigSearchPath
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.plugins import Plugins
from hydra.errors import HydraException, OverrideParseException
from hydra.plugins.search_path_plugin import SearchPathPlugin
from omegaconf import DictConfig, OmegaConf, open_dict
from omegaconf.errors import OmegaConfBaseException

from kraby_study.config import winner, zoo
from kraby_study.config.conf_dirs import CONFIG_MODULE, user_conf_dir
from kraby_study.config.schema import ParamSpace, register_schema
from kraby_study.config.validate import validate
from kraby_study.errors import ConfigError


def _lines_of(err: BaseException) -> list[str]:
    """The informative lines of one exception: no key dumps, no search path, no templates."""
    lines: list[str] = []
    options: list[str] = []
    in_options = False
    for raw in str(err).splitlines():
        line = raw.strip()
        if raw.startswith("\t") and in_options:
            options.append(line)
            continue
        in_options = line.startswith("Available options")
        if (not line or in_options or "$VALUE" in line
                or line.startswith(("full_key:", "object_type", "reference_type",
                                    "Config search path", "provider=", "To append"))):
            continue
        lines.append(re.sub(r"^In '[^']*': ", "", line))
    if options:
        lines.append("available: " + ", ".join(options))
    return lines


def _one_line(err: BaseException) -> str:
    """Hydra and OmegaConf messages span lines and repeat context: keep what names the problem."""
    parts: list[str] = []
    current: BaseException | None = err
    while current is not None:
        for line in _lines_of(current):
            if line not in parts:
                parts.append(line)
        current = current.__cause__ or current.__context__
    return re.sub(r"\s+", " ", "; ".join(parts) or type(err).__name__)


def unreadable(err: OverrideParseException) -> str:
    """One line for an override Hydra cannot parse: its key, what Hydra expected, and what a
    value may be (a word or number, a [list] or {map} with its brackets closed, or a quoted
    string, which may hold anything)."""
    text = str(err.override)
    key, sep, value = text.partition("=")
    said = str(err.message).splitlines()[0] if err.message else "cannot parse it"
    if not sep:
        return f"{text}: not KEY=VALUE ({said})"
    quote = '"' if "'" in value else "'"
    return (f"{key}: cannot read the value {value!r} ({said}); a value is a word or number, "
            f"a [list] or {{map}} with its brackets closed, or a quoted string, which may hold "
            f"= , brackets and spaces: {key}={quote}{value}{quote}")


def check_syntax(overrides: Sequence[str]) -> None:
    """Refuse an override Hydra's grammar cannot parse, in one line
    ([`unreadable`][kraby_study.config.compose.unreadable]) instead of Hydra's message and the
    parser's empty one after it."""
    parser = OverridesParser.create()
    for override in overrides:
        try:
            parser.parse_overrides([override])
        except OverrideParseException as err:
            raise ConfigError(unreadable(err)) from None


class UserConfFirst(SearchPathPlugin):
    """Puts the working folder's ./conf/ before the packaged tree in Hydra's search path, so a
    user's file wins over a packaged one of the same name (``best`` writes ./conf/ppo/...)."""

    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        user_dir = user_conf_dir()
        if user_dir is not None:
            search_path.prepend(provider="kraby-user", path=f"file://{user_dir}")


UNCHOSEN = ("study", "campaign")
"""Config groups that are empty unless chosen."""

RENAMED = {"physics_processes": "shards"}
"""Old setting names still accepted on the command line (see the README's changelog)."""


def refuse_hydra_settings(overrides: Sequence[str]) -> None:
    """Refuse an override of Hydra's own config (``hydra.run.dir=x``, ``hydra/launcher=...``):
    commands compose their config without Hydra's app, so no run folder, launcher or job
    logging of Hydra's exists to set, and the override would otherwise do nothing."""
    for override in overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        if key == "hydra" or key.startswith(("hydra.", "hydra/")):
            raise ConfigError(f"{override}: Hydra's own settings do nothing here (no run "
                              "folder, launcher or job log of Hydra's); results go to the "
                              "store (storage=URL), reports and figures to out=DIR")


def renamed(overrides: Sequence[str]) -> list[str]:
    """The overrides with old setting names replaced by their new ones."""
    out = []
    for override in overrides:
        key, sep, value = override.partition("=")
        out.append(f"{RENAMED.get(key, key)}{sep}{value}" if sep else override)
    return out


NEW_RANGE = "search.params."
"""Where an override adds a range to the search space."""


def new_ranges(overrides: Sequence[str]) -> tuple[list[str], list[tuple[str, dict, bool]]]:
    """The overrides apart from those that add a whole range to the search space
    (``+search.params.NAME={path: ..., type: ...}``, or ``++`` to add or replace), which Hydra
    cannot merge into the typed space: (the rest, [(NAME, range, replace), ...])."""
    rest: list[str] = []
    ranges: list[tuple[str, dict, bool]] = []
    for text in overrides:
        key = text.split("=", 1)[0].lstrip("+")
        name = key.removeprefix(NEW_RANGE)
        if not text.startswith("+") or name == key or "." in name:
            rest.append(text)
            continue
        try:
            override = OverridesParser.create().parse_overrides([text])[0]
            value = override.value()
        except HydraException:
            rest.append(text)  # Hydra names the problem
            continue
        if not isinstance(value, dict):
            rest.append(text)
            continue
        ranges.append((name, value, override.is_force_add()))
    return rest, ranges


def _add_ranges(cfg: DictConfig, ranges: list[tuple[str, dict, bool]]) -> None:
    """Put each new range into the composed space, typed as the space's others."""
    for name, value, replace in ranges:
        if name in cfg.search.params and not replace:
            raise ConfigError(f"+{NEW_RANGE}{name}: {name} is already in the space; "
                              f"++{NEW_RANGE}{name}=... replaces it")
        try:
            with open_dict(cfg.search.params):
                cfg.search.params[name] = OmegaConf.merge(OmegaConf.structured(ParamSpace),
                                                          value)
        except OmegaConfBaseException as err:
            raise ConfigError(f"+{NEW_RANGE}{name}: " + _one_line(err)) from None


def _composed(overrides: Sequence[str]) -> DictConfig:
    """conf/config.yaml composed with ``overrides``, Hydra's own config under ``hydra``;
    ConfigError with a one-line message."""
    register_schema()
    winner.register()
    zoo.register()
    Plugins.instance().register(UserConfFirst)
    GlobalHydra.instance().clear()
    try:
        with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
            return compose(config_name="config", overrides=list(overrides),
                           return_hydra_config=True)
    except (HydraException, OmegaConfBaseException, ValueError) as err:
        raise ConfigError(_one_line(err)) from None
    except AssertionError:
        # OmegaConf asserts when an override reaches under a group that is not chosen.
        unchosen = [o for o in overrides
                    if o.split("=", 1)[0].partition(".")[::2][0] in UNCHOSEN and "." in
                    o.split("=", 1)[0]]
        raise ConfigError("cannot apply " + (" ".join(unchosen) or "the overrides")
                          + ": its config group is not chosen (e.g. study.values=... needs "
                          "study=NAME)") from None
    finally:
        GlobalHydra.instance().clear()


@dataclass(frozen=True)
class Composed:
    """A composed config and the config group files Hydra chose for it."""

    cfg: DictConfig
    choices: dict[str, str]
    """Group -> the file chosen (``ppo`` -> ``zoo``): the last ``group=NAME`` override, else
    the primary config's default (the working folder's ./conf/config.yaml, if it has one)."""

    @property
    def ppo(self) -> str:
        """The ppo config the command trains with."""
        if "ppo" not in self.choices:
            raise ConfigError("the config chooses no ppo config in its defaults")
        return self.choices["ppo"]


def compose_config(overrides: Sequence[str], check: bool = True) -> DictConfig:
    """Compose conf/config.yaml with overrides; raise ConfigError with a one-line message.

    With ``check`` the config is resolved (``${winner:...}`` through the lookup the caller
    installed, [`winners_from`][kraby_study.config.winner.winners_from]) and validated; without, it
    keeps its interpolations.
    """
    return composed(overrides, check).cfg


def composed(overrides: Sequence[str], check: bool = True) -> Composed:
    """[`compose_config`][kraby_study.config.compose.compose_config], with the config group files
    Hydra chose."""
    refuse_hydra_settings(overrides)
    check_syntax(overrides)
    overrides, ranges = new_ranges(renamed(overrides))
    if "ppo=zoo" in overrides and "env=gym" not in overrides:
        # Otherwise Hydra's words: "Key 'normalize' not in 'LegEnvConfig'".
        raise ConfigError("ppo=zoo is rl-zoo3's settings for a Gymnasium id: add env=gym "
                          "env.id=ID")
    cfg = _composed(overrides)
    choices = {str(group): str(name) for group, name in cfg.hydra.runtime.choices.items()
               if name is not None and not str(group).startswith("hydra/")}
    OmegaConf.set_readonly(cfg, False)
    with open_dict(cfg):
        del cfg["hydra"]
    _add_ranges(cfg, ranges)
    if check:
        winner.resolve(cfg)
        validate(cfg)
    return Composed(cfg, choices)
