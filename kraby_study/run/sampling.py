"""A search's Optuna side: its space as distributions, its sampler and its pruner.

The space itself is declared and checked in :mod:`kraby_study.plan.space`, which stays pure.
"""

from __future__ import annotations

import optuna
from omegaconf import DictConfig
from optuna.distributions import (
    BaseDistribution,
    CategoricalDistribution,
    FloatDistribution,
    IntDistribution,
)

from kraby_study.config.validate import to_container
from kraby_study.plan.space import warmup_steps


def distributions(cfg: DictConfig) -> dict[str, BaseDistribution]:
    """The space as Optuna distributions, one per parameter, in the order of the space file."""
    space: dict[str, BaseDistribution] = {}
    for name, p in cfg.search.params.items():
        if p.type == "float":
            space[str(name)] = FloatDistribution(float(p.low), float(p.high), log=bool(p.log))
        elif p.type == "int":
            space[str(name)] = IntDistribution(int(p.low), int(p.high), log=bool(p.log))
        else:
            space[str(name)] = CategoricalDistribution(list(to_container(p.choices)))
    return space


def make_sampler(cfg: DictConfig) -> optuna.samplers.BaseSampler:
    """The seeded sampler of a search."""
    seed = int(cfg.search.seed)
    if cfg.search.sampler == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    return optuna.samplers.TPESampler(seed=seed, n_startup_trials=int(cfg.search.startup_trials),
                                      constant_liar=True)


def make_pruner(cfg: DictConfig) -> optuna.pruners.BasePruner:
    """The pruner of a search; its steps are env steps."""
    warmup = warmup_steps(cfg)
    if cfg.search.pruner == "median":
        return optuna.pruners.MedianPruner(n_startup_trials=int(cfg.search.pruner_startup_trials),
                                           n_warmup_steps=warmup)
    if cfg.search.pruner == "hyperband":
        total = int(cfg.budget.steps) * int(cfg.budget.seeds)
        return optuna.pruners.HyperbandPruner(min_resource=warmup, max_resource=total)
    return optuna.pruners.NopPruner()
