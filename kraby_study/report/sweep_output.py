"""A sweep's files (figures, CSV and Markdown tables) and its section of the index.

Confirm studies are written the same way, with a table of their configurations and a sentence
on whether the source study's winner is the confirmed winner.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from kraby_study.answers.sweep_evidence import Sweep, confirm_arms
from kraby_study.decision.comparison import ALPHA, ANSWER_FROM, answers_name, p_text
from kraby_study.decision.coverage import coverage_note
from kraby_study.decision.failed_seeds import definition_text
from kraby_study.decision.intervals import (
    BAND_NAME,
    SHORT_INTERVAL_NAME,
    interval_name,
    iqm_interval_name,
)
from kraby_study.decision.measures import AUC_NAME, p_improvement_name
from kraby_study.decision.selection import RULE_TEXT
from kraby_study.decision.summary import ValueSummary, note_part
from kraby_study.records.attributes import RUN_MEASURES, StudyKind
from kraby_study.records.definition import stored_eval_set
from kraby_study.records.stored import Outcome
from kraby_study.records.values import value_label
from kraby_study.report import sweep_plots
from kraby_study.report.document import Block, Heading, Image, Items, Links, Table, Text, write_csvs
from kraby_study.report.document import to_markdown as blocks_to_markdown
from kraby_study.report.study_report import StudyReport
from kraby_study.report.style import number, styled

TRAINING_SCORE = "mean episode reward over the last 10 % of training"
"""What a final score is, unless the study is scored by evaluation."""
EVALUATION_SCORE = "the deterministic policy's mean return over the evaluation episodes"
"""What a final score is in a study scored by evaluation."""
CAPTIONS = {
    "learning_curves": "Mean episode reward against environment steps, mean over seeds with its "
                       "95 % Hall skewness-corrected t interval at every n (a cheap interval: "
                       "the curves have hundreds of points); (b) zooms on the last quarter of "
                       "training.",
    "final_score": f"Final score ({TRAINING_SCORE}) of every "
                   f"seed; mean and {SHORT_INTERVAL_NAME} beside them. "
                   "Shaded, and written above each value: its answer against the best (best; "
                   "equivalent; undecided; worse, unshaded), as in the summary's answer "
                   "column.",
    "wallclock": "Mean episode reward against wall-clock time since the start of training.",
    "training_time": "Training time of every run (wall-clock seconds; on a confirm study CPU "
                     "seconds, which fastest_equivalent compares there), with mean and "
                     f"{SHORT_INTERVAL_NAME}.",
    "sample_efficiency": "Sample efficiency (AUC: the mean of a seed's binned mean episode "
                         "rewards over the whole run, the normalised area under its learning "
                         f"curve) of every seed; mean and {SHORT_INTERVAL_NAME} beside "
                         "them.",
    "time_to_threshold": "Environment steps (a) and seconds (b) until a seed's learning curve "
                         "first reached the threshold, for every seed that reached it; beside "
                         f"them the mean over those seeds with its {SHORT_INTERVAL_NAME}. "
                         "k/N: seeds that reached it of the value's complete "
                         "seeds; 'none reached' marks values where none did.",
    "improvement": "Probability of improvement P(best > value) of the best value over each "
                   "other value: the share of pairs of seeds (one of each) where the best "
                   "value's final score is higher, ties counted half, with its 95 % "
                   "Newcombe score-type interval. Dashed: 0.5, neither better.",
}
NEW_FIGURES = ("sample_efficiency", "time_to_threshold", "improvement")
"""Figures that compare values, drawn when a study has more than one."""
DASHED_CAPTION = " Dashed: values dropped by the race (their seeds up to the drop)."
"""Added to the curve figures' captions of a raced study."""
DASHED_FIGURES = ("learning_curves", "wallclock")


def _p_text(p: float) -> str:
    return p_text(p) if np.isfinite(p) else "n/a"


def _interval(low: float, high: float, digits: int = 4) -> str:
    if not (np.isfinite(low) and np.isfinite(high)):
        return "-"
    return f"[{low:.{digits}g}, {high:.{digits}g}]"


