"""A Gymnasium id registered on import (``env.packages=[broken_env]``) whose steps raise: a
run on it ends in an error, not a divergence."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

ENV_ID = "KrabyTestBroken-v0"


class BrokenEnv(gym.Env):
    """Resets fine; every step raises."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action: Any) -> Any:
        raise RuntimeError("this env is broken on purpose")


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point=BrokenEnv, max_episode_steps=10)
