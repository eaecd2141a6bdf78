"""The vectorised env of a Gymnasium id: SB3's DummyVecEnv, each sub-env on its own stream.

Apart from [`kraby_study.env.gym_env`][] because it needs stable-baselines3, which checking a config
never loads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv


@dataclass(frozen=True)
class SubEnvSeeds:
    """The seeds of one sub-env of a run."""

    reset: int
    action: int
    observation: int


def sub_env_seeds(seed: int, n_envs: int, scheme: str) -> list[SubEnvSeeds]:
    """The seeds of a run's ``n_envs`` sub-envs under ``scheme`` (streams or offset)."""
    from kraby_envs.seeding import check_scheme

    if check_scheme(scheme) == "offset":
        return [SubEnvSeeds(seed + i, seed + i, seed + i) for i in range(n_envs)]
    children = np.random.SeedSequence(seed).spawn(n_envs)
    words = [[int(w) for w in child.generate_state(3, np.uint64)] for child in children]
    return [SubEnvSeeds(*w) for w in words]


class StreamSeededVecEnv(DummyVecEnv):
    """A DummyVecEnv whose ``seed(s)`` gives sub-env i the seeds of stream i of ``s``
    ([`sub_env_seeds`][kraby_study.env.gym_vec.sub_env_seeds]) instead of SB3's ``s + i``.

    Args:
        env_fns: One function per sub-env, each making it.
        seeding: streams or offset (`kraby_envs.seeding`).
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