def _with_interval(mean: float, low: float, high: float) -> str:
    text = number(mean, 3)
    if np.isfinite(mean) and np.isfinite(low) and np.isfinite(high):
        text += f" {_interval(low, high, 3)}"
    return text


def _bootstrap_interval(low: float, high: float) -> str:
    return _interval(low, high, 3)


def _reached(row: ValueSummary) -> str:
    return f"{row.reached}/{row.complete}" if row.complete else "-"


def _steps(value: float) -> str:
    return f"{value:,.0f}" if np.isfinite(value) else "-"


SUMMARY_COLUMNS = ["seeds", "IQM final score [95 % CI]", "mean", "answer", "p_worse",
                   "p_equivalent", "failed seeds [95 % CI of the rate]"]
"""The compact table's columns after the value's (summary.csv holds every other number)."""
ANSWER_COLUMNS = ("answer", "p_worse", "p_equivalent")
"""The columns a single-run study's table leaves out: its one value is trivially the best."""


def _answer_cell(sweep: Sweep, value_index: int, row: ValueSummary) -> str:
    """A value's answer; a value the race dropped says after which round."""
    answer = row.answer or "-"
    drop = sweep.dropped.get(value_index)
    return f"{answer} (dropped by the race after round {drop.round})" if drop else answer


def row_mark(answer: str) -> str:
    """The HTML row class of an answer: best and equivalent rows are shaded."""
    return answer if answer in ("best", "equivalent") else ""


def _iqm_cell(row: ValueSummary) -> str:
    """'1.001 [0.9902, 1.011]': the IQM final score and its interval, 4 digits each."""
    text = number(row.iqm)
    if np.isfinite(row.iqm) and np.isfinite(row.iqm_low):
        text += f" {_interval(row.iqm_low, row.iqm_high)}"
    return text


def _p_cell(p: float) -> str:
    return _p_text(p) if np.isfinite(p) else "-"


def summary_table(sweep: Sweep) -> Table:
    """The compact summary: per value its complete seeds, IQM final score with its interval
    (what the answers are about), mean, answer, p_worse, p_equivalent and failed seeds (a
    single-run study, one value, has no answer to show); every other number is in
    summary.csv."""
    compared = bool(sweep.parameter)
    rows = []
    for value_index, row in enumerate(sweep.rows):
        answers = [_answer_cell(sweep, int(value_index), row), _p_cell(row.p_worse),
                   _p_cell(row.p_equivalent)]
        rows.append([str(row.value), str(row.complete), _iqm_cell(row),
                     number(row.final_mean), *(answers if compared else []),
                     _failed_seeds(row)])
    header = SUMMARY_COLUMNS if compared else [c for c in SUMMARY_COLUMNS
                                               if c not in ANSWER_COLUMNS]
    return Table([sweep.name, *header], rows,
                 marks=[row_mark(r.answer) for r in sweep.rows] if compared else [])


def _failed_seeds(row: ValueSummary) -> str:
    """A value's failed seeds, e.g. '2/10 [0.03, 0.56]'; '-' when not counted."""
    if not np.isfinite(row.failed_seeds):
        return "-"
    return (f"{int(row.failed_seeds)}/{row.complete} "
            f"{_interval(row.failed_seeds_low, row.failed_seeds_high)}")


def threshold_text(sweep: Sweep) -> str:
    """The threshold used for steps and seconds to threshold, and where it comes from."""
    if not np.isfinite(sweep.threshold):
        return "Threshold: none (no complete run with a learning curve), so no time to threshold."
    text = f"Threshold for steps and seconds to threshold: mean episode reward >= " \
           f"{number(sweep.threshold)}"
    if not sweep.threshold_default:
        return text + ", set by the report's option report.threshold."
    best = sweep.best
    final = sweep.rows[best].final_mean if best is not None else np.nan
    count = int(sweep.seeds["first_reward"].notna().sum())
    return (text + f", the default: 90 % of the way from the untrained policy's reward "
            f"({number(sweep.untrained)}, the mean first-bin reward of all {count} complete "
            f"seeds) to the best value's mean final score ({number(final)}).")


FAILED_SEED = ("a complete seed whose final score is below the line halfway from the untrained "
               "policy's score to the best value's mean (it learned less than half the best's "
               "gain); rate interval: Clopper-Pearson exact, 95 %")
