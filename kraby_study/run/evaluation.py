"""Deterministic evaluation of a trained policy on a fixed set of targets."""

from __future__ import annotations

from typing import Any

import numpy as np

EVAL_SEED = 20240
"""Seed of the fixed evaluation targets: the same targets for every trial and every run."""


def evaluation_targets(n: int, delta: float) -> np.ndarray:
    """``n`` fixed targets drawn once from the documented target box scaled by delta."""
    from kraby_envs.task import TARGET_CENTRE, TARGET_HALF_EXTENTS

    rng = np.random.default_rng(EVAL_SEED)
    half = TARGET_HALF_EXTENTS * delta
    return TARGET_CENTRE + rng.uniform(-1.0, 1.0, size=(n, 3)) * half


def evaluate(model: Any, env_settings: dict[str, Any], episodes: int) -> float:
    """Mean episode reward of the deterministic policy from rest (0, 0, 0) to fixed targets."""
    import gymnasium as gym

    import kraby_envs

    kwargs = dict(env_settings)
    max_steps = int(kwargs.pop("max_episode_steps"))
    env = gym.make(kraby_envs.ENV_ID, max_episode_steps=max_steps, **kwargs)
    totals = []
    try:
        for target in evaluation_targets(episodes, float(kwargs["delta"])):
            obs, _ = env.reset(options={"joint_angles": (0.0, 0.0, 0.0),
                                        "target": tuple(float(x) for x in target)})
            total, done = 0.0, False
            while not done:
                action, _ = model.predict(obs, deterministic=True)
                obs, reward, terminated, truncated, _ = env.step(action)
                total += float(reward)
                done = terminated or truncated
            totals.append(total)
    finally:
        env.close()
    return float(np.mean(totals))
