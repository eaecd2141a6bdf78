"""A sweep's per-value summary from its runs' table and seed scores: counts, the final score's
mean and interval, IQM, spread, the answers at the margin, the learning curves' metrics
(sample efficiency, time to a threshold), failed seeds, and the verdict.

In a raced study (:mod:`kraby_study.decision.race`) the values the race dropped are never best,
equivalent, selected or any answer of the verdict: they are shown as worse, with the round and
the adjusted p of the look that dropped them, and the others (those still racing and those it
settled as equivalent) are compared on all their seeds."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from kraby_study.decision.comparison import MIN_SEEDS, CompareOptions, Comparison, compare
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
from kraby_study.decision.race import Drop, RaceRuns, StudyRace
from kraby_study.decision.selection import RULES, mean_by_value
from kraby_study.decision.verdict import Verdict, compare_to_best, verdict, welch_p
from kraby_study.records.attributes import SelectRule
from kraby_study.records.stored import Outcome
from kraby_study.records.values import ANSWER_FROM

DROPPED_PREFIX = "dropped by the race"
"""How the summary's note of a value the race dropped begins."""
SETTLED_PREFIX = "settled equivalent by the race"
"""How the summary's note of a value the race settled as equivalent begins."""
SEED_COLUMNS = ["vi", "seed", "number", "final_score", "first_reward", "auc",
                "steps_to_threshold", "seconds_to_threshold", "end_step", "end_seconds"]


def curve_bands(curves: pd.DataFrame) -> pd.DataFrame:
    """Mean reward and its Hall skewness-corrected t interval over seeds, at every n
    (:func:`kraby_study.decision.intervals.describe` without a bootstrap), per value and step
    (vectorised): hundreds of intervals a value, where a bootstrap each would cost seconds."""
    if curves.empty:
        return pd.DataFrame(columns=["vi", "step", "n", "mean", "sd", "low", "high", "wall_time"])
    grouped = describe(curves, ["vi", "step"], "mean_reward")
    grouped["wall_time"] = curves.groupby(["vi", "step"], sort=True)["wall_time"].mean()
    return grouped[["n", "mean", "sd", "low", "high", "wall_time"]].reset_index()


def _finals(done: pd.DataFrame) -> dict[int, list[float]]:
    return {int(vi): group["final_score"].tolist() for vi, group in done.groupby("vi")}


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
    return (f"{DROPPED_PREFIX} after round {drop.round}, adjusted p {_p_short(drop.p)}, at the "
            f"race's per-look alpha {look_alpha:.3g}")


def settled_note(drop: Drop, look_alpha: float) -> str:
    """Why a value got no more seeds although it is a candidate: the look that settled it."""
    return (f"{SETTLED_PREFIX} after round {drop.round} (p {_p_short(drop.p)} at the race's "
            f"per-look alpha {look_alpha:.3g}); compared on its {drop.round} seeds")


def _p_short(p: float) -> str:
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def note_part(note: str, prefix: str) -> str | None:
    """The part of a summary note that begins with ``prefix`` (notes join parts with '; ')."""
    return next((part for part in str(note or "").split("; ") if part.startswith(prefix)),
                None)


