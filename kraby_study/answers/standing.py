"""Where a stored study stands: what ``list`` and the commands' closing lines print."""

from __future__ import annotations

from dataclasses import dataclass

from kraby_study.answers.selected import selection_of
from kraby_study.records import StudyKind, Tally, counted, tally
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


def study_standing(ledger: StudyLedger) -> StudyStanding:
    """Counts and the selection so far of a stored study."""
    attrs = ledger.attrs
    selection = selection_of(ledger)
    return StudyStanding(name=ledger.name, kind=StudyKind.of(attrs.kind),
                         tally=tally(counted(ledger.trials()), attrs.planned),
                         selected=selection.short if selection else "-")
