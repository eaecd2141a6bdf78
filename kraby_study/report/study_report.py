"""What a report wrote: per study, its files and the blocks the index shows."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kraby_study.records.attributes import StudyKind
from kraby_study.report.document import Block


@dataclass
class StudyReport:
    """The report of one study.

    Attributes:
        name: The study's name in the store.
        kind: sweep, train, search, confirm or optuna.
        folder: Where its files are (``out/<study>``).
        status: Where the study stands, e.g. ``7/10 complete, 1 failed, 2 pending``.
        finished: False while runs are still to come.
        files: Every file written, in the order the index lists them.
        blocks: The study's section of the index.
        notes: Things a reader should know (skipped figures, missing models, ...).
        sweep: The tables of a sweep-like study (a ``answers.sweep_evidence.Sweep``), else None.
        result: Its result in a few words, for the index's overview (e.g. the best value and
            the selected one); empty when there is none.
    """

    name: str
    kind: StudyKind
    folder: Path
    status: str
    finished: bool
    files: list[Path] = field(default_factory=list)
    blocks: list[Block] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    sweep: Any = None
    result: str = ""


@dataclass
class ReportIndex:
    """Everything ``write_report`` wrote.

    Attributes:
        out: The output folder.
        markdown: ``out/index.md``.
        html: ``out/index.html``.
        studies: One report per study, in store order.
        seconds: Time taken.
        campaign_files: The campaigns' tables (``<campaign>/campaign.csv``).
    """

    out: Path
    markdown: Path
    html: Path
    studies: list[StudyReport]
    seconds: float = 0.0
    campaign_files: list[Path] = field(default_factory=list)

    @property
    def files(self) -> list[Path]:
        """Every file written, index pages first."""
        return ([self.markdown, self.html] + self.campaign_files
                + [f for s in self.studies for f in s.files])
