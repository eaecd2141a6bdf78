"""Write the report of a store's studies: per study its figures, CSV and Markdown tables, and
``index.md`` and ``index.html`` over them all (`kraby_study.report`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from kraby_study.api.config import Config


@dataclass(frozen=True)
class ReportedStudy:
    """One study's part of a report.

    Attributes:
        name: The study's name in the store.
        kind: ``sweep``, ``train``, ``search``, ``confirm`` or ``optuna``.
        folder: Where its files are.
        status: Where it stands, e.g. ``7/10 complete, 1 failed, 2 pending``.
        finished: False while runs are still to come.
        notes: What a reader should know (skipped figures, missing models, ...).
    """

    name: str
    kind: str
    folder: Path
    status: str
    finished: bool
    notes: list[str]


@dataclass(frozen=True)
class Report:
    """What `write_report` wrote.

    Attributes:
        folder: The output folder.
        html: Its ``index.html``.
        markdown: Its ``index.md``.
        files: Every file written, index pages first.
        studies: Each study's part, in store order.
        seconds: Time taken.
    """

    folder: Path
    html: Path
    markdown: Path
    files: list[Path]
    studies: list[ReportedStudy]
    seconds: float

    def lines(self) -> list[str]:
        """What the command line prints: a line per study, its notes, and where it all is."""
        out = []
        for study in self.studies:
            out.append(f"{study.name} ({study.kind}): {study.status}"
                       + ("" if study.finished else " [partly finished]"))
            out += [f"  note: {note}" for note in study.notes]
        count = len(self.studies)
        out.append(f"report: {count} stud{'y' if count == 1 else 'ies'}, {len(self.files)} "
                   f"files in {self.seconds:.1f} s -> {self.html}")
        return out


def write_report(config: Config, study: str | None = None, fmt: str = "png",
           policy: bool = True) -> Report:
    """Redraw the figures and tables of the stored studies (or one) into ``out``.

    The store is ``config.cfg.storage`` and the folder ``config.cfg.out``; the answers use
    ``compare.margin`` and, when set, ``compare.select`` instead of each study's stored rule.

    Args:
        config: A composed config (`kraby_study.compose`).
        study: Report only this stored study (default: every study and campaign).
        fmt: Figure format, ``png`` or ``svg``.
        policy: Animate the best saved policy of each study (needs its model).

    Returns:
        What was written (`Report`).

    Raises:
        ConfigError: A bad format or output folder; one line.
        StoreError: No store, no study or no study of that name; one line.

    Examples:
        >>> import kraby_study as ks
        >>> written = ks.write_report(ks.compose(["storage=sqlite:///example.db", "out=example"],
        ...                                command="report"), study="clip_range", policy=False)
        >>> written.html.name
        'index.html'
    """
    from types import SimpleNamespace

    from omegaconf import OmegaConf

    from kraby_study.report import write_report

    cfg = config.cfg
    # The report's options with the comparison's: a report may re-analyse any study at any
    # margin, and read another rule than the stored one (compare.select).
    options = SimpleNamespace(**OmegaConf.to_container(cfg.report), margin=cfg.compare.margin,
                              select=cfg.compare.select)
    index = write_report(str(cfg.storage), str(cfg.out), study=study, fmt=fmt, policy=policy,
                         options=options)
    return Report(folder=index.out, html=index.html, markdown=index.markdown,
                  files=list(index.files), seconds=index.seconds,
                  studies=[ReportedStudy(name=r.name, kind=str(r.kind), folder=r.folder,
                                         status=r.status, finished=r.finished,
                                         notes=list(r.notes)) for r in index.studies])