"""What a failed seed is, where no study's line is at hand (the index)."""


def methods(bootstrap: int, min_seeds: int = 2, raced: bool = False,
            failed_seed: str = FAILED_SEED) -> list[str]:
    """What every number of a sweep's summary is, each interval and test named once, for
    values needing ``min_seeds`` complete seeds (``bootstrap``: the report option's resamples
    of the bootstrap-t interval of a mean); ``raced``: what a dropped value's row shows;
    ``failed_seed``: what a failed seed is."""
    items = [
        f"IQM final score [95 % CI]: the interquartile mean of the complete seeds' final "
        f"scores (the mean of the middle half; the mean below 4 seeds), {iqm_interval_name()}. "
        f"Every interval of a mean (training time, AUC; the mean final score in summary.csv): "
        f"{interval_name(bootstrap)}. n, seeds: a value's complete seeds.",
        f"Best: the highest IQM final score among the values with at least report.min_seeds "
        f"= {min_seeds} complete seeds (a value with fewer is left out of every answer). "
        "Answers against the best, about the IQM: equivalent, shown within the margin of the "
        "best (compare.margin, a fraction of the best's |IQM|; the verdict gives it in score "
        "units); worse, shown below the best by more than the margin (or dropped by a race); "
        f"undecided, neither, and every value compared with fewer than {ANSWER_FROM} seeds "
        f"(no test holds its error rate there). Tests: {answers_name(ALPHA)}.",
        f"p_worse: the adjusted p of the step-down against the margin (< {ALPHA:g}: worse). "
        f"p_equivalent: the Bonferroni p of the comparison with the best (< {ALPHA:g}: "
        "equivalent; 1 at margin 0).",
        f"Failed seeds: {failed_seed}.",
        f"Most sample-efficient: the highest mean {AUC_NAME}. Fastest to threshold: the lowest "
        "restricted mean seconds over the seeds with a curve, a seed that never reached the "
        "threshold counted at its curve's last point (a lower bound of the mean time when "
        "reached is below n). Most repeatable: the lowest rescaled final IQR (the "
        "interquartile range of the final scores divided by its expected share of the true "
        "IQR at n for normal data, comparable across n; needs 2 seeds). Each counts only "
        "values with at least report.min_seeds complete seeds.",
        f"Learning-curve bands: {BAND_NAME}, at every n.",
        "summary.csv also holds: the run counts; the mean final score with its interval; the "
        "final IQR, raw and rescaled; AUC; steps and seconds to threshold and the seeds that "
        f"reached it; training time; P(best > value): {p_improvement_name()}; the margin "
        "and the margin its seeds resolve; notes.",
    ]
    if raced:
        items.append("Raced: a value the race dropped is never best, selected or any other "
                     "answer than worse; its note names the round and the adjusted p of the "
                     "race's look that dropped it, at the race's per-look alpha (the rule is "
                     "under Other measures), and the survivors are compared on all their "
                     "seeds.")
    return items


def few_seeds_note(sweep: Sweep) -> str | None:
    """The measured coverage of the intervals drawn from fewer than 5 seeds in this sweep, and
    of those from more where skewed data were covered less than 93 % of the time
    ([`coverage_note`][kraby_study.decision.coverage.coverage_note]); None when neither is drawn
    here."""
    return coverage_note(r.complete for r in sweep.rows if r.complete >= 2)


def left_out_text(sweep: Sweep) -> str | None:
    """The values left out of every comparison and answer for too few seeds, and why; None
    when none is."""
    notes = [(r.value, note_part(r.note, "left out: ")) for r in sweep.rows]
    notes = [(value, note) for value, note in notes if note]
    if not notes:
        return None
    return ("Left out of the best and every answer: "
            + "; ".join(f"{value} ({note.removeprefix('left out: ')})" for value, note in notes)
            + ".")


