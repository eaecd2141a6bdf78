"""Where a stored study stands: what ``list`` and the commands' closing lines print."""

from __future__ import annotations

from dataclasses import dataclass

from optuna.trial import TrialState

from kraby_study.best import find_best
from kraby_study.records import counted, tally
from kraby_study.store.ledger import StudyLedger


@dataclass(frozen=True)
class StudyProgress:
    """Counts of a study's counted trials and its best so far."""

    name: str
    kind: str
    total: int
    """Runs planned (sweeps) or the trial total (searches)."""
    complete: int
    failed: int
    pruned: int
    running: int
    best: str


def study_progress(ledger: StudyLedger) -> StudyProgress:
    """Counts and the best value so far of a stored study."""
    attrs = ledger.attrs
    trials = counted(ledger.trials())
    counts = tally(trials)
    best = find_best(ledger)
    return StudyProgress(
        name=ledger.name, kind=attrs.kind or "optuna",
        total=attrs.planned if attrs.planned is not None else len(trials),
        complete=counts.complete, failed=counts.failed, pruned=counts.pruned,
        running=sum(t.state == TrialState.RUNNING for t in trials),
        best=best.short if best else "-")
