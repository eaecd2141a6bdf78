"""Kraby hexapod leg environments: a Gymnasium env and a batched SB3 VecEnv.

Importing the package registers ``KrabyOneLeg-v0`` (32-step episodes).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .config import ENV_KWARGS, LegConfig, validate_env_kwargs
from .observation import OBSERVATIONS

ENV_ID = "KrabyOneLeg-v0"
MAX_EPISODE_STEPS = 32

if ENV_ID not in gym.registry:
    gym.register(
        id=ENV_ID,
        entry_point="kraby_envs.leg_env:KrabyOneLegEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
    )

_LAZY = {"KrabyBatchedVecEnv": "batched", "make_batched": "batched",
         "KrabyOneLegEnv": "leg_env"}


def __getattr__(name: str) -> Any:
    # The batched env pulls in stable-baselines3 and torch: load it only when used, so that
    # validating settings (the orchestrator's parent process) stays light.
    if name in _LAZY:
        import importlib

        module = importlib.import_module(f".{_LAZY[name]}", __name__)
        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "ENV_ID",
    "ENV_KWARGS",
    "MAX_EPISODE_STEPS",
    "OBSERVATIONS",
    "KrabyBatchedVecEnv",
    "KrabyOneLegEnv",
    "LegConfig",
    "make_batched",
    "validate_env_kwargs",
]
