"""Every stored study with its trials as light rows, read with SQLAlchemy Core from Optuna's own
tables: what ``list`` needs, in a few queries and without Optuna.

Optuna's RDBStorage costs a third of a second to import (its models, alembic's version check),
and it builds a FrozenTrial per trial with every parameter, attribute and intermediate value:
about 12 s for 5,000 trials. A row holds only what counting a study's trials
([`counted`][kraby_study.records.stored.counted], [`tally`][kraby_study.records.stored.tally]) and
its selection so far read ([`kraby_study.answers.selected`][]): number, state, value, the attributes
of [`ROW_ATTRS`][kraby_study.store.rows.ROW_ATTRS], and a swept study's parameter (or its queued
value). Rows satisfy [`StoredTrial`][kraby_study.records.stored.StoredTrial], so the same rules run
on them as on Optuna's trials.

The columns are those of Optuna's models (``optuna/storages/_rdb/models.py``, the schema of
Optuna 3 and later); values and parameters are decoded as Optuna decodes them. Reading writes
nothing: a SQLite file is opened read-only, once the journal of a writer killed mid-transaction,
if one is left, is rolled back (`_rolled_back`).
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections import defaultdict
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from kraby_study.errors import StoreError, first_line
from kraby_study.records.attributes import PROVENANCE_PREFIX, StudyAttrs, StudyKind
from kraby_study.records.values import param_name
from kraby_study.store.tables import read_curves
from kraby_study.store.url import check_url, reading_url, sqlite_path

if TYPE_CHECKING:
    import pandas as pd

ROW_ATTRS = ("key", "retry_of", "failure", "wall_time", "cpu_time", "env_steps", "scores",
             "enqueued", "provenance")
"""The trial attributes a row holds: what counting reads (key, retry_of, failure), the
fastest_equivalent rule's training time (wall_time; cpu_time on a confirm study), the env steps a
dry run's estimate divides by wall_time (env_steps), the seeds' scores a two-objective
search's ties are decided on (scores), which trial is its floor (enqueued), and the key of
what made it (provenance: the command ``list`` offers to retry failed runs with)."""
SQLITE_PATIENCE = 60
"""Seconds a read waits while the writer holds the SQLite file (as the writer's own
connection, [`SqliteBackend`][kraby_study.store.backend.SqliteBackend])."""

# Optuna's tables, as far as they are read here (never created from this metadata).
_optuna = sa.MetaData()
_version_info = sa.Table("version_info", _optuna, sa.Column("schema_version", sa.Integer))
_studies = sa.Table("studies", _optuna, sa.Column("study_id", sa.Integer),
                    sa.Column("study_name", sa.String))
_directions = sa.Table("study_directions", _optuna, sa.Column("study_id", sa.Integer),
                       sa.Column("objective", sa.Integer), sa.Column("direction", sa.String))


def _key_values(name: str, owner: str) -> sa.Table:
    """One of Optuna's attribute tables: an owner id, a key and a JSON value per row."""
    return sa.Table(name, _optuna, sa.Column(owner, sa.Integer), sa.Column("key", sa.String),
                    sa.Column("value_json", sa.Text))


_study_attrs = _key_values("study_user_attributes", "study_id")
_trials = sa.Table("trials", _optuna, sa.Column("trial_id", sa.Integer),
                   sa.Column("number", sa.Integer), sa.Column("study_id", sa.Integer),
                   sa.Column("state", sa.String))
_values = sa.Table("trial_values", _optuna, sa.Column("trial_id", sa.Integer),
                   sa.Column("objective", sa.Integer), sa.Column("value", sa.Float),
                   sa.Column("value_type", sa.String))
_trial_attrs = _key_values("trial_user_attributes", "trial_id")
_system_attrs = _key_values("trial_system_attributes", "trial_id")
_params = sa.Table("trial_params", _optuna, sa.Column("trial_id", sa.Integer),
                   sa.Column("param_name", sa.String), sa.Column("param_value", sa.Float),
                   sa.Column("distribution_json", sa.Text))


