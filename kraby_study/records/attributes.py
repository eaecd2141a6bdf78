"""What kraby-study stores on a study and on each trial beside Optuna's own columns: the kind of
study, its rule, a trial's measures and curve, and where it ran (provenance)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from kraby_study.errors import ConfigError
from kraby_study.records.stored import Outcome, StoredTrial


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
    `kraby_study.decision.selection` for each rule's statistics."""

    FINAL_SCORE = "final_score"
    """The best: the highest IQM of the final scores (the mean below 4 seeds)."""
    AUC = "auc"
    """The highest mean AUC (sample efficiency)."""
    FASTEST_EQUIVALENT = "fastest_equivalent"
    """The lowest mean training time among the best and the values shown equivalent to it
    (within the margin): a value needs evidence to be selected."""

    @classmethod
    def of(cls, stored: str | None) -> SelectRule:
        """The rule a study stored answered by today's rules: a retired name by the rule that
        replaces it ([`RETIRED_RULES`][kraby_study.records.attributes.RETIRED_RULES]); the default
        (final_score) for none or an unknown one."""
        if stored in RETIRED_RULES:
            return RETIRED_RULES[stored]
        try:
            return cls(stored) if stored is not None else cls.FINAL_SCORE
        except ValueError:
            return cls.FINAL_SCORE

    @classmethod
    def check(cls, rule: str, where: str = "study.select") -> SelectRule:
        """The rule named ``rule``; ConfigError naming the known ones."""
        from_text = {r.value: r for r in cls}
        if rule in RETIRED_RULES:
            raise ConfigError(f"{where}: {rule} is retired; use "
                              f"{RETIRED_RULES[rule].value} (a study stored with {rule} "
                              "selects by it)")
        if rule not in from_text:
            raise ConfigError(f"{where} must be one of {', '.join(from_text)}, got {rule!r}")
        return from_text[rule]



RETIRED_RULES: dict[str, SelectRule] = {"fastest_tied": SelectRule.FASTEST_EQUIVALENT}
"""Selection rule names a stored study may carry but a config may not name, each with the
rule that answers such a study today."""

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
    eval_sds: list[float] | None = None
    """A trial scored by evaluation: each seed's sd of its evaluation episodes' returns, in
    seed order (how far one episode's return strays from the run's score)."""

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



@dataclass(frozen=True)
class RunMeasure:
    """A number each run of a sweep measures beside its final score, and how a value's runs
    are summarised: the run table, the per-value summary and summary.csv all follow this
    declaration, so a new per-run measure is a
    [`TrialMeasures`][kraby_study.records.attributes.TrialMeasures] field, an entry of
    [`RUN_MEASURES`][kraby_study.records.attributes.RUN_MEASURES] and the code in
    [`kraby_study.run.trial`][] that measures it."""

    name: str
    """Its column in the run table (trials.csv)."""
    attribute: str
    """The [`TrialMeasures`][kraby_study.records.attributes.TrialMeasures] field it is read from: a
    number, or a list with one entry per seed (a sweep's run has one seed: the first is read)."""
    summary: str
    """How a value's complete runs are summarised: ``describe`` (mean, sd and the interval of
    the mean, as the final score's: columns ``<column>_mean``, ``_sd``, ``_low``, ``_high``)
    or ``rms`` (the root mean square over the runs: one column)."""
    column: str
    """Its per-value column in summary.csv (``describe``: the columns' prefix)."""
    text: str
    """What its per-value number is, for the report's methods."""
    per_seed: bool = False
    """Stored as a list with one entry per seed of a trial (a recheck appends its own seeds'
    entries to the trial's)."""
    evaluated: bool = True
    """Measured only on runs scored by evaluation: summarised only in such studies."""

    @property
    def columns(self) -> tuple[str, ...]:
        """Its per-value columns in summary.csv."""
        if self.summary == "describe":
            return tuple(f"{self.column}_{part}" for part in ("mean", "sd", "low", "high"))
        return (self.column,)

    def read(self, attrs: Mapping[str, Any]) -> float | None:
        """Its value for one run from the run's stored attributes; None when not measured."""
        value = attrs.get(self.attribute)
        if isinstance(value, list):
            value = value[0] if value else None
        return None if value is None else float(value)


