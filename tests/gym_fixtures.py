"""Gymnasium ids registered on import (``env.packages=[gym_fixtures]``), for the env seam's
tests: one whose steps raise (a run on it ends in an error, not a divergence), one tiny env
that renders without any drawing library, and the tiny env on a machine that lacks something
until it is fixed."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

BROKEN_ID = "KrabyTestBroken-v0"
TINY_ID = "KrabyTestTiny-v0"
NEEDS_FIX_ID = "KrabyTestNeedsFix-v0"
FIXED = "KRABY_TEST_FIXED"
"""The environment variable naming the file whose presence fixes the machine."""


class BrokenEnv(gym.Env):
    """Resets fine; every step raises."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action: Any) -> Any:
        raise RuntimeError("this env is broken on purpose")


class TinyEnv(gym.Env):
    """A point to hold at zero: reward minus the squared position; renders as a bar."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    observation_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, render_mode: str | None = None) -> None:
        self.render_mode = render_mode
        self.position = 0.0

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        self.position = float(self.np_random.uniform(-1.0, 1.0))
        return np.array([self.position], np.float32), {}

    def step(self, action: Any) -> Any:
        self.position = float(np.clip(self.position + 0.3 * float(action[0]), -2.0, 2.0))
        return np.array([self.position], np.float32), -self.position ** 2, False, False, {}

    def render(self) -> np.ndarray:
        image = np.full((30, 40, 3), 255, np.uint8)
        image[10:20, : int(10 * (self.position + 2.0))] = (200, 40, 40)
        return image


class NeedsFixEnv(TinyEnv):
    """The tiny env on a machine that lacks something: each step raises while the file named
    by the environment variable ``KRABY_TEST_FIXED`` is missing."""

    def step(self, action: Any) -> Any:
        if not Path(os.environ.get(FIXED, "/nonexistent")).is_file():
            raise RuntimeError("this machine is not fixed yet")
        return super().step(action)


for env_id, entry in ((BROKEN_ID, BrokenEnv), (TINY_ID, TinyEnv), (NEEDS_FIX_ID, NeedsFixEnv)):
    if env_id not in gym.registry:
        gym.register(id=env_id, entry_point=entry, max_episode_steps=10)
