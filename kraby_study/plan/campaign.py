"""A campaign laid out: its stages, and the config of each stage with the earlier winners.

Stage k composes its study file, then the campaign's start settings, then
``PARAMETER=${winner:STUDY}`` for every earlier stage, then the command's own overrides; the
winners resolve through the lookup the caller gives (it reads the store). Nothing here trains
or writes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig, OmegaConf

from kraby_study.config.compose import compose_config
from kraby_study.config.validate import RUN_LENGTH, to_container, validate_run_length
from kraby_study.config.winner import Lookup, references, winners_from
from kraby_study.errors import ConfigError
from kraby_study.records.attributes import SelectRule


@dataclass(frozen=True)
class Stage:
    """One stage of a campaign."""

    number: int
    """Its place in the chain, from 1."""
    study: str
    """The study config it runs (conf/study/STUDY.yaml)."""
    name: str
    """Its name in the store: ``<campaign>-<study>``."""
    parameter: str
    """The setting it sweeps, e.g. ppo.gamma."""
    select: str
    """Its selection rule."""
    documented: Any
    """The value the documented work chose (None: none given)."""

    def stored(self) -> dict[str, Any]:
        """As kept in each stage's attributes."""
        return {"study": self.study, "name": self.name, "parameter": self.parameter,
                "select": self.select, "documented": self.documented}


@dataclass(frozen=True)
class Campaign:
    """A chain of studies, each run with the values the earlier stages selected."""

    name: str
    description: str
    start: dict[str, Any]
    """Dotted setting -> value: where the first stage starts."""
    stages: list[Stage]
    overrides: list[str]
    """The command's own overrides, applied to every stage last."""

    def before(self, stage: Stage) -> list[Stage]:
        """The stages that run before ``stage``."""
        return self.stages[:stage.number - 1]

    def record(self, stage: Stage) -> dict[str, Any]:
        """What a stage stores about its campaign (the report reads the chain from it)."""
        return {"name": self.name, "stage": stage.number, "description": self.description,
                "start": self.start, "stages": [s.stored() for s in self.stages]}


def override_value(value: Any) -> str:
    """A value written in Hydra's override grammar."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ",".join(override_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{override_value(v)}" for k, v in value.items()) + "}"
    text = str(value).replace("\\", "\\\\").replace("'", "\\'")
    return f"'{text}'"


def _key(override: str) -> str:
    return override.split("=", 1)[0].lstrip("+~")


def stage_overrides(campaign: Campaign, stage: Stage) -> list[str]:
    """The overrides that compose a stage: study, start, earlier winners, the command's."""
    start = [f"{key}={override_value(value)}" for key, value in campaign.start.items()]
    winners = [f"{s.parameter}=${{winner:{s.study}}}" for s in campaign.before(stage)
               if s.parameter != stage.parameter]
    return [f"study={stage.study}", *start, *winners, *campaign.overrides]


def _stage_file(name: str, number: int, study: str, overrides: Sequence[str]) -> DictConfig:
    """A stage's composed config, interpolations left as they are."""
    try:
        return compose_config([*overrides, f"study={study}"], check=False)
    except ConfigError as err:
        raise ConfigError(f"campaign {name}, stage {number} ({study}): {err}") from None


def stage_file(campaign: Campaign, stage: Stage) -> DictConfig:
    """A stage's config with its earlier winners left unresolved: what it sweeps and how many
    runs, known before those winners are (a dry run)."""
    return _stage_file(campaign.name, stage.number, stage.study,
                       stage_overrides(campaign, stage))


