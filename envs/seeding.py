"""How a run's seed becomes one random stream per leg.

Each leg draws its start angles and targets from a stream of its own. Two schemes exist:

- ``streams`` (the default): leg ``i`` of a run with seed ``s`` takes child ``i`` of
  ``numpy.random.SeedSequence(s)`` (``SeedSequence(s).spawn(n)[i]``, spawn key ``(i,)``). No
  two (run seed, leg) pairs share a stream, so runs with neighbouring seeds are independent.
- ``offset`` (before streams): leg ``i`` is seeded with ``s + i``, as a Gymnasium env reset
  with ``seed=s + i`` (SB3's ``VecEnv.seed`` convention). Runs ``s`` and ``s + 1`` then share
  all but one leg's episodes; kept so that studies stored with it resume bit for bit.
"""

from __future__ import annotations

import numpy as np

SCHEMES: tuple[str, ...] = ("streams", "offset")
"""The seeding schemes, the default first."""


def check_scheme(scheme: object) -> str:
    """The scheme's name; ValueError naming the schemes for anything else."""
    if scheme not in SCHEMES:
        raise ValueError(f"seeding must be one of {', '.join(SCHEMES)}, got {scheme!r}")
    return str(scheme)


def leg_streams(seed: int, n_envs: int, scheme: str = "streams") -> list[np.random.SeedSequence]:
    """The seed sequence of each of a run's ``n_envs`` legs under ``scheme``."""
    check_scheme(scheme)
    if scheme == "offset":
        return [np.random.SeedSequence(seed + i) for i in range(n_envs)]
    return np.random.SeedSequence(seed).spawn(n_envs)


def leg_generator(stream: np.random.SeedSequence) -> np.random.Generator:
    """The generator a leg draws from: PCG64 on its stream, the generator Gymnasium's
    ``reset(seed=...)`` makes from ``SeedSequence(seed)``."""
    return np.random.Generator(np.random.PCG64(stream))


EVALUATION_KEY = 0x6576616C
"""Spawn key of a run's evaluation stream: child ``EVALUATION_KEY`` of the run's
``SeedSequence(seed)``, far above the children its legs (or a gym env's sub-envs) take,
``0 .. n_envs - 1``."""


def evaluation_stream(seed: int) -> np.random.SeedSequence:
    """The stream a run with seed ``seed`` draws its evaluation episodes from (its test set):
    ``SeedSequence(seed, spawn_key=(EVALUATION_KEY,))``, the child ``EVALUATION_KEY`` of the
    run's own sequence. It shares no state with the run's training streams, and runs of other
    seeds (a confirm's fresh seeds against its search's) draw other episodes."""
    return np.random.SeedSequence(seed, spawn_key=(EVALUATION_KEY,))
