"""Where a stored study stands: what ``list`` and the commands' closing lines print.

``list`` reads every study as light rows ([`kraby_study.store.rows`][]), without Optuna; a command
that holds a study's ledger reads it through Optuna. Both count and select with the same rules
([`counted`][kraby_study.records.stored.counted], [`tally`][kraby_study.records.stored.tally],
[`selected_short`][kraby_study.answers.selected.selected_short]).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any

from kraby_study.answers.selected import Curves, selected_short
from kraby_study.records.attributes import Placement, StudyAttrs, StudyKind
from kraby_study.records.stored import StoredTrial, Tally, counted, tally
from kraby_study.store.rows import reading

if TYPE_CHECKING:
    from kraby_study.store.ledger import StudyLedger


@dataclass(frozen=True)
class StudyStanding:
    """A study's counted trials by outcome, and what it has selected so far."""

    name: str
    kind: StudyKind
    tally: Tally
    """Outcome counts; ``tally.planned`` is the runs planned (sweeps) or the trial total
    (searches)."""
    selected: str
    """What it selects so far, in a few words (``-`` when nothing is complete)."""
    placement: Placement
    """Where its trials ran: how many nodes, and on how many CPU models."""
    command: str | None = None
    """The command that ran its latest trial (as its provenance stores it), None when no
    trial of it started."""

    def retry_line(self) -> str | None:
        """How many counted runs failed with an error and how to run them again, or None when
        none did (a diverged run is a result of its settings, not retried)."""
        errors = self.tally.failed - self.tally.diverged
        if not errors:
            return None
        command = self.command or ""
        if command and "--retry-failed" not in command.split():
            command += " --retry-failed"
        how = f"`{command}`" if command else "its command with --retry-failed"
        return (f"{self.name}: {errors} run(s) failed with an error; to run them again with the "
                f"same seeds and settings: {how}")


def study_standing(ledger: StudyLedger) -> StudyStanding:
    """Counts and the selection so far of a study a command holds."""
    return standing(ledger.name, ledger.attrs, ledger.trials(), ledger.maximize, ledger.curves,
                    ledger.provenances())


def store_standings(url: str) -> list[StudyStanding]:
    """Counts and the selection so far of every study in an existing store, in the order
    Optuna lists them, read without Optuna (``list``); empty when it holds no study.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: No store there, or it cannot be read; one line.
    """
    with reading(url) as reader:
        return [standing(study.name, study.attrs, study.trials, study.maximize,
                         partial(reader.curves, study.name), study.provenance)
                for study in reader.studies()]


def standing(name: str, attrs: StudyAttrs, trials: Sequence[StoredTrial], maximize: bool,
             curves: Curves, records: Mapping[str, Mapping[str, Any]] | None = None,
             ) -> StudyStanding:
    """A study's standing from all its trials (Optuna's or rows): counted, tallied against the
    runs planned, what its rule selects among them, where they ran and the command that ran
    the latest (its provenance ``records``, by key)."""
    records = records or {}
    kept = counted(trials)
    return StudyStanding(name=name, kind=StudyKind.of(attrs.kind),
                         tally=tally(kept, attrs.planned),
                         selected=selected_short(attrs, kept, maximize, curves),
                         placement=Placement.of(records.values()),
                         command=latest_command(trials, records))


def latest_command(trials: Iterable[StoredTrial],
                   records: Mapping[str, Mapping[str, Any]]) -> str | None:
    """The command stored in the provenance of the latest trial that has one."""
    for trial in sorted(trials, key=lambda t: t.number, reverse=True):
        command = records.get(str(trial.user_attrs.get("provenance")), {}).get("command")
        if command:
            return str(command)
    return None