def campaign_of(cfg: DictConfig, overrides: Sequence[str]) -> Campaign:
    """The campaign a config selects, every stage checked before anything runs.

    Args:
        cfg: The command's config (with ``campaign`` set).
        overrides: The command's overrides.

    Raises:
        ConfigError: A bad name, no stages, a stage twice, an unknown study or rule, a
            ``${winner:...}`` in a study file naming itself, a later stage or no stage, or an
            override of a setting that a stage sweeps; one line.
    """
    spec = cfg.campaign
    name = str(spec.name)
    if not name or not name.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"campaign.name {name!r}: use letters, digits, _ and -")
    if not spec.stages:
        raise ConfigError(f"campaign {name} lists no stages")
    # The campaign's own settings (campaign=NAME, campaign.name=...) shape the chain, not a
    # stage: a stage composes no campaign group to apply them to.
    kept = [o for o in overrides if _key(o).split(".", 1)[0] != "campaign"]
    if any(_key(o) == "study" for o in kept):
        raise ConfigError(f"campaign {name} runs its own studies: drop study=...")
    studies = [str(s.study) for s in spec.stages]
    twice = sorted({s for s in studies if studies.count(s) > 1})
    if twice:
        raise ConfigError(f"campaign {name} lists study {twice[0]} twice; a stage is stored "
                          "under its study's name")
    stages: list[Stage] = []
    for number, entry in enumerate(spec.stages, start=1):
        stage_cfg = _stage_file(name, number, str(entry.study), overrides)
        rule = str(entry.select) if entry.select is not None else str(stage_cfg.study.select)
        SelectRule.check(rule, f"campaign {name}, stage {number} ({entry.study}): select")
        stages.append(Stage(number=number, study=str(entry.study),
                            name=f"{name}-{entry.study}",
                            parameter=str(stage_cfg.study.parameter), select=rule,
                            documented=to_container(entry.documented)))
        for setting, ref in references(stage_cfg):
            _check_reference(name, studies, number, setting, ref)
    swept = {s.parameter: s for s in stages}
    for override in kept:
        if _key(override) in swept:
            raise ConfigError(f"{_key(override)} is selected by stage "
                              f"{swept[_key(override)].study} of campaign {name}: drop "
                              f"{override}")
    campaign = Campaign(name=name, description=str(spec.description),
                        start=dict(to_container(spec.start)), stages=stages, overrides=list(kept))
    for stage in stages:
        _check_run_length(campaign, stage)
    return campaign


def _check_run_length(campaign: Campaign, stage: Stage) -> None:
    """Before any stage runs, each stage's runs can be scored at its budget
    ([`validate_run_length`][kraby_study.config.validate.validate_run_length]), for every value it
    sweeps of n_envs or the time limit. A length setting an earlier stage selects is one of that
    stage's values, each checked there; the stage is checked again when it is planned."""
    cfg = stage_file(campaign, stage)
    winners = {setting for setting, _ in references(cfg)}
    if any(path in winners for path in ("budget.steps", "env.id", *RUN_LENGTH)
           if path != stage.parameter):
        return
    env = {key: OmegaConf.select(cfg, f"env.{key}")
           for key in ("id", "max_episode_steps", "packages") if key in cfg.env}
    ppo = {key: None if f"ppo.{key}" in winners else OmegaConf.select(cfg, f"ppo.{key}")
           for key in ("n_envs", "n_steps", "batch_size")}
    where = f"campaign {campaign.name}, stage {stage.number} ({stage.study})"
    swept = stage.parameter in RUN_LENGTH
    for value in to_container(cfg.study["values"]) if swept else [None]:
        root, key = stage.parameter.split(".", 1)
        settings = {"env": dict(env), "ppo": dict(ppo)}
        if swept:
            settings[root][key] = value
        validate_run_length(settings["env"], settings["ppo"], int(cfg.budget.steps),
                            where=f"{where}, value {value!r}: " if swept else f"{where}: ")


def _check_reference(name: str, studies: list[str], number: int, setting: str,
                     ref: str) -> None:
    """A stage's own ``${winner:REF}`` must name an earlier stage."""
    where = f"campaign {name}, stage {number} ({studies[number - 1]}): {setting}: " \
            f"${{winner:{ref}}}"
    if ref not in studies:
        raise ConfigError(f"{where}: {ref!r} is not a stage of the campaign (stages: "
                          f"{', '.join(studies)})")
    index = studies.index(ref) + 1
    if index == number:
        raise ConfigError(f"{where} refers to the stage itself")
    if index > number:
        raise ConfigError(f"{where} refers to a later stage ({index}); a stage takes winners "
                          "from earlier stages only")


def stage_config(campaign: Campaign, stage: Stage, lookup: Lookup) -> DictConfig:
    """A stage's config, its winners resolved through ``lookup``, stored under its stage
    name with its rule.

    Raises:
        ConfigError or StoreError: A winner cannot be read (an earlier stage unfinished) or the
            config is invalid; one line.
    """
    with winners_from(lookup):
        cfg = compose_config(stage_overrides(campaign, stage))
    cfg.study.name = stage.name
    cfg.study.select = stage.select
    return cfg
