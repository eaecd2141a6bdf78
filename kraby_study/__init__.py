"""kraby-study: declarative PPO hyperparameter studies, as a Python library with a command line
on top.

The public API (`kraby_study.api`), re-exported here.

Examples:
    >>> import kraby_study as ks
    >>> found = ks.compare({"a": [10.0, 10.2, 9.9, 10.1, 10.0, 9.8],
    ...                     "b": [9.9, 9.7, 9.8, 10.0, 9.6, 9.8]})
    >>> found.best, found.answer("b")
    ('a', 'equivalent')
"""

from kraby_study.api import (
    Answers,
    Best,
    Config,
    ConfigError,
    Preview,
    Report,
    ReportedStudy,
    Run,
    RunResult,
    Runs,
    StoreError,
    StudyInfo,
    StudyStore,
    ValueAnswer,
    best,
    compare,
    compose,
    confirm,
    open_store,
    preview,
    run_sweep,
    search,
    train,
    write_report,
)

__all__ = ["Answers", "Best", "Config", "ConfigError", "Preview", "Report", "ReportedStudy",
           "Run", "RunResult", "Runs", "StoreError", "StudyInfo", "StudyStore", "ValueAnswer",
           "best", "compare", "compose", "confirm", "open_store", "preview", "run_sweep",
           "search", "train", "write_report"]
