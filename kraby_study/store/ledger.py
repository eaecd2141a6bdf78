"""The only module that talks to the database.

Optuna's RDB storage is the trial ledger of every study (sweeps, searches and single runs), so
``optuna.load_study`` and optuna-dashboard read everything. Learning curves live beside it in one
table, ``kraby_curve_points``, keyed by Optuna's trial id.

SQLite allows one writer: a command that writes holds an exclusive lock on ``<db>.lock`` for its
whole life, and its parent process is the only one that writes. PostgreSQL takes many writers;
there, trials whose owner stopped sending heartbeats are failed and queued again.
"""

from __future__ import annotations

import fcntl
import json
import os
import warnings
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from typing import IO, Any

import optuna
import sqlalchemy as sa
from optuna.storages import RDBStorage
from optuna.trial import FrozenTrial, TrialState

from kraby_study.config import sqlite_path
from kraby_study.messages import first_line

KIND = "kraby_kind"
DEFINITION = "kraby_definition"
FINGERPRINT = "kraby_fingerprint"
PLANNED = "kraby_planned"
RETRY_OF = "retry_of"
INTERRUPTED = "interrupted"
# PostgreSQL advisory-lock keys: LOCK_BASE while a command creates the tables or defines a study,
# LOCK_BASE plus a study's id while one queues that study's trials ("krab" in ASCII, shifted).
LOCK_BASE = 0x6B726162 * 1000

# Heartbeats and stale-trial failing are marked experimental by Optuna; they are what several
# machines on one study rely on, so the warning would only alarm users.
warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)

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


class StoreError(RuntimeError):
    """The store cannot be used as asked; the message is one line."""


