"""The checks Hydra cannot express: values a command could not run with, refused in one line."""

from __future__ import annotations

import importlib.util
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from kraby_study.config.schema import PPOConfig
from kraby_study.env import adapter_for, check_scheme
from kraby_study.errors import ConfigError
from kraby_study.records.attributes import SelectRule
from kraby_study.records.definition import EVAL_SETS, FINAL_FRACTION, REWARDS
from kraby_study.records.values import ANSWER_FROM
from kraby_study.store.url import check_url


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
                 "learning_rate", "log_std_init"):
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
    for name in ("learning_rate_schedule", "clip_range_schedule"):
        value = getattr(ppo, name)
        _require(value in SCHEDULES,
                 f"{prefix}.{name} must be one of {', '.join(SCHEDULES)}, got {value!r}")
    _require(int(ppo.sde_sample_freq) >= -1,
             f"{prefix}.sde_sample_freq must be -1 (once per rollout) or a number of steps, got "
             f"{ppo.sde_sample_freq}")
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


SCHEDULES = ("constant", "linear")
"""How learning_rate and clip_range move over training: fixed, or linearly down to 0."""


def validate_env(env: DictConfig, ppo: PPOConfig | DictConfig | None = None) -> None:
    """Refuse environment settings its adapter does not accept (and, given the ppo settings,
    PPO settings its spaces cannot take), without training anything."""
    adapter_for(env).validate(env, ppo)


def validate_budget(budget: DictConfig) -> None:
    """Refuse budgets that cannot give a learning curve."""
    _require(int(budget.steps) >= 1, f"budget.steps must be at least 1, got {budget.steps}")
    _require(int(budget.seeds) >= 1, f"budget.seeds must be at least 1, got {budget.seeds}")
    _require(int(budget.curve_every) >= 1,
             f"budget.curve_every must be at least 1, got {budget.curve_every}")


RUN_LENGTH = ("ppo.n_envs", "env.max_episode_steps")
"""The settings beside budget.steps that decide whether a run can be scored
([`validate_run_length`][kraby_study.config.validate.validate_run_length])."""


