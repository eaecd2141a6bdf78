"""A search's Optuna side: its space as distributions, its sampler and its pruner.

The space itself is declared and checked in [`kraby_study.plan.space`][], which stays pure.
"""

from __future__ import annotations

import warnings

import numpy as np
import optuna
from omegaconf import DictConfig
from optuna.distributions import (
    BaseDistribution,
    CategoricalDistribution,
    FloatDistribution,
    IntDistribution,
)

from kraby_study.config.validate import to_container
from kraby_study.plan.space import objectives, pruner_name, warmup_steps, wilcoxon_seeds


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


def directions(cfg: DictConfig) -> list[str]:
    """The study's directions: the reward maximised, then any cost minimised."""
    return ["maximize", "minimize"][:len(objectives(cfg))]


def sampler_seed(seed: int, opening: int) -> int:
    """The seed the sampler of a search's ``opening``-th command (from 0) draws from: ``seed``
    for the first, else a child of (seed, opening). A command that resumes a search, or joins
    it from another machine, seeded as the first was would draw the first one's random trials
    again; two that join at once take different openings."""
    if opening == 0:
        return seed
    return int(np.random.SeedSequence([seed, opening]).generate_state(1)[0])


def make_sampler(cfg: DictConfig, opening: int = 0) -> optuna.samplers.BaseSampler:
    """The seeded sampler of a search's ``opening``-th command
    ([`sampler_seed`][kraby_study.run.sampling.sampler_seed]). TPE handles one objective or two
    (Optuna's multi-objective TPE); NSGA-II keeps Optuna's default population. The GP sampler
    (Optuna's Gaussian-process sampler, which models the score's noise) draws its first
    ``startup_trials`` *complete* trials at random, as random search of the same seed draws them; it
    learns nothing from a pruned trial."""
    seed = sampler_seed(int(cfg.search.seed), opening)
    if cfg.search.sampler == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    if cfg.search.sampler == "nsga2":
        return optuna.samplers.NSGAIISampler(seed=seed)
    if cfg.search.sampler == "gp":
        return optuna.samplers.GPSampler(seed=seed,
                                         n_startup_trials=int(cfg.search.startup_trials))
    return optuna.samplers.TPESampler(seed=seed, n_startup_trials=int(cfg.search.startup_trials),
                                      constant_liar=True)


def racing_sampler(cfg: DictConfig, asked: int) -> optuna.samplers.BaseSampler:
    """The sampler a racing search asks its ``asked``-th configuration (from 0) of: seeded from
    (search.seed, asked) ([`sampler_seed`][kraby_study.run.sampling.sampler_seed]), so a resumed
    search, rebuilding it from the store, asks what an uninterrupted one would have. TPE is
    multivariate (one joint density over the space, not one per parameter: Falkner et al.
    2018); the GP and random samplers as in a search."""
    seed = sampler_seed(int(cfg.search.seed), asked)
    startup = int(cfg.search.startup_trials)
    if cfg.search.sampler == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    if cfg.search.sampler == "gp":
        return optuna.samplers.GPSampler(seed=seed, n_startup_trials=startup)
    # Multivariate TPE is experimental in Optuna: its warning would only alarm users.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        return optuna.samplers.TPESampler(seed=seed, n_startup_trials=startup,
                                          multivariate=True)


def make_pruner(cfg: DictConfig) -> optuna.pruners.BasePruner:
    """The pruner of a search; its steps are env steps.

    The wilcoxon pruner sees one value per seed, the seed's own score at the env steps of its
    end, so the same seed has the same step in every trial; it pairs a trial's seeds with the
    best trial's and prunes when the one-sided signed-rank test gives p < search.wilcoxon_p
    (and the trial's mean is below the best's). Its startup is the test's own: no fewer
    seeds than can reach that p (4 at 0.1), so a tie-corrected approximation cannot act
    sooner. It waits for no complete trials beyond the best one.
    """
    pruner = pruner_name(cfg)
    if pruner == "wilcoxon":
        p = float(cfg.search.wilcoxon_p)
        # Experimental in Optuna (since 3.6): its warning at construction would only alarm
        # users; store/store.py silences the same warning for heartbeats.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            return optuna.pruners.WilcoxonPruner(p_threshold=p,
                                                 n_startup_steps=wilcoxon_seeds(p))
    warmup = warmup_steps(cfg)
    if pruner == "median":
        return optuna.pruners.MedianPruner(n_startup_trials=int(cfg.search.pruner_startup_trials),
                                           n_warmup_steps=warmup)
    if pruner == "hyperband":
        total = int(cfg.budget.steps) * int(cfg.budget.seeds)
        return optuna.pruners.HyperbandPruner(min_resource=warmup, max_resource=total)
    return optuna.pruners.NopPruner()
