"""One study's ledger: queue, claim, ask, record, heartbeat, requeue, and the curves.

With [`kraby_study.store.store`][] the only code that touches the database. Outside the store a
trial is named by its number in its study; Optuna's internal ids stay in here.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence
from contextlib import AbstractContextManager
from datetime import datetime
from typing import TYPE_CHECKING, Any

import optuna
from optuna.distributions import BaseDistribution
from optuna.storages import RDBStorage
from optuna.trial import FrozenTrial, TrialState

from kraby_study.records.attributes import (
    PROVENANCE_PREFIX,
    CurvePoint,
    StudyAttrs,
    TrialAttrs,
    TrialResult,
    provenance_key,
    retry_facts,
)
from kraby_study.records.stored import Failure, Outcome, counted, failure, is_diverged, outcome
from kraby_study.store.attempts import queue_attempt, requeue_stale
from kraby_study.store.backend import LOCK_BASE, Backend
from kraby_study.store.tables import curve_points, read_curves

if TYPE_CHECKING:
    import pandas as pd


class StudyLedger:
    """The trials of one stored study, read and written through the store."""

    def __init__(self, study: optuna.Study, storage: RDBStorage, backend: Backend) -> None:
        self._study = study
        self._storage = storage
        self._backend = backend
        self._study_id = self._storage.get_study_id_from_name(study.study_name)
        self._ids: dict[int, int] = {}
        self._provenance_keys: set[str] = set()

    # the study -------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The study's name."""
        return self._study.study_name

    @property
    def attrs(self) -> StudyAttrs:
        """What kraby-study stored on the study."""
        return StudyAttrs.of(self._study.user_attrs)

    @property
    def maximize(self) -> bool:
        """Whether higher values are better (kraby-study's studies all maximise)."""
        return self._study.directions[0] == optuna.study.StudyDirection.MAXIMIZE

    @property
    def objectives(self) -> int:
        """How many objectives the study has: one, or a score and a cost (a two-objective
        search)."""
        return len(self._study.directions)

    def update(self, attrs: StudyAttrs) -> None:
        """Store the fields that are set in ``attrs`` (e.g. a new planned total)."""
        for key, value in attrs.stored().items():
            self._study.set_user_attr(key, value)

    @property
    def exclusive(self) -> bool:
        """True when this command is the store's only writer (a locked SQLite file): every
        running trial is then its own."""
        return self._backend.exclusive

    def plan_lock(self) -> AbstractContextManager[None]:
        """Serialise queueing this study's trials across machines (a locked SQLite file
        already is)."""
        return self._backend.server_lock(self._storage.engine, LOCK_BASE + self._study_id)

    # reading ---------------------------------------------------------------------------------

    def trials(self, *states: TrialState) -> list[FrozenTrial]:
        """The study's trials (of the given states, or all), in number order."""
        found = self._study.get_trials(deepcopy=False, states=states or None)
        for trial in found:
            self._ids[trial.number] = trial._trial_id
        return sorted(found, key=lambda t: t.number)

    def curves(self, numbers: Collection[int] | None = None) -> pd.DataFrame:
        """Learning-curve points (columns ``CURVE_COLUMNS``) of the given trials, or all, in one
        query, sorted by trial and step; empty for a plain Optuna store."""
        if numbers is None or any(n not in self._ids for n in numbers):
            self.trials()  # the ids of every trial, in one query
        numbers_of = {trial_id: number for number, trial_id in self._ids.items()}
        with self._storage.engine.connect() as connection:
            return read_curves(connection, self._study_id, numbers_of, numbers)

    # writing ---------------------------------------------------------------------------------

    def _id(self, number: int) -> int:
        if number not in self._ids:
            self._ids[number] = self._storage.get_trial_id_from_study_id_trial_number(
                self._study_id, number)
        return self._ids[number]

    def use_sampler(self, sampler: optuna.samplers.BaseSampler) -> None:
        """Draw this command's new trials with ``sampler`` (stored trials are kept)."""
        self._study.sampler = sampler

    def queue(self, params: Mapping[str, Any], attrs: TrialAttrs) -> None:
        """Queue a trial with fixed parameters, to be claimed or asked for later."""
        self._study.enqueue_trial(params=dict(params), user_attrs=attrs.stored())

    def claim(self, keys: Collection[str],
              choices: Mapping[str, Sequence[Any]]) -> FrozenTrial | None:
        """Take the first waiting trial whose key is one of ``keys``; atomic, so no two workers
        take the same. Its queued parameters are recorded as categorical ones over
        ``choices``."""
        for trial in self.trials(TrialState.WAITING):
            if trial.user_attrs.get("key") not in keys:
                continue
            trial_id = self._id(trial.number)
            if self._storage.set_trial_state_values(trial_id, TrialState.RUNNING):
                self.heartbeat([trial.number])
                live = optuna.Trial(self._study, trial_id)
                for name, values in choices.items():
                    live.suggest_categorical(name, list(values))
                return self._storage.get_trial(trial_id)
        return None

    def ask(self, distributions: Mapping[str, BaseDistribution]) -> FrozenTrial:
        """A new running trial, its parameters drawn by the sampler from ``distributions`` (or
        fixed, for a queued retry)."""
        trial = self._study.ask(fixed_distributions=dict(distributions))
        self._ids[trial.number] = trial._trial_id
        self.heartbeat([trial.number])
        return self._storage.get_trial(trial._trial_id)

    def set_attrs(self, number: int, attrs: TrialAttrs) -> None:
        """Store the fields that are set in ``attrs`` on a trial."""
        trial_id = self._id(number)
        for key, value in attrs.stored().items():
            self._storage.set_trial_user_attr(trial_id, key, value)

    def note_provenance(self, number: int, facts: Mapping[str, str]) -> str:
        """Store what made a trial: the record once per study (``kraby_provenance:<key>``), its key
        on the trial; a failed trial queued again on purpose adds the attempt it retries and
        that attempt's failure ([`retry_facts`][kraby_study.records.attributes.retry_facts]).
        Returns the key."""
        facts = {**facts, **retry_facts(TrialAttrs.of(self._storage.get_trial(self._id(number))))}
        key = provenance_key(facts)
        if key not in self._provenance_keys:
            self._study.set_user_attr(PROVENANCE_PREFIX + key, dict(facts))
            self._provenance_keys.add(key)
        self.set_attrs(number, TrialAttrs(provenance=key))
        return key

    def provenances(self) -> dict[str, dict[str, str]]:
        """Every provenance record stored on the study, by key."""
        return {name[len(PROVENANCE_PREFIX):]: dict(value)
                for name, value in self._study.user_attrs.items()
                if name.startswith(PROVENANCE_PREFIX) and isinstance(value, dict)}

    def set_constraint(self, number: int, key: str, value: float) -> None:
        """Store one of a trial's constraint values (feasible at 0 or less), which Optuna's
        samplers read; set once, before the trial is told."""
        optuna.Trial(self._study, self._id(number)).set_constraint(key, value)

    def refuse(self, number: int, reason: str) -> None:
        """Fail a trial that cannot run (a sampled configuration the rules refuse)."""
        self.set_attrs(number, TrialAttrs(failure=reason))
        self._study.tell(number, state=TrialState.FAIL)

    def checkpoint(self, number: int, step: int, value: float) -> bool:
        """Record an intermediate value; False when the pruner stops the trial there."""
        trial = optuna.Trial(self._study, self._id(number))
        trial.report(value, step)
        return not trial.should_prune()

    def record(self, number: int, result: TrialResult) -> None:
        """Store a finished trial: its curve, its attributes, then its final state."""
        self.write_curves({number: result.curve})
        self.set_attrs(number, TrialAttrs(**vars(result.measures())))
        if result.outcome == Outcome.COMPLETE and self.objectives == 2:
            self._study.tell(number, [result.final_score, result.training_time()])
        elif result.outcome == Outcome.COMPLETE:
            self._study.tell(number, result.final_score)
        elif result.outcome == Outcome.PRUNED:
            self._study.tell(number, state=TrialState.PRUNED)
        else:
            self._study.tell(number, state=TrialState.FAIL)

    def withdraw(self, number: int, reason: str) -> bool:
        """End a queued trial that will never run (a raced value's queued retry once the value
        is dropped) as pruned, saying why; False when it had already left the queue."""
        trial_id = self._id(number)
        try:
            self._storage.set_trial_user_attr(trial_id, "failure", reason)
            return self._storage.set_trial_state_values(trial_id, TrialState.PRUNED)
        except optuna.exceptions.UpdateFinishedTrialError:
            return False

    def requeue(self, number: int, reason: str) -> None:
        """Give back a trial that will not finish here, saying why, and queue a new attempt."""
        trial_id = self._id(number)
        try:
            self._storage.set_trial_user_attr(trial_id, "failure", reason)
            failed = self._storage.set_trial_state_values(trial_id, TrialState.FAIL)
        except optuna.exceptions.UpdateFinishedTrialError:
            return  # another process finished or gave it back first
        if failed:
            requeue_stale(self._study, self._storage.get_trial(trial_id))

    def retry_failed(self) -> tuple[list[int], int]:
        """Queue a new attempt of every counted run that failed with an error, with its key,
        seed and parameters, saying on it how the earlier attempt failed. A diverged run is a
        result of its settings and stays; complete, pruned and pending runs are left alone,
        and so is a trial without a key (a sampled configuration refused before it ran).
        Returns the numbers of the trials queued again, and how many counted runs diverged."""
        with self.plan_lock():
            kept = counted(self.trials())
            failed = [t for t in kept if outcome(t) == Outcome.FAILED
                      and not is_diverged(t) and t.user_attrs.get("key") is not None]
            for trial in failed:
                queue_attempt(self._study, trial, str(trial.user_attrs.get("failure")))
        return [t.number for t in failed], sum(map(is_diverged, kept))

    def requeue_orphans(self) -> int:
        """Queue again the trials a stopped command left running; returns how many.

        With a locked SQLite file every running trial is an orphan; on a server, those whose
        heartbeat went stale.
        """
        if self.exclusive:
            orphans = self.trials(TrialState.RUNNING)
            for trial in orphans:
                self.requeue(trial.number, failure(Failure.INTERRUPTED, "its command stopped"))
            return len(orphans)
        before = len(self.trials(TrialState.RUNNING))
        optuna.storages.fail_stale_trials(self._study)
        # Optuna skips a running trial with no heartbeat at all: one whose command stopped
        # between taking it and its first heartbeat. Past the grace period it is an orphan too.
        for number in self._unbeaten(self._grace()):
            self.requeue(number, failure(Failure.INTERRUPTED, "its command stopped before "
                                         "its first heartbeat"))
        return before - len(self.trials(TrialState.RUNNING))

    def _grace(self) -> float:
        """Seconds without a heartbeat after which a running trial is stale: the storage's
        grace period, or twice its heartbeat interval when it has none (Optuna's rule)."""
        if self._storage.grace_period is not None:
            return float(self._storage.grace_period)
        return 2.0 * float(self._storage.heartbeat_interval or 0)

    def _unbeaten(self, grace: float) -> list[int]:
        """Running trials that never had a heartbeat and started over ``grace`` seconds ago
        (``datetime_start`` is the taking command's local time, as Optuna writes it)."""
        from optuna.storages._rdb import models

        session = self._storage.scoped_session()
        try:
            rows = (session.query(models.TrialModel)
                    .filter(models.TrialModel.study_id == self._study_id,
                            models.TrialModel.state == TrialState.RUNNING)
                    .all())
            now = datetime.now()
            return [row.number for row in rows
                    if not row.heartbeats and row.datetime_start is not None
                    and (now - row.datetime_start).total_seconds() > grace]
        finally:
            session.close()

    def heartbeat(self, numbers: Iterable[int]) -> None:
        """Tell other machines these trials' owner is alive (PostgreSQL only)."""
        if not self.exclusive:
            for number in numbers:
                self._storage.record_heartbeat(self._id(number))

    def write_curves(self, curves: Mapping[int, Sequence[CurvePoint]]) -> None:
        """Replace the learning curves of trials (by number) in one transaction."""
        if any(number not in self._ids for number in curves):
            self.trials()  # one query for every id
        ids = [self._id(number) for number in curves]
        rows = [{"study_id": self._study_id, "trial_id": trial_id, "step": p.step,
                 "mean_reward": p.mean_reward, "wall_time": p.wall_time, "episodes": p.episodes}
                for trial_id, points in zip(ids, curves.values(), strict=True) for p in points]
        with self._storage.engine.begin() as conn:
            conn.execute(curve_points.delete().where(curve_points.c.trial_id.in_(ids)))
            if rows:
                conn.execute(curve_points.insert(), rows)
