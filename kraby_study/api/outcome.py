"""What a training call did: its study's counts, whether it was stopped, the line it ends with
and the exit code the command line returns for it."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from kraby_study.records.stored import Tally
    from kraby_study.run.runner import CommandRun


@dataclass(frozen=True)
class RunResult:
    """How a sweep, campaign, search, confirm study or training run ended.

    Attributes:
        study: The study's name in the store (a campaign's name for a campaign).
        complete: The study's complete runs (or trials), this call's and earlier ones.
        failed: Its failed runs.
        pruned: Its pruned runs (a search's stopped trials, a race's withdrawn retries).
        planned: The runs it plans (a search: its trial total; a campaign: its stages).
        interrupted: The call was stopped (Ctrl-C); rerunning it continues.
        errors: Runs of this call that ended in an error (not a divergence, which is a
            result).
        message: The line the command line prints last; None for a campaign, whose stages
            say how they ended as they go.
        warning: What to say when runs ended in errors; None otherwise.
        exit_code: 0 done, 1 runs ended in errors (or a campaign's stage has runs left),
            130 interrupted.
        score: A training run's final score (None for other calls, or when it has none).
        model_path: Where a training run's model is saved (None when not kept).
    """

    study: str
    complete: int
    failed: int
    pruned: int
    planned: int
    interrupted: bool
    errors: int
    message: str | None
    warning: str | None
    exit_code: int
    score: float | None = None
    model_path: str | None = None

    @property
    def finished(self) -> bool:
        """Every planned run has ended (complete, failed or pruned)."""
        return self.complete + self.failed + self.pruned >= self.planned


def exit_code(summary: CommandRun) -> int:
    """A training call's exit code: 130 interrupted, 1 when runs ended in errors, else 0; a
    divergence is a result, not an error."""
    if summary.interrupted:
        return 130
    return 1 if summary.errors else 0


def run_result(study: str, summary: CommandRun, counts: Tally, message: str | None,
        planned: int | None = None) -> RunResult:
    """The result of a call that ran one study: ``counts`` of the study (against ``planned``
    runs, else the count's own), ``summary`` of what this call ran."""
    return RunResult(study=study, complete=counts.complete, failed=counts.failed,
                     pruned=counts.pruned,
                     planned=counts.planned if planned is None else planned,
                     interrupted=summary.interrupted,
                     errors=summary.errors, message=message, warning=summary.errors_line(),
                     exit_code=exit_code(summary))


def output(stream: TextIO | None) -> TextIO:
    """Where progress goes: the stream given, else standard output at call time."""
    return sys.stdout if stream is None else stream