def requeue(study: optuna.Study, trial: FrozenTrial) -> None:
    """Queue a fresh attempt of an interrupted trial; the later attempt supersedes it.

    Also Optuna's heartbeat callback, for trials whose owner stopped sending heartbeats.
    """
    attrs = {k: v for k, v in trial.user_attrs.items() if k in ("key", "seed")}
    attrs[RETRY_OF] = trial.number
    params = trial.params or trial.system_attrs.get("fixed_params", {})
    study.enqueue_trial(params=dict(params), user_attrs=attrs)


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
            heartbeat = {"heartbeat_interval": heartbeat_interval,
                         "grace_period": heartbeat_grace,
                         "heartbeat_stale_trial_callback": requeue}
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

    # studies ---------------------------------------------------------------------------------

    def study_names(self) -> list[str]:
        """Names of every study in the store."""
        return [s.study_name for s in self.storage.get_all_studies()]

    def load(self, name: str) -> optuna.Study:
        """An existing study; StoreError if there is none of that name."""
        try:
            return optuna.load_study(study_name=name, storage=self.storage)
        except KeyError:
            raise StoreError(f"no study named {name!r} in {self.url}") from None

    def open_study(self, name: str, kind: str, definition: dict[str, Any], fingerprint: str,
                   sampler: optuna.samplers.BaseSampler | None = None,
                   pruner: optuna.pruners.BasePruner | None = None) -> optuna.Study:
        """Create a study, or load it after checking it was defined the same way."""
        # On a server, commands starting at once must not both take the study as new.
        with self._server_lock(LOCK_BASE):
            study = optuna.create_study(study_name=name, storage=self.storage, sampler=sampler,
                                        pruner=pruner, direction="maximize",
                                        load_if_exists=True)
            stored = study.user_attrs.get(FINGERPRINT)
            if stored is None:
                study.set_user_attr(KIND, kind)
                study.set_user_attr(DEFINITION, definition)
                study.set_user_attr(FINGERPRINT, fingerprint)
        if stored is not None and stored != fingerprint:
            old = study.user_attrs.get(DEFINITION, {})
            changed = describe_change(old, definition)
            raise StoreError(f"study {name!r} in {self.url} was defined differently ({changed}); "
                             "choose another name (study.name=...) or another storage")
        return study

    def plan_lock(self, study: optuna.Study) -> AbstractContextManager[None]:
        """Serialise queueing a study's trials across machines (a locked SQLite file already is)."""
        return self._server_lock(LOCK_BASE + study._study_id)

    def _server_lock(self, key: int) -> AbstractContextManager[None]:
        """An advisory lock shared by every command on a PostgreSQL server; nothing on SQLite,
        where the file lock already makes a command the only writer."""
        return nullcontext() if self.db_path is not None else advisory_lock(self.engine, key)

    # trials ----------------------------------------------------------------------------------

    def fail_orphans(self, study: optuna.Study) -> int:
        """Queue again the trials a stopped command left running; returns how many."""
        if self.exclusive:
            orphans = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
            for trial in orphans:
                self.give_back(study, trial._trial_id, f"{INTERRUPTED}: its command stopped")
            return len(orphans)
        before = len(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)))
        optuna.storages.fail_stale_trials(study)
        after = len(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)))
        return before - after

    def claim(self, study: optuna.Study, keys: set[str]) -> FrozenTrial | None:
        """Take a waiting trial whose key is planned; atomic, so no two workers take the same."""
        waiting = study.get_trials(deepcopy=False, states=(TrialState.WAITING,))
        for trial in sorted(waiting, key=lambda t: t.number):
            if trial.user_attrs.get("key") not in keys:
                continue
            if self.storage.set_trial_state_values(trial._trial_id, TrialState.RUNNING):
                self.heartbeat(trial._trial_id)
                return self.storage.get_trial(trial._trial_id)
        return None

    def give_back(self, study: optuna.Study, trial_id: int, reason: str) -> None:
        """Fail a trial that will not finish here, saying why, and queue a new attempt."""
        try:
            self.storage.set_trial_user_attr(trial_id, "failure", reason)
            failed = self.storage.set_trial_state_values(trial_id, TrialState.FAIL)
        except optuna.exceptions.UpdateFinishedTrialError:
            return  # another process finished or gave it back first
        if failed:
            requeue(study, self.storage.get_trial(trial_id))

    def heartbeat(self, trial_id: int) -> None:
        """Tell other machines this trial's owner is alive (PostgreSQL only)."""
        if not self.exclusive:
            self.storage.record_heartbeat(trial_id)

    def set_attrs(self, trial_id: int, attrs: dict[str, Any]) -> None:
        """Store user attributes of a trial."""
        for key, value in attrs.items():
            self.storage.set_trial_user_attr(trial_id, key, value)

    def write_curve(self, study_id: int, trial_id: int, points: list[Any]) -> None:
        """Replace a trial's learning curve with the given points."""
        rows = [{"study_id": study_id, "trial_id": trial_id, "step": p.step,
                 "mean_reward": p.mean_reward, "wall_time": p.wall_time, "episodes": p.episodes}
                for p in points]
        with self.engine.begin() as conn:
            conn.execute(curve_points.delete().where(curve_points.c.trial_id == trial_id))
            if rows:
                conn.execute(curve_points.insert(), rows)

    def curves(self, study: optuna.Study) -> list[dict[str, Any]]:
        """Every curve point of a study, as rows."""
        query = sa.select(curve_points).where(curve_points.c.study_id == study._study_id)
        try:
            with self.engine.connect() as conn:
                return [dict(row._mapping) for row in conn.execute(query)]
        except sa.exc.OperationalError:
            return []


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


def record_result(store: Store, study: optuna.Study, trial_id: int, result: Any) -> None:
    """Store a finished trial: its curve, its attributes, then its final state."""
    store.write_curve(study._study_id, trial_id, result.curve)
    attrs: dict[str, Any] = {"status": result.status, "env_steps": result.env_steps,
                             "wall_time": result.wall_time, "started": result.started,
                             "ended": result.ended}
    for name in ("failure", "final_score", "train_reward", "pruned_at"):
        if getattr(result, name) is not None:
            attrs[name] = getattr(result, name)
    store.set_attrs(trial_id, attrs)
    trial = optuna.Trial(study, trial_id)
    if result.status == "complete":
        study.tell(trial, result.final_score)
    elif result.status == "pruned":
        study.tell(trial, state=TrialState.PRUNED)
    else:
        study.tell(trial, state=TrialState.FAIL)
