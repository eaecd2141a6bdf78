"""Deterministic evaluation of a trained policy on the fixed targets
(:func:`kraby_envs.rollout.fixed_targets`)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

import kraby_envs
from kraby_envs.rollout import fixed_targets, rollout


def evaluate(model: Any, env_settings: dict[str, Any], episodes: int) -> float:
    """Mean episode reward of the deterministic policy from rest to ``episodes`` fixed
    targets."""
    kwargs = dict(env_settings)
    max_steps = int(kwargs.pop("max_episode_steps"))
    env = gym.make(kraby_envs.ENV_ID, max_episode_steps=max_steps, **kwargs)

    def act(observation: Any) -> Any:
        return model.predict(observation, deterministic=True)[0]

    try:
        totals = [sum(s.reward for s in rollout(env, act, target))
                  for target in fixed_targets(episodes, float(kwargs["delta"]))]
    finally:
        env.close()
    return float(np.mean(totals))
