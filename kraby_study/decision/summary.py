"""A sweep's per-value summary from its runs' table, its seed scores and its one comparison,
as typed rows ([`ValueSummary`][kraby_study.decision.summary.ValueSummary], one per value) the
report renders and writes as summary.csv: counts, the final score's mean and interval (bootstrap-t
from 5 seeds, Hall's skewness-corrected t below), the IQM and its trimmed-t interval (Tukey and
McLaughlin 1963), spread, the answers at the margin, the learning curves' metrics (sample
efficiency, time to a threshold), failed seeds (Clopper-Pearson rate interval), the per-run measures
([`RUN_MEASURES`][kraby_study.records.attributes.RUN_MEASURES]), the selected value, and the
verdict.

In a raced study ([`kraby_study.decision.race`][]) the values the race dropped are never best,
equivalent, selected or any answer of the verdict: they are shown as worse, with the round and the
adjusted p of the look that dropped them, and the others (those still racing and those it settled as
equivalent) are compared on all their seeds."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from kraby_study.decision.comparison import Comparison, p_text
from kraby_study.decision.failed_seeds import failed_seeds, failure_line
from kraby_study.decision.intervals import (
    BOOTSTRAP_REPETITIONS,
    describe,
    iqm,
    iqm_interval,
    mean_interval,
)
from kraby_study.decision.measures import (
    auc,
    curve_rewards,
    default_threshold,
    first_reach,
    iqr,
    iqr_unbiased,
    p_improvement,
    p_improvement_interval,
    seed_samples,
)
from kraby_study.decision.race import Drop, StudyRace
from kraby_study.decision.selection import select
from kraby_study.decision.verdict import Verdict, verdict
from kraby_study.records.attributes import RUN_MEASURES
from kraby_study.records.stored import Outcome
from kraby_study.records.values import ANSWER_FROM

DROPPED_PREFIX = "dropped by the race"
"""How the summary's note of a value the race dropped begins."""
SETTLED_PREFIX = "settled equivalent by the race"
"""How the summary's note of a value the race settled as equivalent begins."""
SEED_COLUMNS = ["value_index", "seed", "number", "final_score", "first_reward", "auc",
                "steps_to_threshold", "seconds_to_threshold", "end_step", "end_seconds"]


def curve_bands(curves: pd.DataFrame) -> pd.DataFrame:
    """Mean reward and its Hall skewness-corrected t interval over seeds, at every n
    ([`describe`][kraby_study.decision.intervals.describe] without a bootstrap), per value and step
    (vectorised): hundreds of intervals a value, where a bootstrap each would cost seconds."""
    if curves.empty:
        return pd.DataFrame(columns=["value_index", "step", "n", "mean", "sd", "low", "high",
                                     "wall_time"])
    grouped = describe(curves, ["value_index", "step"], "mean_reward")
    grouped["wall_time"] = curves.groupby(["value_index", "step"], sort=True)["wall_time"].mean()
    return grouped[["n", "mean", "sd", "low", "high", "wall_time"]].reset_index()


def _finals(done: pd.DataFrame) -> dict[int, list[float]]:
    return {int(i): group["final_score"].tolist() for i, group in done.groupby("value_index")}


def left_out_note(n: int, min_seeds: int) -> str:
    """Why a value with ``n`` complete seeds is in no comparison and no answer of the verdict."""
    return (f"left out: {n} complete seed{'s' if n != 1 else ''}, fewer than report.min_seeds "
            f"= {min_seeds}")


def untested_note() -> str:
    """Why a value is undecided whatever its scores: no test of it against the best is run."""
    return (f"not tested: fewer than {ANSWER_FROM} seeds here or on the best, so undecided by "
            "rule")


def dropped_note(drop: Drop, look_alpha: float) -> str:
    """Why a value the race dropped is shown as worse: the look that dropped it."""
    return (f"{DROPPED_PREFIX} after round {drop.round}, {drop.why()}, at the "
            f"race's per-look alpha {look_alpha:.3g}")


