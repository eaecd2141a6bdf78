"""The store's connection: URLs, the engine, the writer lock, the tables, the list of studies.

Together with :mod:`kraby_study.store.ledger` this is the only code that talks to the database.
Optuna's RDB storage is the trial ledger of every study (sweeps, searches and single runs), so
``optuna.load_study`` and optuna-dashboard read everything; learning curves live beside it in
one table, ``kraby_curve_points``.

SQLite allows one writer: a command that writes holds an exclusive lock on ``<db>.lock`` for its
whole life, and its parent process is the only one that writes. PostgreSQL takes many writers;
there, trials whose owner stopped sending heartbeats are failed and queued again.
"""

from __future__ import annotations

import fcntl
import json
import os
import sqlite3
import warnings
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import optuna
import sqlalchemy as sa
from optuna.storages import RDBStorage

from kraby_study.errors import ConfigError, StoreError, first_line
from kraby_study.records import StudyAttrs

if TYPE_CHECKING:
    from kraby_study.store.ledger import StudyLedger

# PostgreSQL advisory-lock keys: LOCK_BASE while a command creates the tables or defines a study,
# LOCK_BASE plus a study's id while one queues that study's trials ("krab" in ASCII, shifted).
LOCK_BASE = 0x6B726162 * 1000
SQLITE_MAGIC = b"SQLite format 3\x00"
OPTUNA_TABLES = ("studies", "trials", "version_info")
POSTGRES_EXTRA = "pip install 'kraby-study[postgres]'"

# Heartbeats and stale-trial failing are marked experimental by Optuna; they are what several
# machines on one study rely on, so the warning would only alarm users.
warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)

LOST_DATABASE = (sa.exc.OperationalError, sa.exc.InterfaceError)
"""The errors of a database out of reach (a server restarting, a network cut): worth a retry."""

metadata = sa.MetaData()
curve_points = sa.Table(
    "kraby_curve_points", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("study_id", sa.Integer, nullable=False, index=True),
    sa.Column("trial_id", sa.Integer, nullable=False, index=True),
    sa.Column("step", sa.Integer, nullable=False),
    sa.Column("mean_reward", sa.Float, nullable=False),
    sa.Column("wall_time", sa.Float, nullable=False),
    sa.Column("episodes", sa.Integer, nullable=False),
)


def check_url(url: str) -> None:
    """Refuse database URLs other than SQLite files and PostgreSQL servers with a driver.

    Raises:
        ConfigError: Not a URL, another database, an in-memory SQLite, or a PostgreSQL URL
            whose driver is not installed; one line.
    """
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        parsed = make_url(url)
    except ArgumentError:
        raise ConfigError(f"storage {url!r} is not a database URL (e.g. sqlite:///studies/"
                          "kraby.db or postgresql+psycopg://user@host/db)") from None
    backend = parsed.get_backend_name()
    if backend not in ("sqlite", "postgresql"):
        raise ConfigError(f"storage {url!r}: only sqlite and postgresql databases are supported")
    if backend == "sqlite" and (not parsed.database or parsed.database == ":memory:"):
        raise ConfigError(f"storage {url!r}: a SQLite store must be a file")
    if backend == "postgresql":
        try:
            parsed.get_dialect().import_dbapi()
        except (ImportError, NoSuchModuleError):
            driver = parsed.get_driver_name()
            raise ConfigError(f"storage {parsed.render_as_string()!r} needs the PostgreSQL "
                              f"driver {driver}, which is not installed: {POSTGRES_EXTRA} (and "
                              "write the URL as postgresql+psycopg://...)") from None


def sqlite_path(url: str) -> Path | None:
    """The file behind a SQLite URL, or None for other databases."""
    from sqlalchemy.engine import make_url

    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return None
    return Path(str(parsed.database))


def shown_url(url: str) -> str:
    """A database URL as reports show it, any password hidden."""
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


def check_store_file(url: str) -> None:
    """Refuse a SQLite store that is missing, empty, not a database, or not a study store.

    SQLAlchemy and Optuna would both create an empty database at a wrong path: readers check
    first. Servers are checked when connecting instead.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: The file cannot be a study store; one line.
    """
    check_url(url)
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


