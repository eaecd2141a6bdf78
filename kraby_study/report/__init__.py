"""Reports: a store's studies as figures, CSV and Markdown tables, index.md and index.html.

Data flow: store -> :mod:`load` (trials and curve frames) -> ``*_tables`` (tables and
statistics) -> ``*_plots`` (matplotlib figures) -> ``*_output`` (files and index sections) ->
:mod:`build` (``write_report``). The statistics are described in :mod:`kraby_study.decision`.
"""

from kraby_study.report.build import run_report, write_report
from kraby_study.report.study_report import ReportIndex, StudyReport
from kraby_study.report.style import check_format

__all__ = ["ReportIndex", "StudyReport", "check_format", "run_report",
           "write_report"]
