"""One training run: TrialSpec -> stable-baselines3 PPO on the batched leg world -> TrialResult.

A trial never touches the database; the runner records what it returns.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from kraby_study.messages import first_line
from kraby_study.spec import TrialSpec

FINAL_FRACTION = 0.1
"""The final score averages the episodes that end in this last fraction of training."""

CheckpointHook = Callable[[int, float], bool]
"""Called with (env steps, intermediate value); False stops the run (a pruner's decision)."""
ProgressHook = Callable[[int], None]
"""Called now and then with the env steps done so far."""


@dataclass(frozen=True)
class CurvePoint:
    """Mean reward of the episodes that ended in one bin of environment steps."""

    step: int
    """Environment steps at the end of the bin."""
    mean_reward: float
    """Mean episode reward (sum over the episode's steps) of the bin's episodes."""
    wall_time: float
    """Seconds since training started, when the bin's last episode ended."""
    episodes: int
    """Episodes that ended in the bin."""


@dataclass
class TrialResult:
    """What a run gives back: its curve, timings, final score and how it ended."""

    key: str
    status: str
    """complete, failed or pruned."""
    curve: list[CurvePoint] = field(default_factory=list)
    final_score: float | None = None
    env_steps: int = 0
    wall_time: float = 0.0
    started: str = ""
    ended: str = ""
    failure: str | None = None
    """Why a failed run failed (diverged: ... for NaN losses or parameters)."""
    pruned_at: int | None = None
    """Environment steps at which a pruner stopped the run."""
    train_reward: float | None = None
    """Mean episode reward over the last 10 % of training (the final score unless the objective
    is an evaluation)."""
    checkpoints: list[tuple[int, float]] = field(default_factory=list)


def bin_curve(episodes: list[tuple[int, float, float]], every: int) -> list[CurvePoint]:
    """Average (end step, reward, wall time) episodes into bins of ``every`` env steps."""
    bins: dict[int, list[tuple[int, float, float]]] = {}
    for episode in episodes:
        bins.setdefault((episode[0] - 1) // every, []).append(episode)
    return [
        CurvePoint(step=(index + 1) * every,
                   mean_reward=float(np.mean([e[1] for e in members])),
                   wall_time=max(e[2] for e in members), episodes=len(members))
        for index, members in sorted(bins.items())
    ]


def final_score(episodes: list[tuple[int, float, float]], total_steps: int) -> float | None:
    """Mean episode reward over the last 10 % of training (None if no episode ended there)."""
    start = total_steps * (1.0 - FINAL_FRACTION)
    late = [e[1] for e in episodes if e[0] > start]
    return float(np.mean(late)) if late else None


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _has_nan(model: Any) -> bool:
    import torch

    return any(not bool(torch.isfinite(p).all()) for p in model.policy.parameters())


def _is_divergence(err: BaseException) -> bool:
    text = str(err).lower()
    return "nan" in text or "invalid values" in text or "inf" in text.split()


def build_model(spec: TrialSpec, env: Any, seed: int) -> Any:
    """The PPO learner of a spec on a given vectorised environment."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    ppo = spec.settings["ppo"]
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[ppo["activation"]]
    arch = list(ppo["net_arch"])
    model = PPO(
        "MlpPolicy", env, n_steps=ppo["n_steps"], batch_size=ppo["batch_size"],
        n_epochs=ppo["n_epochs"], gamma=ppo["gamma"], gae_lambda=ppo["gae_lambda"],
        clip_range=ppo["clip_range"], ent_coef=ppo["ent_coef"], vf_coef=ppo["vf_coef"],
        max_grad_norm=ppo["max_grad_norm"], learning_rate=ppo["learning_rate"],
        policy_kwargs={"net_arch": {"pi": arch, "vf": arch}, "activation_fn": activation},
        seed=seed, device="cpu", verbose=0)
    # A logger with no outputs: SB3's default one makes an empty folder in /tmp per model.
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def make_env(spec: TrialSpec, seed: int, processes: int = 1) -> Any:
    """The batched world of a spec: n_envs legs stepped in ``processes`` processes."""
    from kraby_envs import make_batched

    env = dict(spec.settings["env"])
    max_steps = int(env.pop("max_episode_steps"))
    return make_batched(n_envs=int(spec.settings["ppo"]["n_envs"]), seed=seed,
                        max_episode_steps=max_steps, processes=processes, **env)


@dataclass
class _Run:
    """One training run of a trial (one seed)."""

    episodes: list[tuple[int, float, float]] = field(default_factory=list)
    env_steps: int = 0
    failure: str | None = None
    pruned_at: int | None = None
    score: float | None = None
    train_reward: float | None = None
    model: Any = None


def _train(spec: TrialSpec, seed: int, offset: int, on_checkpoint: CheckpointHook | None,
           on_progress: ProgressHook | None, checkpoints: list[tuple[int, float]] | None,
           physics_processes: int) -> _Run:
    """Train one seed; progress steps count from ``offset`` (earlier seeds).

    With ``checkpoints`` (a list to fill), the mean episode reward since the last checkpoint is
    reported every ``spec.checkpoint_every`` env steps before the end of the run.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    run = _Run()
    t0 = time.perf_counter()

    class Recorder(BaseCallback):
        """Collects finished episodes; reports checkpoints and progress; stops when pruned."""

        def __init__(self) -> None:
            super().__init__()
            self.next_checkpoint = spec.checkpoint_every or 0
            self.window_start = 0
            self.last_progress = 0.0

        def _on_step(self) -> bool:
            now = time.perf_counter() - t0
            for info in self.locals["infos"]:
                episode = info.get("episode")
                if episode is not None:
                    run.episodes.append((self.num_timesteps, float(episode["r"]), now))
            if on_progress is not None and now - self.last_progress >= 1.0:
                self.last_progress = now
                on_progress(offset + self.num_timesteps)
            if (checkpoints is not None and spec.checkpoint_every
                    and spec.steps > self.num_timesteps >= self.next_checkpoint):
                if not self._checkpoint():
                    return False
            # SB3 trains in whole rollouts; stopping here gives every run the same experience
            # (the unfinished rollout is not learnt from).
            return self.num_timesteps < spec.steps

        def _checkpoint(self) -> bool:
            step = self.num_timesteps
            recent = [e[1] for e in run.episodes[self.window_start:]]
            self.window_start = len(run.episodes)
            while self.next_checkpoint <= step:
                self.next_checkpoint += int(spec.checkpoint_every or 1)
            if not recent:
                return True
            # Report at the boundary crossed, so every trial reports at the same steps.
            every = int(spec.checkpoint_every or 1)
            boundary = offset + (step // every) * every
            value = float(np.mean(recent))
            assert checkpoints is not None
            checkpoints.append((boundary, value))
            if on_checkpoint is not None and not on_checkpoint(boundary, value):
                run.pruned_at = boundary
                return False
            return True

    env = make_env(spec, seed, physics_processes)
    try:
        run.model = build_model(spec, env, seed)
        run.model.learn(total_timesteps=spec.steps, callback=Recorder())
        if _has_nan(run.model):
            run.failure = "diverged: the policy's parameters became NaN"
    except (ValueError, RuntimeError, FloatingPointError) as err:
        kind = "diverged" if _is_divergence(err) else "error"
        run.failure = f"{kind}: {type(err).__name__}: {first_line(err)[:300]}"
    finally:
        env.close()
    run.env_steps = int(run.model.num_timesteps) if run.model is not None else 0
    if run.failure is None and run.pruned_at is None:
        run.train_reward = final_score(run.episodes, run.env_steps)
        if spec.objective == "evaluation":
            from kraby_study.evaluation import evaluate

            run.score = evaluate(run.model, spec.settings["env"], spec.eval_episodes)
        else:
            run.score = run.train_reward
        if run.score is None or not math.isfinite(run.score):
            run.failure = "error: no finite score (no episode ended in the last 10 %)"
    return run


def mean_curve(curves: list[list[CurvePoint]]) -> list[CurvePoint]:
    """Average several runs' curves bin by bin (a trial of k seeds stores one curve)."""
    if len(curves) == 1:
        return curves[0]
    by_step: dict[int, list[CurvePoint]] = {}
    for curve in curves:
        for point in curve:
            by_step.setdefault(point.step, []).append(point)
    return [CurvePoint(step=step, mean_reward=float(np.mean([p.mean_reward for p in pts])),
                       wall_time=float(np.mean([p.wall_time for p in pts])),
                       episodes=sum(p.episodes for p in pts))
            for step, pts in sorted(by_step.items())]


def run_trial(spec: TrialSpec, on_checkpoint: CheckpointHook | None = None,
              on_progress: ProgressHook | None = None,
              physics_processes: int = 1) -> TrialResult:
    """Train PPO as the spec says; divergence and errors come back as a failed result.

    A spec with repeats > 1 trains seeds seed .. seed + repeats - 1 one after the other. Its
    intermediate values (searches) are the mean episode reward every ``checkpoint_every`` env
    steps of the first seed, then, at the end of each seed but the last, the mean score of the
    seeds so far; steps count across seeds. So a pruner compares trials at equal experience, and
    can stop a bad configuration during or after its first seed. (Within later seeds a learning
    curve starts again from scratch and would compare with the others' first-seed curves.)
    ``physics_processes`` sets how many processes step the legs: speed only, the result is
    the same.
    """
    started = _now()
    t0 = time.perf_counter()
    checkpoints: list[tuple[int, float]] = []
    runs: list[_Run] = []
    for index in range(spec.repeats):
        run = _train(spec, spec.seed + index, index * spec.steps, on_checkpoint, on_progress,
                     checkpoints if index == 0 else None, physics_processes)
        runs.append(run)
        if run.failure is not None or run.pruned_at is not None:
            break
        if spec.checkpoint_every and index + 1 < spec.repeats:
            step = (index + 1) * spec.steps
            value = float(np.mean([r.score for r in runs]))
            checkpoints.append((step, value))
            if on_checkpoint is not None and not on_checkpoint(step, value):
                run.pruned_at = step
                break
    last = runs[-1]
    result = TrialResult(
        key=spec.key, status="complete",
        curve=mean_curve([bin_curve(r.episodes, spec.curve_every) for r in runs]),
        env_steps=sum(r.env_steps for r in runs), wall_time=time.perf_counter() - t0,
        started=started, ended=_now(), checkpoints=checkpoints)
    if last.failure is not None:
        result.status, result.failure = "failed", last.failure
    elif last.pruned_at is not None:
        result.status, result.pruned_at = "pruned", last.pruned_at
    else:
        result.final_score = float(np.mean([r.score for r in runs]))
        rewards = [r.train_reward for r in runs if r.train_reward is not None]
        result.train_reward = float(np.mean(rewards)) if rewards else None
        if spec.model_path:
            best = max(runs, key=lambda r: float(r.score or -math.inf))
            Path(spec.model_path).parent.mkdir(parents=True, exist_ok=True)
            best.model.save(spec.model_path)
    return result
