"""Reading a store for a report: refuse bad stores early, load each study as DataFrames.

The report only reads. A missing, empty or foreign file is refused before SQLAlchemy or Optuna
touch it, because both would happily create an empty database at a wrong path.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import optuna
import pandas as pd
import sqlalchemy as sa
from optuna.trial import FrozenTrial

from kraby_study.config import ConfigError, sqlite_path, validate_storage
from kraby_study.ledger import attempts_by_key, superseded
from kraby_study.messages import first_line
from kraby_study.store import (
    DEFINITION,
    KIND,
    PLANNED,
    Store,
    StoreError,
    curve_points,
)

SQLITE_MAGIC = b"SQLite format 3\x00"
OPTUNA_TABLES = ("studies", "trials", "version_info")
CURVE_COLUMNS = ["trial_id", "step", "mean_reward", "wall_time", "episodes"]


@dataclass
class StudyData:
    """One stored study, as the report sees it.

    Attributes:
        name: The study's name in the store.
        kind: ``sweep``, ``train``, ``search`` or ``optuna`` (a study kraby-study did not make).
        study: The Optuna study.
        definition: The stored definition (sweeps and single runs), else empty.
        trials: The trials that count, in trial-number order: for sweeps and single runs the
            latest attempt of each planned run, otherwise every trial no retry replaced.
        curves: Learning-curve points of the counted trials (one query per study), columns
            ``trial_id, step, mean_reward, wall_time, episodes``.
        planned: Planned number of runs (or trials), if the store says.
        replaced: Interrupted attempts that a later attempt superseded (not results).
    """

    name: str
    kind: str
    study: optuna.Study
    definition: dict[str, Any]
    trials: list[FrozenTrial]
    curves: pd.DataFrame
    planned: int | None = None
    replaced: int = 0


def check_store_file(url: str) -> None:
    """Refuse a SQLite store that is missing, empty, not a database, or not a study store.

    Args:
        url: Database URL; servers (PostgreSQL) are checked when connecting instead.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: The file cannot be a study store; the message is one line.
    """
    validate_storage(url)
    path = sqlite_path(url)
    if path is None:
        return
    if not path.exists():
        raise StoreError(f"no study store at {path}")
    if not path.is_file():
        raise StoreError(f"{path} is not a file, so not a study store")
    if path.stat().st_size == 0:
        raise StoreError(f"{path} is empty, not a study store")
    with open(path, "rb") as handle:
        if handle.read(len(SQLITE_MAGIC)) != SQLITE_MAGIC:
            raise StoreError(f"{path} is not a SQLite database, so not a study store")
    try:
        connection = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            rows = connection.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
        finally:
            connection.close()
    except sqlite3.Error as err:
        raise StoreError(f"cannot read {path}: {err}") from None
    missing = [name for name in OPTUNA_TABLES if name not in {row[0] for row in rows}]
    if missing:
        raise StoreError(f"{path} is a SQLite database but not a study store "
                         f"(no {', '.join(missing)} table)")


@contextmanager
def report_store(url: str) -> Iterator[Store]:
    """The store at ``url`` opened read-only, never created.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: The store is missing, unreadable or holds no study.
    """
    check_store_file(url)
    try:
        store = Store(url, create=False, writer=False)
    except (sa.exc.SQLAlchemyError, optuna.exceptions.OptunaError) as err:
        raise StoreError(f"cannot open the store {url}: {first_line(err)}") from None
    try:
        try:
            names = store.study_names()
        except (sa.exc.SQLAlchemyError, optuna.exceptions.OptunaError) as err:
            raise StoreError(f"cannot read the store {url}: {first_line(err)}") from None
        if not names:
            raise StoreError(f"no studies in {url}: run one first (kraby-study run ...)")
        yield store
    finally:
        store.close()


def select_studies(store: Store, name: str | None) -> list[str]:
    """The names to report: every study, or the one asked for.

    Raises:
        StoreError: No study of that name; the message lists the stored ones.
    """
    names = store.study_names()
    if name is None:
        return names
    if name not in names:
        shown = ", ".join(names[:10]) + (", ..." if len(names) > 10 else "")
        raise StoreError(f"no study named {name!r} in {store.url} (studies: {shown})")
    return [name]


def counted_trials(kind: str, trials: list[FrozenTrial]) -> tuple[list[FrozenTrial], int]:
    """The trials that are results or still to come, and how many attempts were replaced."""
    keyed = [t for t in trials if t.user_attrs.get("key") is not None]
    if kind in ("sweep", "train") and keyed:
        latest = attempts_by_key(trials)
        chosen = sorted(latest.values(), key=lambda t: t.number)
        return chosen, len(keyed) - len(chosen)
    replaced = superseded(trials)
    chosen = [t for t in trials if t.number not in replaced]
    return chosen, len(trials) - len(chosen)


def read_curves(store: Store, study_id: int, trial_ids: list[int]) -> pd.DataFrame:
    """Every curve point of a study in one query, restricted to the given trials."""
    query = (sa.select(*[curve_points.c[name] for name in CURVE_COLUMNS])
             .where(curve_points.c.study_id == study_id))
    with store.engine.connect() as connection:
        if sa.inspect(connection).has_table(curve_points.name):
            frame = pd.read_sql(query, connection)
        else:  # a plain Optuna store: no curves
            frame = pd.DataFrame(columns=CURVE_COLUMNS)
    frame = frame[frame["trial_id"].isin(trial_ids)]
    return frame.sort_values(["trial_id", "step"], kind="stable").reset_index(drop=True)


def load_study(store: Store, name: str) -> StudyData:
    """A study, its counted trials and their curves."""
    study = store.load(name)
    attrs = study.user_attrs
    kind = str(attrs.get(KIND, "optuna"))
    if kind not in ("sweep", "train", "search"):
        kind = "optuna"
    definition = attrs.get(DEFINITION, {}) or {}
    if kind == "sweep" and "parameter" not in definition:
        kind = "optuna"
    trials, replaced = counted_trials(kind, study.get_trials(deepcopy=False))
    planned = attrs.get(PLANNED)
    curves = read_curves(store, study._study_id, [t._trial_id for t in trials])
    return StudyData(name=name, kind=kind, study=study, definition=dict(definition),
                     trials=trials, curves=curves,
                     planned=int(planned) if planned is not None else None, replaced=replaced)


def check_format(fmt: str) -> str:
    """The figure format, lower case; ConfigError unless png or svg."""
    value = str(fmt).lower().lstrip(".")
    if value not in ("png", "svg"):
        raise ConfigError(f"report format must be png or svg, got {fmt!r}")
    return value
