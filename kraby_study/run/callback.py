"""The stable-baselines3 callback of a training run: episodes, progress, checkpoints, the stop.

Imported by the trial only, in the worker process (it needs stable-baselines3).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from kraby_study.run.curve import Episode

CheckpointHook = Callable[[int, float], bool]
"""Called with (env steps, intermediate value); False stops the run (a pruner's decision)."""
ProgressHook = Callable[[int], None]
"""Called now and then with the env steps done so far."""
TrialProgress = Callable[[int, float], None]
"""A trial's progress: called now and then with the env steps done so far (its seeds
together) and the CPU seconds the trial has used so far."""


class EpisodeRecorder(BaseCallback):
    """Collects finished episodes, reports progress and checkpoints, and stops the run at its
    budget or when a checkpoint prunes it.

    Args:
        steps: The run's budget in env steps: SB3 trains in whole rollouts, so the run stops at
            the first step at or past it (the unfinished rollout is not learnt from).
        offset: Env steps of the trial's earlier seeds; progress and checkpoints count from it.
        checkpoint_every: Env steps between two intermediate values; None for none.
        on_checkpoint: Receives each intermediate value (a search's pruner).
        on_progress: Receives the env steps done, at most once a second.
    """

    def __init__(self, steps: int, offset: int = 0, checkpoint_every: int | None = None,
                 on_checkpoint: CheckpointHook | None = None,
                 on_progress: ProgressHook | None = None) -> None:
        super().__init__()
        self.steps = steps
        self.offset = offset
        self.every = checkpoint_every
        self.on_checkpoint = on_checkpoint
        self.on_progress = on_progress
        self.episodes: list[Episode] = []
        self.pruned_at: int | None = None
        """Env steps (with the offset) at which a checkpoint stopped the run."""
        self._t0 = time.perf_counter()
        self._next_checkpoint = checkpoint_every or 0
        self._window_start = 0
        self._last_progress = 0.0

    def _on_step(self) -> bool:
        now = time.perf_counter() - self._t0
        for info in self.locals["infos"]:
            episode = info.get("episode")
            if episode is not None:
                self.episodes.append((self.num_timesteps, float(episode["r"]), now))
        if self.on_progress is not None and now - self._last_progress >= 1.0:
            self._last_progress = now
            self.on_progress(self.offset + self.num_timesteps)
        if self.every and self.steps > self.num_timesteps >= self._next_checkpoint:
            if not self._checkpoint():
                return False
        return self.num_timesteps < self.steps

    def _checkpoint(self) -> bool:
        """Report the mean reward since the last checkpoint; False when pruned."""
        assert self.every is not None
        step = self.num_timesteps
        recent = [e[1] for e in self.episodes[self._window_start:]]
        self._window_start = len(self.episodes)
        while self._next_checkpoint <= step:
            self._next_checkpoint += self.every
        if not recent:
            return True
        # Report at the boundary crossed, so every trial reports at the same steps.
        boundary = self.offset + (step // self.every) * self.every
        value = float(np.mean(recent))
        if self.on_checkpoint is not None and not self.on_checkpoint(boundary, value):
            self.pruned_at = boundary
            return False
        return True
