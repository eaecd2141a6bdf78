"""A study store: Optuna's tables plus the learning curves, at a database URL.

Together with [`kraby_study.store.ledger`][] the only code that talks to the database. Optuna's RDB
storage is the trial ledger of every study (sweeps, searches and single runs), so
``optuna.load_study`` and optuna-dashboard read everything; learning curves live beside it in one
table ([`kraby_study.store.tables`][]). What differs between SQLite and PostgreSQL is in
[`kraby_study.store.backend`][].
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import Any

import optuna
import sqlalchemy as sa
from optuna.storages import RDBStorage

from kraby_study.errors import StoreError, first_line
from kraby_study.records.attributes import StudyAttrs
from kraby_study.store.backend import LOCK_BASE, Backend, backend_for, check_store_file
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.rows import read_only
from kraby_study.store.tables import drop_orphan_curves, metadata
from kraby_study.store.url import check_url, sqlite_path

# Heartbeats and stale-trial failing are marked experimental by Optuna; they are what several
# machines on one study rely on, so the warning would only alarm users.
warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
# Optuna's own INFO line per trial would repeat the command's progress lines.
optuna.logging.set_verbosity(optuna.logging.WARNING)

LOST_DATABASE = (sa.exc.OperationalError, sa.exc.InterfaceError)
"""The errors of a database out of reach (a server restarting, a network cut): worth a retry."""


class Store:
    """A study store at a database URL: Optuna's tables plus the learning curves."""

    def __init__(self, url: str, *, create: bool = True, writer: bool = True,
                 heartbeat_interval: int = 5, heartbeat_grace: int = 30) -> None:
        self.url = url
        self.backend: Backend = backend_for(url, create=create, writer=writer,
                                            heartbeat_interval=heartbeat_interval,
                                            heartbeat_grace=heartbeat_grace)
        self.storage: RDBStorage | None = None
        try:
            with self.backend.schema_lock(create):
                self.storage = RDBStorage(url, skip_table_creation=not create,
                                          **self.backend.storage_kwargs())
                if create:
                    metadata.create_all(self.storage.engine)
                if create and writer:
                    with self.storage.engine.begin() as connection:
                        drop_orphan_curves(connection)
        except (sa.exc.SQLAlchemyError, optuna.exceptions.OptunaError, RuntimeError,
                ValueError) as err:
            self.close()
            # Optuna wraps the driver's error in a generic one: name the cause.
            cause = err.__cause__ if isinstance(err, optuna.exceptions.OptunaError) else None
            raise StoreError(f"cannot open the store {url}: {first_line(cause or err)}") from None
        self.engine = self.storage.engine

    @property
    def exclusive(self) -> bool:
        """True when this process is the store's only writer (a locked SQLite file)."""
        return self.backend.exclusive

    def close(self) -> None:
        """Release the writer lock and the connections."""
        if self.storage is not None:
            self.storage.engine.dispose()
        self.backend.close()

    def server_lock(self, key: int) -> AbstractContextManager[None]:
        """A lock shared by every command on the database (nothing on a locked SQLite file)."""
        return self.backend.server_lock(self.engine, key)

    # studies ---------------------------------------------------------------------------------

    def study_names(self) -> list[str]:
        """Names of every study in the store."""
        assert self.storage is not None
        return [s.study_name for s in self.storage.get_all_studies()]

    def load(self, name: str) -> StudyLedger:
        """An existing study; StoreError if there is none of that name."""
        try:
            study = optuna.load_study(study_name=name, storage=self.storage)
        except KeyError:
            raise StoreError(f"no study named {name!r} in {self.url}") from None
        return self._ledger(study)

    def define(self, name: str, attrs: StudyAttrs,
               sampler: optuna.samplers.BaseSampler | None = None,
               pruner: optuna.pruners.BasePruner | None = None,
               directions: list[str] | None = None) -> StudyLedger:
        """Create a study, or load it after checking it was defined the same way.

        ``directions``: Optuna's, one per objective (default: one maximised score). A stored
        study keeps its own; its definition says how many objectives it has, so a change is
        refused as a changed definition.

        Raises:
            StoreError: A study of that name was defined differently; the message names the
                first changed settings.
        """
        # On a server, commands starting at once must not both take the study as new.
        with self.server_lock(LOCK_BASE):
            study = optuna.create_study(study_name=name, storage=self.storage, sampler=sampler,
                                        pruner=pruner, directions=directions or ["maximize"],
                                        load_if_exists=True)
            stored = StudyAttrs.of(study.user_attrs)
            if stored.fingerprint is None:
                for key, value in attrs.stored().items():
                    study.set_user_attr(key, value)
        check_same_definition(name, self.url, stored, attrs)
        return self._ledger(study)

    def _ledger(self, study: optuna.Study) -> StudyLedger:
        assert self.storage is not None
        return StudyLedger(study, self.storage, self.backend)


def check_same_definition(name: str, url: str, stored: StudyAttrs, attrs: StudyAttrs) -> None:
    """Refuse a study stored under ``name`` with another definition than ``attrs``.

    Raises:
        StoreError: The fingerprints differ; the message names the first changed settings.
    """
    if stored.fingerprint is not None and stored.fingerprint != attrs.fingerprint:
        changed = describe_change(stored.definition, attrs.definition)
        raise StoreError(f"study {name!r} in {url} was defined differently ({changed}); "
                         "choose another name (run: study.name=..., optuna: --study-name, confirm: "
                         "confirm.name=...) or another storage")


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


def study_exists(url: str, name: str) -> bool:
    """Whether a study of that name is stored, read without creating or writing anything.

    Loading a study through Optuna creates its tables when they are missing, which would race a
    command still creating them: this reads through the backend's read-only URL, and on SQLite
    any error there (no file or table yet) reads as no study.
    """
    try:
        with read_only(url) as conn:
            return conn is not None and sa.inspect(conn).has_table("studies") and conn.execute(
                sa.text("SELECT 1 FROM studies WHERE study_name = :n"), {"n": name}
            ).first() is not None
    except sa.exc.DBAPIError:
        if sqlite_path(url) is None:
            raise
        return False


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
    check_url(url)
    path = sqlite_path(url)
    if path is not None:
        check_store_file(path)
    with opened(url, create=False, writer=False) as store:
        try:
            names = store.study_names()
        except (sa.exc.SQLAlchemyError, optuna.exceptions.OptunaError) as err:
            raise StoreError(f"cannot read the store {url}: {first_line(err)}") from None
        if not names:
            raise StoreError(f"no studies in {url}: run one first (kraby-study run ...)")
        yield store