def race_text(sweep: Sweep) -> str | None:
    """What a raced study's race did: its rule (named once), the values it dropped and when,
    and the runs it made against the fixed design's; None for a study that did not race."""
    race = sweep.race
    if race is None:
        return None
    dropped = ", ".join(f"{_label(sweep, value_index)} after round {drop.round} "
                        f"({drop.why()})" for value_index, drop in sorted(
                            sweep.dropped.items(), key=lambda item: (item[1].round, item[0])))
    state = "the race is over" if race.over else f"{race.rounds} round(s) decided so far"
    return (f"Race ({race.rules.describe()}): "
            + (f"dropped {dropped}" if dropped else "nothing dropped")
            + f"; {state}; {race.saved_text()}. Best, answers and the selection are among the "
            "survivors.")


def _named(sweep: Sweep, values: list[int]) -> str:
    return ", ".join(_label(sweep, value_index) for value_index in values) or "none"


def _answered(sweep: Sweep, answer: str) -> list[int]:
    """The values whose summary answer is ``answer``, in the summary's order."""
    return [value_index for value_index, r in enumerate(sweep.rows) if r.answer == answer]


def answer_lines(sweep: Sweep) -> list[str]:
    """The answer of every value other than the best, one line per answer, the margin in score
    units once; empty when no other value was compared."""
    compared = sweep.comparison
    others = [i for a in ("equivalent", "worse", "undecided") for i in _answered(sweep, a)]
    if compared is None or not others:
        return []
    if compared.fraction > 0:
        equivalent = (f"Equivalent (within the margin of the best, {compared.margin:.3g} in "
                      f"score units): {_named(sweep, _answered(sweep, 'equivalent'))}.")
        worse = "Worse (below the best by more than the margin)"
    else:
        equivalent = "Equivalent: none (margin 0: no value can be shown equivalent)."
        worse = "Worse (below the best)"
    return [equivalent, f"{worse}: {_named(sweep, _answered(sweep, 'worse'))}.",
            f"Undecided (neither shown equivalent nor worse): "
            f"{_named(sweep, _answered(sweep, 'undecided'))}."]


def resolution_text(sweep: Sweep) -> str | None:
    """The warning when the margin is below what the seeds resolve, or what they resolve;
    None without a margin."""
    compared = sweep.comparison
    if compared is None or compared.fraction <= 0:
        return None
    reason = compared.unanswered_text()
    unanswered = f"{reason[0].upper()}{reason[1:]}." if reason else None
    warning = compared.resolution_text()
    if warning:
        return f"Warning: {warning}." + (f" {unanswered}" if unanswered else "")
    if unanswered:
        return unanswered
    if math.isfinite(compared.resolution):
        return (f"These seeds resolve a margin of about {compared.resolution:.3g} (median over "
                "the values of (t + t_0.8) x Yuen's standard error of the IQM contrast with the "
                "best).")
    return None


def _label(sweep: Sweep, value_index: int) -> str:
    return str(sweep.labels[value_index])


def _located(name: str, location: float, low: float, high: float, n: int,
             extra: str = "") -> str:
    """'NAME 1.001 (95 % CI [0.9902, 1.011], n=8EXTRA)'; without the interval when it is NaN."""
    interval = f"95 % CI {_interval(low, high)}, " if np.isfinite(low) else ""
    return f"{name} {number(location)} ({interval}n={n}{extra})"


def _mean_text(row: ValueSummary) -> str:
    """'mean final score 1.001 (95 % CI [0.9902, 1.011], n=8)'."""
    return _located("mean final score", row.final_mean, row.final_low, row.final_high,
                    row.complete)


def _iqm_text(row: ValueSummary) -> str:
    """'IQM final score 1.001 (95 % CI [0.9902, 1.011], n=8; mean 0.998)'."""
    return _located("IQM final score", row.iqm, row.iqm_low, row.iqm_high, row.complete,
                    f"; mean {number(row.final_mean)}")


def _auc_text(row: ValueSummary) -> str:
    text = f"AUC {number(row.auc_mean)}"
    if np.isfinite(row.auc_low):
        text += f", 95 % CI {_interval(row.auc_low, row.auc_high)}"
    return text + f", n={int(row.complete)}"


def _reach_text(row: ValueSummary) -> str:
    return (f"{number(row.seconds_to_threshold, 3)} s, "
            f"{_steps(row.steps_to_threshold)} env steps, restricted mean over the seeds, "
            f"{row.reached}/{row.complete} reached it")


