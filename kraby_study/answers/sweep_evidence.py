"""A sweep (or a single-run or confirm study) read once from the store into its evidence and
its answers: one row per run, the seed scores every decision reads, the race's state, and the
summary, verdict and selection [`kraby_study.decision.summary`][] decides from them. The report
draws what [`build_sweep`][kraby_study.answers.sweep_evidence.build_sweep] hands it.

Figures and metrics draw from the complete runs only; failed runs are counted and listed, runs
still to come are counted as pending, and nothing is dropped without a trace. A confirm study
is a sweep whose values are the labels of the configurations it retrains (in the order given).

Every decision (the summary's answers, the verdict, the ``selected`` column) reads one
[`Comparison`][kraby_study.decision.comparison.Comparison], made once per study by
[`sweep_comparison`][kraby_study.answers.seed_scores.sweep_comparison] from the seed scores of the
runs' table ([`seed_scores`][kraby_study.decision.summary.seed_scores]): the numbers ``best``,
``${winner:...}`` and campaigns read from the trials
([`samples`][kraby_study.answers.seed_scores.samples]) and compare there too. The report reads the
decision as typed rows ([`ValueSummary`][kraby_study.decision.summary.ValueSummary])."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from kraby_study.answers.raced import race_runs
from kraby_study.answers.seed_scores import sweep_comparison, swept_values, time_measure
from kraby_study.answers.selected import study_rule
from kraby_study.answers.study_data import StudyData
from kraby_study.decision.comparison import MARGIN, MIN_SEEDS, CompareOptions, Comparison
from kraby_study.decision.intervals import BOOTSTRAP_REPETITIONS
from kraby_study.decision.race import Drop, RaceRuns, StudyRace
from kraby_study.decision.summary import (
    SEED_COLUMNS,
    ValueSummary,
    decide_sweep,
    seed_scores,
    summary_frame,
)
from kraby_study.decision.verdict import Verdict, empty_verdict
from kraby_study.records.attributes import RUN_MEASURES, SelectRule, StudyKind
from kraby_study.records.definition import scored_by_evaluation
from kraby_study.records.stored import Outcome, outcome, tally
from kraby_study.records.values import swept_value, value_key, value_label

SINGLE_LABEL = "all seeds"
TRIAL_COLUMNS = ["number", "key", "seed", "value_index", "value", "outcome", "final_score",
                 *(m.name for m in RUN_MEASURES), "wall_time", "cpu_time", "env_steps",
                 "failure", "model_path"]
"""The run table's columns: what a run is, its final score, its per-run measures
([`RUN_MEASURES`][kraby_study.records.attributes.RUN_MEASURES]) and what it cost."""


@dataclass
class Sweep:
    """Everything the figures and tables of one sweep need.

    Attributes:
        data: The stored study.
        parameter: Dotted name of the swept setting ("" for a single-run study).
        name: The setting's short name (the Optuna parameter), or "all seeds".
        values: The swept values in figure order (by value when all are numbers).
        labels: How each value is written.
        trials: One row per counted run (columns ``TRIAL_COLUMNS``); ``value_index`` indexes values.
        curves: Curve points of the complete runs, with their ``value_index`` and ``seed``.
        bands: Per value and step: n, mean, sd, low, high of the reward; mean wall time.
        rows: What the evidence says of each value, typed
            ([`ValueSummary`][kraby_study.decision.summary.ValueSummary]), in value order.
        seeds: One row per complete run (columns ``SEED_COLUMNS``): its final score, its
            first curve point's reward, its AUC, when it first reached the threshold and its
            curve's last point (env steps and seconds).
        threshold: The reward a curve must reach (NaN when there is no curve to set it).
        threshold_default: True when the threshold is the default (see
            [`study_threshold`][kraby_study.decision.summary.study_threshold]), False when the
            report's options set it.
        untrained: The untrained policy's reward: the mean first-bin reward of every complete
            seed of the study (NaN without curves).
        bootstrap: The report option ``report.bootstrap``: resamples of the bootstrap-t
            interval of a mean ([`mean_interval`][kraby_study.decision.intervals.mean_interval]).
        verdict: The study's verdict
            ([`verdict`][kraby_study.decision.verdict.verdict]).
        race: A raced study's race, its dropped values by index in ``values``; None for a
            study that did not race.
    """

    data: StudyData
    parameter: str
    name: str
    values: list[Any]
    labels: list[str]
    trials: pd.DataFrame
    curves: pd.DataFrame
    bands: pd.DataFrame
    rows: list[ValueSummary]
    seeds: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=SEED_COLUMNS))
    threshold: float = math.nan
    threshold_default: bool = True
    untrained: float = math.nan
    bootstrap: int = BOOTSTRAP_REPETITIONS
    verdict: Verdict = field(default_factory=empty_verdict)
    min_seeds: int = MIN_SEEDS
    """Fewest complete seeds a value needs to be best or any answer of the verdict."""
    rule: str = SelectRule.FINAL_SCORE
    """The study's selection rule (its stored one, or ``compare.select``); the summary's
    ``selected`` column marks the value it selects once no run is pending."""
    race: StudyRace | None = None
    comparison: Comparison[int] | None = None
    """The study's one comparison: the summary's answers, the verdict and the selection."""
    final_scores: dict[int, list[float]] = field(default_factory=dict)
    """Per value index, the complete runs' final scores the comparison read, in run order."""
    reach: pd.DataFrame = field(default_factory=pd.DataFrame)
    """Per value, the mean env steps and seconds to the threshold over the seeds that reached
    it, with their intervals ([`reach_means`][kraby_study.decision.summary.reach_means])."""
    failure_line: float = math.nan
    """The final score below which a seed failed ([`kraby_study.decision.failed_seeds`][]); NaN when
    not defined."""

    @property
    def summary(self) -> pd.DataFrame:
        """The rows as one table (summary.csv's columns;
        [`summary_frame`][kraby_study.decision.summary.summary_frame])."""
        return summary_frame(self.rows)

    @property
    def dropped(self) -> dict[int, Drop]:
        """The values the race dropped, by index in ``values`` (empty without a race)."""
        return self.race.dropped if self.race is not None else {}

    @property
    def kind(self) -> StudyKind:
        """The study's kind: sweep, confirm or train."""
        return self.data.kind

    @property
    def by_evaluation(self) -> bool:
        """Its runs are scored by the evaluation objective (a confirm of an evaluation
        search): the final score is the deterministic policy's mean evaluation return, and
        the summary holds the training reward beside it."""
        return scored_by_evaluation(self.data.definition)

    @property
    def time_attr(self) -> str:
        """The trial column the summary's training time describes: the one
        fastest_equivalent compares
        ([`time_measure`][kraby_study.answers.seed_scores.time_measure])."""
        return time_measure(self.kind)

    @property
    def time_unit(self) -> str:
        """How the training time is written: ``CPU s`` on a confirm study, ``wall s`` else."""
        return "CPU s" if self.time_attr == "cpu_time" else "wall s"

    @property
    def counts(self) -> dict[str, int]:
        """Runs complete, failed, pruned and pending (planned runs without a trial are
        pending)."""
        return self.data.tally.counts()

    @property
    def finished(self) -> bool:
        """No run is still to come."""
        return self.counts["pending"] == 0

    def status(self) -> str:
        """'10/10 complete', or e.g. '7/10 complete, 1 failed, 2 pending'."""
        c = self.counts
        parts = [f"{c['complete']}/{c['planned']} complete"]
        parts += [f"{c[name]} {name}" for name in (Outcome.FAILED, Outcome.PRUNED, Outcome.PENDING)
                  if c[name]]
        return ", ".join(parts)

    @property
    def best(self) -> int | None:
        """Index of the best value (highest IQM final score), if any run is complete."""
        return self.comparison.best if self.comparison is not None else None