def settled_note(drop: Drop, look_alpha: float) -> str:
    """Why a value got no more seeds although it is a candidate: the look that settled it."""
    return (f"{SETTLED_PREFIX} after round {drop.round} (p {p_text(drop.p)} at the race's "
            f"per-look alpha {look_alpha:.3g}); compared on its {drop.round} seeds")


def note_part(note: str, prefix: str) -> str | None:
    """The part of a summary note that begins with ``prefix`` (notes join parts with '; ')."""
    return next((part for part in str(note or "").split("; ") if part.startswith(prefix)),
                None)


def summarise(trials: pd.DataFrame, labels: list[str], comparison: Comparison[int],
              bootstrap: int = BOOTSTRAP_REPETITIONS,
              dropped: Mapping[int, Drop] | None = None,
              look_alpha: float = math.nan, time_attr: str = "wall_time",
              settled: Mapping[int, Drop] | None = None,
              final: Mapping[int, list[float]] | None = None) -> pd.DataFrame:
    """One row per value: run counts; the round after which a race dropped it
    (``dropped_at``, empty for a survivor and in a study that did not race); the complete
    seeds' final score (mean, sd, interval of the mean,
    [`mean_interval`][kraby_study.decision.intervals.mean_interval] with ``bootstrap`` resamples;
    IQM with its trimmed-t interval; IQR raw and rescaled to be comparable across n) and training
    time (the trial column ``time_attr``,
    [`time_measure`][kraby_study.answers.seed_scores.time_measure]); the probability that the best
    value beats this one, with its Newcombe score-type interval; the ``answer`` of the comparison,
    written out (best, equivalent, worse, undecided; ``left out`` for a value with too few seeds,
    empty for one without any), with ``p_worse`` and ``p_equivalent`` (empty where no test of the
    value against the best is run), the margin in score units (``margin``, the same on every row)
    and the smallest margin its seeds resolve
    (``margin_resolvable``); and a note naming why a value with fewer than ``min_seeds``
    complete seeds is left out, or which look of the race dropped or settled it. The curve
    metrics are added by [`add_curve_metrics`][kraby_study.decision.summary.add_curve_metrics].

    ``comparison`` is the study's one comparison, made in the answers layer
    ([`sweep_comparison`][kraby_study.answers.seed_scores.sweep_comparison]). ``dropped`` (by value
    index) are the values a race dropped as worse, at per-look level ``look_alpha``: they are left
    out of the comparison (never best or equivalent, answer worse); ``settled``, those it settled as
    equivalent, which stay in it. ``final``: each value's complete seeds' final scores from
    the pass every decision reads ([`seed_scores`][kraby_study.decision.summary.seed_scores]); None:
    read from ``trials``.
    """
    dropped = dict(dropped or {})
    settled = dict(settled or {})
    done = trials[trials["outcome"] == Outcome.COMPLETE]
    score = describe(done, "value_index", "final_score", bootstrap=bootstrap)
    time = describe(done, "value_index", time_attr, bootstrap=bootstrap)
    counts = pd.crosstab(trials["value_index"], trials["outcome"])
    # A run whose value cannot be read ("?") is described but never in the decisions' pass.
    scores = {**_finals(done), **(final or {})}
    best = comparison.best
    left_out = comparison.left_out
    rows = []
    for value_index, label in enumerate(labels):
        count = counts.loc[value_index] if value_index in counts.index else pd.Series(dtype=int)
        finals = scores.get(value_index, [])
        s = score.loc[value_index] if value_index in score.index else None
        t = time.loc[value_index] if value_index in time.index else None
        steps = done.loc[done["value_index"] == value_index, "env_steps"]
        iqm_low, iqm_high = iqm_interval(finals)
        if best is None or value_index == best or not finals:
            improvement, improvement_low, improvement_high = np.nan, np.nan, np.nan
        else:
            improvement = p_improvement(scores[best], finals)
            improvement_low, improvement_high = p_improvement_interval(scores[best], finals)
        drop = dropped.get(value_index)
        notes = [dropped_note(drop, look_alpha)] if drop is not None else []
        if value_index in settled:
            notes.append(settled_note(settled[value_index], look_alpha))
        if value_index in left_out:
            notes.append(left_out_note(len(finals), comparison.min_seeds))
        untested = value_index in comparison.unanswered
        if untested:
            notes.append(untested_note())
        answer = ("worse" if drop is not None else
                  str(comparison.answers[value_index]) if value_index in comparison.answers else
                  "left out" if value_index in left_out else "")
        rows.append({
            "value": label,
            "complete": int(count.get(Outcome.COMPLETE, 0)),
            "failed": int(count.get(Outcome.FAILED, 0)),
            "pruned": int(count.get(Outcome.PRUNED, 0)),
            "pending": int(count.get(Outcome.PENDING, 0)),
            "dropped_at": drop.round if drop is not None else None,
            "final_mean": s["mean"] if s is not None else np.nan,
            "final_sd": s["sd"] if s is not None else np.nan,
            "final_low": s["low"] if s is not None else np.nan,
            "final_high": s["high"] if s is not None else np.nan,
            "iqm": iqm(finals),
            "iqm_low": iqm_low,
            "iqm_high": iqm_high,
            # A spread needs two seeds: one seed's IQR of 0 would read as perfectly repeatable.
            "final_iqr": iqr(finals) if len(finals) >= 2 else np.nan,
            "final_iqr_unbiased": iqr_unbiased(finals),
            "time_mean": t["mean"] if t is not None else np.nan,
            "time_low": t["low"] if t is not None else np.nan,
            "time_high": t["high"] if t is not None else np.nan,
            "env_steps": float(steps.mean()) if len(steps) else np.nan,
            # An untested value has no p: the comparison's 1 only keeps it out of every answer.
            "p_worse": np.nan if untested else comparison.p_worse.get(value_index, np.nan),
            "p_equivalent": (np.nan if untested
                             else comparison.p_equivalent.get(value_index, np.nan)),
            "p_improvement": improvement,
            "p_improvement_low": improvement_low,
            "p_improvement_high": improvement_high,
            "answer": answer,
            "margin": comparison.margin,
            "margin_resolvable": comparison.resolvable.get(value_index, np.nan),
            "note": "; ".join(notes),
        })
    frame = pd.DataFrame(rows)
    if not frame.empty:  # one schema, raced or not: an empty cell where nothing was dropped
        frame["dropped_at"] = frame["dropped_at"].astype("Int64")
    return frame