def study_exists(url: str, name: str) -> bool:
    """Whether a study of that name is stored, read without creating or writing anything.

    Loading a study through Optuna creates its tables when they are missing, which would race a
    command still creating them: this opens a SQLite file read-only, and any error there (no
    file or table yet) reads as no study.
    """
    path = sqlite_path(url)
    if path is not None:
        if not path.exists():
            return False
        url = f"sqlite:///file:{path}?mode=ro&uri=true"
    engine = sa.create_engine(url, poolclass=sa.pool.NullPool)
    try:
        with engine.connect() as conn:
            return sa.inspect(conn).has_table("studies") and conn.execute(
                sa.text("SELECT 1 FROM studies WHERE study_name = :n"), {"n": name}
            ).first() is not None
    except sa.exc.DBAPIError:
        if path is None:
            raise
        return False
    finally:
        engine.dispose()


@contextmanager
def advisory_lock(engine: sa.Engine, key: int) -> Iterator[None]:
    """Hold a PostgreSQL session lock, shared by every command on the server, for a block."""
    with engine.connect() as conn:
        conn.execute(sa.text("SELECT pg_advisory_lock(:k)"), {"k": key})
        try:
            yield
        finally:
            conn.execute(sa.text("SELECT pg_advisory_unlock(:k)"), {"k": key})
            conn.commit()


class Store:
    """A study store at a database URL: Optuna's tables plus the learning curves."""

    def __init__(self, url: str, *, create: bool = True, writer: bool = True,
                 heartbeat_interval: int = 5, heartbeat_grace: int = 30) -> None:
        check_url(url)
        self.url = url
        self.db_path = sqlite_path(url)
        self._lock_file: IO[str] | None = None
        if self.db_path is not None:
            if not create and not self.db_path.is_file():
                raise StoreError(f"no study store at {self.db_path}")
            self.db_path.parent.mkdir(parents=True, exist_ok=True)
            if writer:
                self._lock()
        heartbeat: dict[str, Any] = {}
        if self.db_path is None:
            from kraby_study.store.ledger import requeue_stale

            heartbeat = {"heartbeat_interval": heartbeat_interval,
                         "grace_period": heartbeat_grace,
                         "heartbeat_stale_trial_callback": requeue_stale}
        engine_kwargs: dict[str, Any] = (
            {"connect_args": {"timeout": 60}} if self.db_path is not None
            else {"pool_pre_ping": True})
        try:
            with self._schema_lock(create):
                self.storage = RDBStorage(url, engine_kwargs=engine_kwargs,
                                          skip_table_creation=not create, **heartbeat)
                if create:
                    metadata.create_all(self.storage.engine)
        except (sa.exc.SQLAlchemyError, optuna.exceptions.OptunaError, RuntimeError,
                ValueError) as err:
            self.close()
            # Optuna wraps the driver's error in a generic one: name the cause.
            cause = err.__cause__ if isinstance(err, optuna.exceptions.OptunaError) else None
            raise StoreError(f"cannot open the store {url}: {first_line(cause or err)}") from None
        self.engine = self.storage.engine

    @contextmanager
    def _schema_lock(self, create: bool) -> Iterator[None]:
        """Serialise creating the tables across commands on one server.

        PostgreSQL's CREATE TABLE races with itself: commands starting at once on an empty
        database would fail with a duplicate type. SQLite needs nothing: the file lock serialises.
        """
        if self.db_path is not None or not create:
            yield
            return
        engine = sa.create_engine(self.url, poolclass=sa.pool.NullPool)
        try:
            with advisory_lock(engine, LOCK_BASE):
                yield
        finally:
            engine.dispose()

    def _lock(self) -> None:
        assert self.db_path is not None
        lock_path = self.db_path.with_name(self.db_path.name + ".lock")
        handle = open(lock_path, "a+")  # noqa: SIM115 - held open for the command's life
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            owner = handle.read().strip() or "?"
            handle.close()
            raise StoreError(f"{self.db_path} is in use by another kraby-study command (pid "
                             f"{owner}); SQLite takes one writer: wait for it, or use "
                             "PostgreSQL to run several at once") from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        self._lock_file = handle

    @property
    def exclusive(self) -> bool:
        """True when this process is the store's only writer (a locked SQLite file)."""
        return self._lock_file is not None

    def close(self) -> None:
        """Release the writer lock and the connections."""
        storage = getattr(self, "storage", None)
        if storage is not None:
            storage.engine.dispose()
        if self._lock_file is not None:
            fcntl.flock(self._lock_file, fcntl.LOCK_UN)
            self._lock_file.close()
            self._lock_file = None

    def server_lock(self, key: int) -> AbstractContextManager[None]:
        """An advisory lock shared by every command on a PostgreSQL server; nothing on SQLite,
        where the file lock already makes a command the only writer."""
        return nullcontext() if self.db_path is not None else advisory_lock(self.engine, key)

    # studies ---------------------------------------------------------------------------------

    def study_names(self) -> list[str]:
        """Names of every study in the store."""
        return [s.study_name for s in self.storage.get_all_studies()]

    def load(self, name: str) -> StudyLedger:
        """An existing study; StoreError if there is none of that name."""
        try:
            study = optuna.load_study(study_name=name, storage=self.storage)
        except KeyError:
            raise StoreError(f"no study named {name!r} in {self.url}") from None
        from kraby_study.store.ledger import StudyLedger

        return StudyLedger(self, study)

    def define(self, name: str, attrs: StudyAttrs,
               sampler: optuna.samplers.BaseSampler | None = None,
               pruner: optuna.pruners.BasePruner | None = None) -> StudyLedger:
        """Create a study, or load it after checking it was defined the same way.

        Raises:
            StoreError: A study of that name was defined differently; the message names the
                first changed settings.
        """
        # On a server, commands starting at once must not both take the study as new.
        with self.server_lock(LOCK_BASE):
            study = optuna.create_study(study_name=name, storage=self.storage, sampler=sampler,
                                        pruner=pruner, direction="maximize",
                                        load_if_exists=True)
            stored = StudyAttrs.of(study.user_attrs)
            if stored.fingerprint is None:
                for key, value in attrs.stored().items():
                    study.set_user_attr(key, value)
        check_same_definition(name, self.url, stored, attrs)
        from kraby_study.store.ledger import StudyLedger

        return StudyLedger(self, study)


