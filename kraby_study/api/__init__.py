"""The Python API: what each command of the command line does, as functions that return
dataclasses.

Compose a config from the same overrides the command line takes (`compose`), run it
(`run_sweep`, `train`, `search`, `confirm`; `preview` shows the plan instead), read a store
(`open_store`: its studies, each study's runs and answers as objects with `to_frame()`),
answer any seed scores with the project's four answers (`compare`), and write the report
(`write_report`) or read a study's selected settings (`best`). The command line
(`kraby_study.cli`) parses arguments, calls one of these and prints.

A bad input raises `ConfigError` (a setting) or `StoreError` (the store), each with a one-line
message, before any work starts. Importing this package loads no Hydra, Optuna, database,
statistics or training code: each call imports what it needs.

Examples:
    >>> import kraby_study as ks
    >>> config = ks.compose(["study=ent_coef", "budget=smoke"])
    >>> config.cfg.budget.seeds
    2
"""

from kraby_study.api.answers import Answers, Run, Runs, ValueAnswer, compare
from kraby_study.api.config import Config, compose
from kraby_study.api.dry_run import Preview, preview
from kraby_study.api.fresh_seeds import confirm
from kraby_study.api.optuna_search import search
from kraby_study.api.outcome import RunResult
from kraby_study.api.report import Report, ReportedStudy, write_report
from kraby_study.api.run import run_sweep, train
from kraby_study.api.settings_files import Best, best
from kraby_study.api.store import StudyInfo, StudyStore, open_store
from kraby_study.errors import ConfigError, StoreError

__all__ = ["Answers", "Best", "Config", "ConfigError", "Preview", "Report", "ReportedStudy",
           "Run", "RunResult", "Runs", "StoreError", "StudyInfo", "StudyStore", "ValueAnswer",
           "best", "compare", "compose", "confirm", "open_store", "preview", "run_sweep",
           "search", "train", "write_report"]