def first_points(curves: pd.DataFrame) -> pd.DataFrame:
    """The curve points of each trial in step order (a stable sort, so equal steps keep their
    stored order)."""
    return curves.sort_values(["number", "step"], kind="stable")


def best_mean(summary: pd.DataFrame) -> float:
    """The mean final score of the summary's best value; NaN when none is best."""
    best = summary.index[summary["answer"] == "best"]
    return float(summary.loc[best[0], "final_mean"]) if len(best) else math.nan


def study_threshold(curves: pd.DataFrame, summary: pd.DataFrame,
                    threshold: float | None) -> tuple[float, bool, float]:
    """The reward a learning curve must reach.

    Args:
        curves: Curve points of the complete runs.
        summary: The summary (for the best value's mean final score).
        threshold: The report's threshold, or None for the default.

    Returns:
        (threshold, whether it is the default, the untrained reward). The default is
        [`default_threshold`][kraby_study.decision.measures.default_threshold] of the untrained
        reward (the mean over every complete seed of its first curve point's reward) and the best
        value's mean final score; NaN when either is missing.
    """
    ordered = first_points(curves)
    first = ordered.drop_duplicates("number")["mean_reward"].to_numpy(dtype=float)
    untrained = float(np.mean(first)) if len(first) else math.nan
    if threshold is not None:
        return float(threshold), False, untrained
    best_final = best_mean(summary)
    if not (np.isfinite(untrained) and np.isfinite(best_final)):
        return math.nan, True, untrained
    return float(default_threshold(untrained, best_final)), True, untrained