def check_same_definition(name: str, url: str, stored: StudyAttrs, attrs: StudyAttrs) -> None:
    """Refuse a study stored under ``name`` with another definition than ``attrs``.

    Raises:
        StoreError: The fingerprints differ; the message names the first changed settings.
    """
    if stored.fingerprint is not None and stored.fingerprint != attrs.fingerprint:
        changed = describe_change(stored.definition, attrs.definition)
        raise StoreError(f"study {name!r} in {url} was defined differently ({changed}); "
                         "choose another name (study.name=...) or another storage")


def describe_change(old: dict[str, Any], new: dict[str, Any], prefix: str = "") -> str:
    """The first differing entries of two definitions, for a one-line message."""
    changes: list[str] = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            inner = describe_change(a, b, f"{prefix}{key}.")
            if inner:
                changes.append(inner)
        elif json.dumps(a, default=str) != json.dumps(b, default=str):
            changes.append(f"{prefix}{key}: {a} -> {b}")
    return ", ".join(changes[:3])


@contextmanager
def opened(url: str, **kwargs: Any) -> Iterator[Store]:
    """A store closed on exit."""
    store = Store(url, **kwargs)
    try:
        yield store
    finally:
        store.close()


@contextmanager
def opened_for_reading(url: str) -> Iterator[Store]:
    """An existing store holding at least one study, opened read-only and never created.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: The store is missing, unreadable or holds no study; one line.
    """
    check_store_file(url)
    with opened(url, create=False, writer=False) as store:
        try:
            names = store.study_names()
        except (sa.exc.SQLAlchemyError, optuna.exceptions.OptunaError) as err:
            raise StoreError(f"cannot read the store {url}: {first_line(err)}") from None
        if not names:
            raise StoreError(f"no studies in {url}: run one first (kraby-study run ...)")
        yield store