def failed_seeds_line(sweep: Sweep) -> str | None:
    """The values with failed seeds, e.g. 'Failed seeds: 0.05 1 of 8'; None when no seed
    failed (or the line is not defined)."""
    if not np.isfinite(sweep.failure_line):
        return None
    rows = [r for r in sweep.rows if np.isfinite(r.failed_seeds) and r.failed_seeds > 0]
    if not rows:
        return None
    parts = [f"{row.value}{' (selected)' if row.selected else ''}: "
             f"{int(row.failed_seeds)} of {row.complete}" for row in rows]
    return (f"Failed seeds (final score below {number(sweep.failure_line)}): "
            + "; ".join(parts) + ".")


def _single_lines(sweep: Sweep, row: ValueSummary) -> list[str]:
    """A single-run study's verdict: its final score, AUC and time to threshold."""
    reached = (f"Threshold reached in {_reach_text(row)}." if row.reached else
               "No seed reached the threshold.")
    text = _mean_text(row)
    return [f"{text[0].upper()}{text[1:]}.", f"Sample efficiency: {_auc_text(row)}.",
            reached]


def verdict_lines(sweep: Sweep) -> list[str]:
    """The verdict block, at most six short lines: the best value's IQM final score with its
    interval and its mean, every other value's answer (the margin once), the failed seeds, and
    the value the rule selects."""
    best = sweep.verdict.best
    if best is None:
        return ["No run is complete yet, so no value can be compared."]
    row = sweep.rows[best]
    if not sweep.parameter:
        return _single_lines(sweep, row)
    lines = [f"Best: {_label(sweep, best)}, {_iqm_text(row)}.", *answer_lines(sweep)]
    failing = failed_seeds_line(sweep)
    chosen = selection_text(sweep)
    return lines + [text for text in (failing, chosen) if text]


def other_measures(sweep: Sweep) -> list[str]:
    """The verdict's other findings: the most sample-efficient, the fastest to the threshold,
    the most repeatable, what a race did and the values left out; empty for a single run."""
    result = sweep.verdict
    if result.best is None or not sweep.parameter:
        return []
    items = []
    if result.most_sample_efficient is not None:
        row = sweep.rows[result.most_sample_efficient]
        items.append(f"Most sample-efficient: {_label(sweep, result.most_sample_efficient)} "
                     f"({_auc_text(row)}).")
    if result.fastest is not None:
        row = sweep.rows[result.fastest]
        items.append(f"Fastest to threshold: {_label(sweep, result.fastest)} "
                     f"({_reach_text(row)}, lowest restricted mean).")
    elif np.isfinite(sweep.threshold):
        items.append(f"No value reached the threshold {number(sweep.threshold)}.")
    if result.most_repeatable is not None:
        row = sweep.rows[result.most_repeatable]
        items.append(f"Most repeatable: {_label(sweep, result.most_repeatable)} (rescaled final "
                     f"IQR {number(row.final_iqr_unbiased, 3)}, raw "
                     f"{number(row.final_iqr, 3)}, n={row.complete}).")
    found = [race_text(sweep), left_out_text(sweep)]
    return items + [text for text in found if text]


def arms_table(sweep: Sweep) -> Table:
    """A confirm study's configurations: origin, the source's score, the confirmed score."""
    rows = [[arm.label, arm.origin, number(arm.source_score),
             number(arm.confirmed.final_mean),
             _interval(arm.confirmed.final_low, arm.confirmed.final_high),
             number(arm.confirmed.iqm),
             _bootstrap_interval(arm.confirmed.iqm_low, arm.confirmed.iqm_high),
             str(arm.confirmed.complete)]
            for arm in confirm_arms(sweep)]
    return Table(["configuration", "origin", "source's score", "confirmed mean final score",
                  "95 % CI", "confirmed IQM", "95 % trimmed-t CI", "n"], rows,
                 marks=[row_mark(r.answer) for r in sweep.rows])


WINNER_ANSWER = {
    "equivalent": " {winner} is equivalent to it: within the margin.",
    "undecided": " {winner} is undecided against it: neither shown within the margin nor below "
                 "it, so it may still be as good.",
    "worse": " {winner} is worse: below it by more than the margin.",
}
"""What the sentence on the source's winner adds, by the winner's answer."""


