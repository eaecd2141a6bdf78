"""The two databases a store may live in, behind one small interface.

SQLite allows one writer: a command that writes holds an exclusive lock on ``<db>.lock`` for its
whole life, and its parent process is the only one that writes. PostgreSQL takes many writers:
there, commands serialise creating tables and defining studies with advisory locks, and trials
whose owner stopped sending heartbeats are failed and queued again.
"""

from __future__ import annotations

import fcntl
import os
import sqlite3
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import IO, Any, Protocol

import sqlalchemy as sa

from kraby_study.errors import StoreError
from kraby_study.store.attempts import requeue_stale
from kraby_study.store.tables import OPTUNA_TABLES
from kraby_study.store.url import check_url, sqlite_path

LOCK_BASE = 0x6B726162 * 1000
"""PostgreSQL advisory-lock keys: LOCK_BASE while a command creates the tables or defines a
study, LOCK_BASE plus a study's id while one queues that study's trials ("krab" in ASCII)."""
SQLITE_MAGIC = b"SQLite format 3\x00"


class Backend(Protocol):
    """What differs between the databases a store may live in."""

    url: str

    @property
    def exclusive(self) -> bool:
        """True when this process is the store's only writer."""
        ...

    def storage_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of Optuna's ``RDBStorage`` for this database."""
        ...

    def schema_lock(self, create: bool) -> AbstractContextManager[None]:
        """Held while the tables are created, so that commands starting at once do not race."""
        ...

    def server_lock(self, engine: sa.Engine, key: int) -> AbstractContextManager[None]:
        """A lock shared by every command on the database (nothing where one writer is all)."""
        ...

    def close(self) -> None:
        """Let go of what the backend holds (a writer lock)."""
        ...


class SqliteBackend:
    """A SQLite file: one writer, the command holding ``<db>.lock``."""

    def __init__(self, url: str, *, create: bool, writer: bool) -> None:
        path = sqlite_path(url)
        assert path is not None
        self.url = url
        self.path = path
        self._lock_file: IO[str] | None = None
        if not create and not path.is_file():
            raise StoreError(f"no study store at {path}")
        path.parent.mkdir(parents=True, exist_ok=True)
        if writer:
            self._lock()

    @property
    def exclusive(self) -> bool:
        """True while this process holds the writer lock."""
        return self._lock_file is not None

    def storage_kwargs(self) -> dict[str, Any]:
        """A patient connection (another reader may hold the file briefly)."""
        return {"engine_kwargs": {"connect_args": {"timeout": 60}}}

    def schema_lock(self, create: bool) -> AbstractContextManager[None]:
        """Nothing: the file lock already serialises writers."""
        return nullcontext()

    def server_lock(self, engine: sa.Engine, key: int) -> AbstractContextManager[None]:
        """Nothing: the file lock already makes this command the only writer."""
        return nullcontext()

    def _lock(self) -> None:
        lock_path = self.path.with_name(self.path.name + ".lock")
        handle = open(lock_path, "a+")  # noqa: SIM115 - held open for the command's life
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            owner = handle.read().strip() or "?"
            handle.close()
            raise StoreError(f"{self.path} is in use by another kraby-study command (pid "
                             f"{owner}); SQLite takes one writer: wait for it, or use "
                             "PostgreSQL to run several at once") from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        self._lock_file = handle

    def close(self) -> None:
        """Release the writer lock."""
        if self._lock_file is not None:
            fcntl.flock(self._lock_file, fcntl.LOCK_UN)
            self._lock_file.close()
            self._lock_file = None


class PostgresBackend:
    """A PostgreSQL server: many writers, advisory locks and heartbeats."""

    def __init__(self, url: str, *, heartbeat_interval: int, heartbeat_grace: int) -> None:
        self.url = url
        self.heartbeat_interval = heartbeat_interval
        self.heartbeat_grace = heartbeat_grace

    @property
    def exclusive(self) -> bool:
        """Never: other commands may write at the same time."""
        return False

    def storage_kwargs(self) -> dict[str, Any]:
        """Connections checked before use (a server may restart), and heartbeats whose lapse
        queues a trial again."""
        return {"engine_kwargs": {"pool_pre_ping": True},
                "heartbeat_interval": self.heartbeat_interval,
                "grace_period": self.heartbeat_grace,
                "heartbeat_stale_trial_callback": requeue_stale}

    @contextmanager
    def schema_lock(self, create: bool) -> Iterator[None]:
        """PostgreSQL's CREATE TABLE races with itself: commands starting at once on an empty
        database would fail with a duplicate type."""
        if not create:
            yield
            return
        engine = sa.create_engine(self.url, poolclass=sa.pool.NullPool)
        try:
            with advisory_lock(engine, LOCK_BASE):
                yield
        finally:
            engine.dispose()

    def server_lock(self, engine: sa.Engine, key: int) -> AbstractContextManager[None]:
        """An advisory lock shared by every command on the server."""
        return advisory_lock(engine, key)

    def close(self) -> None:
        """Nothing to let go."""


def backend_for(url: str, *, create: bool = True, writer: bool = True,
                heartbeat_interval: int = 5, heartbeat_grace: int = 30) -> Backend:
    """The backend of a database URL (checked first).

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: A SQLite file that must exist does not, or is in use by another writer.
    """
    check_url(url)
    if sqlite_path(url) is not None:
        return SqliteBackend(url, create=create, writer=writer)
    return PostgresBackend(url, heartbeat_interval=heartbeat_interval,
                           heartbeat_grace=heartbeat_grace)


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


def check_store_file(path: Path) -> None:
    """Refuse a SQLite file that is missing, empty, not a database, or not a study store.

    SQLAlchemy and Optuna would both create an empty database at a wrong path: readers check
    first.

    Raises:
        StoreError: The file cannot be a study store; one line.
    """
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
