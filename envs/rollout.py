"""Running a policy on the leg from a fixed start to given targets: one rule for every user.

Evaluation (the ``evaluation`` objective) scores a policy over episodes from
:data:`START_ANGLES` to targets drawn from the run's own evaluation stream
(:func:`evaluation_targets`; studies stored before took :func:`fixed_targets`, one set for
every run); the report's policy GIF draws the first few fixed targets. Both go through
:func:`rollout`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from kraby_envs.seeding import evaluation_stream, leg_generator
from kraby_envs.task import TARGET_CENTRE, TARGET_HALF_EXTENTS

FIXED_TARGETS_SEED = 20240
"""Seed of the fixed targets: the same targets for every trial, run and report."""
START_ANGLES = (0.0, 0.0, 0.0)
"""Every fixed episode starts from this pose: the middle of the training start range."""


def _targets(rng: np.random.Generator, n: int, delta: float) -> np.ndarray:
    """``n`` targets uniform in the target box scaled by ``delta``, drawn in order from
    ``rng`` (so the first ``k`` of ``n`` are the ``k`` drawn alone)."""
    half = TARGET_HALF_EXTENTS * delta
    return TARGET_CENTRE + rng.uniform(-1.0, 1.0, size=(n, 3)) * half


def fixed_targets(n: int, delta: float) -> np.ndarray:
    """``n`` fixed targets, drawn once (seeded) from the target box scaled by ``delta``, the
    same for every run: the evaluation of studies stored before each run drew its own, and the
    report's GIF. The first ``k`` of ``n`` are the targets of ``fixed_targets(k, delta)``."""
    return _targets(np.random.default_rng(FIXED_TARGETS_SEED), n, delta)


def evaluation_targets(n: int, delta: float, seed: int) -> np.ndarray:
    """The ``n`` evaluation targets of the run with seed ``seed``, drawn from its evaluation
    stream (:func:`kraby_envs.seeding.evaluation_stream`), apart from its training legs'
    streams and from every other run's; the first ``k`` of ``n`` are those of ``k``."""
    return _targets(leg_generator(evaluation_stream(seed)), n, delta)


@dataclass(frozen=True)
class RolloutStep:
    """One moment of an episode: after the reset (step 0) or after an env step."""

    step: int
    observation: Any
    reward: float
    """Reward of this env step (0 at the reset)."""
    info: dict[str, Any]
    ended: bool
    """The episode ended here (terminated or truncated)."""


def rollout(env: gym.Env, act: Callable[[Any], Any], target: Any,
            seed: int | None = None) -> Iterator[RolloutStep]:
    """The steps of one episode from :data:`START_ANGLES` to ``target``, ``act`` choosing each
    action from the observation; the env's time limit ends it."""
    observation, info = env.reset(
        seed=seed, options={"joint_angles": START_ANGLES,
                            "target": tuple(float(x) for x in target)})
    step = 0
    yield RolloutStep(step, observation, 0.0, info, False)
    ended = False
    while not ended:
        observation, reward, terminated, truncated, info = env.step(act(observation))
        step += 1
        ended = bool(terminated or truncated)
        yield RolloutStep(step, observation, float(reward), info, ended)