def seed_metrics(trials: pd.DataFrame, curves: pd.DataFrame, threshold: float) -> pd.DataFrame:
    """One row per complete run: its final score, its curve's first reward, its AUC
    ([`auc`][kraby_study.decision.measures.auc] of the curve in step order), the env steps and
    seconds at which the curve first reached ``threshold`` (NaN if never, or without a curve) and
    the env steps and seconds of its curve's last point (where a seed that never reached it is
    censored)."""
    done = trials[trials["outcome"] == Outcome.COMPLETE]
    per_trial: dict[int, tuple[float, ...]] = {}
    for number, group in first_points(curves).groupby("number", sort=False):
        rewards = group["mean_reward"].to_numpy(dtype=float)
        step_points = group["step"].to_numpy(dtype=float)
        wall = group["wall_time"].to_numpy(dtype=float)
        steps, seconds = first_reach(step_points, rewards, wall, threshold)
        per_trial[int(number)] = (float(rewards[0]), auc(rewards), steps, seconds,
                                  float(step_points[-1]), float(wall[-1]))
    missing = (math.nan,) * 6
    rows = []
    for row in done.itertuples(index=False):
        metrics = per_trial.get(int(row.number), missing)
        rows.append((int(row.value_index), row.seed, int(row.number), float(row.final_score),
                     *metrics))
    frame = pd.DataFrame(rows, columns=SEED_COLUMNS)
    for column in SEED_COLUMNS[3:]:
        frame[column] = frame[column].astype(float)
    return frame


def add_curve_metrics(summary: pd.DataFrame, seeds: pd.DataFrame,
                      bootstrap: int = BOOTSTRAP_REPETITIONS) -> pd.DataFrame:
    """The summary with the curve metrics of each value's complete seeds: AUC (mean and
    interval over the seeds with a curve,
    [`mean_interval`][kraby_study.decision.intervals.mean_interval] with ``bootstrap`` resamples),
    env steps and seconds to the threshold and how many seeds reached it.

    Steps and seconds to the threshold are restricted means over the seeds with a curve: a seed
    that never reached the threshold counts at its curve's last point, so the mean is a lower
    bound of the true mean time when ``reached`` is below the seeds with a curve. NaN when no
    seed reached it.
    """
    columns: dict[str, list[float]] = {name: [] for name in (
        "auc_mean", "auc_low", "auc_high", "steps_to_threshold", "seconds_to_threshold",
        "reached")}
    groups = dict(iter(seeds.groupby("value_index", sort=True)))
    for value_index in summary.index:
        group = groups.get(value_index, seeds.iloc[:0])
        aucs = group["auc"].dropna().to_numpy()
        mean, low, high = mean_interval(aucs, resamples=bootstrap)
        reached = group[group["steps_to_threshold"].notna()]
        curved = group[group["end_step"].notna()]
        columns["auc_mean"].append(mean)
        columns["auc_low"].append(low)
        columns["auc_high"].append(high)
        for name, end in (("steps_to_threshold", "end_step"),
                          ("seconds_to_threshold", "end_seconds")):
            censored = curved[name].fillna(curved[end])
            columns[name].append(float(censored.mean()) if len(reached) else math.nan)
        columns["reached"].append(len(reached))
    out = summary.copy()
    at = list(out.columns).index("final_iqr_unbiased") + 1
    for offset, (name, values) in enumerate(columns.items()):
        out.insert(at + offset, name, values)
    out["reached"] = out["reached"].astype(int)
    return out


