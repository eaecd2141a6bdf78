"""An Optuna search (or any Optuna study) as tables: trials, parameters, importances, and a
two-objective search's front.

Works on any single-objective study with complete, pruned and failed trials, and on
kraby-study's two-objective searches (a score and a cost); kraby searches add env-step
checkpoints (``pruned_at``) and timings in user attributes.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import optuna
import pandas as pd
from optuna.distributions import (
    BaseDistribution,
)
from optuna.trial import FrozenTrial

from kraby_study.answers.racing_search import RacingSearch, racing_rules, racing_search
from kraby_study.answers.search_front import SearchFront, front_rule, search_front
from kraby_study.answers.study_data import StudyData
from kraby_study.answers.sweep_evidence import option
from kraby_study.decision.comparison import MARGIN, MIN_SEEDS, CompareOptions
from kraby_study.decision.front import FrontChoice
from kraby_study.records.attributes import StudyKind, TrialAttrs
from kraby_study.records.definition import stored_floor, two_objectives
from kraby_study.records.stored import Outcome, known_number, outcome
from kraby_study.records.values import best_trial, cost, ranking, score

TOP = 10
"""Rows of the top-trials table."""


@dataclass
class Search:
    """Everything the figures and tables of one search need.

    Attributes:
        data: The stored study.
        maximize: Whether higher objective values are better.
        trials: One row per counted trial: number, outcome, value, env_steps, wall_time,
            pruned_at, cost_stop (the CPU seconds a trial stopped for its cost was projected
            to use), failure, then one column per parameter.
        params: Parameter names, in first-seen order.
        distributions: A distribution per parameter (from the trials that used it).
        importances: Parameter importances (PED-ANOVA), or None with ``importance_note`` saying why.
        front: A two-objective search's front and selection; None for one objective.
        racing: A racing search's configurations and incumbent; None for another search.
    """

    data: StudyData
    maximize: bool
    trials: pd.DataFrame
    params: list[str]
    distributions: dict[str, BaseDistribution]
    importances: dict[str, float] | None
    importance_note: str
    front: SearchFront | None = None
    racing: RacingSearch | None = None

    @property
    def complete(self) -> list[FrozenTrial]:
        """Complete trials with a score."""
        return [t for t in self.data.trials
                if outcome(t) == Outcome.COMPLETE and score(t) is not None]

    @property
    def best(self) -> FrozenTrial | None:
        """The best complete trial."""
        return best_trial(self.data.trials, self.maximize, 1 if self.front is None else 2)

    def counts(self) -> dict[str, int]:
        """Trials complete, pruned, failed and pending (planned trials not started are pending)."""
        return self.data.tally.counts()

    @property
    def finished(self) -> bool:
        """No trial is still to come."""
        return self.counts()["pending"] == 0

    def status(self) -> str:
        """E.g. '50/50 trials done: 31 complete, 17 pruned, 2 failed'."""
        c = self.counts()
        done = c["complete"] + c["pruned"] + c["failed"]
        text = (f"{done}/{c['planned']} trials done: {c['complete']} complete, "
                f"{c['pruned']} pruned, {c['failed']} failed")
        return text + (f", {c['pending']} pending" if c["pending"] else "")


def param_columns(trials: list[FrozenTrial]) -> tuple[list[str], dict[str, BaseDistribution]]:
    """Parameter names in first-seen order, and a distribution for each."""
    names: list[str] = []
    distributions: dict[str, BaseDistribution] = {}
    for trial in trials:
        for name, distribution in trial.distributions.items():
            if name not in distributions:
                names.append(name)
                distributions[name] = distribution
    return names, distributions


def importances(maximize: bool, trials: list[FrozenTrial],
                params: list[str]) -> tuple[dict[str, float] | None, str]:
    """PED-ANOVA importances of the parameters (Optuna's default evaluator, no scikit-learn),
    or None and the reason they cannot be computed."""
    done = [t for t in trials if outcome(t) == Outcome.COMPLETE and score(t) is not None]
    if len(done) < 2:
        return None, f"parameter importances need at least 2 complete trials ({len(done)} so far)"
    varying = [p for p in params if len({repr(t.params.get(p)) for t in done}) > 1]
    if not varying:
        return None, "no parameter varies across the complete trials"
    # An in-memory copy of the trials read, by their score alone (a two-objective search's
    # trials have two values): the evaluator reads a study, not the store.
    study = optuna.create_study(direction="maximize" if maximize else "minimize")
    study.add_trials([optuna.trial.create_trial(params=t.params, distributions=t.distributions,
                                                value=score(t)) for t in done])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = optuna.importance.get_param_importances(
                study, evaluator=optuna.importance.PedAnovaImportanceEvaluator(),
                params=varying)
    except (RuntimeError, ValueError) as err:
        return None, f"parameter importances could not be computed ({err})"
    return {k: float(v) for k, v in result.items()}, ""


def trial_rows(trials: list[FrozenTrial], params: list[str],
               two: bool = False) -> pd.DataFrame:
    """One row per trial (``trial``: the number the search knows it by, its first attempt's;
    ``number``: Optuna's number of the attempt that holds it now, a retry's or a recheck's)
    with its outcome, value (its score) and the seeds it is the mean of (``seeds``: none for
    a trial that did not complete), costs (``training_time``: CPU s per
    seed of a complete trial) and parameters; with
    ``two`` (a two-objective search) also its cost objective (``cost``, CPU s per seed) and
    the configuration it was enqueued as (``enqueued``)."""
    rows = []
    for trial in trials:
        attrs = trial.user_attrs
        stored = TrialAttrs.of(trial)
        state = outcome(trial)
        steps = attrs.get("env_steps")
        if steps is None and trial.intermediate_values:
            steps = max(trial.intermediate_values)
        rows.append({
            "number": trial.number, "trial": known_number(trial), "outcome": state.value,
            "value": float(score(trial))  # type: ignore[arg-type]
            if state == Outcome.COMPLETE and score(trial) is not None else math.nan,
            # The seeds its score is the mean of: budget.seeds, more for a rechecked trial.
            "seeds": (len(attrs["scores"]) if state == Outcome.COMPLETE and attrs.get("scores")
                      else math.nan),
            "cost": cost(trial) if state == Outcome.COMPLETE else None,
            "training_time": stored.training_time() if state == Outcome.COMPLETE else None,
            "enqueued": stored.enqueued or "",
            "env_steps": steps, "wall_time": attrs.get("wall_time", _duration(trial)),
            "pruned_at": attrs.get("pruned_at", max(trial.intermediate_values)
                                   if state == Outcome.PRUNED and trial.intermediate_values
                                   else None),
            "cost_stop": attrs.get("cost_stop"),
            "failure": attrs.get("failure", "") if state == Outcome.FAILED else "",
            **{name: trial.params.get(name) for name in params},
        })
    extra = ["cost", "enqueued"] if two else []
    frame = pd.DataFrame(rows, columns=["number", "trial", "outcome", "value", "seeds", *extra,
                                        "env_steps", "wall_time", "training_time",
                                        "pruned_at", "cost_stop", "failure", *params])
    for column in ("seeds", "env_steps", "wall_time", "training_time", "pruned_at",
                   "cost_stop", *extra[:1]):
        frame[column] = pd.to_numeric(frame[column], errors="coerce").astype(float)
    return frame


def _duration(trial: FrozenTrial) -> float | None:
    if trial.datetime_start is None or trial.datetime_complete is None:
        return None
    return (trial.datetime_complete - trial.datetime_start).total_seconds()


def build_search(data: StudyData, options: Any = None) -> Search:
    """The tables of a search study; ``options``: the report's (``margin``: compare.margin,
    ``select``: compare.select, ``min_seeds``), None for the defaults."""
    maximize = data.ledger.maximize
    params, distributions = param_columns(data.trials)
    imp, note = importances(maximize, data.trials, params)
    two = is_two_objective(data)
    judged = CompareOptions(margin=float(option(options, "margin", MARGIN)),
                            min_seeds=int(option(options, "min_seeds", MIN_SEEDS)),
                            select=option(options, "select", None))
    return Search(data=data, maximize=maximize, trials=trial_rows(data.trials, params, two),
                  params=params, distributions=distributions, importances=imp,
                  importance_note=note,
                  front=(search_front(data.trials, stored_floor(data.definition),
                                      front_rule(data.ledger.attrs.select, judged), judged)
                         if two else None),
                  racing=(racing_search(data.definition, data.trials)
                          if racing_rules(data.kind, data.definition) is not None else None))


def is_two_objective(data: StudyData) -> bool:
    """A kraby-study search of a reward and a cost (a foreign multi-objective study is not
    drawn)."""
    return data.kind == StudyKind.SEARCH and two_objectives(data.definition)


@dataclass(frozen=True)
class FrontTrial:
    """One trial of a two-objective search's front, as the report shows it."""

    trial: int
    score: float
    cost: float
    """CPU seconds per seed."""
    enqueued: Any
    """The configuration it was enqueued as (e.g. a baseline's name); empty for a sampled one."""
    best: bool
    """It has the best score."""
    equivalent: bool
    """Shown equivalent to the best score (the rule ``fastest_equivalent`` admits it)."""
    selected: bool
    """The rule selects it."""
    answer: str
    """Its answer against the best score (empty when untested)."""
    params: dict[str, Any]
    """Its sampled settings, by parameter name."""


def front_trials(search: Search) -> list[FrontTrial]:
    """The front's trials, best score first."""
    assert search.front is not None
    choice = search.front.choice
    rows = search.trials.set_index("trial")
    found = []
    for point in sorted(search.front.front, key=lambda p: -p.score):
        row = rows.loc[point.key]
        found.append(FrontTrial(
            trial=point.key, score=point.score, cost=point.cost, enqueued=row["enqueued"],
            best=choice is not None and point.key == choice.best.key,
            equivalent=choice is not None and point.key in choice.equivalent,
            selected=choice is not None and point.key == choice.chosen.key,
            answer=answer_of(choice, point.key),
            params={name: row[name] for name in search.params}))
    return found


def front_frame(trials: list[FrontTrial], params: list[str]) -> pd.DataFrame:
    """pareto.csv: one row per front trial, one column per field and per parameter."""
    return pd.DataFrame(
        [{"trial": t.trial, "score": t.score, "cost": t.cost, "enqueued": t.enqueued,
          "best": t.best, "equivalent": t.equivalent, "selected": t.selected,
          "answer": t.answer, **t.params} for t in trials],
        columns=["trial", "score", "cost", "enqueued", "best", "equivalent", "selected",
                 "answer", *params])


def answer_of(choice: FrontChoice[int] | None, key: int) -> str:
    """A front trial's answer against the best score (empty when untested)."""
    compared = choice.comparison if choice is not None else None
    if compared is None or key not in compared.answers:
        return ""
    return str(compared.answers[key])


def configuration_frame(racing: RacingSearch) -> pd.DataFrame:
    """configurations.csv of a racing search: one row per configuration, in the order it was
    asked for, with its seeds, IQM, CPU s per run, how it left and its parameters."""
    names = list(dict.fromkeys(name for c in racing.configurations for name in c.params))
    return pd.DataFrame(
        [{"configuration": c.key, "enqueued": c.enqueued or "", "seeds": c.seeds,
          "failed": c.failed, "iqm": c.iqm, "cpu_per_run": c.cpu,
          "standing": c.standing.left.value, "left": c.left_text(),
          "scores": " ".join(f"{v:.6g}" for v in c.scores.values()),
          **{name: c.params.get(name) for name in names}} for c in racing.configurations],
        columns=["configuration", "enqueued", "seeds", "failed", "iqm", "cpu_per_run",
                 "standing", "left", "scores", *names])


def top_trials(search: Search, count: int = TOP) -> pd.DataFrame:
    """The best complete trials, best first as the pick ranks them (of equal scores the one
    on more seeds, then the cheaper: [`ranking`][kraby_study.records.values.ranking]), with a rank
    column."""
    done = search.trials[search.trials["outcome"] == Outcome.COMPLETE]
    by_number = {t.number: t for t in search.data.trials}
    order = sorted(done["number"], key=lambda n: ranking(by_number[n], search.maximize))
    done = done.set_index("number", drop=False).loc[order[:count]].reset_index(drop=True)
    return done.drop(columns=["outcome", "pruned_at", "failure"]).assign(
        rank=range(1, len(done) + 1))[["rank", "trial", "number", "value", "seeds", "training_time",
                                       *search.params, "env_steps", "wall_time"]]
