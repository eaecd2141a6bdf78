"""What a trial gives back to the runner: its outcome, learning curve, timings and score."""

from __future__ import annotations

from dataclasses import dataclass, field

from kraby_study.records import Outcome


@dataclass(frozen=True)
class CurvePoint:
    """Mean reward of the episodes that ended in one bin of environment steps."""

    step: int
    """Environment steps at the end of the bin."""
    mean_reward: float
    """Mean episode reward (sum over the episode's steps) of the bin's episodes."""
    wall_time: float
    """Seconds since training started, when the bin's last episode ended."""
    episodes: int
    """Episodes that ended in the bin."""


@dataclass
class TrialResult:
    """What a run gives back: how it ended, its curve, timings and final score."""

    outcome: Outcome
    """complete, failed or pruned."""
    curve: list[CurvePoint] = field(default_factory=list)
    """Its learning curve (the mean over its seeds, bin by bin)."""
    final_score: float | None = None
    """The score of a complete run (see :class:`kraby_study.records.TrialAttrs`)."""
    env_steps: int = 0
    """Env steps trained, over all its seeds."""
    wall_time: float = 0.0
    """Seconds it took."""
    started: str = ""
    """When it started (UTC, ISO 8601)."""
    ended: str = ""
    """When it ended (UTC, ISO 8601)."""
    failure: str | None = None
    """Why a failed run failed (``diverged: ...`` for NaN losses or parameters)."""
    pruned_at: int | None = None
    """Environment steps at which a pruner stopped the run."""
    train_reward: float | None = None
    """Mean episode reward over the last 10 % of training (the final score unless the objective
    is an evaluation)."""