def add_run_measures(summary: pd.DataFrame, trials: pd.DataFrame,
                     bootstrap: int = BOOTSTRAP_REPETITIONS, evaluated: bool = False
                     ) -> pd.DataFrame:
    """``summary`` with each per-run measure's per-value columns
    ([`RUN_MEASURES`][kraby_study.records.attributes.RUN_MEASURES]) over the value's complete seeds
    that measured it: ``describe``, the mean, sd and interval of the mean
    ([`describe`][kraby_study.decision.intervals.describe], as the final score's); ``rms``, the root
    mean square. The measures of runs scored by evaluation only when ``evaluated``; NaN where no
    seed measured it. No decision reads them."""
    complete = trials[trials["outcome"] == Outcome.COMPLETE]
    out = summary
    for measure in RUN_MEASURES:
        if measure.evaluated and not evaluated:
            continue
        done = complete[complete[measure.name].notna()]
        if measure.summary == "describe":
            parts = dict(zip(("mean", "sd", "low", "high"), measure.columns, strict=True))
            if done.empty:
                out = out.assign(**{column: np.nan for column in parts.values()})
                continue
            found = describe(done, "value_index", measure.name, bootstrap=bootstrap)
            out = out.join(found[list(parts)].rename(columns=parts))  # NaN: no such seeds
        else:
            rms = done.groupby("value_index")[measure.name].apply(
                lambda e: float(np.sqrt(np.mean(e ** 2))))
            out = out.assign(**{measure.column: [rms.get(i, np.nan) for i in out.index]})
    return out


def add_failed_seeds(summary: pd.DataFrame, seeds: pd.DataFrame, untrained: float
                     ) -> tuple[pd.DataFrame, float]:
    """``summary`` with each value's failed seeds ([`kraby_study.decision.failed_seeds`][]):
    ``failed_seeds`` (count), ``failed_seeds_low`` and ``failed_seeds_high`` (the exact interval of
    the rate); and the failure line (NaN when it is not defined: no best, no curve, or a best that
    learned nothing)."""
    line = failure_line(untrained, best_mean(summary))
    groups = dict(iter(seeds.groupby("value_index", sort=True)))
    found = [failed_seeds(groups[i]["final_score"].tolist() if i in groups else [], line)
             for i in summary.index]
    out = summary.assign(failed_seeds=[f.count if f.seeds else np.nan for f in found],
                         failed_seeds_low=[f.low for f in found],
                         failed_seeds_high=[f.high for f in found])
    return out, line


def study_verdict(summary: pd.DataFrame, comparison: Comparison[int]) -> Verdict:
    """The verdict of [`verdict`][kraby_study.decision.verdict.verdict] from the study's one
    ``comparison`` (whose family leaves out the values a race dropped) and the summary rows. The
    fastest is by the restricted mean seconds (a seed that never reached the threshold counts at its
    run's end); the rescaled IQR (``final_iqr_unbiased``) decides the most repeatable."""
    return verdict(comparison, auc_means=summary["auc_mean"].to_dict(),
                   seconds=summary["seconds_to_threshold"].to_dict(),
                   iqrs=summary["final_iqr_unbiased"].to_dict())


REACH_COLUMNS = ("steps_to_threshold", "seconds_to_threshold")


def reach_means(seeds: pd.DataFrame, values: int, bootstrap: int) -> pd.DataFrame:
    """Per value (index 0 to ``values`` - 1): the mean env steps and seconds to the threshold
    over the seeds that reached it, each with its interval
    ([`mean_interval`][kraby_study.decision.intervals.mean_interval]), columns ``<measure>_mean``,
    ``_low`` and ``_high``: the marks of the time-to-threshold figure (the summary's columns are
    restricted means over every seed instead)."""
    rows = []
    for value_index in range(values):
        row: dict[str, float] = {}
        for column in REACH_COLUMNS:
            kept = (seeds["value_index"] == value_index) & seeds[column].notna()
            found = seeds.loc[kept, column].to_numpy()
            mean, low, high = mean_interval(found, resamples=bootstrap)
            row |= {f"{column}_mean": mean, f"{column}_low": low, f"{column}_high": high}
        rows.append(row)
    return pd.DataFrame(rows, index=pd.RangeIndex(values, name="value_index"))