RUN_MEASURES: tuple[RunMeasure, ...] = (
    RunMeasure("train_reward", "train_reward", "describe", "train",
               "the training reward (mean episode reward over the last 10 % of training): "
               "mean, sd and interval of the mean over the value's complete seeds"),
    RunMeasure("eval_error", "eval_errors", "rms", "eval_se",
               "the evaluation standard error, the share of a run's score that its evaluation "
               "episodes add (the sd of their returns over sqrt(episodes)): root mean square "
               "over the value's complete seeds", per_seed=True),
    RunMeasure("eval_sd", "eval_sds", "rms", "eval_sd",
               "the evaluation return sd, how far one evaluation episode's return strays from "
               "its run's score (the sd of the returns over the run's evaluation episodes): "
               "root mean square over the value's complete seeds", per_seed=True),
)
"""The per-run measures beside the final score, in the order of their columns."""

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
    measured ([`TrialMeasures`][TrialMeasures]); every field optional on read."""

    key: str | None = None
    """Identity of the planned run within its study, stable across attempts (see the key
    functions below): ``v<value index>-s<seed>`` in sweeps, ``s<seed>`` for ``train``,
    ``t<trial number>`` in searches, ``c<configuration>-s<seed>`` in racing searches."""
    seed: int | None = None
    """Seed of the run's first training run (a search trial trains seed, seed + 1, ...)."""
    settings: dict[str, Any] | None = None
    """The resolved ``env`` and ``ppo`` settings it trained with (batch size explicit)."""
    steps: int | None = None
    """Env steps of each training run (the budget)."""
    model_path: str | None = None
    """Where its final model (SB3 zip) is saved, if models are kept."""
    retry_of: int | None = None
    """Number of the trial this attempt replaces: an interrupted one, or a failed one queued
    again on purpose (``retry_failed``)."""
    retried_failure: str | None = None
    """The failure of the earlier attempt, when a failed trial was queued again on purpose
    (``retry_failed``); its provenance record names it too."""
    recheck_of: int | None = None
    """Number of the search trial this attempt rechecks on more seeds (``search.recheck``): it
    trains the seeds after the trial's own and holds the scores of both, so it replaces the
    trial (same key)."""
    provenance: str | None = None
    """Key of what made it ([`provenance_key`][provenance_key]): the record itself is stored once
    per study under ``kraby_provenance:<key>``."""
    enqueued: str | None = None
    """The configuration a new search evaluated first (``search.enqueue``), e.g. ppo=tuned;
    kept by its later attempts."""
    suggest_cpu: float | None = None
    """A search trial: CPU seconds the command's process spent asking the sampler for it (a
    Gaussian process's fit costs more than TPE's); part of what the search spends under its
    CPU budget, not of the trial's own cpu_time."""
    race_order: int | None = None
    """A racing search's run: its place among the study's ended runs (1, 2, ...), stored as it
    ends; its race is replayed in this order (`kraby_study.decision.race.intensify`)."""
    cost_stop: float | None = None
    """A search trial stopped for its cost (``search.trial_share``): the CPU seconds it was
    projected to use, to its last env step, at the checkpoint where it was stopped. It is
    stored as pruned."""

    def training_time(self) -> float | None:
        """CPU seconds per seed ([`TrialMeasures.training_time`][TrialMeasures.training_time]).
        A recheck's CPU seconds are its own seeds' (its env steps over the steps a seed), while
        its scores hold the original trial's too: it is divided by the seeds it trained."""
        time = super().training_time()
        if time is None or self.recheck_of is None or not self.steps or not self.env_steps:
            return time
        trained = round(self.env_steps / self.steps)
        return float(self.cpu_time) / trained if trained > 0 else time  # type: ignore[arg-type]

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
    """Runs planned (sweeps) or the trial total (searches); a search its CPU budget stopped
    plans the trials it ran."""
    cpu_budget: float | None = None
    """A search's CPU budget (search.cpu_budget) in CPU seconds, as the latest command that
    set one gave it."""
    explored: float | None = None
    """The CPU budget under which a search's exploring ended to pay for its rechecks
    (search.recheck): a later command under the same budget only rechecks."""
    sampler: str | None = field(default=None, metadata={"stored": "sampler"})
    """A search's sampler (tpe, random, nsga2 or gp)."""
    sampler_seed: int | None = field(default=None, metadata={"stored": "sampler_seed"})
    """A search's sampler seed."""
    openings: int | None = None
    """How many commands have started on a search: the next one's sampler draws from a child
    of (seed, openings), so no two commands draw alike (`kraby_study.run.sampling`)."""
    select: str | None = None
    """A sweep's selection rule (`kraby_study.decision.selection`); None: final_score. Not part
    of the definition: choosing another rule changes no run."""
    inputs: list[dict[str, Any]] | None = None
    """Settings taken from earlier studies' selected values: setting, value, study, rule."""
    campaign: dict[str, Any] | None = None
    """A campaign stage's place: the campaign's name, this stage's number (from 1) and every
    stage (study, parameter, select, documented)."""
    race: dict[str, Any] | None = None
    """A raced study's standing, rewritten after each of its runs: rounds decided, whether the
    race is over, runs used and, per value, its seeds ended, the round it was dropped after
    and the p that dropped it (`kraby_study.decision.race`)."""

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


PROVENANCE_PREFIX = "kraby_provenance:"
"""A study attribute named ``kraby_provenance:<key>`` holds one distinct provenance record."""


def provenance_key(facts: Mapping[str, str]) -> str:
    """A short hash naming a provenance record: equal records share it, and a trial from
    another machine, version or command gets another."""
    text = json.dumps(dict(facts), sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:12]


RAY_NODE = "ray_node"
"""The provenance field of a trial run on Ray: the Ray node id of the actor that ran it."""


def retry_facts(attrs: TrialAttrs) -> dict[str, str]:
    """The provenance fields of a failed trial queued again on purpose (``retry_failed``): the
    number of the attempt it retries and that attempt's failure; none for any other."""
    if attrs.retried_failure is None:
        return {}
    return {"retry_of": str(attrs.retry_of), "retried_failure": attrs.retried_failure}


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
