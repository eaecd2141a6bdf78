"""Which adapter serves a run's env settings: the one module that knows every adapter, apart
from the adapters themselves so that none of them imports it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kraby_study.env.adapter import EnvAdapter


def adapter_for(env: Mapping[str, Any]) -> EnvAdapter:
    """The adapter of a run's env settings (a dict or a config node): gym when they name an
    ``id``, else the leg."""
    # keys(), not `in`: a config node's `in` is False for a missing value (env=gym, no id yet).
    if "id" in env.keys():
        from kraby_study.env.gym_env import GYM

        return GYM
    from kraby_study.env.leg import LEG

    return LEG
