"""``write_report``: every study of a store -> figures, tables, ``index.md`` and ``index.html``.

The store is read first (one query per table per study) and closed before anything is drawn.
"""

from __future__ import annotations

import re
import tempfile
import time
from pathlib import Path
from typing import Any, TextIO

from kraby_study.answers.search_evidence import build_search, is_two_objective
from kraby_study.answers.study_data import StudyData, load_study, select_studies
from kraby_study.answers.sweep_evidence import build_sweep, option
from kraby_study.decision.comparison import seeds_needed
from kraby_study.decision.intervals import BOOTSTRAP_REPETITIONS, interval_name
from kraby_study.errors import ConfigError, first_line
from kraby_study.records.attributes import StudyKind
from kraby_study.report import search_output, sweep_output
from kraby_study.report.campaign_output import campaigns, write_campaign
from kraby_study.report.document import (
    Block,
    Heading,
    Image,
    Items,
    Links,
    Table,
    Text,
    to_html,
    to_markdown,
)
from kraby_study.report.reproducibility import write_reproducibility
from kraby_study.report.study_report import ReportIndex, StudyReport
from kraby_study.report.style import check_format
from kraby_study.store.store import opened_for_reading
from kraby_study.store.url import shown_url, sqlite_path

TITLE = "kraby-study report"
Candidates = list[tuple[str, dict[str, Any], str]]


def folder_name(name: str, taken: set[str]) -> str:
    """A file-system-safe, unique folder name for a study."""
    base = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "study"
    candidate, counter = base, 2
    while candidate in taken:
        candidate, counter = f"{base}_{counter}", counter + 1
    taken.add(candidate)
    return candidate


def find_model(path: str, url: str) -> Path | None:
    """A saved model file: as stored, or relative to the store's folder (for relative paths
    recorded by a command run from another directory)."""
    model = Path(path)
    if model.is_file():
        return model
    db = sqlite_path(url)
    if model.is_absolute() or db is None:
        return None
    for base in (db.parent, db.parent.parent):
        for candidate in (base / model, base / Path(*model.parts[-3:])):
            if candidate.is_file():
                return candidate
    return None


def add_policy(report: StudyReport, candidates: Candidates, url: str, rel: str) -> None:
    """Animate the best saved policy of a study, or say why there is none."""
    if not candidates:
        report.notes.append("no saved model (save_models=false?): no policy animation")
        return
    for path, settings, description in candidates:
        model = find_model(path, url)
        if model is None:
            continue
        from kraby_study.report.policy import render_policy

        target = report.folder / "policy.gif"
        try:
            render_policy(str(model), settings, target)
        except Exception as err:  # noqa: BLE001 - a broken model must not cost the whole report
            first = (str(err).strip().splitlines() or [type(err).__name__])[0]
            report.notes.append(f"policy animation failed for {model}: {first}")
            return
        report.files.append(target)
        from kraby_study.env import adapter_for

        shown = adapter_for(settings.get("env") or {}).shown
        image = Image(f"{rel}/policy.gif", "trained policy",
                      f"The best trained policy, {description}, {shown} "
                      "(deterministic actions, real time).")
        links = [i for i, b in enumerate(report.blocks) if isinstance(b, Links)]
        report.blocks.insert(links[-1] if links else len(report.blocks), image)
        return
    report.notes.append(f"saved model not found ({candidates[0][0]}): no policy animation")


def report_study(data: StudyData, folder: Path, rel: str, fmt: str, url: str,
                 policy: bool, options: Any = None) -> StudyReport:
    """The files and index section of one study; ``options`` as in
    [`write_report`][kraby_study.report.build.write_report]."""
    candidates: Candidates
    if data.kind.seeded:
        sweep = build_sweep(data, options)
        report = sweep_output.write_sweep(sweep, folder, rel, fmt)
        report.sweep = sweep
        candidates = sweep_output.policy_candidates(sweep)
    elif data.ledger.objectives > 1 and not is_two_objective(data):
        folder.mkdir(parents=True, exist_ok=True)
        report = StudyReport(name=data.name, kind=data.kind, folder=folder,
                             status=f"{len(data.trials)} trials", finished=True)
        report.notes.append("multi-objective study: not drawn (kraby-study draws its own "
                            "two-objective searches only)")
        report.blocks = [Heading(data.name, 2)]
        candidates = []
    else:
        search = build_search(data, options)
        report = search_output.write_search(search, folder, rel, fmt)
        candidates = search_output.policy_candidates(search)
    if policy and (data.kind != StudyKind.OPTUNA or candidates):
        add_policy(report, candidates, url, rel)
    record = write_reproducibility(data, folder)
    report.files.append(record)
    report.blocks.append(Links("How it was made", [(record.name, f"{rel}/{record.name}")]))
    if report.notes:
        report.blocks.insert(min(2, len(report.blocks)),
                             Text("Note: " + "; ".join(report.notes) + "."))
    return report


def _overview(reports: list[StudyReport]) -> Table:
    rows = [[r.name, r.kind, r.status if r.finished else f"partly finished: {r.status}",
             r.result or "-", f"{r.folder.name}/"] for r in reports]
    return Table(["study", "kind", "status", "result", "folder"], rows)


SCORE_TEXT = ("Final score: mean episode reward over the last 10 % of a run's training, in its "
              "env's reward units (the leg's: minus the squared tip-target distance in m^2, "
              "summed over the episode); in a study scored by evaluation, the deterministic "
              "policy's mean return over the evaluation episodes. Figures use complete runs "
              "only; failed runs are listed. Intervals other than those below are named where "
              "they are shown.")