@dataclass(frozen=True)
class ConfirmArm:
    """One configuration a confirm study retrained: where it came from, the score its source
    study gave it on the tuning seeds, and what the fresh seeds say of it."""

    label: str
    origin: str
    """The source trial or baseline it was taken from ("-" when the definition names none)."""
    source_score: float
    """Its score in the source study (NaN for a baseline, or when none is stored)."""
    confirmed: ValueSummary
    """Its row of the confirm study's summary: confirmed scores, intervals, n, answer."""


def confirm_arms(sweep: Sweep) -> list[ConfirmArm]:
    """A confirm study's configurations, in the order of its values."""
    arms = {str(arm.get("label")): arm for arm in sweep.data.definition.get("arms") or []
            if isinstance(arm, dict)}
    found = []
    for value_index, label in enumerate(sweep.labels):
        arm = arms.get(label, {})
        source = arm.get("source_score")
        found.append(ConfirmArm(
            label=label, origin=str(arm.get("origin") or "-"),
            source_score=float(source) if source is not None else math.nan,
            confirmed=sweep.rows[value_index]))
    return found


def option(options: Any, name: str, default: Any) -> Any:
    """A report option (an attribute of ``options``), or ``default`` when it or ``options`` is
    None."""
    value = getattr(options, name, None) if options is not None else None
    return default if value is None else value


@dataclass(frozen=True)
class SweepEvidence:
    """What a stored sweep's runs say, read once: its values, one row per run, the complete
    runs' curves and, in a raced study, the race's ended runs. Nothing here is decided yet."""

    parameter: str
    name: str | None
    values: list[Any]
    labels: list[str]
    known: int
    """How many of ``values`` the study lists (a last "?" holds runs whose value is unread)."""
    trials: pd.DataFrame
    curves: pd.DataFrame
    time_attr: str
    finished: bool
    race: RaceRuns | None


def _or_nan(value: float | None) -> float:
    return np.nan if value is None else value


