"""The environment seam: every use of an environment goes through one adapter per kind.

A run's env settings choose the adapter ([`adapter_for`][kraby_study.env.registry.adapter_for]):
settings with an ``id`` name a Gymnasium environment (``env=gym``, [`kraby_study.env.gym_env`][]),
settings without one are the leg's (``env=leg``, [`kraby_study.env.leg`][]). An adapter validates
the settings, builds the vectorised env of a run (its n_envs on independent seed streams), evaluates
a policy and gives the frames of a few episodes.
"""

from kraby_envs.seeding import SCHEMES, check_scheme
from kraby_study.env.adapter import EnvAdapter, Frame, normalizer_path, saved_normalizer
from kraby_study.env.registry import adapter_for

__all__ = ["SCHEMES", "check_scheme", "EnvAdapter", "Frame", "adapter_for", "normalizer_path",
           "saved_normalizer"]