class RowState(Enum):
    """A trial's state under the name Optuna stores (its TrialState's)."""

    RUNNING = 0
    COMPLETE = 1
    PRUNED = 2
    FAIL = 3
    WAITING = 4


@dataclass(frozen=True)
class TrialRow:
    """One trial as ``list`` reads it (a
    [`StoredTrial`][kraby_study.records.stored.StoredTrial])."""

    number: int
    state: RowState
    value: float | None
    """Its value when it has exactly one (Optuna's ``FrozenTrial.value``); None otherwise."""
    values: list[float] | None
    """Its values, one per objective (Optuna's ``FrozenTrial.values``); None without any."""
    params: dict[str, Any]
    """A swept study's parameter, when the trial has it; empty for other studies."""
    user_attrs: dict[str, Any]
    """The attributes of [`ROW_ATTRS`][kraby_study.store.rows.ROW_ATTRS] it has."""
    system_attrs: dict[str, Any]
    """``fixed_params`` of a swept study's trial without its parameter (queued, not run)."""


@dataclass(frozen=True)
class StudyRows:
    """One stored study: its attributes, direction and trial rows (in number order)."""

    name: str
    attrs: StudyAttrs
    maximize: bool
    """Whether higher values are better (kraby-study's studies all maximise)."""
    trials: list[TrialRow]
    provenance: dict[str, dict[str, Any]]
    """Its provenance records by key (what made its trials: ``list`` counts their nodes)."""


class StoreReader:
    """An existing store read without Optuna: its studies as rows, and their curves."""

    def __init__(self, url: str) -> None:
        """Open the store at ``url`` for reading; nothing is created or written.

        Raises:
            ConfigError: The URL is not a supported database URL.
            StoreError: No SQLite file there, or no Optuna store behind the URL; one line.
        """
        check_url(url)
        path = sqlite_path(url)
        if path is not None and not path.is_file():
            raise StoreError(f"no study store at {path}")
        reading = _reading_url(url)
        assert reading is not None
        self.url = url
        self._engine = sa.create_engine(
            reading, poolclass=sa.pool.NullPool,
            connect_args={"timeout": SQLITE_PATIENCE} if path is not None else {})
        self._ids: dict[str, tuple[int, dict[int, int]]] = {}
        try:
            with self._engine.connect() as connection:
                connection.execute(sa.select(_version_info.c.schema_version)).first()
        except sa.exc.SQLAlchemyError as err:
            self.close()
            raise StoreError(f"cannot open the store {url}: {first_line(err)}") from None

    def close(self) -> None:
        """Let go of the connections."""
        self._engine.dispose()

    def studies(self) -> list[StudyRows]:
        """Every study in the store, in the order Optuna lists them (by creation).

        Raises:
            StoreError: The database failed while being read; one line.
        """
        try:
            with self._engine.connect() as connection:
                return self._read(connection)
        except sa.exc.SQLAlchemyError as err:
            raise StoreError(f"cannot read the store {self.url}: {first_line(err)}") from None

    def study_attrs(self, name: str) -> StudyAttrs | None:
        """The stored attributes of the study named ``name`` (its definition among them),
        read without its trials; None when there is no such study.

        Raises:
            StoreError: The database failed while being read; one line.
        """
        try:
            with self._engine.connect() as connection:
                names, attrs, _, _ = _read_studies(connection)
        except sa.exc.SQLAlchemyError as err:
            raise StoreError(f"cannot read the store {self.url}: {first_line(err)}") from None
        ids = {study_name: study_id for study_id, study_name in names.items()}
        return attrs[ids[name]] if name in ids else None

    def curves(self, name: str, numbers: Collection[int] | None = None) -> pd.DataFrame:
        """Learning-curve points of a study read by
        [`studies`][kraby_study.store.rows.StoreReader.studies] (columns ``CURVE_COLUMNS``), of the
        given trials or all, sorted by trial and step."""
        study_id, numbers_of = self._ids[name]
        with self._engine.connect() as connection:
            return read_curves(connection, study_id, numbers_of, numbers)

    def _read(self, connection: sa.Connection) -> list[StudyRows]:
        names, attrs, maximize, provenance = _read_studies(connection)
        swept = {study_id: param_name(str(a.definition["parameter"]))
                 for study_id, a in attrs.items()
                 if StudyKind.of(a.kind).swept and "parameter" in a.definition}
        values = _read_values(connection)
        user_attrs: dict[int, dict[str, Any]] = defaultdict(dict)
        for trial_id, key, value_json in connection.execute(
                sa.select(_trial_attrs.c.trial_id, _trial_attrs.c.key, _trial_attrs.c.value_json)
                .where(_trial_attrs.c.key.in_(ROW_ATTRS))):
            user_attrs[trial_id][key] = json.loads(value_json)
        params, queued = _read_swept(connection, swept)
        rows: dict[int, list[TrialRow]] = defaultdict(list)
        numbers_of: dict[int, dict[int, int]] = defaultdict(dict)
        for trial_id, number, study_id, state in connection.execute(
                sa.select(_trials.c.trial_id, _trials.c.number, _trials.c.study_id,
                          _trials.c.state).order_by(_trials.c.study_id, _trials.c.number)):
            numbers_of[study_id][trial_id] = number
            param = {swept[study_id]: params[trial_id]} if trial_id in params else {}
            fixed = ({"fixed_params": json.loads(queued[trial_id])}
                     if not param and trial_id in queued else {})
            mine = values.get(trial_id, [])
            rows[study_id].append(TrialRow(
                number=number, state=RowState[state],
                value=mine[0] if len(mine) == 1 else None, values=mine or None, params=param,
                user_attrs=user_attrs.get(trial_id, {}), system_attrs=fixed))
        self._ids = {name: (study_id, numbers_of[study_id]) for study_id, name in names.items()}
        return [StudyRows(name=name, attrs=attrs[study_id],
                          maximize=maximize.get(study_id, False), trials=rows[study_id],
                          provenance=provenance[study_id])
                for study_id, name in names.items()]