def sweep_evidence(data: StudyData) -> SweepEvidence:
    """A sweep's evidence from its stored trials and curves (a single-run study: one value):
    one pass over the trials, through the record schema alone."""
    definition = data.definition
    time_attr = time_measure(data.kind)  # the training time the summary shows and the rule reads
    if data.kind.swept:
        parameter = str(definition["parameter"])
        name, values = swept_values(data.kind, definition, data.trials)
        labels = [value_label(v) for v in values]
    else:
        parameter, name, values, labels = "", None, [SINGLE_LABEL], [SINGLE_LABEL]
    index = {value_key(v): i for i, v in enumerate(values)}
    rows = []
    for trial in data.trials:
        attrs = trial.user_attrs
        value = swept_value(trial, name, values) if name else None
        value_index = index.get(value_key(value), -1) if name else 0
        state = outcome(trial)
        ended = state != Outcome.PENDING
        rows.append({
            "number": trial.number, "key": attrs.get("key"), "seed": attrs.get("seed"),
            "value_index": value_index,
            "value": value_label(values[value_index]) if value_index >= 0 and name else
            (SINGLE_LABEL if not name else "?"),
            "outcome": state.value,
            "final_score": float(trial.value)
            if state == Outcome.COMPLETE and trial.value is not None else np.nan,
            # Measured by a complete run only; NaN where a run does not store the measure.
            **{m.name: _or_nan(m.read(attrs)) if state == Outcome.COMPLETE else np.nan
               for m in RUN_MEASURES},
            "wall_time": attrs.get("wall_time", np.nan) if ended else np.nan,
            "cpu_time": attrs.get("cpu_time", np.nan) if ended else np.nan,
            "env_steps": attrs.get("env_steps", np.nan) if ended else np.nan,
            # A sweep's pruned run is a raced value's retry, withdrawn: its reason says so.
            "failure": (attrs.get("failure", "")
                        if state in (Outcome.FAILED, Outcome.PRUNED) else ""),
            "model_path": attrs.get("model_path")})
    trials = pd.DataFrame(rows, columns=TRIAL_COLUMNS)
    for column in ("final_score", *(m.name for m in RUN_MEASURES), "wall_time", "cpu_time",
                   "env_steps"):
        trials[column] = pd.to_numeric(trials[column], errors="coerce").astype(float)
    known = len(values)
    # A run whose value cannot be read: show it, do not drop it.
    if (trials["value_index"] < 0).any():
        values, labels = values + ["?"], labels + ["?"]
        trials.loc[trials["value_index"] < 0, "value_index"] = len(values) - 1
    # A race's ended runs, each value placed in the report's order (matched by value).
    race = race_runs(definition, data.trials, values[:known]) if data.kind.swept else None
    complete = trials[trials["outcome"] == Outcome.COMPLETE][["value_index", "seed", "number"]]
    return SweepEvidence(parameter=parameter, name=name, values=values, labels=labels,
                         known=known, trials=trials,
                         curves=data.curves.merge(complete, on="number", how="inner"),
                         time_attr=time_attr,
                         finished=tally(data.trials, data.planned).counts()["pending"] == 0,
                         race=race)


def build_sweep(data: StudyData, options: Any = None) -> Sweep:
    """The evidence and answers of a sweep or confirm study, or of a single-run study (one
    value, several seeds), as the report draws them: read once
    ([`sweep_evidence`][kraby_study.answers.sweep_evidence.sweep_evidence]), decided once
    ([`decide_sweep`][kraby_study.decision.summary.decide_sweep]).

    Args:
        data: The stored study.
        options: The report's options (``bootstrap``: resamples of the bootstrap-t interval
            of a mean, ``threshold``: reward to reach or None for the default,
            ``min_seeds``: fewest complete seeds of a value in any comparison, ``margin``:
            ``compare.margin``, ``select``: ``compare.select``); None for the defaults.
    """
    judged = CompareOptions(margin=float(option(options, "margin", MARGIN)),
                            min_seeds=int(option(options, "min_seeds", MIN_SEEDS)),
                            select=option(options, "select", None))
    rule = study_rule(data.ledger.attrs.select, judged)
    evidence = sweep_evidence(data)
    race = evidence.race.replayed() if evidence.race is not None else None
    found = seed_scores(evidence.trials, evidence.curves, evidence.known, evidence.time_attr,
                        swept=evidence.name is not None)
    comparison = sweep_comparison(found.final, race.dropped if race is not None else (),
                                  judged, tests=True)
    decided = decide_sweep(
        evidence.trials, evidence.curves, evidence.labels, comparison, found,
        bootstrap=int(option(options, "bootstrap", BOOTSTRAP_REPETITIONS)),
        threshold=option(options, "threshold", None), race=race,
        time_attr=evidence.time_attr, train_reward=scored_by_evaluation(data.definition),
        rule=rule if evidence.name is not None and evidence.finished else None)
    return Sweep(data=data, parameter=evidence.parameter, name=evidence.name or SINGLE_LABEL,
                 values=evidence.values, rule=rule, labels=evidence.labels,
                 trials=evidence.trials, curves=evidence.curves, bands=decided.bands,
                 rows=decided.rows, seeds=decided.seeds, threshold=decided.threshold,
                 threshold_default=decided.threshold_default, untrained=decided.untrained,
                 bootstrap=decided.bootstrap, verdict=decided.verdict,
                 min_seeds=decided.comparison.min_seeds, race=decided.race,
                 comparison=decided.comparison, final_scores=found.final,
                 failure_line=decided.failure_line,
                 reach=decided.reach)