def summarise(trials: pd.DataFrame, labels: list[str],
              bootstrap: int = BOOTSTRAP_REPETITIONS, min_seeds: int = MIN_SEEDS,
              dropped: Mapping[int, Drop] | None = None,
              look_alpha: float = math.nan, time_attr: str = "wall_time",
              comparison: Comparison[int] | None = None,
              settled: Mapping[int, Drop] | None = None,
              final: Mapping[int, list[float]] | None = None) -> pd.DataFrame:
    """One row per value: run counts; the round after which a race dropped it
    (``dropped_at``, empty for a survivor and in a study that did not race); the complete
    seeds' final score (mean, sd, interval of the mean,
    :func:`kraby_study.decision.intervals.mean_interval` with ``bootstrap`` resamples; IQM with its
    trimmed-t interval; IQR raw and rescaled to be comparable across n) and training time (the trial
    column ``time_attr``, :func:`kraby_study.decision.selection.time_measure`); the raw two-sided
    Welch p-value against the best value (``p_vs_best``) and the adjusted p of the closed Holm-Welch
    step-down (``p_holm``, :func:`kraby_study.decision.comparison.compare_with_best`); the
    probability that the best value beats this one, with its Newcombe score-type interval; a mark:
    ``best``, ``tie`` (adjusted p >= 0.05: not shown worse at margin 0) or empty; the ``answer`` of
    the comparison, written out (best, equivalent, worse, undecided; ``left out`` for a value with
    too few seeds, empty for one without any), with ``p_worse`` and ``p_equivalent`` (empty
    where no test of the value against the best is run), the margin in
    score units (``margin``, the same on every row) and the smallest margin its seeds resolve
    (``margin_resolvable``); and a note naming why a value with fewer than ``min_seeds``
    complete seeds is left out, or which look of the race dropped or settled it. The curve
    metrics are added by :func:`add_curve_metrics`.

    ``comparison`` is the study's one comparison (:func:`kraby_study.decision.comparison.compare`);
    None: compared here at margin 0. ``dropped`` (by value index) are the values a race
    dropped as worse, at per-look level ``look_alpha``: they are left out of the comparison
    (never best or equivalent, ``p_holm`` empty, answer worse); ``settled``, those it settled
    as equivalent, which stay in it. ``final``: each value's complete seeds' final scores from
    the pass every decision reads (:func:`kraby_study.decision.selection.samples`); None: read from
    ``trials``.
    """
    dropped = dict(dropped or {})
    settled = dict(settled or {})
    done = trials[trials["outcome"] == Outcome.COMPLETE]
    score = describe(done, "vi", "final_score", bootstrap=bootstrap)
    time = describe(done, "vi", time_attr, bootstrap=bootstrap)
    counts = pd.crosstab(trials["vi"], trials["outcome"])
    # A run whose value cannot be read ("?") is described but never in the decisions' pass.
    scores = {**_finals(done), **(final or {})}
    survivors = {vi: finals for vi, finals in scores.items() if vi not in dropped}
    if comparison is None:
        comparison = compare(survivors, 0.0, min_seeds=min_seeds)
    best = comparison.best
    _, pvalues = compare_to_best(survivors, min_seeds=comparison.min_seeds)
    if best is not None:  # for information, as for any value: no mark uses it
        pvalues.update({vi: welch_p(scores[best], scores[vi]) for vi in dropped if vi in scores})
    left_out = comparison.left_out
    raw = [pvalues.get(vi, np.nan) for vi in range(len(labels))]
    adjusted = [comparison.p_adjusted.get(vi, np.nan) for vi in range(len(labels))]
    rows = []
    for vi, label in enumerate(labels):
        count = counts.loc[vi] if vi in counts.index else pd.Series(dtype=int)
        finals = scores.get(vi, [])
        p_holm = adjusted[vi]
        mark = "best" if vi == best else ("tie" if vi in comparison.tied else "")
        s = score.loc[vi] if vi in score.index else None
        t = time.loc[vi] if vi in time.index else None
        steps = done.loc[done["vi"] == vi, "env_steps"]
        iqm_low, iqm_high = iqm_interval(finals)
        if best is None or vi == best or not finals:
            improvement, improvement_low, improvement_high = np.nan, np.nan, np.nan
        else:
            improvement = p_improvement(scores[best], finals)
            improvement_low, improvement_high = p_improvement_interval(scores[best], finals)
        drop = dropped.get(vi)
        notes = [dropped_note(drop, look_alpha)] if drop is not None else []
        if vi in settled:
            notes.append(settled_note(settled[vi], look_alpha))
        if vi in left_out:
            notes.append(left_out_note(len(finals), comparison.min_seeds))
        untested = vi in comparison.unanswered
        if untested:
            notes.append(untested_note())
        answer = ("worse" if drop is not None else
                  str(comparison.answers[vi]) if vi in comparison.answers else
                  "left out" if vi in left_out else "")
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
            "p_vs_best": raw[vi],
            "p_holm": p_holm,
            # An untested value has no p: the comparison's 1 only keeps it out of every answer.
            "p_worse": np.nan if untested else comparison.p_worse.get(vi, np.nan),
            "p_equivalent": np.nan if untested else comparison.p_equivalent.get(vi, np.nan),
            "p_improvement": improvement,
            "p_improvement_low": improvement_low,
            "p_improvement_high": improvement_high,
            "mark": mark,
            "answer": answer,
            "margin": comparison.margin,
            "margin_resolvable": comparison.resolvable.get(vi, np.nan),
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
    best = summary.index[summary["mark"] == "best"]
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
        :func:`kraby_study.decision.measures.default_threshold` of the untrained reward (the mean
        over every complete seed of its first curve point's reward) and the best value's mean final
        score; NaN when either is missing.
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
    (:func:`kraby_study.decision.measures.auc` of the curve in step order), the env steps and
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
        rows.append((int(row.vi), row.seed, int(row.number), float(row.final_score), *metrics))
    frame = pd.DataFrame(rows, columns=SEED_COLUMNS)
    for column in SEED_COLUMNS[3:]:
        frame[column] = frame[column].astype(float)
    return frame


def add_curve_metrics(summary: pd.DataFrame, seeds: pd.DataFrame,
                      bootstrap: int = BOOTSTRAP_REPETITIONS) -> pd.DataFrame:
    """The summary with the curve metrics of each value's complete seeds: AUC (mean and
    interval over the seeds with a curve, :func:`kraby_study.decision.intervals.mean_interval` with
    ``bootstrap`` resamples), env steps and seconds to the threshold and how
    many seeds reached it.

    Steps and seconds to the threshold are restricted means over the seeds with a curve: a seed
    that never reached the threshold counts at its curve's last point, so the mean is a lower
    bound of the true mean time when ``reached`` is below the seeds with a curve. NaN when no
    seed reached it.
    """
    columns: dict[str, list[float]] = {name: [] for name in (
        "auc_mean", "auc_low", "auc_high", "steps_to_threshold", "seconds_to_threshold",
        "reached")}
    groups = dict(iter(seeds.groupby("vi", sort=True)))
    for vi in summary.index:
        group = groups.get(vi, seeds.iloc[:0])
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


def add_train_reward(summary: pd.DataFrame, trials: pd.DataFrame,
                     bootstrap: int = BOOTSTRAP_REPETITIONS) -> pd.DataFrame:
    """``summary`` with each value's training reward (mean episode reward over the last 10 %
    of training) over its complete seeds: ``train_mean``, ``train_sd`` and the interval of
    the mean ``train_low``, ``train_high`` (:func:`kraby_study.decision.intervals.describe`, as the
    final score's). For a study scored by evaluation, whose final score is not the training
    reward; no decision reads it."""
    done = trials[(trials["outcome"] == Outcome.COMPLETE) & trials["train_reward"].notna()]
    columns = {"mean": "train_mean", "sd": "train_sd", "low": "train_low", "high": "train_high"}
    if done.empty:
        return summary.assign(**{column: np.nan for column in columns.values()})
    train = describe(done, "vi", "train_reward", bootstrap=bootstrap)
    return summary.join(train[list(columns)].rename(columns=columns))  # NaN: no such seeds


def add_eval_error(summary: pd.DataFrame, trials: pd.DataFrame) -> pd.DataFrame:
    """``summary`` with each value's evaluation standard error (``eval_se``): the root mean
    square over its complete seeds of each run's standard error from its own episodes, the
    test set's share of a run's score (NaN for runs stored without one)."""
    done = trials[(trials["outcome"] == Outcome.COMPLETE) & trials["eval_error"].notna()]
    rms = done.groupby("vi")["eval_error"].apply(lambda e: float(np.sqrt(np.mean(e ** 2))))
    return summary.assign(eval_se=[rms.get(vi, np.nan) for vi in summary.index])


def add_failed_seeds(summary: pd.DataFrame, seeds: pd.DataFrame, untrained: float
                     ) -> tuple[pd.DataFrame, float]:
    """``summary`` with each value's failed seeds (:mod:`kraby_study.decision.failed_seeds`):
    ``failed_seeds`` (count), ``failed_seeds_low`` and ``failed_seeds_high`` (the exact
    interval of the rate); and the failure line (NaN when it is not defined: no best, no
    curve, or a best that learned nothing)."""
    line = failure_line(untrained, best_mean(summary))
    groups = dict(iter(seeds.groupby("vi", sort=True)))
    found = [failed_seeds(groups[vi]["final_score"].tolist() if vi in groups else [], line)
             for vi in summary.index]
    out = summary.assign(failed_seeds=[f.count if f.seeds else np.nan for f in found],
                         failed_seeds_low=[f.low for f in found],
                         failed_seeds_high=[f.high for f in found])
    return out, line


def study_verdict(summary: pd.DataFrame, seeds: pd.DataFrame,
                  min_seeds: int = MIN_SEEDS, dropped: Collection[int] = (),
                  comparison: Comparison[int] | None = None) -> Verdict:
    """The verdict of :func:`kraby_study.decision.verdict.verdict` from the summary rows and the
    seeds' final scores, reading the study's one ``comparison`` when given. The fastest is by the
    restricted mean seconds (a seed that never reached the threshold counts at its run's end);
    the rescaled IQR (``final_iqr_unbiased``) decides the most repeatable. Values a race dropped
    (``dropped``, by index) are no answer."""
    final = {int(vi): group["final_score"].tolist() for vi, group in seeds.groupby("vi")
             if int(vi) not in dropped}

    def kept(column: str) -> dict[int, float]:
        return {vi: v for vi, v in summary[column].to_dict().items() if vi not in dropped}

    return verdict(final, auc_means=kept("auc_mean"), seconds=kept("seconds_to_threshold"),
                   iqrs=kept("final_iqr_unbiased"), p_holm=kept("p_holm"), min_seeds=min_seeds,
                   comparison=comparison)


REACH_COLUMNS = ("steps_to_threshold", "seconds_to_threshold")


def reach_means(seeds: pd.DataFrame, values: int, bootstrap: int) -> pd.DataFrame:
    """Per value (index 0 to ``values`` - 1): the mean env steps and seconds to the threshold
    over the seeds that reached it, each with its interval
    (:func:`kraby_study.decision.intervals.mean_interval`), columns ``<measure>_mean``,
    ``_low`` and ``_high``: the marks of the time-to-threshold figure (the summary's columns are
    restricted means over every seed instead)."""
    rows = []
    for vi in range(values):
        row: dict[str, float] = {}
        for column in REACH_COLUMNS:
            found = seeds.loc[(seeds["vi"] == vi) & seeds[column].notna(), column].to_numpy()
            mean, low, high = mean_interval(found, resamples=bootstrap)
            row |= {f"{column}_mean": mean, f"{column}_low": low, f"{column}_high": high}
        rows.append(row)
    return pd.DataFrame(rows, index=pd.RangeIndex(values, name="vi"))


@dataclass(frozen=True)
class SweepAnswers:
    """What a sweep's evidence decides: the one comparison, the per-value summary (answers,
    marks, the selected value), the per-seed metrics, the curves' bands, the race (None
    without one) and the verdict."""

    comparison: Comparison[int]
    summary: pd.DataFrame
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
    (:func:`reach_means`)."""


def seed_scores(trials: pd.DataFrame, curves: pd.DataFrame, known: int, time_attr: str
                ) -> tuple[dict[int, list[float]], dict[int, list[float]], dict[int, list[float]]]:
    """Per value with a complete run (among the first ``known``), in value order: the complete
    runs' final scores, their curves' AUCs and their training times (column ``time_attr``),
    each in run order: the numbers every decision reads."""
    done = trials[(trials["outcome"] == Outcome.COMPLETE) & trials["final_score"].notna()
                  & (trials["vi"] < known)]
    runs = done[["vi", "number", "final_score", time_attr]].itertuples(index=False)
    return seed_samples(((int(vi), int(number), float(score), float(spent))
                         for vi, number, score, spent in runs), curve_rewards(curves))


def decide_sweep(trials: pd.DataFrame, curves: pd.DataFrame, labels: list[str],
                 judged: CompareOptions, *, bootstrap: int, threshold: float | None,
                 race: RaceRuns | None, swept: bool, known: int, time_attr: str,
                 train_reward: bool, rule: str | None) -> SweepAnswers:
    """The answers of a sweep from its evidence, in one pass.

    Args:
        trials: One row per counted run (``vi`` indexes ``labels``).
        curves: Curve points of the complete runs, with their ``vi`` and ``seed``.
        labels: How each value is written.
        judged: The comparison's margin, alpha, fewest seeds and rule.
        bootstrap: Resamples of the bootstrap-t interval of a mean.
        threshold: The reward a curve must reach, None for the default.
        race: A raced study's ended runs (None: it did not race): its dropped values are
            never best, equivalent or selected.
        swept: The study sweeps a setting; False for a single-run study (one value).
        known: How many of the values the study lists (a last "?" is not compared).
        time_attr: The trial column read as training time.
        train_reward: The runs are scored by evaluation: add the training reward and the
            evaluation's standard error beside the final score.
        rule: The rule that selects a value (None while runs are pending, or in a single-run
            study).
    """
    state = race.replayed() if race is not None else None
    dropped = state.dropped if state is not None else {}
    settled = state.settled if state is not None else {}
    look_alpha = state.rules.look_alpha if state is not None else math.nan
    final, aucs, seconds = seed_scores(trials, curves, known, time_attr)
    if not swept:  # one value: every complete run's score
        final = _finals(trials[trials["outcome"] == Outcome.COMPLETE])
    comparison = compare({vi: v for vi, v in final.items() if vi not in dropped},
                         judged.margin, judged.alpha, judged.min_seeds)
    summary = summarise(trials, labels, bootstrap, comparison.min_seeds, dropped, look_alpha,
                        time_attr, comparison, settled, final)
    level, is_default, untrained = study_threshold(curves, summary, threshold)
    seeds = seed_metrics(trials, curves, level)
    summary = add_curve_metrics(summary, seeds, bootstrap)
    summary, failure = add_failed_seeds(summary, seeds, untrained)
    if train_reward:
        summary = add_train_reward(summary, trials, bootstrap)
        summary = add_eval_error(summary, trials)
    chosen = (RULES[SelectRule(rule)].select(comparison, mean_by_value(aucs),
                                             mean_by_value(seconds))
              if rule is not None else None)
    summary["selected"] = [vi == chosen for vi in summary.index]
    return SweepAnswers(comparison=comparison, summary=summary, seeds=seeds,
                        bands=curve_bands(curves), threshold=level,
                        threshold_default=is_default, untrained=untrained,
                        failure_line=failure, bootstrap=bootstrap,
                        verdict=study_verdict(summary, seeds, comparison.min_seeds,
                                              list(dropped), comparison), race=state,
                        reach=reach_means(seeds, len(summary), bootstrap))