def winner_text(sweep: Sweep) -> str | None:
    """Whether the source study's winner is the confirmed winner; None without a source
    winner."""
    definition = sweep.data.definition
    winner = definition.get("source_winner")
    if winner is None:
        return None
    winner = str(winner)
    source = definition.get("source")
    owner = f"{source}'s" if source else "The source's"
    best = sweep.verdict.best
    if best is None:
        return f"{owner} winner {winner} cannot be checked yet: no confirmed run is complete."
    row = sweep.rows[best]
    label = _label(sweep, best)
    fresh = f"the best IQM final score on {row.complete} fresh seeds"
    if winner == label:
        return f"{owner} winner {winner} is the confirmed winner: it has {fresh}."
    text = f"{owner} winner {winner} is not the confirmed winner: {label} has {fresh}."
    if winner not in sweep.labels:
        return text + f" {winner} was not retrained here."
    index = sweep.labels.index(winner)
    if index in sweep.dropped:
        return text + (f" The race dropped {winner} after round "
                       f"{sweep.dropped[index].round}.")
    answer = sweep.rows[index].answer
    return text + WINNER_ANSWER.get(answer, "").format(winner=winner)


def confirm_blocks(sweep: Sweep) -> tuple[list[Block], list[Block]]:
    """A confirm study's blocks: its configuration table (before the verdict) and the sentence
    on the source's winner (after it); empty for other kinds."""
    if sweep.kind != StudyKind.CONFIRM:
        return [], []
    winner = winner_text(sweep)
    return ([Text("Configurations retrained on fresh seeds:"), arms_table(sweep)],
            [Text(winner)] if winner else [])


def failed_items(sweep: Sweep) -> list[str]:
    """One line per failed or pruned run: value, seed, trial and reason."""
    failed = sweep.trials[sweep.trials["outcome"].isin([Outcome.FAILED, Outcome.PRUNED])]
    prefix = f"{sweep.name} = " if sweep.parameter else ""
    return [f"{prefix}{r['value']}, seed {r['seed']} (trial {r['number']}): "
            f"{r['failure'] or r['outcome']}" for _, r in failed.iterrows()]


def _write_tables(sweep: Sweep, folder: Path) -> list[Path]:
    summary = sweep.summary.copy()
    summary.insert(0, "parameter", sweep.parameter or "-")
    trials = sweep.trials.drop(columns=["value_index"]).rename(columns={"value": sweep.name})
    curves = sweep.curves.assign(value=[sweep.labels[int(v)] for v in sweep.curves["value_index"]])
    curves = curves[["value", "seed", "number", "step", "mean_reward", "wall_time", "episodes"]]
    curves = curves.rename(columns={"value": sweep.name, "number": "trial"})
    bands = sweep.bands.assign(value=[sweep.labels[int(v)] for v in sweep.bands["value_index"]])
    bands = bands[["value", "step", "n", "mean", "sd", "low", "high", "wall_time"]]
    bands = bands.rename(columns={"value": sweep.name, "low": "ci_low", "high": "ci_high"})
    frames: list[tuple[str, pd.DataFrame]] = [("summary.csv", summary), ("trials.csv", trials),
                                              ("curves.csv", curves), ("curves_mean.csv", bands)]
    return write_csvs(folder, frames)


def evaluated_text(sweep: Sweep) -> str:
    """The per-run measures of runs scored by evaluation
    ([`RUN_MEASURES`][kraby_study.records.attributes.RUN_MEASURES]): what each is, where summary.csv
    holds it, and each root-mean-square measure by value."""
    measured = [m for m in RUN_MEASURES if m.evaluated]
    what = "; ".join(f"{', '.join(m.columns)}: {m.text}" for m in measured)
    by_value = " ".join(
        f"{m.column} by value: " + "; ".join(
            f"{row.value} {number(row.measures.get(m.column, math.nan), 3)}"
            for row in sweep.rows) + "."
        for m in measured if m.summary == "rms")
    return f"Beside it in summary.csv, and read by no answer: {what}. {by_value}"