def methods_blocks(reports: list[StudyReport], bootstrap: int, min_seeds: int) -> list[Block]:
    """The index's methods, after every result: what a final score is and, when a study has
    seeds, what each number of a sweep's summary is."""
    blocks: list[Block] = [Heading("Methods", 2), Text(SCORE_TEXT)]
    if any(report.kind.seeded for report in reports):
        blocks.append(Items(sweep_output.methods(bootstrap, min_seeds)))
    else:
        blocks.append(Text(f"Intervals of a mean: {interval_name(bootstrap)}."))
    return blocks


def index_blocks(url: str, reports: list[StudyReport],
                 bootstrap: int = BOOTSTRAP_REPETITIONS,
                 campaigns: list[Block] | None = None, min_seeds: int = 2) -> list[Block]:
    """The index page: an overview with each study's result, the campaigns, every study's
    section, then the methods."""
    blocks: list[Block] = [
        Heading(TITLE, 1),
        Text(f"Store: {shown_url(url)}. {len(reports)} stud{'y' if len(reports) == 1 else 'ies'}"
             " reported; the methods are at the end."),
        _overview(reports),
        *(campaigns or []),
    ]
    for report in reports:
        blocks += report.blocks
    return blocks + methods_blocks(reports, bootstrap, min_seeds)


def check_folder(out: Path) -> None:
    """Refuse an output folder that cannot be created or written, before any work.

    Raises:
        ConfigError: The folder is a file, cannot be created, or cannot be written; one line.
    """
    if out.exists() and not out.is_dir():
        raise ConfigError(f"report folder {out} is a file")
    existing = next((p for p in [out, *out.parents] if p.exists()), Path("."))
    if not existing.is_dir():
        raise ConfigError(f"cannot create the report folder {out}: {existing} is a file")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as err:
        reason = err.strerror or first_line(err)
        raise ConfigError(f"cannot write the report folder {out}: {reason}") from None


def write_report(url: str, out: Path | str, study: str | None = None, fmt: str = "png",
                 policy: bool = True, options: Any = None) -> ReportIndex:
    """Report every study of a store (or one) into ``out``.

    Args:
        url: Database URL of the store (SQLite file or PostgreSQL); never created.
        out: Output folder: ``out/<study>/`` per study, ``out/index.md`` and ``out/index.html``.
        study: Report only this study.
        fmt: Figure format, png or svg (animations are GIFs either way).
        policy: Animate the best saved policy of each study (needs PyBullet and SB3).
        options: The report's statistics options (``bootstrap``: resamples of the bootstrap
            intervals; ``threshold``: the reward for steps/seconds to threshold, None for the
            default); None for the defaults.

    Returns:
        What was written.

    Raises:
        ConfigError: A bad format, database URL or output folder; one-line message.
        StoreError: A missing, empty or unreadable store, a store without studies, or an
            unknown study name; one-line message.
    """
    start = time.perf_counter()
    fmt = check_format(fmt)
    out = Path(out)
    check_folder(out)
    with opened_for_reading(url) as store:
        studies = [load_study(store, name) for name in select_studies(store, study)]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"cannot create the report folder {out}: {first_line(err)}") from None
    taken: set[str] = set()
    reports = []
    for data in studies:
        rel = folder_name(data.name, taken)
        reports.append(report_study(data, out / rel, rel, fmt, url, policy, options))
    sweeps = {r.name: r.sweep for r in reports if r.sweep is not None}
    chains: list[Block] = []
    chain_files: list[Path] = []
    # A campaign is drawn from all its stages: only when the whole store is reported.
    for name, record in (campaigns(sweeps) if study is None else {}).items():
        rel = folder_name(name, taken)
        blocks, files = write_campaign(name, record, sweeps, out / rel, rel)
        chains += blocks
        chain_files += files
    blocks = index_blocks(url, reports, int(option(options, "bootstrap",
                                                   BOOTSTRAP_REPETITIONS)), chains,
                          seeds_needed(int(option(options, "min_seeds", 2))))
    markdown, html = out / "index.md", out / "index.html"
    markdown.write_text(to_markdown(blocks), encoding="utf-8")
    html.write_text(to_html(blocks, TITLE), encoding="utf-8")
    return ReportIndex(out=out, markdown=markdown, html=html, studies=reports,
                       seconds=time.perf_counter() - start, campaign_files=chain_files)


def run_report(url: str, out: Path | str, study: str | None = None, fmt: str = "png",
               stream: TextIO | None = None, policy: bool = True, options: Any = None) -> int:
    """``kraby-study report``: write the report and say where it is; returns the exit code.

    Raises:
        ConfigError: As [`write_report`][kraby_study.report.build.write_report].
        StoreError: As [`write_report`][kraby_study.report.build.write_report].
    """
    index = write_report(url, out, study=study, fmt=fmt, policy=policy, options=options)
    if stream is not None:
        for report in index.studies:
            line = f"{report.name} ({report.kind}): {report.status}"
            if not report.finished:
                line += " [partly finished]"
            print(line, file=stream)
            for note in report.notes:
                print(f"  note: {note}", file=stream)
        print(f"report: {len(index.studies)} stud{'y' if len(index.studies) == 1 else 'ies'}, "
              f"{len(index.files)} files in {index.seconds:.1f} s -> {index.html}", file=stream)
    return 0
