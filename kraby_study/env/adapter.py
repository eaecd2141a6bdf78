"""What an environment adapter does, and which adapter a run's env settings choose."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from kraby_study.env.evaluation import Evaluation


@dataclass(frozen=True)
class Frame:
    """One rendered moment of an episode, as the report's policy GIF shows it."""

    image: np.ndarray
    """RGB pixels (height x width x 3)."""
    caption: str
    """What the moment is (episode, time, a measure of the task)."""
    duration_ms: int
    """How long the GIF shows it."""


class EnvAdapter(Protocol):
    """One kind of environment, seen by the orchestrator."""

    kind: str
    """The env group's option: leg or gym."""
    shown: str
    """What the GIF of [`frames`][kraby_study.env.adapter.EnvAdapter.frames] shows, as its caption
    says it."""
    view: tuple[float, float, float]
    """How the GIF crops a rendered image: the fraction kept and its centre (x, y), as
    fractions of the width and height."""

    def validate(self, env: Mapping[str, Any], ppo: Mapping[str, Any] | None = None) -> None:
        """Refuse settings the env cannot run with (and, given the ppo settings, PPO settings
        the env's spaces cannot take), in one line: ConfigError."""
        ...

    def make_vec(self, env: Mapping[str, Any], n_envs: int, seed: int, seeding: str,
                 shards: int = 1, gamma: float = 0.99) -> Any:
        """The SB3 VecEnv of a run: ``n_envs`` envs, env i on stream i of ``seed`` under
        ``seeding``, each finished episode's info holding SB3's ``episode`` record in the env's
        own reward units; ``shards`` processes step it where the env can be split; ``gamma``
        is the discount a VecNormalize scales returns with."""
        ...

    def evaluate(self, model: Any, env: Mapping[str, Any], episodes: int,
                 normalizer: Any = None, seed: int | None = None) -> Evaluation:
        """The returns of the deterministic policy over ``episodes`` evaluation episodes of
        the run with seed ``seed``, drawn from its evaluation stream (apart from its training
        streams and from every other seed's episodes); ``seed`` None: the one set every run
        shared before (``eval_set: fixed``). ``normalizer`` is the run's VecNormalize, if
        any. Episodes are stepped side by side ([`kraby_study.env.evaluation`][])."""
        ...

    def frames(self, model: Any, env: Mapping[str, Any], size: tuple[int, int],
               normalizer: Any = None) -> Iterator[Frame]:
        """The frames of the first few evaluation episodes, rendered offscreen at about
        ``size`` (width, height) pixels, actions deterministic."""
        ...

    def describe(self, env: Mapping[str, Any]) -> dict[str, str]:
        """What the env is, as provenance stores it (the id, its package and version); empty
        for the leg, which is part of kraby-study itself."""
        ...

    def label(self, env: Mapping[str, Any]) -> str:
        """The env in a few words, as ``--dry-run`` shows it."""
        ...

    def time_limit(self, env: Mapping[str, Any]) -> int | None:
        """The most steps an episode can last (its time limit), or None when it has none."""
        ...



def normalizer_path(model_path: str | Path) -> Path:
    """Where a model's VecNormalize statistics are saved: ``<model>.vecnormalize.pkl`` beside
    its zip."""
    path = Path(model_path)
    return path.with_name(f"{path.stem}.vecnormalize.pkl")


def saved_normalizer(model_path: str | Path) -> Any:
    """The VecNormalize statistics saved beside a model
    ([`normalizer_path`][kraby_study.env.adapter.normalizer_path]), or None when it was trained
    without them."""
    import pickle

    stats = normalizer_path(model_path)
    if not stats.is_file():
        return None
    with stats.open("rb") as handle:
        return pickle.load(handle)  # noqa: S301 - written by this project's trial