def describe_sweep(sweep: Sweep) -> str:
    """What was run: parameter, values, seeds, budget, and where it stands."""
    definition = sweep.data.definition
    seeds = int(sweep.trials["seed"].nunique()) if len(sweep.trials) else 0
    each = f"{seeds} seeds each"
    if sweep.race is not None:  # a dropped value has fewer: the race's rule is in the verdict
        each = f"at most {sweep.race.rules.seeds} seeds each, raced"
    steps = definition.get("steps")
    budget = f", {steps:,} environment steps per run" if isinstance(steps, int) else ""
    if sweep.kind == StudyKind.CONFIRM:
        source = definition.get("source")
        origin = f" from {source}" if source else ""
        fresh = each.replace(" seeds each", " fresh seeds each")
        scored = ""
        if sweep.by_evaluation:
            episodes = definition.get("eval_episodes")
            drawn = ("drawn from its own seed's evaluation stream, so none is an episode its "
                     "source selected on" if stored_eval_set(definition) == "run" else
                     "that every run shares (one fixed set)")
            scored = (f" Scored by evaluation: a run's final score is its deterministic "
                      f"policy's mean return over {episodes} evaluation episodes {drawn}. "
                      f"{evaluated_text(sweep)}")
        return (f"Confirmation of {len(sweep.values)} configurations{origin} on {fresh}"
                f"{budget}. Status: {sweep.status()}.{scored}")
    if not sweep.parameter:
        return f"Single training run, {seeds} seed(s){budget}. Status: {sweep.status()}."
    inputs = sweep.data.ledger.attrs.inputs or []
    taken = "; ".join(f"{i['setting']} = {value_label(i['value'])}, selected in {i['study']}"
                      f" ({i['rule']})" for i in inputs)
    return (f"Sweep of {sweep.parameter} over {len(sweep.values)} values, {each}"
            f"{budget}. Status: {sweep.status()}."
            + (f" Settings from earlier studies: {taken}." if taken else ""))


def selection_text(sweep: Sweep) -> str | None:
    """Which value the study's rule selects (None for a single-run study)."""
    if not sweep.parameter:
        return None
    rule = f"rule {sweep.rule}: {RULE_TEXT[sweep.rule]}"
    chosen = [value_index for value_index, r in enumerate(sweep.rows) if r.selected]
    if chosen:
        return f"Selected ({rule}): {sweep.labels[chosen[0]]}."
    if not sweep.finished:
        return f"Selected ({rule}): none until the {sweep.counts['pending']} pending run(s) end."
    return f"Selected ({rule}): none, no run is complete."


CSV_NOTE = "Every other number of each value is in summary.csv; the methods are at the end."


def details_blocks(sweep: Sweep) -> list[Block]:
    """What was run, a confirm study's configurations, the other measures, the threshold and
    the failed or pruned runs: below the compact table."""
    arms, _ = confirm_blocks(sweep)
    blocks: list[Block] = [Text(describe_sweep(sweep)), *arms]
    others = other_measures(sweep)
    if others:
        blocks += [Text("Other measures:"), Items(others)]
    blocks.append(Text(threshold_text(sweep)))
    failed = failed_items(sweep)
    if failed:
        blocks += [Text(f"Failed or pruned runs ({len(failed)}), not in the figures:"),
                   Items(failed)]
    if sweep.data.replaced:
        blocks.append(Text(f"{sweep.data.replaced} interrupted attempt(s) were run again; "
                           "only the later attempts count."))
    return blocks


def summary_methods(sweep: Sweep) -> list[str]:
    """The methods section of a sweep's summary: what its final score is, each interval and
    test named once, a failed seed's line in score units, and the measured coverage of its
    few-seed intervals."""
    score = EVALUATION_SCORE if sweep.by_evaluation else TRAINING_SCORE
    failed = (definition_text(sweep.failure_line, sweep.untrained)
              if np.isfinite(sweep.failure_line) else FAILED_SEED)
    coverage = few_seeds_note(sweep)
    clock = "CPU" if sweep.time_unit == "CPU s" else "wall-clock"
    return [f"Final score: {score}. Training time (summary.csv's time_mean, time_low, "
            f"time_high): {clock} seconds per run.",
            *methods(sweep.bootstrap, sweep.min_seeds, sweep.race is not None, failed),
            *([coverage] if coverage else [])]


