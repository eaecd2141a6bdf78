"""Reports: a store's studies as figures, CSV and Markdown tables, index.md and index.html.

Data flow: store -> :mod:`source` (DataFrames) -> :mod:`sweep` / :mod:`search` (tables and
statistics) -> ``*_plots`` (matplotlib figures) -> ``*_output`` (files and index sections) ->
:mod:`build` (``write_report``). The statistics are described in :mod:`stats`.
"""

from kraby_study.report.build import run_report, write_report
from kraby_study.report.results import ReportIndex, StudyReport
from kraby_study.report.source import check_format

FORMATS = ("png", "svg")

__all__ = ["FORMATS", "ReportIndex", "StudyReport", "check_format", "run_report",
           "write_report"]
