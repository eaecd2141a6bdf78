"""A plan's race rules from the config: pure, checked before anything runs."""

from __future__ import annotations

from omegaconf import DictConfig

from kraby_study.config.validate import validate_racing
from kraby_study.errors import ConfigError
from kraby_study.plan.spec import RaceRules


def race_rules(cfg: DictConfig, seeds: list[int], where: str, search: bool = False
               ) -> RaceRules | None:
    """The rules of ``racing.*`` for a plan whose values get ``seeds``, one per round (their
    count is the setting named ``where``); None when racing is off.

    Raises:
        ConfigError: ``racing.min_seeds`` is below 2 or above ``seeds``, or ``racing.alpha`` is
            outside (0, 0.5].
    """
    validate_racing(cfg.racing, len(seeds), where)
    if not cfg.racing.enabled:
        return None
    below = str(cfg.racing.below)
    if below != "cap" and not search:
        raise ConfigError(f"racing.below={below} applies to a racing search (optuna --racing) "
                          "only: a race of values has no incumbent")
    return RaceRules(seeds=len(seeds), round_seeds=tuple(seeds),
                     min_seeds=int(cfg.racing.min_seeds), alpha=float(cfg.racing.alpha),
                     paired=bool(cfg.racing.paired), margin=float(cfg.compare.margin),
                     below=below)
