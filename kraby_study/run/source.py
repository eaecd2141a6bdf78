"""What sweeps and searches share as trial sources: recording, giving back, heartbeats."""

from __future__ import annotations

from typing import TextIO

import optuna
from optuna.trial import FrozenTrial, TrialState

from kraby_study.spec import TrialSpec
from kraby_study.store import Store, record_result
from kraby_study.trial import TrialResult

UNFINISHED = (TrialState.RUNNING, TrialState.WAITING)


class StudySource:
    """A trial source backed by one stored study; subclasses decide which trials to run."""

    def __init__(self, store: Store, study: optuna.Study) -> None:
        self.store = store
        self.study = study

    def record(self, trial_id: int, spec: TrialSpec, result: TrialResult) -> str:
        """Store a finished trial; returns a short outcome for the progress display."""
        record_result(self.store, self.study, trial_id, result)
        if result.status == "complete":
            return f"complete, score {result.final_score:.4g} ({result.wall_time:.0f} s)"
        if result.status == "pruned":
            return f"pruned at {result.pruned_at:,} env steps"
        return f"failed ({result.failure})"

    def interrupted(self, trial_id: int, spec: TrialSpec, reason: str) -> None:
        """Give back a trial that will not finish in this command."""
        self.store.give_back(self.study, trial_id, reason)

    def heartbeat(self, trial_ids: list[int]) -> None:
        """Tell the store these trials are alive."""
        for trial_id in trial_ids:
            self.store.heartbeat(trial_id)

    def running_elsewhere(self) -> bool:
        """Whether other commands still run trials that could come back (PostgreSQL)."""
        if self.store.exclusive:
            return False
        self.store.fail_orphans(self.study)
        return any(t.state in UNFINISHED for t in self.counted(
            self.study.get_trials(deepcopy=False)))

    def counted(self, trials: list[FrozenTrial]) -> list[FrozenTrial]:
        """The trials that make up the study's result (one attempt per run)."""
        raise NotImplementedError


def rerun_orphans(store: Store, study: optuna.Study, stream: TextIO) -> None:
    """Queue again the trials a stopped command left running, and say so."""
    rerun = store.fail_orphans(study)
    if rerun:
        print(f"{rerun} trial(s) left running by a stopped command will run again",
              file=stream)
