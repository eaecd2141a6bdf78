"""Reports: a store's studies as figures, CSV and Markdown tables, index.md and index.html.

Data flow: store -> the answers layer's typed evidence of each study
([`load_study`][kraby_study.answers.study_data.load_study],
[`build_sweep`][kraby_study.answers.sweep_evidence.build_sweep],
[`build_search`][kraby_study.answers.search_evidence.build_search]) -> ``*_plots`` (matplotlib
figures) -> ``*_output`` (files and index sections) -> [`kraby_study.report.build`][]
([`write_report`][kraby_study.report.build.write_report]). The statistics are described in
[`kraby_study.decision`][].
"""

from kraby_study.report.build import run_report, write_report
from kraby_study.report.study_report import ReportIndex, StudyReport
from kraby_study.report.style import check_format

__all__ = ["ReportIndex", "StudyReport", "check_format", "run_report",
           "write_report"]
