"""A stored trial as the rules read it ([`StoredTrial`][StoredTrial]), its outcome, its run's key
and which attempts count."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol, TypeVar


class StateName(Protocol):
    """A trial's state, read by its name (Optuna's TrialState: WAITING, RUNNING, COMPLETE,
    PRUNED, FAIL)."""

    @property
    def name(self) -> str: ...


class StoredTrial(Protocol):
    """What the rules below read of a stored trial: Optuna's FrozenTrial has it all, a light row
    of `kraby_study.store.rows` the part ``list`` needs."""

    @property
    def number(self) -> int: ...

    @property
    def state(self) -> StateName: ...

    @property
    def value(self) -> float | None: ...

    @property
    def values(self) -> list[float] | None: ...

    @property
    def params(self) -> dict[str, Any]: ...

    @property
    def user_attrs(self) -> dict[str, Any]: ...

    @property
    def system_attrs(self) -> dict[str, Any]: ...


T = TypeVar("T", bound=StoredTrial)


class Outcome(StrEnum):
    """How a trial stands, in the words every command and the report use."""

    COMPLETE = "complete"
    """Trained to its budget; its value is its score."""
    FAILED = "failed"
    """Ended without a score: it diverged (NaN) or raised an error. A result, not a crash."""
    PRUNED = "pruned"
    """Stopped early by a search's pruner."""
    PENDING = "pending"
    """Not a result yet: waiting, running, or given back unfinished (interrupted)."""


class Failure(StrEnum):
    """The kind of a failure, the first word of a trial's ``failure`` attribute."""

    DIVERGED = "diverged"
    """The loss or the policy's parameters became NaN or infinite."""
    ERROR = "error"
    """Training raised an error, or gave no finite score."""
    INTERRUPTED = "interrupted"
    """Its command or worker stopped: the run is queued again, this attempt is no result."""


def failure(kind: Failure, detail: str) -> str:
    """A failure reason as stored: ``<kind>: <detail>``, on one line."""
    text = " ".join(str(detail).split())
    return f"{kind.value}: {text}"


def failure_kind(reason: str | None) -> Failure | None:
    """The kind of a stored failure reason (None when it names none)."""
    head = str(reason or "").split(":", 1)[0].strip()
    try:
        return Failure(head)
    except ValueError:
        return None


# Keys -------------------------------------------------------------------------------------------

SWEEP_KEY = re.compile(r"^v(\d+)-s(\d+)$")


def sweep_key(value_index: int, seed: int) -> str:
    """The key of a sweep's run: its value's index in the study file and its seed."""
    return f"v{value_index}-s{seed}"


def parse_sweep_key(key: str | None) -> tuple[int, int] | None:
    """(value index, seed) of a sweep key, or None for another key."""
    match = SWEEP_KEY.match(str(key or ""))
    return (int(match.group(1)), int(match.group(2))) if match else None


RACING_KEY = re.compile(r"^c(\d+)-s(\d+)$")


def racing_key(config: int, seed: int) -> str:
    """The key of a racing search's run: its configuration's number (in the order the search
    asked for them, from 0) and its seed."""
    return f"c{config}-s{seed}"


def parse_racing_key(key: str | None) -> tuple[int, int] | None:
    """(configuration number, seed) of a racing search's key, or None for another key."""
    match = RACING_KEY.match(str(key or ""))
    return (int(match.group(1)), int(match.group(2))) if match else None


def train_key(seed: int) -> str:
    """The key of a ``train`` run: its seed."""
    return f"s{seed}"


def search_key(number: int) -> str:
    """The key of a search trial: the number of its first attempt."""
    return f"t{number}"


def known_number(trial: StoredTrial) -> int:
    """The number a search trial is known by: its first attempt's, read from its key (``t10``),
    whichever attempt holds it now (a retry, or a recheck on more seeds); a trial without a
    search key by its own number."""
    key = trial.user_attrs.get("key")
    if isinstance(key, str) and key.startswith("t") and key[1:].isdigit():
        return int(key[1:])
    return trial.number


# Outcomes and which trials count -----------------------------------------------------------------


def outcome(trial: StoredTrial) -> Outcome:
    """A trial's outcome; a failed attempt that was given back unfinished is pending."""
    # By name, so that this module loads no Optuna (optuna.trial.TrialState).
    state = trial.state.name
    if state == "COMPLETE":
        return Outcome.COMPLETE
    if state == "PRUNED":
        return Outcome.PRUNED
    if state == "FAIL":
        reason = trial.user_attrs.get("failure")
        # A failed trial with no reason was given back by Optuna's heartbeat (a lost owner).
        if reason is None or failure_kind(reason) == Failure.INTERRUPTED:
            return Outcome.PENDING
        return Outcome.FAILED
    return Outcome.PENDING


def is_diverged(trial: StoredTrial) -> bool:
    """A failed trial whose training diverged: a result of its settings (its seed would
    diverge again), not an error to run again."""
    return (trial.state.name == "FAIL"
            and failure_kind(trial.user_attrs.get("failure")) == Failure.DIVERGED)


def is_interrupted(trial: StoredTrial) -> bool:
    """A trial given back unfinished: its run is queued again, it is no result."""
    return trial.state.name == "FAIL" and outcome(trial) == Outcome.PENDING


