"""Evaluation of a trained policy: many episodes stepped side by side, one batched forward pass
of the policy per step for every episode still running.

An episode is a reset (its ``reset`` keyword arguments: a seed, options) followed by the
deterministic policy's actions until the env ends it. Stepping episodes side by side gives each
exactly the actions it would get alone (the policy sees each row of the batch apart), at the
cost of one forward pass per step of the longest episode instead of one per step of every
episode.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

LOCKSTEP = 64
"""Most episodes stepped side by side (envs made at once); more episodes take further rounds on
the same envs."""


@dataclass(frozen=True)
class Evaluation:
    """The returns of one run's evaluation episodes."""

    returns: tuple[float, ...]
    """Each episode's return, in the order of its resets."""

    @property
    def mean(self) -> float:
        """The run's evaluation score: the mean return."""
        return float(np.mean(self.returns)) if self.returns else math.nan

    @property
    def error(self) -> float:
        """The standard error of [`mean`][kraby_study.env.evaluation.Evaluation.mean] from the
        episodes alone (sd / sqrt(n)); NaN below 2 episodes. It is the share of a run's score that
        the test set's sampling adds."""
        n = len(self.returns)
        return float(np.std(self.returns, ddof=1) / math.sqrt(n)) if n > 1 else math.nan


def lockstep_returns(make: Callable[[], Any], resets: Sequence[Mapping[str, Any]],
                     act: Callable[[np.ndarray], np.ndarray], width: int = LOCKSTEP
                     ) -> list[float]:
    """The return of one episode per entry of ``resets``, up to ``width`` stepped side by side.

    Args:
        make: Makes one Gymnasium env (called at most ``width`` times; closed here).
        resets: Keyword arguments of each episode's ``env.reset``.
        act: The actions of a batch of observations (first axis: the episodes).
        width: Most envs made and stepped at once.
    """
    returns: list[float] = []
    envs: list[Any] = []
    try:
        for start in range(0, len(resets), max(1, width)):
            chunk = resets[start:start + max(1, width)]
            while len(envs) < len(chunk):
                envs.append(make())
            returns.extend(_side_by_side(envs[:len(chunk)], chunk, act))
    finally:
        for env in envs:
            env.close()
    return returns


def _side_by_side(envs: Sequence[Any], resets: Sequence[Mapping[str, Any]],
                  act: Callable[[np.ndarray], np.ndarray]) -> list[float]:
    """One episode on each env, from its reset, until every one has ended."""
    observations = [env.reset(**dict(reset))[0] for env, reset in zip(envs, resets, strict=True)]
    totals = [0.0] * len(envs)
    running = list(range(len(envs)))
    while running:
        actions = act(np.stack([observations[i] for i in running]))
        still = []
        for i, action in zip(running, actions, strict=True):
            observation, reward, terminated, truncated, _ = envs[i].step(action)
            observations[i] = observation
            totals[i] += float(reward)
            if not (terminated or truncated):
                still.append(i)
        running = still
    return totals
