"""What a stored trial is: one record schema for the runner, ``list``, ``best`` and the report.

The lowest layer of kraby-study: it imports no database, Optuna or statistics code, so config
and plan may use it and stay pure. Optuna's trials are read here by their state's name.

Every study (a sweep, a search, a single training run) is an Optuna study. kraby-study adds:

- on the study, the attributes of :class:`StudyAttrs` (what kind of study, how it was defined);
- on each trial, the attributes of :class:`TrialAttrs` (its key, seed, settings and result);
- beside Optuna's tables, the learning curve of each trial (see :mod:`kraby_study.store`).

A planned run may take several attempts (a worker died, a command was stopped): the attempt
that counts is the latest one with the run's key (:func:`counted`). A trial's :class:`Outcome`
reads its Optuna state and failure reason; an interrupted attempt is not a result. The rules
here read a trial through :class:`StoredTrial`: Optuna's FrozenTrial, or the light row
``list`` reads straight from the tables (:mod:`kraby_study.store.rows`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol, TypeVar

from kraby_study.errors import ConfigError


class StateName(Protocol):
    """A trial's state, read by its name (Optuna's TrialState: WAITING, RUNNING, COMPLETE,
    PRUNED, FAIL)."""

    @property
    def name(self) -> str: ...


class StoredTrial(Protocol):
    """What the rules below read of a stored trial: Optuna's FrozenTrial has it all, a light row
    of :mod:`kraby_study.store.rows` the part ``list`` needs."""

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


class StudyKind(StrEnum):
    """What made a stored study, in the words every command and the report use."""

    SWEEP = "sweep"
    """One setting over listed values, several seeds each (``run study=...``)."""
    CONFIRM = "confirm"
    """Configurations retrained on fresh seeds (``confirm``): a sweep over their labels."""
    SEARCH = "search"
    """An Optuna search whose sampler draws settings from a space (``optuna``)."""
    TRAIN = "train"
    """Single training runs (``train``)."""
    OPTUNA = "optuna"
    """A study kraby-study did not make (no kind stored)."""

    @classmethod
    def of(cls, stored: str | None) -> StudyKind:
        """The kind of a study from its stored attribute; OPTUNA for anything else."""
        try:
            return cls(stored) if stored is not None else cls.OPTUNA
        except ValueError:
            return cls.OPTUNA

    @property
    def swept(self) -> bool:
        """Its trials sweep one parameter over listed values (a confirm study's values are its
        configurations' labels): what it selects is a value, not a trial."""
        return self in (StudyKind.SWEEP, StudyKind.CONFIRM)

    @property
    def seeded(self) -> bool:
        """Its trials are seeds of values (sweeps, confirm studies, train runs): reported with
        learning curves per value."""
        return self in (StudyKind.SWEEP, StudyKind.CONFIRM, StudyKind.TRAIN)


class SelectRule(StrEnum):
    """How a finished sweep's value is selected (``study.select``); see
    :mod:`kraby_study.selection` for each rule's statistics."""

    FINAL_SCORE = "final_score"
    """The highest mean final score."""
    AUC = "auc"
    """The highest mean AUC (sample efficiency)."""
    FASTEST_TIED = "fastest_tied"
    """The lowest mean training time among the best and the values not shown worse than it
    (at margin 0): the rule of earlier releases, which a noisy value enters by its spread."""
    FASTEST_EQUIVALENT = "fastest_equivalent"
    """The lowest mean training time among the best and the values shown equivalent to it
    (within the margin): a value needs evidence to be selected."""

    @classmethod
    def of(cls, stored: str | None) -> SelectRule:
        """The rule a study stored; the default (final_score) for none or an unknown one."""
        try:
            return cls(stored) if stored is not None else cls.FINAL_SCORE
        except ValueError:
            return cls.FINAL_SCORE

    @classmethod
    def check(cls, rule: str, where: str = "study.select") -> SelectRule:
        """The rule named ``rule``; ConfigError naming the known ones."""
        from_text = {r.value: r for r in cls}
        if rule not in from_text:
            raise ConfigError(f"{where} must be one of {', '.join(from_text)}, got {rule!r}")
        return from_text[rule]


@dataclass(frozen=True)
class CurvePoint:
    """Mean reward of the episodes that ended in one bin of environment steps."""

    step: int
    """Environment steps at the end of the bin."""
    mean_reward: float
    """Mean episode reward (sum over the episode's steps) of the bin's episodes."""
    wall_time: float
    """Seconds since training started, when the bin's last episode ended."""
    episodes: int
    """Episodes that ended in the bin."""


@dataclass(kw_only=True)
class TrialMeasures:
    """What a trial measured, as it gives it back and as it is stored (every field optional)."""

    env_steps: int | None = None
    """Env steps it actually trained, over all its seeds (fewer when pruned or failed)."""
    wall_time: float | None = None
    """Seconds it took, from the first env step to the end of the last seed."""
    cpu_time: float | None = None
    """CPU seconds it used, user and system, over all its seeds: the worker process's and those
    of the processes that stepped its legs. Unlike wall_time, other work on the machine moves
    it little."""
    started: str | None = None
    """When it started (UTC, ISO 8601)."""
    ended: str | None = None
    """When it ended (UTC, ISO 8601)."""
    final_score: float | None = None
    """Its score: the mean episode reward over the last 10 % of training, or the evaluation
    objective's value in a search that asks for it; the trial's Optuna value too."""
    train_reward: float | None = None
    """Mean episode reward over the last 10 % of training (the final score unless the
    objective is an evaluation)."""
    failure: str | None = None
    """Why it failed or was given back: ``<Failure kind>: <detail>``."""
    pruned_at: int | None = None
    """Env steps at which the pruner stopped it."""
    scores: list[float] | None = None
    """Each seed's score, in seed order, of a trial that trained to its end: the sample the
    comparison with the best reads for a search trial (its final_score is their mean)."""
    eval_errors: list[float] | None = None
    """A trial scored by evaluation: each seed's evaluation standard error, in seed order
    (the sd of its episodes' returns over sqrt(episodes): the test set's own noise)."""

    def measures(self) -> TrialMeasures:
        """Only the measured fields (of a result or of stored attributes)."""
        return TrialMeasures(**{f.name: getattr(self, f.name)
                                for f in dataclasses.fields(TrialMeasures)})

    def training_time(self) -> float | None:
        """The cost objective ``training_time``: CPU seconds per seed, the trial's cpu_time
        over the seeds it scored; None without both."""
        if self.cpu_time is None or not self.scores:
            return None
        return float(self.cpu_time) / len(self.scores)


@dataclass(kw_only=True)
class TrialResult(TrialMeasures):
    """What a run gives back to the runner: how it ended, its curve, and what it measured."""

    outcome: Outcome
    """complete, failed or pruned."""
    curve: list[CurvePoint] = field(default_factory=list)
    """Its learning curve (the mean over its seeds, bin by bin)."""


@dataclass(kw_only=True)
class TrialAttrs(TrialMeasures):
    """The user attributes kraby-study stores on a trial: what it is (below) and what it
    measured (:class:`TrialMeasures`); every field optional on read."""

    key: str | None = None
    """Identity of the planned run within its study, stable across attempts (see the key
    functions below): ``v<value index>-s<seed>`` in sweeps, ``s<seed>`` for ``train``,
    ``t<trial number>`` in searches."""
    seed: int | None = None
    """Seed of the run's first training run (a search trial trains seed, seed + 1, ...)."""
    settings: dict[str, Any] | None = None
    """The resolved ``env`` and ``ppo`` settings it trained with (batch size explicit)."""
    steps: int | None = None
    """Env steps of each training run (the budget)."""
    model_path: str | None = None
    """Where its final model (SB3 zip) is saved, if models are kept."""
    retry_of: int | None = None
    """Number of the interrupted trial this attempt replaces."""
    provenance: str | None = None
    """Key of what made it (:func:`provenance_key`): the record itself is stored once per study
    under ``kraby_provenance:<key>``."""
    enqueued: str | None = None
    """The configuration a new search evaluated first (``search.enqueue``), e.g. ppo=tuned;
    kept by its later attempts."""

    def stored(self) -> dict[str, Any]:
        """The attributes to store: every field that is set."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}

    @classmethod
    def of(cls, trial: StoredTrial) -> TrialAttrs:
        """The attributes of a stored trial (unknown attributes ignored)."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in trial.user_attrs.items() if k in names})


@dataclass
class StudyAttrs:
    """The user attributes kraby-study stores on a study."""

    kind: str | None = None
    """sweep, train or search; None for a study kraby-study did not make."""
    definition: dict[str, Any] = field(default_factory=dict)
    """What must not change under the study's name: parameter and values or search space,
    fixed settings, budget."""
    fingerprint: str | None = None
    """Hash of the definition; a command with another definition under this name is refused."""
    planned: int | None = None
    """Runs planned (sweeps) or the trial total (searches)."""
    sampler: str | None = field(default=None, metadata={"stored": "sampler"})
    """A search's sampler (tpe or random)."""
    sampler_seed: int | None = field(default=None, metadata={"stored": "sampler_seed"})
    """A search's sampler seed."""
    select: str | None = None
    """A sweep's selection rule (:mod:`kraby_study.selection`); None: final_score. Not part
    of the definition: choosing another rule changes no run."""
    inputs: list[dict[str, Any]] | None = None
    """Settings taken from earlier studies' selected values: setting, value, study, rule."""
    campaign: dict[str, Any] | None = None
    """A campaign stage's place: the campaign's name, this stage's number (from 1) and every
    stage (study, parameter, select, documented)."""
    race: dict[str, Any] | None = None
    """A raced study's standing, rewritten after each of its runs: rounds decided, whether the
    race is over, runs used and, per value, its seeds ended, the round it was dropped after
    and the p that dropped it (:mod:`kraby_study.race`)."""

    @staticmethod
    def stored_names() -> dict[str, str]:
        """Field name -> stored name: ``kraby_<field>``, but for the sampler's, which
        optuna-dashboard users read as they are."""
        return {f.name: f.metadata.get("stored", f"kraby_{f.name}")
                for f in dataclasses.fields(StudyAttrs)}

    def stored(self) -> dict[str, Any]:
        """The attributes to store, under their stored names: every field that is set."""
        names = self.stored_names()
        return {names[k]: v for k, v in dataclasses.asdict(self).items()
                if v is not None and v != {}}

    @classmethod
    def of(cls, user_attrs: Mapping[str, Any]) -> StudyAttrs:
        """The attributes of a stored study (unknown attributes ignored)."""
        return cls(**{name: user_attrs[stored] for name, stored in cls.stored_names().items()
                      if stored in user_attrs})


# Keys -------------------------------------------------------------------------------------------

SWEEP_KEY = re.compile(r"^v(\d+)-s(\d+)$")


def sweep_key(value_index: int, seed: int) -> str:
    """The key of a sweep's run: its value's index in the study file and its seed."""
    return f"v{value_index}-s{seed}"


def parse_sweep_key(key: str | None) -> tuple[int, int] | None:
    """(value index, seed) of a sweep key, or None for another key."""
    match = SWEEP_KEY.match(str(key or ""))
    return (int(match.group(1)), int(match.group(2))) if match else None


def train_key(seed: int) -> str:
    """The key of a ``train`` run: its seed."""
    return f"s{seed}"


def search_key(number: int) -> str:
    """The key of a search trial: the number of its first attempt."""
    return f"t{number}"


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
    running = 0
    total = 0
    for trial in trials:
        counts[outcome(trial)] += 1
        running += trial.state.name == "RUNNING"
        total += 1
    return Tally(complete=counts[Outcome.COMPLETE], failed=counts[Outcome.FAILED],
                 pruned=counts[Outcome.PRUNED], pending=counts[Outcome.PENDING],
                 running=running, planned=max(planned or 0, total))


# Values and the best one --------------------------------------------------------------------------


def value_key(value: Any) -> Hashable:
    """The equality rule for swept values: numbers by value (1 == 1.0), also inside lists and
    dicts ([64, 64] == [64.0, 64.0]); the rest by JSON."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return ("number", float(value))
    return ("other", json.dumps(_numbers_as_floats(value), sort_keys=True, default=str))


def _numbers_as_floats(value: Any) -> Any:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, list | tuple):
        return [_numbers_as_floats(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _numbers_as_floats(v) for k, v in value.items()}
    return value


def value_label(value: Any) -> str:
    """How a swept value is written in tables, legends and messages."""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def param_name(parameter: str) -> str:
    """The Optuna parameter name of a swept setting: its last part (ppo.gamma -> gamma)."""
    return parameter.split(".")[-1]


def is_numeric(values: Sequence[Any]) -> bool:
    """True when every value is a real number (bools are not)."""
    return bool(values) and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def ordered_values(planned: list[Any], found: list[Any], sort: bool = True) -> list[Any]:
    """Planned values plus any other value found, sorted when all are numbers (and ``sort``)."""
    values = list(planned)
    known = {value_key(v) for v in values}
    for value in found:
        if value is not None and value_key(value) not in known:
            known.add(value_key(value))
            values.append(value)
    if sort and is_numeric(values):
        values.sort(key=float)
    return values


K = TypeVar("K", bound=Hashable)


def best_group(scores: Mapping[K, Sequence[float]]) -> K | None:
    """The group with the highest mean score (the first such in order); None if none has one."""
    best: K | None = None
    best_mean = -math.inf
    for group, values in scores.items():
        if len(values) and (mean := math.fsum(values) / len(values)) > best_mean:
            best, best_mean = group, mean
    return best


def swept_value(trial: StoredTrial, name: str, planned: Sequence[Any]) -> Any:
    """A sweep trial's value: its parameter, its queued parameter, or its key's value index."""
    if name in trial.params:
        return trial.params[name]
    fixed = trial.system_attrs.get("fixed_params") or {}
    if name in fixed:
        return fixed[name]
    parsed = parse_sweep_key(trial.user_attrs.get("key"))
    if parsed is not None and parsed[0] < len(planned):
        return planned[parsed[0]]
    return None


def score(trial: StoredTrial) -> float | None:
    """A trial's score: its value, or its first objective's (a two-objective search's reward);
    None without one. (Optuna's ``FrozenTrial.value`` raises on a trial of two objectives.)"""
    values = trial.values
    return float(values[0]) if values else None


def cost(trial: StoredTrial) -> float | None:
    """A two-objective search trial's cost (its second objective); None for one objective."""
    values = trial.values
    return float(values[1]) if values and len(values) > 1 else None


def floor_score(trials: Iterable[StoredTrial], floor: str) -> float | None:
    """The score of a search's floor: its complete trial enqueued as ``ppo=<floor>`` (the first
    such attempt); None while none is complete."""
    for trial in trials:
        if (outcome(trial) == Outcome.COMPLETE and TrialAttrs.of(trial).enqueued == f"ppo={floor}"
                and score(trial) is not None):
            return score(trial)
    return None


def best_trial(trials: Iterable[T], maximize: bool = True, objectives: int = 1) -> T | None:
    """The complete trial with the best score (a search's best); None when none is complete.

    kraby-study maximises; ``maximize=False`` serves foreign studies that minimise. Trials
    count when they have ``objectives`` values, by the first: 2 for a two-objective search's
    best score; a foreign study of several objectives has no single best.
    """
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and t.values
            and len(t.values) == objectives]
    pick = max if maximize else min
    return pick(done, key=lambda t: float(score(t)), default=None)  # type: ignore[arg-type]


PROVENANCE_PREFIX = "kraby_provenance:"
"""A study attribute named ``kraby_provenance:<key>`` holds one distinct provenance record."""


def provenance_key(facts: Mapping[str, str]) -> str:
    """A short hash naming a provenance record: equal records share it, and a trial from
    another machine, version or command gets another."""
    text = json.dumps(dict(facts), sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:12]


RAY_NODE = "ray_node"
"""The provenance field of a trial run on Ray: the Ray node id of the actor that ran it."""


@dataclass(frozen=True)
class Placement:
    """Where a study's trials ran, read from its provenance records (every attempt that
    started, a lost node's too): the nodes and the CPU models."""

    nodes: int
    """Distinct machines: Ray nodes by node id (a node started again gets a new id), and by
    hostname the trials run without Ray."""
    cpus: tuple[str, ...]
    """The distinct CPU models, sorted."""

    @classmethod
    def of(cls, records: Iterable[Mapping[str, Any]]) -> Placement:
        """The placement of these provenance records."""
        machines: set[str] = set()
        cpus: set[str] = set()
        for record in records:
            node = record.get(RAY_NODE)
            machines.add(f"ray:{node}" if node else f"host:{record.get('hostname')}")
            cpus.add(str(record.get("cpu", "unknown")))
        return cls(nodes=len(machines), cpus=tuple(sorted(cpus)))

    def text(self) -> str:
        """``-`` with no record, else ``N node(s)``, with the CPU models counted when more
        than one: the study's seeds are then not reproducible bit for bit across them."""
        if not self.nodes:
            return "-"
        where = f"{self.nodes} node{'s' if self.nodes != 1 else ''}"
        return where if len(self.cpus) < 2 else f"{where}, {len(self.cpus)} CPU models"


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


# A search's objectives ------------------------------------------------------------------------

FINAL_FRACTION = 0.1
"""A run's final score averages the episodes that end in this last fraction of its steps."""

REWARDS = ("final_reward", "evaluation")
"""A search's rewards, maximised: the mean episode reward over the last 10 % of training, or
the deterministic policy's mean return over the run's evaluation episodes."""
COSTS = ("training_time",)
"""A search's costs, minimised: ``training_time`` is CPU seconds per seed
(:meth:`TrialMeasures.training_time`)."""


def objective_names(objective: Any) -> list[str]:
    """A search's objective as names: one name (as stored by a one-objective search) or a
    list of names."""
    if isinstance(objective, str):
        return [objective]
    return [str(name) for name in objective]


def check_objective(objective: Any) -> list[str]:
    """The objective's names, a reward first and then any cost; ConfigError, one line, for an
    unknown name, more than two, two rewards, two costs or a cost alone."""
    names = objective_names(objective)
    shown = f"search.objective={_listed(names)}"
    for name in names:
        if name not in REWARDS + COSTS:
            raise ConfigError(f"{shown}: unknown objective {name!r}: choose a reward "
                              f"({' or '.join(REWARDS)}), optionally with the cost "
                              f"{' or '.join(COSTS)}")
    rewards = [n for n in names if n in REWARDS]
    costs = [n for n in names if n in COSTS]
    if len(names) > 2:
        raise ConfigError(f"{shown}: at most two objectives, a reward and a cost, got "
                          f"{len(names)}")
    if len(rewards) != 1:
        raise ConfigError(f"{shown}: " + ("two rewards: give one reward and a cost, e.g. "
                                          "[final_reward,training_time]" if rewards else
                                          "a cost alone: give a reward with it, e.g. "
                                          "[final_reward,training_time]"))
    if len(costs) > 1:
        raise ConfigError(f"{shown}: two costs: give one reward and one cost")
    return rewards + costs


def _listed(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else f"[{','.join(names)}]"


def stored_objective(names: Sequence[str]) -> str | list[str]:
    """The objective as a search's definition stores it: one name as a string (as every
    one-objective search stored it), two as a list."""
    return names[0] if len(names) == 1 else list(names)


SEEDING = "streams"
"""The seeding scheme of a new study: each leg of a run its own child stream of the run's seed
(``numpy.random.SeedSequence(seed).spawn(n_envs)``)."""
LEGACY_SEEDING = "offset"
"""The scheme of every study stored before streams existed (leg i seeded with seed + i); its
definition has no ``seeding`` key."""
SEEDING_TEXT = {
    "streams": "streams: env i of the run with seed s (a leg, on the leg) draws from child i "
               "of numpy.random.SeedSequence(s), so no two runs share an env's stream",
    "offset": "offset: env i of the run with seed s is seeded with s + i, so runs s and s + 1 "
              "share all envs but one (the scheme before streams)",
}
"""How reports and ``--dry-run`` name each scheme."""


def seed_text(seeds: Iterable[int]) -> str:
    """Seeds as ranges, e.g. ``0-9, 12 (11 seeds)``; ``none`` when there are none."""
    ordered = sorted(set(seeds))
    if not ordered:
        return "none"
    parts: list[str] = []
    start = prev = ordered[0]
    for seed in [*ordered[1:], None]:
        if seed is not None and seed == prev + 1:
            prev = seed
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if seed is not None:
            start = prev = seed
    return f"{', '.join(parts)} ({len(ordered)} seed{'s' if len(ordered) != 1 else ''})"


def stored_seeding(definition: Mapping[str, Any]) -> str:
    """A stored definition's seeding scheme: its ``seeding``, offset when it has none."""
    return str(definition.get("seeding", LEGACY_SEEDING))


EVAL_SETS = ("run", "fixed")
"""Where a run's evaluation episodes come from: ``run``, its own, drawn from its seed's
evaluation stream (a test set no run of another seed shares: a confirm's fresh seeds never
see its search's episodes); ``fixed``, one set every run shared (studies stored before)."""
EVAL_SET = "run"
"""The evaluation set of a new study."""
LEGACY_EVAL_SET = "fixed"
"""The evaluation set of every study stored before runs drew their own: its definition has no
``eval_set``."""
EVAL_EPISODES = 200
"""Evaluation episodes per run of a new study (docs/statistics.md: their standard error
against the margin on Pendulum-v1 and the leg)."""
LEGACY_EVAL_EPISODES = 16
"""Evaluation episodes of a study stored before ``eval_episodes`` was stored (searches always
stored it)."""


def _evaluation_part(definition: Mapping[str, Any]) -> Mapping[str, Any]:
    """Where a stored definition keeps its evaluation settings: a search's ``search``
    section, the definition itself for a confirm."""
    search = definition.get("search")
    return search if isinstance(search, Mapping) else definition


def stored_eval_set(definition: Mapping[str, Any]) -> str:
    """A stored definition's evaluation set: its ``eval_set``, fixed when it has none."""
    return str(_evaluation_part(definition).get("eval_set", LEGACY_EVAL_SET))


def stored_eval_episodes(definition: Mapping[str, Any]) -> int | None:
    """A stored definition's evaluation episodes; None when it stores none (a study not
    scored by evaluation)."""
    episodes = _evaluation_part(definition).get("eval_episodes")
    return int(episodes) if episodes is not None else None


def two_objectives(definition: Mapping[str, Any]) -> bool:
    """Whether a stored search definition has a reward and a cost."""
    objective = definition.get("search", {}).get("objective", REWARDS[0])
    return len(objective_names(objective)) == 2


def scored_by_evaluation(definition: Mapping[str, Any]) -> bool:
    """Whether a stored study's runs are scored by the evaluation objective (a confirm of an
    evaluation search stores its objective; every other study is scored by final_reward)."""
    return definition.get("objective") == REWARDS[1]


def stored_floor(definition: Mapping[str, Any]) -> str | None:
    """A stored two-objective search's floor (an enqueued ppo config's name); None for a search
    stored without one (one objective, ``search.floor=null``, or made before floors existed)."""
    floor = definition.get("search", {}).get("floor")
    return str(floor) if floor is not None and two_objectives(definition) else None