def counted(trials: Iterable[T]) -> list[T]:
    """The trials that make a study's result, in trial-number order.

    One attempt counts per planned run: the latest trial with its key. A trial without a key
    (a foreign Optuna study, a search trial refused before it had one) counts unless a later
    attempt names it in ``retry_of``.
    """
    ordered = sorted(trials, key=lambda t: t.number)
    replaced = {int(t.user_attrs["retry_of"]) for t in ordered if "retry_of" in t.user_attrs}
    latest: dict[str, int] = {}
    for trial in ordered:
        key = trial.user_attrs.get("key")
        if key is not None:
            latest[str(key)] = trial.number
    keep = set(latest.values())

    def counts(trial: T) -> bool:
        if trial.user_attrs.get("key") is not None:
            return trial.number in keep
        return trial.number not in replaced

    return [t for t in ordered if counts(t)]


def spent_cpu(trials: Iterable[StoredTrial]) -> float:
    """CPU seconds the trials used, every attempt counted (a failed or retried one too): the
    ended trials' stored ``cpu_time`` (a running trial has none yet), and what asking the
    sampler for each cost (``suggest_cpu``, stored when it is asked for)."""
    return float(sum(float(t.user_attrs.get("cpu_time") or 0.0)
                     + float(t.user_attrs.get("suggest_cpu") or 0.0) for t in trials))


def latest_by_key(trials: Iterable[T]) -> dict[str, T]:
    """The counted trial of each key."""
    return {str(t.user_attrs["key"]): t for t in counted(trials)
            if t.user_attrs.get("key") is not None}


@dataclass
class Tally:
    """How many counted trials stand at each outcome, and how many runs are planned.

    Two tallies are equal when they count the same outcomes.
    """

    complete: int = 0
    failed: int = 0
    pruned: int = 0
    pending: int = 0
    running: int = field(default=0, compare=False)
    """Of the pending ones, those running now (here or on another machine)."""
    diverged: int = field(default=0, compare=False)
    """Of the failed ones, those whose training diverged: results of their settings, which
    ``--retry-failed`` leaves alone (the others failed with an error)."""
    planned: int = field(default=0, compare=False)
    """Runs planned (sweeps) or the trial total (searches); never fewer than the trials
    counted."""

    @property
    def ended(self) -> int:
        """Trials that are results: complete, failed or pruned."""
        return self.complete + self.failed + self.pruned

    @property
    def finished(self) -> bool:
        """No planned run is still to come."""
        return self.ended >= self.planned

    @property
    def left(self) -> int:
        """Runs still to come: pending trials and planned runs without a trial yet."""
        return max(self.planned - self.ended, 0)

    def counts(self) -> dict[str, int]:
        """As a table shows them: planned, complete, failed, pruned, and pending (every run
        still to come)."""
        return {"planned": self.planned, Outcome.COMPLETE.value: self.complete,
                Outcome.FAILED.value: self.failed, Outcome.PRUNED.value: self.pruned,
                Outcome.PENDING.value: self.left}


def tally(trials: Iterable[StoredTrial], planned: int | None = None) -> Tally:
    """Outcome counts of the given (counted) trials, against ``planned`` runs (None: as many
    as there are trials)."""
    counts = {o: 0 for o in Outcome}
    running = diverged = total = 0
    for trial in trials:
        counts[outcome(trial)] += 1
        running += trial.state.name == "RUNNING"
        diverged += is_diverged(trial)
        total += 1
    return Tally(complete=counts[Outcome.COMPLETE], failed=counts[Outcome.FAILED],
                 pruned=counts[Outcome.PRUNED], pending=counts[Outcome.PENDING],
                 running=running, diverged=diverged, planned=max(planned or 0, total))


def trial_seeds(trial: StoredTrial, per_trial: int = 1) -> list[int]:
    """The seeds a trial trained: its seed and the next ``per_trial - 1`` (a search trial
    trains several one after another); none when it has no seed stored."""
    seed = trial.user_attrs.get("seed")
    return [] if seed is None else [int(seed) + i for i in range(per_trial)]


def offset_leg_seeds(trial: StoredTrial, per_trial: int = 1) -> set[int]:
    """Under offset seeding, the seed every leg of a trial's runs was reset with: s + i for
    each of its seeds s and legs i < n_envs (two runs share a leg's stream where these meet)."""
    n_envs = int(trial.user_attrs.get("settings", {}).get("ppo", {}).get("n_envs", 1))
    return {seed + leg for seed in trial_seeds(trial, per_trial) for leg in range(n_envs)}


# The ended runs of a race ---------------------------------------------------------------------


def place(key: str, seeds: list[int]) -> tuple[int, int] | None:
    """(value index, seed index) of a run's key; None for a key of no round."""
    parsed = parse_sweep_key(key)
    if parsed is None or parsed[1] not in seeds:
        return None
    return parsed[0], seeds.index(parsed[1])


def ended_runs(latest: Mapping[str, StoredTrial], seeds: list[int]
               ) -> dict[int, dict[int, float]]:
    """Per value, its ended runs by seed index: the final score of a complete run, NaN for one
    that ended without a score (failed)."""
    runs: dict[int, dict[int, float]] = {}
    for key, trial in latest.items():
        where = place(key, seeds)
        if where is None:
            continue
        ended = outcome(trial)
        if ended == Outcome.COMPLETE and trial.value is not None:
            runs.setdefault(where[0], {})[where[1]] = float(trial.value)
        elif ended == Outcome.FAILED:
            runs.setdefault(where[0], {})[where[1]] = math.nan
    return runs


def diverged_runs(latest: Mapping[str, StoredTrial], seeds: list[int]) -> dict[int, set[int]]:
    """Per value, the seed indices of its ended runs that diverged (a failure whose kind is
    [`Failure.DIVERGED`][kraby_study.records.stored.Failure]; an error is not counted)."""
    found: dict[int, set[int]] = {}
    for key, trial in latest.items():
        where = place(key, seeds)
        if where is not None and is_diverged(trial):
            found.setdefault(where[0], set()).add(where[1])
    return found
