"""What sweeps and searches share as trial sources: recording, requeueing, heartbeats."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TextIO

from optuna.trial import FrozenTrial, TrialState

from kraby_study.plan.spec import TrialSpec
from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import counted, spent_cpu
from kraby_study.run.provenance import command_facts
from kraby_study.store.ledger import StudyLedger

UNFINISHED = (TrialState.RUNNING, TrialState.WAITING)


class StudySource:
    """A trial source backed by one stored study; subclasses decide which trials to run."""

    def __init__(self, ledger: StudyLedger) -> None:
        self.ledger = ledger

    def started(self, number: int, machine: Mapping[str, str]) -> None:
        """Store what makes a trial that just started: the machine training it (as its worker
        says) and this command."""
        self.ledger.note_provenance(number, {**machine, **command_facts()})

    def record(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        """Store a finished trial."""
        self.ledger.record(number, result)

    def requeue(self, number: int, spec: TrialSpec, reason: str) -> None:
        """Give back a trial that will not finish in this command, to run again."""
        self.ledger.requeue(number, reason)

    def heartbeat(self, numbers: list[int]) -> None:
        """Tell the store these trials are alive."""
        self.ledger.heartbeat(numbers)

    def checkpoint(self, number: int, step: int, value: float) -> bool:
        """Record an intermediate value; False prunes the trial (sweeps never prune)."""
        return True

    def stopped_why(self, number: int) -> str | None:
        """Why this source stopped a trial itself (a search's cost cap); None here."""
        return None

    def using(self, number: int, steps: int, cpu: float) -> None:
        """Note the env steps a running trial has trained and the CPU seconds it has used so
        far (only a search under a CPU budget counts them)."""

    def running_elsewhere(self) -> bool:
        """Whether other commands still run trials that could come back (PostgreSQL)."""
        if self.ledger.exclusive:
            return False
        self.ledger.requeue_orphans()
        return any(t.state in UNFINISHED for t in self.counted())

    def counted(self) -> list[FrozenTrial]:
        """The trials that make up this command's part of the study (one attempt per run)."""
        return counted(self.ledger.trials())


class BudgetedSource(StudySource):
    """A search's source under ``search.cpu_budget``: what it has spent, whether the budget is
    used, and how its progress lines and start line say so. Subclasses say what the runs this
    command runs have used so far
    ([`running_cpu`][kraby_study.run.source.BudgetedSource.running_cpu])."""

    cpu_budget: float | None
    """CPU seconds the search may use; None: no limit."""

    def running_cpu(self) -> float:
        """CPU seconds the trials this command runs have used so far."""
        raise NotImplementedError

    def spent(self) -> float:
        """CPU seconds the search has used: its ended trials', every attempt counted, what
        the trials this command runs have used so far (a trial another machine runs counts
        once it ends), and what asking the sampler for each trial cost."""
        return spent_cpu(self.ledger.trials()) + self.running_cpu()

    def over_budget(self) -> bool:
        """Whether the search has used its CPU budget (never without one)."""
        return self.cpu_budget is not None and self.spent() >= self.cpu_budget

    def used_text(self) -> str:
        """What a progress line shows of the CPU budget: ``845 of 1,200 CPU s used``."""
        return f"{self.spent():,.0f} of {self.cpu_budget or 0:,.0f} CPU s used"

    def budget_text(self) -> str:
        """The start line's CPU budget part: the budget and what is already spent."""
        if self.cpu_budget is None:
            return ""
        return f"; until {self.cpu_budget:,.0f} CPU s are used ({self.spent():,.0f} so far)"


def requeue_orphans(ledger: StudyLedger, stream: TextIO) -> None:
    """Queue again the trials a stopped command left running, and say so."""
    requeued = ledger.requeue_orphans()
    if requeued:
        print(f"{requeued} trial(s) left running by a stopped command will run again",
              file=stream)


def retry_failed(ledger: StudyLedger, stream: TextIO) -> int:
    """Queue the study's failed runs again with their seeds and settings, and say so; returns
    how many."""
    numbers, diverged = ledger.retry_failed()
    if numbers:
        print(f"{len(numbers)} failed trial(s) of {ledger.name} queued again with the same seeds "
              f"and settings: {', '.join(map(str, numbers))}", file=stream, flush=True)
    if diverged:
        print(f"{diverged} diverged run(s) of {ledger.name} not queued again: a divergence is a "
              "result of its settings", file=stream, flush=True)
    return len(numbers)