def steps_per_env(steps: int, n_envs: int) -> int:
    """The steps each env of a run takes: SB3 steps all ``n_envs`` at once, and a run stops at
    the first step at or past its budget of ``steps``
    ([`EpisodeRecorder`][kraby_study.run.callback.EpisodeRecorder])."""
    return -(-int(steps) // int(n_envs))


def scores_a_full_episode(steps: int, n_envs: int, limit: int) -> bool:
    """Whether a run of ``steps`` on ``n_envs`` envs can score an episode of ``limit`` steps:
    one of each env's episodes of exactly that length, back to back from its first step,
    ends in the last [`FINAL_FRACTION`][kraby_study.records.definition.FINAL_FRACTION] of the run,
    as [`final_score`][kraby_study.run.curve.final_score] counts them (at the same env step)."""
    per_env = steps_per_env(steps, n_envs)
    last_end = (per_env // limit) * limit * n_envs
    return last_end > per_env * n_envs * (1.0 - FINAL_FRACTION)


def validate_run_length(env: Any, ppo: Any, steps: int, objective: str = REWARDS[0],
                        where: str = "", fixed_steps: bool = False) -> None:
    """Refuse a run whose last 10 % cannot hold the end of an episode of the env's full time
    limit, when that is where its score comes from (the final_reward objective).

    The final score is the mean reward of the episodes that end in the run's last 10 % of
    steps. An env that only truncates (the leg, Pendulum-v1) ends every episode at its time
    limit, so such a run would score nothing and fail "no finite score" after all its work.
    An env that also terminates (CartPole-v1) ends some episodes earlier, but those are the
    episodes it fails: a configuration that has learnt to last would be scored by its
    failures, or not at all. Which kind an id is cannot be known before it runs, so the rule
    is the same for both. Runs of at least 10 time limits per env always pass; an env
    without a time limit is not checked. The evaluation objective scores the policy on
    evaluation episodes instead, so its runs are not refused (their training reward is then
    stored only when an episode ended late enough).

    Args:
        env: The run's env settings.
        ppo: Its PPO settings (n_envs, and n_steps and batch_size for another n_envs).
        steps: Its budget in env steps.
        objective: How it is scored
            ([`REWARDS`][kraby_study.records.definition.REWARDS]).
        where: What the message names first (a study's value, a confirm's configuration).
        fixed_steps: The steps are not the command's budget.steps (a confirm retrains at the
            confirmed study's): only another n_envs is offered.
    """
    if objective != REWARDS[0]:
        return
    adapter = adapter_for(env)
    limit = adapter.time_limit(env)
    n_envs = int(ppo["n_envs"])
    if limit is None or scores_a_full_episode(steps, n_envs, limit):
        return
    per_env = steps_per_env(steps, n_envs)
    whose = "the leg's" if adapter.kind == "leg" else f"{env['id']}'s"
    first = math.floor(per_env * (1.0 - FINAL_FRACTION)) + 1
    enough = -(-per_env // limit) * limit * n_envs
    other = _other_n_envs(ppo, steps, limit)
    offers = [] if fixed_steps else [f"budget.steps={enough} (or any from "
                                     f"{10 * limit * n_envs} on) with ppo.n_envs={n_envs}"]
    if other is not None:
        offers.append(f"ppo.n_envs={other}" + ("" if fixed_steps else
                                               f" with budget.steps={steps}"))
    raise ConfigError(
        f"{where}{'' if fixed_steps else 'budget.steps='}{steps}"
        f"{' steps' if fixed_steps else ''} with ppo.n_envs={n_envs} is {per_env} steps per "
        f"env, and no episode of the full {limit} steps ({whose} time limit) can end in the "
        f"last 10 % of them (steps {first}-{per_env}), where the final score is taken"
        + (f": give {', or '.join(offers)}" if offers else ""))


def _other_n_envs(ppo: Any, steps: int, limit: int) -> int | None:
    """The n_envs nearest the given one (the smaller first, at most twice it) with which a run
    of ``steps`` scores a full episode and the rollout n_steps x n_envs still splits into its
    batches (when n_steps is known)."""
    n_envs, n_steps, batch = int(ppo["n_envs"]), ppo.get("n_steps"), ppo.get("batch_size")
    for distance in range(1, n_envs + 1):
        for other in (n_envs - distance, n_envs + distance):
            if other < 1 or not scores_a_full_episode(steps, other, limit):
                continue
            if n_steps is None:  # not known yet (a campaign stage's earlier winner)
                return other
            rollout = int(n_steps) * other
            if rollout % (int(batch) if batch is not None else 1) == 0 and rollout >= 2:
                return other
    return None


def validate(cfg: DictConfig) -> None:
    """Check a composed config as a whole: every value a command could use."""
    validate_ppo(cfg.ppo)
    validate_env(cfg.env, cfg.ppo)
    validate_budget(cfg.budget)
    check_url(cfg.storage)
    for name in ("heartbeat_interval", "heartbeat_grace", "db_retry_seconds"):
        _require(int(cfg[name]) >= 1, f"{name} must be at least 1, got {cfg[name]}")
    _require(cfg.heartbeat_grace > cfg.heartbeat_interval,
             f"heartbeat_grace ({cfg.heartbeat_grace}) must exceed heartbeat_interval "
             f"({cfg.heartbeat_interval})")
    for name in ("workers", "shards"):
        if cfg[name] is not None:
            _require(int(cfg[name]) >= 1, f"{name} must be at least 1, got {cfg[name]}")
    validate_executor(cfg)
    validate_tensorboard(cfg)
    _require(int(cfg.seed) >= 0, f"seed must be >= 0, got {cfg.seed}")
    if cfg.seeding is not None:
        try:
            check_scheme(str(cfg.seeding))
        except ValueError as err:
            raise ConfigError(f"{err} (or null: a stored study's own)") from None
    if cfg.search.eval_episodes is not None:
        _require(int(cfg.search.eval_episodes) >= 2,
                 f"search.eval_episodes must be at least 2 (a standard error needs two), got "
                 f"{cfg.search.eval_episodes}")
    if cfg.search.eval_set is not None:
        _require(cfg.search.eval_set in EVAL_SETS,
                 f"search.eval_set must be one of {', '.join(EVAL_SETS)} (or null: a stored "
                 f"study's own), got {cfg.search.eval_set!r}")
    if cfg.confirm.name is not None:
        _require(bool(str(cfg.confirm.name).strip()),
                 "confirm.name must name a study (or be null for the default name)")
    if cfg.confirm.seed is not None:
        _require(int(cfg.confirm.seed) >= 0,
                 f"confirm.seed must be >= 0, got {cfg.confirm.seed}")
    _require(int(cfg.report.bootstrap) >= 100,
             f"report.bootstrap must be at least 100 resamples, got {cfg.report.bootstrap}")
    _require(int(cfg.report.min_seeds) >= 2,
             f"report.min_seeds must be at least 2 (a test needs two seeds), got "
             f"{cfg.report.min_seeds}")
    _require(int(cfg.confirm.top) >= 1, f"confirm.top must be at least 1, got {cfg.confirm.top}")
    _require(int(cfg.confirm.seeds) >= 2,
             f"confirm.seeds must be at least 2 (an interval needs two), got {cfg.confirm.seeds}")
    validate_racing(cfg.racing)
    margin = float(cfg.compare.margin)
    _require(math.isfinite(margin) and margin >= 0,
             f"compare.margin must be at least 0 (a fraction of the best's |IQM|), got "
             f"{cfg.compare.margin}")
    _require(margin <= 1, f"compare.margin is a fraction of the best's |IQM|: at most 1, got "
             f"{cfg.compare.margin}")
    if cfg.compare.select is not None:
        SelectRule.check(str(cfg.compare.select), "compare.select")
    if cfg.report.threshold is not None:
        _finite("report.threshold", float(cfg.report.threshold))
    if cfg.report.threshold is not None and adapter_for(cfg.env).kind == "leg":
        # The leg's reward is minus a squared distance: no episode scores above 0.
        _require(float(cfg.report.threshold) <= 0.0,
                 f"report.threshold must be at most 0, the leg's highest possible episode "
                 f"reward (minus a squared distance), got {cfg.report.threshold}")
    if cfg.study is not None:
        SelectRule.check(str(cfg.study.select))
    if cfg.campaign is not None:
        for stage in cfg.campaign.stages:
            if stage.select is not None:
                SelectRule.check(str(stage.select), f"campaign stage {stage.study}: select")


def validate_racing(racing: DictConfig, seeds: int | None = None,
                    where: str = "budget.seeds") -> None:
    """A race's settings hold together: alpha in (0, 0.5], min_seeds at least
    [`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM] (no answer below) and, when racing with
    ``seeds`` the most seeds a value gets (named ``where``), at most that."""
    alpha = float(racing.alpha)
    _require(0 < alpha <= 0.5, f"racing.alpha must be in (0, 0.5], got {racing.alpha}")
    _require(str(racing.below) in BELOW_RULES,
             f"racing.below must be one of {', '.join(BELOW_RULES)}, got {racing.below!r}")
    _require(int(racing.min_seeds) >= ANSWER_FROM,
             f"racing.min_seeds must be at least {ANSWER_FROM} (no value is answered worse or "
             f"equivalent with fewer seeds), got {racing.min_seeds}")
    if racing.enabled and seeds is not None:
        _require(int(racing.min_seeds) <= seeds,
                 f"racing.min_seeds ({racing.min_seeds}) must not exceed {where} ({seeds}), "
                 "the most seeds a value gets")


BELOW_RULES = ("cap", "look")
"""When a racing search's challenger below the incumbent on their common seeds leaves."""

EXECUTORS = ("local", "ray")


def validate_executor(cfg: DictConfig) -> None:
    """The executor is known, and Ray is installed when it is asked for."""
    _require(str(cfg.executor) in EXECUTORS,
             f"executor must be one of {', '.join(EXECUTORS)}, got {cfg.executor!r}")
    if cfg.ray.cpus_per_trial is not None:
        _require(int(cfg.ray.cpus_per_trial) >= 1,
                 f"ray.cpus_per_trial must be at least 1, got {cfg.ray.cpus_per_trial}")
    _require(int(cfg.ray.start_seconds) >= 1,
             f"ray.start_seconds must be at least 1, got {cfg.ray.start_seconds}")
    if cfg.executor == "ray":
        _require(importlib.util.find_spec("ray") is not None,
                 "executor=ray needs Ray, which is not installed: pip install "
                 "'kraby-study[ray]'")


def validate_tensorboard(cfg: DictConfig) -> None:
    """A TensorBoard folder, when one is asked for, is a folder name, and TensorBoard (which
    SB3's tensorboard logger writes with) is installed."""
    if cfg.tensorboard_dir is None:
        return
    _require(str(cfg.tensorboard_dir).strip() != "",
             "tensorboard_dir must name a folder (or be null for no TensorBoard logs)")
    folder = Path(str(cfg.tensorboard_dir)).expanduser()
    _require(not folder.exists() or folder.is_dir(), f"tensorboard_dir {folder} is a file")
    _require(importlib.util.find_spec("tensorboard") is not None,
             "tensorboard_dir needs TensorBoard, which is not installed: pip install "
             "'kraby-study[tensorboard]'")


def check_writable(folder: Path, name: str) -> None:
    """Refuse a folder that cannot be made or written, in one line: the folders missing on
    the way are made for the check, a file is written and removed, and what was made is
    removed again."""
    missing = []
    existing = folder
    while not existing.exists():
        missing.append(existing)
        if existing.parent == existing:
            break
        existing = existing.parent
    _require(existing.is_dir(), f"{name} {folder}: {existing} is a file")
    made: list[Path] = []
    try:
        for path in reversed(missing):
            path.mkdir()
            made.append(path)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise ConfigError(f"{name} {folder} cannot be written: "
                          f"{err.strerror or type(err).__name__}") from None
    finally:
        for path in reversed(made):
            path.rmdir()


def cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def to_container(cfg: DictConfig | Any) -> Any:
    """A plain, JSON-ready copy of a config node."""
    return OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else cfg
