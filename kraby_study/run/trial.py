"""One trial: TrialSpec -> stable-baselines3 PPO on the batched leg world -> TrialResult.

A trial never touches the database; the runner records what it returns.
"""

from __future__ import annotations

import math
import resource
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kraby_study.env import adapter_for, normalizer_path
from kraby_study.errors import first_line
from kraby_study.plan.spec import TrialSpec, ppo_setting
from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Failure, Outcome, failure
from kraby_study.run.curve import Episode, bin_curve, final_score, mean_curve

if TYPE_CHECKING:
    from kraby_study.run.callback import (
        CheckpointHook,
        EpisodeRecorder,
        ProgressHook,
        TrialProgress,
    )


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def cpu_seconds() -> float:
    """CPU seconds (user + system) used so far by this process and its ended children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _has_nan(model: Any) -> bool:
    import torch

    return any(not bool(torch.isfinite(p).all()) for p in model.policy.parameters())


def _is_divergence(err: BaseException) -> bool:
    text = str(err).lower()
    return "nan" in text or "invalid values" in text or "inf" in text.split()


def build_model(spec: TrialSpec, env: Any, seed: int, logs: Path | None = None) -> Any:
    """The PPO learner of a spec on a given vectorised environment; with ``logs``, SB3 writes
    what it logs (rollout reward, losses, fps) there as TensorBoard events."""
    import torch
    from stable_baselines3 import PPO

    ppo = spec.settings["ppo"]
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[ppo["activation"]]
    arch = list(ppo["net_arch"])
    policy_kwargs: dict[str, Any] = {"net_arch": {"pi": arch, "vf": arch},
                                     "activation_fn": activation}
    # Only settings away from SB3's defaults are passed: SB3 keeps its own default otherwise.
    for name in ("ortho_init", "log_std_init"):
        if name in ppo:
            policy_kwargs[name] = ppo[name]
    extra = {name: ppo[name] for name in ("use_sde", "sde_sample_freq") if name in ppo}
    model = PPO(
        "MlpPolicy", env, n_steps=ppo["n_steps"], batch_size=ppo["batch_size"],
        n_epochs=ppo["n_epochs"], gamma=ppo["gamma"], gae_lambda=ppo["gae_lambda"],
        clip_range=schedule(ppo["clip_range"], ppo_setting(ppo, "clip_range_schedule")),
        ent_coef=ppo["ent_coef"], vf_coef=ppo["vf_coef"], max_grad_norm=ppo["max_grad_norm"],
        learning_rate=schedule(ppo["learning_rate"], ppo_setting(ppo, "learning_rate_schedule")),
        policy_kwargs=policy_kwargs, seed=seed, device="cpu", verbose=0, **extra)
    model.set_logger(sb3_logger(logs))
    return model


def schedule(value: float, kind: str) -> Any:
    """A setting as SB3 takes it: the number itself (constant), or a function of the progress
    remaining (1 at the start, 0 at the end) going linearly from the number to 0 (linear,
    rl-zoo3's ``lin_<number>``)."""
    if kind == "constant":
        return value
    from stable_baselines3.common.utils import LinearSchedule

    return LinearSchedule(start=float(value), end=0.0, end_fraction=1.0)


def sb3_logger(logs: Path | None) -> Any:
    """SB3's logger of a run: TensorBoard events in ``logs``, or no output at all.

    Without outputs rather than SB3's default, which makes an empty folder in /tmp per model.
    """
    from stable_baselines3.common.logger import Logger, TensorBoardOutputFormat

    if logs is None:
        return Logger(folder=None, output_formats=[])
    return Logger(folder=str(logs), output_formats=[TensorBoardOutputFormat(str(logs))])


def tensorboard_folder(run: str, seed: int) -> Path:
    """A new folder ``<run>-seed<seed>`` for one seed's TensorBoard logs, made here.

    Made exclusively: when an earlier attempt of the run (a retry, an interrupted trial run
    again) left that folder, the next free ``-attempt2``, ``-attempt3``, ... is taken, so no
    two runs ever write into one folder and TensorBoard shows each attempt apart.
    """
    base = Path(f"{run}-seed{seed}")
    base.parent.mkdir(parents=True, exist_ok=True)
    attempt = 1
    while True:
        folder = base if attempt == 1 else base.with_name(f"{base.name}-attempt{attempt}")
        try:
            folder.mkdir()
        except FileExistsError:
            attempt += 1
            continue
        return folder


def make_env(spec: TrialSpec, seed: int, shards: int = 1) -> Any:
    """The vectorised env of a spec ([`kraby_study.env`][]): n_envs envs stepped in ``shards``
    processes where the env allows, each on its own stream of ``seed`` by the
    spec's seeding scheme."""
    env = spec.settings["env"]
    return adapter_for(env).make_vec(env, int(spec.settings["ppo"]["n_envs"]), seed,
                                     spec.seeding, shards=shards,
                                     gamma=float(spec.settings["ppo"]["gamma"]))


def normalizer_of(env: Any) -> Any:
    """The VecNormalize of a vectorised env, or None."""
    from stable_baselines3.common.vec_env import VecNormalize

    return env if isinstance(env, VecNormalize) else None


@dataclass
class _Seed:
    """One training run of a trial (one seed)."""

    episodes: list[Episode] = field(default_factory=list)
    env_steps: int = 0
    failure: str | None = None
    pruned_at: int | None = None
    score: float | None = None
    train_reward: float | None = None
    eval_error: float | None = None
    """The standard error of an evaluation score from its episodes."""
    eval_sd: float | None = None
    """The sd of the returns of its evaluation episodes (NaN below 2 episodes)."""
    model: Any = None
    normalizer: Any = None
    """The run's VecNormalize (its statistics as training left them), or None."""


def _learn(spec: TrialSpec, seed: int, recorder: EpisodeRecorder, shards: int) -> _Seed:
    """Train one seed with the recorder as callback; divergence and errors are noted."""
    run = _Seed()
    logs = tensorboard_folder(spec.tensorboard_run, seed) if spec.tensorboard_run else None
    env = make_env(spec, seed, shards)
    run.normalizer = normalizer_of(env)
    try:
        run.model = build_model(spec, env, seed, logs)
        run.model.learn(total_timesteps=spec.steps, callback=recorder)
        if _has_nan(run.model):
            run.failure = failure(Failure.DIVERGED, "the policy's parameters became NaN")
    except (ValueError, RuntimeError, FloatingPointError) as err:
        kind = Failure.DIVERGED if _is_divergence(err) else Failure.ERROR
        run.failure = failure(kind, f"{type(err).__name__}: {first_line(err)[:300]}")
    finally:
        env.close()
        if run.model is not None:
            run.model.logger.close()  # writes out the last TensorBoard events
    run.episodes = recorder.episodes
    run.pruned_at = recorder.pruned_at
    run.env_steps = int(run.model.num_timesteps) if run.model is not None else 0
    return run


def _score(spec: TrialSpec, run: _Seed, seed: int) -> None:
    """The final score of the seed ``seed`` that trained to its end."""
    run.train_reward = final_score(run.episodes, run.env_steps)
    if spec.objective == "evaluation":
        env = spec.settings["env"]
        # Each seed's own test set (eval_set run), or the one every run shared before.
        own = seed if spec.eval_set == "run" else None
        evaluation = adapter_for(env).evaluate(run.model, env, spec.eval_episodes,
                                               run.normalizer, seed=own)
        run.score, run.eval_error = evaluation.mean, evaluation.error
        returns = np.asarray(evaluation.returns, dtype=float)
        run.eval_sd = float(np.std(returns, ddof=1)) if len(returns) > 1 else math.nan
    else:
        run.score = run.train_reward
    if run.score is None or not math.isfinite(run.score):
        run.failure = failure(Failure.ERROR, "no finite score (no episode ended in the last "
                                             "10 %)")


def run_trial(spec: TrialSpec, on_checkpoint: CheckpointHook | None = None,
              on_progress: TrialProgress | None = None, shards: int = 1) -> TrialResult:
    """Train PPO as the spec says; divergence and errors come back as a failed result.

    A spec of several seeds trains seeds seed .. seed + seeds - 1 one after the other. Its
    intermediate values (searches) are the mean episode reward every ``checkpoint_every`` env
    steps of the first seed, then, at the end of each seed but the last, the mean score of the
    seeds so far; steps count across seeds. So a pruner compares trials at equal experience, and
    can stop a bad configuration during or after its first seed. (Within later seeds a learning
    curve starts again from scratch and would compare with the others' first-seed curves.)
    With ``seed_scores`` (the wilcoxon pruner) they are instead each seed's own score at the
    env steps of its end, every seed's, so a complete trial holds all its seeds for later trials
    to be paired with; a stop after the last seed has nothing left to save and is not taken.
    ``on_progress`` hears the env steps done and the CPU seconds used so far (a search's CPU
    budget counts running trials by it). ``shards`` sets how many processes step the legs: speed
    only, the result is the same.
    """
    from kraby_study.run.callback import EpisodeRecorder

    started = _now()
    t0 = time.perf_counter()
    cpu0 = cpu_seconds()

    progress = None if on_progress is None else _with_cpu(on_progress, cpu0)

    runs: list[_Seed] = []
    for index in range(spec.seeds):
        within = spec.checkpoint_every if index == 0 and not spec.seed_scores else None
        recorder = EpisodeRecorder(spec.steps, offset=index * spec.steps,
                                   checkpoint_every=within, on_checkpoint=on_checkpoint,
                                   on_progress=progress)
        run = _learn(spec, spec.seed + index, recorder, shards)
        runs.append(run)
        if run.failure is None and run.pruned_at is None:
            _score(spec, run, spec.seed + index)
        if run.failure is not None or run.pruned_at is not None:
            break
        if on_checkpoint is not None and _stopped_after(spec, runs, on_checkpoint):
            break
    return _result(spec, runs, started, time.perf_counter() - t0, cpu_seconds() - cpu0)


def _with_cpu(on_progress: TrialProgress, cpu0: float) -> ProgressHook:
    """The recorder's progress hook: the env steps done, with the CPU seconds used since
    ``cpu0``."""

    def progress(steps: int) -> None:
        on_progress(steps, cpu_seconds() - cpu0)

    return progress


def _stopped_after(spec: TrialSpec, runs: list[_Seed], on_checkpoint: CheckpointHook) -> bool:
    """Report the intermediate value at the end of the latest seed, if there is one; True
    when the pruner stops the trial there (never after the last seed)."""
    step = len(runs) * spec.steps
    last = len(runs) == spec.seeds
    if spec.seed_scores:
        go_on = on_checkpoint(step, float(runs[-1].score))  # type: ignore[arg-type]
    elif spec.checkpoint_every and not last:
        go_on = on_checkpoint(step, float(np.mean([r.score for r in runs])))
    else:
        return False
    if go_on or last:
        return False
    runs[-1].pruned_at = step
    return True


def _result(spec: TrialSpec, runs: list[_Seed], started: str, seconds: float,
            cpu: float) -> TrialResult:
    """The trial's result from its seeds; the best seed's model is saved if asked."""
    last = runs[-1]
    result = TrialResult(
        outcome=Outcome.COMPLETE,
        curve=mean_curve([bin_curve(r.episodes, spec.curve_every) for r in runs]),
        env_steps=sum(r.env_steps for r in runs), wall_time=seconds, cpu_time=cpu,
        started=started, ended=_now())
    if last.failure is not None:
        result.outcome, result.failure = Outcome.FAILED, last.failure
    elif last.pruned_at is not None:
        result.outcome, result.pruned_at = Outcome.PRUNED, last.pruned_at
    else:
        result.scores = [float(r.score) for r in runs]  # type: ignore[arg-type]
        result.final_score = float(np.mean(result.scores))
        rewards = [r.train_reward for r in runs if r.train_reward is not None]
        result.train_reward = float(np.mean(rewards)) if rewards else None
        if spec.objective == "evaluation":
            result.eval_errors = [float(r.eval_error) for r in runs  # type: ignore[arg-type]
                                  if r.eval_error is not None]
            result.eval_sds = [float(r.eval_sd) for r in runs  # type: ignore[arg-type]
                               if r.eval_sd is not None]
        if spec.model_path:
            best = max(runs, key=lambda r: float(r.score or -math.inf))
            Path(spec.model_path).parent.mkdir(parents=True, exist_ok=True)
            best.model.save(spec.model_path)
            if best.normalizer is not None:
                # Evaluation and the report's GIF need the observation statistics too.
                best.normalizer.save(str(normalizer_path(spec.model_path)))
    return result