@dataclass(frozen=True)
class ValueSummary:
    """What a sweep's evidence says of one value: the report's tables, figures and summary.csv
    read these fields (summary.csv's columns are their names, in this order, with the per-run
    measures' columns in place of ``measures``)."""

    value: str
    """How the value is written."""
    complete: int
    failed: int
    pruned: int
    pending: int
    """Its runs by outcome (pending: planned and not ended)."""
    dropped_at: int | None
    """The round after which a race dropped it; None for a survivor or without a race."""
    final_mean: float
    final_sd: float
    final_low: float
    final_high: float
    """The complete seeds' final score: mean, sd and the interval of the mean."""
    iqm: float
    iqm_low: float
    iqm_high: float
    """The interquartile mean (IQM) of the final scores and its trimmed-t interval."""
    final_iqr: float
    """The final scores' interquartile range (NaN below 2 seeds)."""
    final_iqr_unbiased: float
    """The IQR rescaled to be comparable across n."""
    auc_mean: float
    auc_low: float
    auc_high: float
    """Sample efficiency (AUC): mean and interval over the seeds with a curve."""
    steps_to_threshold: float
    seconds_to_threshold: float
    """Restricted mean env steps and seconds to the threshold (NaN when no seed reached it)."""
    reached: int
    """Seeds whose curve reached the threshold."""
    time_mean: float
    time_low: float
    time_high: float
    """Training time per run: mean and interval of the mean."""
    env_steps: float
    """Mean env steps per complete run."""
    p_worse: float
    p_equivalent: float
    """The comparison's p of each answer (NaN where untested or for the best)."""
    p_improvement: float
    p_improvement_low: float
    p_improvement_high: float
    """P(best > value) with its Newcombe interval (NaN for the best)."""
    answer: str
    """best, equivalent, worse, undecided, ``left out`` (too few seeds) or empty (no seed)."""
    margin: float
    """The comparison's margin in score units (the same on every row)."""
    margin_resolvable: float
    """The smallest margin its seeds resolve against the best (NaN where untested)."""
    note: str
    """Why it is left out, untested, or what a race did with it; parts joined by '; '."""
    failed_seeds: float
    failed_seeds_low: float
    failed_seeds_high: float
    """Its failed seeds (NaN when not counted) and the exact interval of the rate."""
    measures: dict[str, float]
    """The per-run measures' per-value columns
    ([`RUN_MEASURES`][kraby_study.records.attributes.RUN_MEASURES]), by column name."""
    selected: bool
    """The study's rule selects it."""


_SCALARS = [f.name for f in dataclasses.fields(ValueSummary)
            if f.name not in ("measures", "selected")]


def value_rows(frame: pd.DataFrame) -> list[ValueSummary]:
    """The typed rows of the per-value table the summary's steps build, in value order."""
    scalars = set(_SCALARS) | {"selected"}
    rows = []
    for record in frame.to_dict("records"):
        dropped = record["dropped_at"]
        rows.append(ValueSummary(
            **{name: record[name] for name in _SCALARS if name != "dropped_at"},
            dropped_at=None if pd.isna(dropped) else int(dropped),
            measures={k: float(v) for k, v in record.items() if k not in scalars},
            selected=bool(record["selected"])))
    return rows


def summary_frame(rows: Sequence[ValueSummary]) -> pd.DataFrame:
    """The rows as one table, a column per field in order (summary.csv, and a notebook's
    view): the per-run measures' columns where ``measures`` stands."""
    records = [{**{name: getattr(r, name) for name in _SCALARS}, **r.measures,
                "selected": r.selected} for r in rows]
    frame = pd.DataFrame(records, columns=list(records[0]) if records else
                         [*_SCALARS, "selected"])
    frame["dropped_at"] = frame["dropped_at"].astype("Int64")
    return frame


@dataclass(frozen=True)
class SweepAnswers:
    """What a sweep's evidence decides: the one comparison, the per-value summary (answers,
    the selected value), the per-seed metrics, the curves' bands, the race (None
    without one) and the verdict."""

    comparison: Comparison[int]
    rows: list[ValueSummary]
    """One per value, in value order."""
    seeds: pd.DataFrame
    bands: pd.DataFrame
    threshold: float
    threshold_default: bool
    untrained: float
    failure_line: float
    bootstrap: int
    verdict: Verdict
    race: StudyRace | None
    reach: pd.DataFrame
    """Per value, the mean time to the threshold over the seeds that reached it
    ([`reach_means`][kraby_study.decision.summary.reach_means])."""


