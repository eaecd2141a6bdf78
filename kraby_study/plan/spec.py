"""TrialSpec: what a worker process needs to run one trial, and nothing heavier to import."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class TrialSpec:
    """Everything one training run needs; a trial is a pure function of it."""

    study: str
    """Name of the study the run belongs to."""
    key: str
    """Identity of the run within its study, stable across reruns (e.g. 'v3-s2')."""
    seed: int
    """Seed of the policy, the sampler and every leg's resets."""
    steps: int
    """Environment steps to train for (exactly, to a multiple of n_envs)."""
    curve_every: int
    """Environment steps per learning-curve point."""
    settings: dict[str, Any]
    """Resolved env and ppo settings; ppo.batch_size is always a number here."""
    value: Any = None
    """Value of the swept setting."""
    model_path: str | None = None
    """Where to save the final model (SB3 zip), or None."""
    checkpoint_every: int | None = None
    """Report progress to a pruner every this many environment steps (searches only)."""
    seeds: int = 1
    """Training runs, with seeds seed, seed + 1, ...; the score is their mean (searches)."""
    objective: str = "final_reward"
    """final_reward (mean reward over the last 10 % of training) or evaluation."""
    eval_episodes: int = 16
    """Fixed targets of the evaluation objective."""
    label: str = ""
    """How progress lines name the run, e.g. 'clip_range=0.2 seed 1'."""