def _read_studies(connection: sa.Connection) -> tuple[
        dict[int, str], dict[int, StudyAttrs], dict[int, bool], dict[int, dict[str, Any]]]:
    """By study id, in creation order: names, attributes, whether the first objective is
    maximised, and the provenance records by key."""
    names = dict(connection.execute(
        sa.select(_studies.c.study_id, _studies.c.study_name)
        .order_by(_studies.c.study_id)).all())
    stored: dict[int, dict[str, Any]] = defaultdict(dict)
    for study_id, key, value_json in connection.execute(
            sa.select(_study_attrs.c.study_id, _study_attrs.c.key, _study_attrs.c.value_json)):
        stored[study_id][key] = json.loads(value_json)
    maximize = {study_id: direction == "MAXIMIZE" for study_id, direction in
                connection.execute(sa.select(_directions.c.study_id, _directions.c.direction)
                                   .where(_directions.c.objective == 0))}
    provenance = {study_id: {key[len(PROVENANCE_PREFIX):]: value
                             for key, value in stored[study_id].items()
                             if key.startswith(PROVENANCE_PREFIX) and isinstance(value, dict)}
                  for study_id in names}
    return (names, {study_id: StudyAttrs.of(stored[study_id]) for study_id in names}, maximize,
            provenance)


def _read_values(connection: sa.Connection) -> dict[int, list[float]]:
    """Every trial's values by trial id, objective by objective."""
    values: dict[int, list[float]] = defaultdict(list)
    for trial_id, value, value_type in connection.execute(
            sa.select(_values.c.trial_id, _values.c.value, _values.c.value_type)
            .order_by(_values.c.trial_id, _values.c.objective)):
        values[trial_id].append(_value(value, value_type))
    return values