@dataclass(frozen=True)
class SeedScores:
    """Per value with a complete run, in value order: the complete runs' final scores, their
    curves' AUCs and their training times, each in run order: the numbers every decision
    reads."""

    final: dict[int, list[float]]
    aucs: dict[int, list[float]]
    seconds: dict[int, list[float]]


def seed_scores(trials: pd.DataFrame, curves: pd.DataFrame, known: int, time_attr: str,
                swept: bool = True) -> SeedScores:
    """The [`SeedScores`][kraby_study.decision.summary.SeedScores] of the values among the first
    ``known`` (training time: the column ``time_attr``); a single-run study (``swept`` False) has
    one value, every complete run's score."""
    done = trials[(trials["outcome"] == Outcome.COMPLETE) & trials["final_score"].notna()
                  & (trials["value_index"] < known)]
    runs = done[["value_index", "number", "final_score", time_attr]].itertuples(index=False)
    final, aucs, seconds = seed_samples(((int(value_index), int(number), float(score), float(spent))
                                         for value_index, number, score, spent in runs),
                                        curve_rewards(curves))
    if not swept:
        final = _finals(trials[trials["outcome"] == Outcome.COMPLETE])
    return SeedScores(final=final, aucs=aucs, seconds=seconds)


def decide_sweep(trials: pd.DataFrame, curves: pd.DataFrame, labels: list[str],
                 comparison: Comparison[int], samples: SeedScores, *, bootstrap: int,
                 threshold: float | None, race: StudyRace | None, time_attr: str,
                 train_reward: bool, rule: str | None) -> SweepAnswers:
    """The answers of a sweep from its evidence and its one comparison, in one pass.

    Args:
        trials: One row per counted run (``value_index`` indexes ``labels``).
        curves: Curve points of the complete runs, with their ``value_index`` and ``seed``.
        labels: How each value is written.
        comparison: The study's one comparison of ``samples.final`` (the values a race
            dropped left out), made in the answers layer.
        samples: The seed scores every decision reads
            ([`seed_scores`][kraby_study.decision.summary.seed_scores]).
        bootstrap: Resamples of the bootstrap-t interval of a mean.
        threshold: The reward a curve must reach, None for the default.
        race: A raced study's race replayed (None: it did not race): its dropped values are
            never best, equivalent or selected.
        time_attr: The trial column read as training time.
        train_reward: The runs are scored by evaluation: add the training reward and the
            evaluation's standard error beside the final score.
        rule: The rule that selects a value (None while runs are pending, or in a single-run
            study).
    """
    dropped = race.dropped if race is not None else {}
    settled = race.settled if race is not None else {}
    look_alpha = race.rules.look_alpha if race is not None else math.nan
    summary = summarise(trials, labels, comparison, bootstrap, dropped, look_alpha,
                        time_attr, settled, samples.final)
    level, is_default, untrained = study_threshold(curves, summary, threshold)
    seeds = seed_metrics(trials, curves, level)
    summary = add_curve_metrics(summary, seeds, bootstrap)
    summary, failure = add_failed_seeds(summary, seeds, untrained)
    summary = add_run_measures(summary, trials, bootstrap, evaluated=train_reward)
    chosen = (select(rule, comparison, samples.aucs, samples.seconds)
              if rule is not None else None)
    summary["selected"] = [value_index == chosen for value_index in summary.index]
    return SweepAnswers(comparison=comparison, rows=value_rows(summary), seeds=seeds,
                        bands=curve_bands(curves), threshold=level,
                        threshold_default=is_default, untrained=untrained,
                        failure_line=failure, bootstrap=bootstrap,
                        verdict=study_verdict(summary, comparison), race=race,
                        reach=reach_means(seeds, len(summary), bootstrap))
