"""Typed configuration: the schema Hydra composes into, and the checks Hydra cannot express.

The dataclasses are registered in Hydra's ConfigStore, so a misspelt key or a value of the wrong
type fails while the config is composed. ``validate`` then refuses impossible values (a negative
learning rate, a batch size that does not divide the rollout, ...) before anything runs.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf


class ConfigError(ValueError):
    """A configuration a user gave that cannot be run; its message is one line."""


@dataclass
class EnvConfig:
    """The simulated leg: keyword arguments of ``kraby_envs.KrabyOneLegEnv``."""

    observation: str = "default"
    """Observation variant: default, with_tip, with_tip_to_target or sin_angles."""
    delta: float = 0.5
    """Size of the target box relative to the documented one (0..1)."""
    time_step: float = 0.05 / 12
    """Physics time step in seconds."""
    frameskip: int = 12
    """Physics sub-steps per environment step (control period = time_step x frameskip)."""
    max_episode_steps: int = 32
    """Episode length (a time limit, no terminal state)."""


@dataclass
class PPOConfig:
    """PPO settings in stable-baselines3's names."""

    n_envs: int = 32
    """Legs simulated side by side in one world."""
    n_steps: int = 128
    """Steps per leg per rollout; a rollout holds n_steps x n_envs transitions."""
    batch_size: int | None = None
    """Minibatch size; null means one minibatch of the whole rollout (nminibatches 1)."""
    n_epochs: int = 30
    """Passes over each rollout."""
    gamma: float = 0.9
    """Discount factor."""
    gae_lambda: float = 0.95
    """GAE bias-variance trade-off."""
    clip_range: float = 0.2
    """PPO clipping of the probability ratio."""
    ent_coef: float = 0.01
    """Entropy bonus weight."""
    vf_coef: float = 0.5
    """Value loss weight."""
    max_grad_norm: float = 0.5
    """Gradient clipping."""
    learning_rate: float = 1e-3
    """Adam step size (constant)."""
    net_arch: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layers of the policy and value networks (separate networks, same shape)."""
    activation: str = "tanh"
    """Hidden activation: tanh or relu."""


@dataclass
class StudyConfig:
    """A one-at-a-time sweep: one parameter, its values; the other settings come with the file."""

    name: str = MISSING
    """Name of the study in the store."""
    parameter: str = MISSING
    """Dotted path of the swept setting, e.g. ppo.ent_coef or env.observation."""
    values: list[Any] = MISSING
    """The values tried, in the order figures list them."""
    description: str = ""
    """What the study asks, shown by ``list`` and in reports."""


@dataclass
class BudgetConfig:
    """How much experience each training run gets."""

    name: str = "full"
    """Label of the budget."""
    steps: int = 250_000
    """Environment steps per training run (a run stops there, even inside a rollout)."""
    seeds: int = 10
    """Training runs (seeds) per value."""
    curve_every: int = 2048
    """Environment steps per learning-curve point."""


@dataclass
class ParamSpace:
    """The range of one searched setting."""

    path: str = MISSING
    """Dotted setting it sets (ppo.gamma, env.observation); ppo.nminibatches sets the batch size
    to n_steps x n_envs / nminibatches, so the batch always divides the rollout."""
    type: str = MISSING
    """float, int or categorical."""
    low: float | None = None
    """Lower bound (float and int)."""
    high: float | None = None
    """Upper bound, included (float and int)."""
    log: bool = False
    """Sample on a log scale (bounds must be > 0)."""
    choices: list[Any] | None = None
    """The values of a categorical parameter."""


@dataclass
class SearchConfig:
    """An Optuna search: the space, the sampler and pruner, and what is maximised."""

    name: str = "search"
    """Name of the study in the store."""
    trials: int = 50
    """Total trials of the study, over every invocation (a rerun tops it up to this number)."""
    sampler: str = "tpe"
    """tpe or random."""
    pruner: str = "median"
    """median, hyperband or none."""
    seed: int = 0
    """Seed of the sampler, stored with the study."""
    startup_trials: int = 5
    """Trials sampled at random before TPE starts."""
    pruner_startup_trials: int = 3
    """Complete trials the median pruner waits for: it compares with their values."""
    warmup: float = 0.5
    """Fraction of the first seed during which no trial is pruned: the first updates' reward
    says little about a configuration (it is mostly the untrained policy's)."""
    checkpoints: int = 4
    """Intervals of equal env steps in a trial's first seed; the mean reward of each but the
    last is an intermediate value (the pruner's steps), as is the mean score after each seed
    but the last."""
    objective: str = "final_reward"
    """final_reward: mean episode reward over the last 10 % of training; evaluation: mean
    reward of the deterministic policy on a fixed set of targets (reset options)."""
    eval_episodes: int = 16
    """Fixed targets of the evaluation objective."""
    params: dict[str, ParamSpace] = field(default_factory=dict)
    """The space: Optuna parameter name -> range."""


@dataclass
class KrabyConfig:
    """Everything a command needs: composed from conf/config.yaml and the command line."""

    env: EnvConfig = field(default_factory=EnvConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    budget: BudgetConfig = field(default_factory=BudgetConfig)
    study: StudyConfig | None = None
    search: SearchConfig = field(default_factory=SearchConfig)
    storage: str = "sqlite:///studies/kraby.db"
    """Database URL: a SQLite file (created on demand) or postgresql+psycopg://user@host/db."""
    workers: int | None = None
    """Worker processes; null means one per core."""
    physics_processes: int | None = None
    """Processes stepping each trial's legs; null: the cores the workers leave (cores // workers).
    Results are the same for any number."""
    heartbeat_interval: int = 5
    """PostgreSQL: seconds between heartbeats of a running trial."""
    heartbeat_grace: int = 30
    """PostgreSQL: a running trial silent this long is failed and queued again."""
    db_retry_seconds: int = 60
    """How long a command keeps retrying a database it lost before it gives up."""
    seed: int = 0
    """Seed of the first training run; run n of a study uses seed + n."""
    save_models: bool = True
    """Keep each trial's final model (SB3 zip) beside the store."""
    models_dir: str | None = None
    """Where models go; null: a folder named after the SQLite file (else studies/models)."""
    out: str = "reports"
    """Output folder of ``report``."""


def register_schema() -> None:
    """Register the schema so conf/config.yaml can build on it (idempotent)."""
    cs = ConfigStore.instance()
    cs.store(name="kraby_schema", node=KrabyConfig)


def rollout_size(ppo: PPOConfig | DictConfig) -> int:
    """Transitions collected per rollout: n_steps x n_envs."""
    return int(ppo.n_steps) * int(ppo.n_envs)


def resolved_batch_size(ppo: PPOConfig | DictConfig) -> int:
    """The minibatch size actually used (the whole rollout when batch_size is null)."""
    return rollout_size(ppo) if ppo.batch_size is None else int(ppo.batch_size)


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise ConfigError(message)


def _finite(name: str, value: float) -> None:
    _require(math.isfinite(value), f"{name} must be a finite number, got {value}")


def validate_ppo(ppo: PPOConfig | DictConfig, prefix: str = "ppo") -> None:
    """Refuse PPO settings stable-baselines3 could not train with."""
    for name in ("gamma", "gae_lambda", "clip_range", "ent_coef", "vf_coef", "max_grad_norm",
                 "learning_rate"):
        _finite(f"{prefix}.{name}", float(getattr(ppo, name)))
    for name in ("n_envs", "n_steps", "n_epochs"):
        value = int(getattr(ppo, name))
        _require(value >= 1, f"{prefix}.{name} must be at least 1, got {value}")
    _require(ppo.learning_rate > 0, f"{prefix}.learning_rate must be > 0, got {ppo.learning_rate}")
    _require(0 < ppo.gamma <= 1, f"{prefix}.gamma must be in (0, 1], got {ppo.gamma}")
    _require(0 <= ppo.gae_lambda <= 1,
             f"{prefix}.gae_lambda must be in [0, 1], got {ppo.gae_lambda}")
    _require(ppo.clip_range > 0, f"{prefix}.clip_range must be > 0, got {ppo.clip_range}")
    _require(ppo.ent_coef >= 0, f"{prefix}.ent_coef must be >= 0, got {ppo.ent_coef}")
    _require(ppo.vf_coef >= 0, f"{prefix}.vf_coef must be >= 0, got {ppo.vf_coef}")
    _require(ppo.max_grad_norm > 0,
             f"{prefix}.max_grad_norm must be > 0, got {ppo.max_grad_norm}")
    _require(len(ppo.net_arch) >= 1 and all(int(w) >= 1 for w in ppo.net_arch),
             f"{prefix}.net_arch must list at least one positive layer width, got "
             f"{list(ppo.net_arch)}")
    _require(ppo.activation in ("tanh", "relu"),
             f"{prefix}.activation must be tanh or relu, got {ppo.activation!r}")
    rollout = rollout_size(ppo)
    if ppo.batch_size is not None:
        batch = int(ppo.batch_size)
        _require(batch >= 2, f"{prefix}.batch_size must be at least 2, got {batch}")
        _require(rollout % batch == 0,
                 f"{prefix}.batch_size {batch} does not divide the rollout n_steps x n_envs = "
                 f"{ppo.n_steps} x {ppo.n_envs} = {rollout}")
    else:
        _require(rollout >= 2, f"the rollout n_steps x n_envs must hold at least 2 steps, got "
                 f"{rollout}")


def validate_env(env: EnvConfig | DictConfig) -> None:
    """Refuse environment settings the leg does not accept (checked without a physics client)."""
    from kraby_envs import validate_env_kwargs

    try:
        validate_env_kwargs(**env_kwargs(env))
    except ValueError as err:
        raise ConfigError(f"env: {err}") from None
    _require(int(env.max_episode_steps) >= 1,
             f"env.max_episode_steps must be at least 1, got {env.max_episode_steps}")


def env_kwargs(env: EnvConfig | DictConfig) -> dict[str, Any]:
    """Keyword arguments of the leg environment (the time limit is passed separately)."""
    return {
        "observation": str(env.observation),
        "delta": float(env.delta),
        "time_step": float(env.time_step),
        "frameskip": int(env.frameskip),
    }


def validate_budget(budget: BudgetConfig | DictConfig) -> None:
    """Refuse budgets that cannot give a learning curve."""
    _require(int(budget.steps) >= 1, f"budget.steps must be at least 1, got {budget.steps}")
    _require(int(budget.seeds) >= 1, f"budget.seeds must be at least 1, got {budget.seeds}")
    _require(int(budget.curve_every) >= 1,
             f"budget.curve_every must be at least 1, got {budget.curve_every}")


def validate_storage(url: str) -> None:
    """Refuse database URLs other than SQLite and PostgreSQL ones."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        parsed = make_url(url)
    except ArgumentError:
        raise ConfigError(f"storage {url!r} is not a database URL (e.g. sqlite:///studies/"
                          "kraby.db or postgresql+psycopg://user@host/db)") from None
    backend = parsed.get_backend_name()
    _require(backend in ("sqlite", "postgresql"),
             f"storage {url!r}: only sqlite and postgresql databases are supported")
    if backend == "sqlite":
        _require(bool(parsed.database) and parsed.database != ":memory:",
                 f"storage {url!r}: a SQLite store must be a file")


def validate(cfg: DictConfig) -> None:
    """Check a composed config as a whole: every value a command could use."""
    validate_env(cfg.env)
    validate_ppo(cfg.ppo)
    validate_budget(cfg.budget)
    validate_storage(cfg.storage)
    for name in ("heartbeat_interval", "heartbeat_grace", "db_retry_seconds"):
        _require(int(cfg[name]) >= 1, f"{name} must be at least 1, got {cfg[name]}")
    _require(cfg.heartbeat_grace > cfg.heartbeat_interval,
             f"heartbeat_grace ({cfg.heartbeat_grace}) must exceed heartbeat_interval "
             f"({cfg.heartbeat_interval})")
    for name in ("workers", "physics_processes"):
        if cfg[name] is not None:
            _require(int(cfg[name]) >= 1, f"{name} must be at least 1, got {cfg[name]}")
    _require(int(cfg.seed) >= 0, f"seed must be >= 0, got {cfg.seed}")


def cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def worker_count(cfg: DictConfig) -> int:
    """Worker processes to use: the configured number, or one per core."""
    return int(cfg.workers) if cfg.workers is not None else cores()


def sqlite_path(url: str) -> Path | None:
    """The file behind a SQLite URL, or None for other databases."""
    from sqlalchemy.engine import make_url

    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return None
    return Path(str(parsed.database))


def to_container(cfg: DictConfig | Any) -> Any:
    """A plain, JSON-ready copy of a config node."""
    return OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else cfg