def _read_swept(connection: sa.Connection,
           swept: dict[int, str]) -> tuple[dict[int, Any], dict[int, str]]:
    """The swept studies' trials (by study id -> parameter name): trial id -> swept value, and
    trial id -> fixed_params JSON (the value a trial was queued with)."""
    if not swept:
        return {}, {}
    params: dict[int, Any] = {}
    decoded: dict[str, dict[str, Any]] = {}
    which = sa.or_(*(sa.and_(_trials.c.study_id == study_id, _params.c.param_name == name)
                     for study_id, name in swept.items()))
    for trial_id, value, distribution in connection.execute(
            sa.select(_params.c.trial_id, _params.c.param_value, _params.c.distribution_json)
            .join(_trials, _trials.c.trial_id == _params.c.trial_id).where(which)):
        if distribution not in decoded:
            decoded[distribution] = json.loads(distribution)
        params[trial_id] = _external(value, decoded[distribution])
    queued = dict(connection.execute(
        sa.select(_system_attrs.c.trial_id, _system_attrs.c.value_json)
        .join(_trials, _trials.c.trial_id == _system_attrs.c.trial_id)
        .where(_trials.c.study_id.in_(list(swept)),
               _system_attrs.c.key == "fixed_params")).all())
    return params, queued


def _value(value: float | None, value_type: str) -> float:
    """A stored trial value (Optuna's ``TrialValueModel.stored_repr_to_value``)."""
    if value_type == "INF_POS":
        return math.inf
    if value_type == "INF_NEG":
        return -math.inf
    assert value is not None
    return float(value)


def _external(value: float, distribution: dict[str, Any]) -> Any:
    """A parameter as Optuna gives it back (``json_to_distribution(...).to_external_repr``):
    a categorical's choice, an integer distribution's int, or the float itself."""
    kind = str(distribution.get("name") or distribution.get("type", ""))
    if kind in ("CategoricalDistribution", "categorical"):
        choices = (distribution["attributes"]["choices"] if "attributes" in distribution
                   else distribution["choices"])
        return choices[int(value)]
    if kind.startswith("Int") or kind == "int":
        return int(value)
    return value


@contextmanager
def read_only(url: str) -> Iterator[sa.Connection | None]:
    """A connection through the backend's read-only URL, which never creates or writes
    anything (a killed writer's journal aside, `_rolled_back`); None when there is nothing to read
    (a SQLite file not there yet). Errors of the database are the caller's to
    name."""
    reading = _reading_url(url)
    if reading is None:
        yield None
        return
    engine = sa.create_engine(reading, poolclass=sa.pool.NullPool)
    try:
        with engine.connect() as connection:
            yield connection
    finally:
        engine.dispose()


def _rolled_back(path: Path) -> None:
    """Roll back the journal a writer killed mid-transaction left beside a SQLite file.

    SQLite undoes such a hot journal on the next read of a connection that may write; a
    read-only connection refuses the file until then ("attempt to write a readonly database"),
    so a study whose command was killed while writing could be neither read nor resumed. The
    rollback restores the last committed state, as the next writer would, and writes nothing
    else. The journal of a writer still at work is not hot, and the read leaves it alone.
    """
    if not Path(f"{path}-journal").exists():
        return
    try:
        connection = sqlite3.connect(f"file:{path}?mode=rw", uri=True, timeout=SQLITE_PATIENCE)
    except sqlite3.Error:
        return  # not writable here: the read-only open that follows names the problem
    try:
        connection.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except sqlite3.Error:
        pass  # likewise
    finally:
        connection.close()


def _reading_url(url: str) -> str | None:
    """The backend's read-only URL ([`reading_url`][kraby_study.store.url.reading_url]), a SQLite
    file's journal rolled back first if a killed writer left one."""
    path = sqlite_path(url)
    if path is not None and path.exists():
        _rolled_back(path)
    return reading_url(url)


def has_store(url: str) -> bool:
    """Whether Optuna's tables are at ``url``, read without creating or writing anything: False
    for a SQLite file not there yet or without them, and for a database without them.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: The database cannot be reached; one line.
    """
    check_url(url)
    try:
        with read_only(url) as connection:
            return connection is not None and sa.inspect(connection).has_table(
                _version_info.name)
    except sa.exc.SQLAlchemyError as err:
        raise StoreError(f"cannot open the store {url}: {first_line(err)}") from None


@contextmanager
def reading(url: str) -> Iterator[StoreReader]:
    """An existing store opened for reading without Optuna, closed on exit."""
    reader = StoreReader(url)
    try:
        yield reader
    finally:
        reader.close()