def result_text(sweep: Sweep) -> str:
    """The index overview's cell: the best value and the selected one."""
    best = sweep.verdict.best
    if best is None:
        return "no complete run"
    if not sweep.parameter:
        return _mean_text(sweep.rows[best])
    chosen = [value_index for value_index, r in enumerate(sweep.rows) if r.selected]
    picked = _label(sweep, chosen[0]) if chosen else "none yet"
    return f"best {_label(sweep, best)}; selected {picked}"


def write_sweep(sweep: Sweep, folder: Path, rel: str, fmt: str) -> StudyReport:
    """Draw a sweep's figures and write its tables into ``folder``.

    Args:
        sweep: The sweep.
        folder: Its output folder (created).
        rel: The folder relative to the index pages.
        fmt: png or svg.

    Returns:
        Its report; the policy animation is added by the caller.
    """
    folder.mkdir(parents=True, exist_ok=True)
    report = StudyReport(name=sweep.data.name, kind=sweep.data.kind, folder=folder,
                         status=sweep.status(), finished=sweep.finished)
    figures: list[tuple[str, Any]] = [("learning_curves", sweep_plots.draw_learning_curves),
                                      ("final_score", sweep_plots.draw_final_score),
                                      ("wallclock", sweep_plots.draw_wallclock)]
    if len(sweep.values) > 1:
        figures.append(("training_time", sweep_plots.draw_training_time))
        figures += [(stem, getattr(sweep_plots, f"draw_{stem}")) for stem in NEW_FIGURES]
    images: list[Block] = []
    if (sweep.trials["outcome"] == Outcome.COMPLETE).any():
        with styled():
            for stem, draw in figures:
                path = draw(sweep, folder / f"{stem}.{fmt}")
                report.files.append(path)
                caption = CAPTIONS[stem]
                if stem == "final_score" and sweep.by_evaluation:
                    caption = caption.replace(TRAINING_SCORE, EVALUATION_SCORE)
                if stem == "time_to_threshold":
                    caption += f" {threshold_text(sweep)}"
                if stem in DASHED_FIGURES and sweep.dropped:
                    caption += DASHED_CAPTION
                images.append(Image(f"{rel}/{path.name}", stem.replace("_", " "), caption))
    else:
        report.notes.append("no complete run yet: no figures")
    tables = _write_tables(sweep, folder)
    said = Items(verdict_lines(sweep))
    _, winner = confirm_blocks(sweep)
    warning = resolution_text(sweep)
    top: list[Block] = [said, *winner, summary_table(sweep), *([Text(warning)] if warning else [])]
    details = details_blocks(sweep)
    summary_md = folder / "summary.md"
    summary_md.write_text(blocks_to_markdown(
        [Heading(f"{sweep.data.name}: summary", 1), *top, Text(CSV_NOTE),
         Heading("Details", 2), *details, Heading("Methods", 2),
         Items(summary_methods(sweep))]), encoding="utf-8")
    report.files += tables + [summary_md]
    report.result = result_text(sweep)
    report.blocks = [Heading(f"{sweep.data.name}", 2), *top, *details, *images]
    report.blocks.append(Links("Tables", [(p.name, f"{rel}/{p.name}") for p in
                                          [summary_md, *tables]]))
    return report


def policy_candidates(sweep: Sweep) -> list[tuple[str, dict[str, Any], str]]:
    """Saved models to animate, best first: the best value's seeds by final score.

    Returns:
        (model path, settings, description) triples.
    """
    best = sweep.best
    if best is None:
        return []
    rows = sweep.trials
    done = rows[(rows["outcome"] == Outcome.COMPLETE) & (rows["value_index"] == best)]
    done = done.sort_values("final_score", ascending=False)
    trials = {t.number: t for t in sweep.data.trials}
    out = []
    for _, row in done.iterrows():
        path = row["model_path"]
        if isinstance(path, str) and path:
            what = f"{sweep.name} = {row['value']}, " if sweep.parameter else ""
            out.append((path, dict(trials[int(row["number"])].user_attrs.get("settings") or {}),
                        f"{what}seed {row['seed']} (final score {number(row['final_score'])})"))
    return out
