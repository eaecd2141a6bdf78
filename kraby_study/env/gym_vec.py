"""The vectorised env of a Gymnasium id: SB3's DummyVecEnv, each sub-env on its own stream.

Apart from :mod:`kraby_study.env.gym_env` because it needs stable-baselines3, which checking a
config never loads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from stable_baselines3.common.vec_env import DummyVecEnv

from kraby_study.env.gym_env import sub_env_seeds


class StreamSeededVecEnv(DummyVecEnv):
    """A DummyVecEnv whose ``seed(s)`` gives sub-env i the seeds of stream i of ``s``
    (:func:`kraby_study.env.gym_env.sub_env_seeds`) instead of SB3's ``s + i``.

    Args:
        env_fns: One function per sub-env, each making it.
        seeding: streams or offset (:mod:`kraby_envs.seeding`).
    """

    def __init__(self, env_fns: list[Callable[[], Any]], seeding: str) -> None:
        super().__init__(env_fns)
        self.seeding = seeding

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        if seed is None:
            return super().seed(None)
        seeds = sub_env_seeds(int(seed), self.num_envs, self.seeding)
        for env, chosen in zip(self.envs, seeds, strict=True):
            env.action_space.seed(chosen.action)
            env.observation_space.seed(chosen.observation)
        # Gymnasium seeds each env's generator at its next reset, as SB3 does with its own.
        self._seeds = [chosen.reset for chosen in seeds]
        return self._seeds
