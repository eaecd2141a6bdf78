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

from kraby_study.answers.sweep_evidence import Sweep, arms_frame
from kraby_study.decision.comparison import answers_name
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
from kraby_study.decision.summary import note_part
from kraby_study.decision.verdict import HOLM_NAME, PROCEDURE_NAME, TEST_NAME
from kraby_study.records.attributes import StudyKind
from kraby_study.records.definition import stored_eval_set
from kraby_study.records.stored import Outcome
from kraby_study.records.values import value_label
from kraby_study.report import sweep_plots
from kraby_study.report.document import Block, Heading, Image, Items, Links, Table, Text, write_csvs
from kraby_study.report.document import to_markdown as blocks_to_markdown
from kraby_study.report.study_report import StudyReport
from kraby_study.report.style import number, styled

MARK_TEXT = {"best": "best", "tie": "\u2248 best", "": ""}
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
                   "Shaded: the best mean, and the "
                   f"values not significantly worse than it ({PROCEDURE_NAME}).",
    "wallclock": "Mean episode reward against wall-clock time since the start of training.",
    "training_time": "Training time of every run (wall-clock seconds; on a confirm study CPU "
                     "seconds, which fastest_tied compares there), with mean and "
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


def _p_text(p: float, mark: str) -> str:
    if mark == "best":
        return "-"
    if not np.isfinite(p):
        return "n/a"
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


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


def _reached(row: pd.Series) -> str:
    return f"{row['reached']}/{row['complete']}" if row["complete"] else "-"


def _steps(value: float) -> str:
    return f"{value:,.0f}" if np.isfinite(value) else "-"


def _race_p_text(sweep: Sweep, vi: int, row: pd.Series) -> str:
    """The adjusted p cell: the survivors' step-down's, or the race's look that dropped it."""
    drop = sweep.dropped.get(vi)
    if drop is None:
        return _p_text(row["p_holm"], row["mark"])
    return f"{_p_text(drop.p, '')} (race, round {drop.round})"


def summary_table(sweep: Sweep) -> Table:
    """The summary as a table of formatted cells, best and tied rows marked; a raced study's
    table says after which round the race dropped a value."""
    raced = sweep.race is not None
    trained = sweep.by_evaluation  # build_sweep gives its summary the training reward
    header = [sweep.name, "complete", "failed", "pruned", "pending",
              *(["dropped after round"] if raced else []),
              "final score", "95 % CI", "sd", "failed seeds [95 % CI of the rate]",
              *(["evaluation se", "training reward [95 % CI]", "training sd"]
                if trained else []),
              "IQM [95 % trimmed-t CI]", "final IQR", "final IQR (rescaled)", "AUC [95 % CI]",
              "env steps to threshold", "seconds to threshold", "reached",
              f"training time ({sweep.time_unit})",
              "Welch p vs best", "adjusted p (step-down)", "P(best > value) [95 % Newcombe CI]", "",
              "answer", "note"]
    rows = []
    for vi, row in sweep.summary.iterrows():
        dropped = vi in sweep.dropped
        rows.append([
            str(row["value"]), str(row["complete"]), str(row["failed"]), str(row["pruned"]),
            str(row["pending"]),
            *([str(sweep.dropped[vi].round) if dropped else "-"] if raced else []),
            number(row["final_mean"]), _interval(row["final_low"], row["final_high"]),
            number(row["final_sd"], 3), _failed_seeds(row),
            *([number(row["eval_se"], 3),
               _with_interval(row["train_mean"], row["train_low"], row["train_high"]),
               number(row["train_sd"], 3)] if trained else []),
            _with_interval(row["iqm"], row["iqm_low"], row["iqm_high"]),
            number(row["final_iqr"], 3), number(row["final_iqr_unbiased"], 3),
            _with_interval(row["auc_mean"], row["auc_low"], row["auc_high"]),
            _steps(row["steps_to_threshold"]), number(row["seconds_to_threshold"], 3),
            _reached(row),
            _with_interval(row["time_mean"], row["time_low"], row["time_high"]),
            _p_text(row["p_vs_best"], row["mark"]), _race_p_text(sweep, int(vi), row),
            "-" if row["mark"] == "best" else
            _with_interval(row["p_improvement"], row["p_improvement_low"],
                           row["p_improvement_high"]),
            "dropped" if dropped else MARK_TEXT[row["mark"]], str(row.get("answer") or "-"),
            str(row["note"] or "")])
    return Table(header, rows, marks=list(sweep.summary["mark"]))


def _failed_seeds(row: pd.Series) -> str:
    """A value's failed seeds, e.g. '2/10 [0.03, 0.56]'; '-' when not counted."""
    if not np.isfinite(row["failed_seeds"]):
        return "-"
    return (f"{int(row['failed_seeds'])}/{row['complete']} "
            f"{_interval(row['failed_seeds_low'], row['failed_seeds_high'])}")


def failed_seeds_text(sweep: Sweep) -> str | None:
    """The values with failed seeds, the selected one first named as such, and what a failed
    seed is; None when no seed failed (or the line is not defined)."""
    if not np.isfinite(sweep.failure_line):
        return None
    rows = sweep.summary[sweep.summary["failed_seeds"].fillna(0) > 0]
    if rows.empty:
        return None
    parts = []
    for vi, row in rows.iterrows():
        selected = " (selected)" if bool(sweep.summary.loc[vi].get("selected", False)) else ""
        rate = _interval(row["failed_seeds_low"], row["failed_seeds_high"])
        parts.append(f"{row['value']}{selected} {int(row['failed_seeds'])} of "
                     f"{row['complete']} (rate 95 % CI {rate})")
    meaning = definition_text(sweep.failure_line, sweep.untrained)
    return "Failed seeds: " + "; ".join(parts) + f" ({meaning})."


def threshold_text(sweep: Sweep) -> str:
    """The threshold used for steps and seconds to threshold, and where it comes from."""
    if not np.isfinite(sweep.threshold):
        return "Threshold: none (no complete run with a learning curve), so no time to threshold."
    text = f"Threshold for steps and seconds to threshold: mean episode reward >= " \
           f"{number(sweep.threshold)}"
    if not sweep.threshold_default:
        return text + ", set by the report's option report.threshold."
    best = sweep.best
    final = sweep.summary.iloc[best]["final_mean"] if best is not None else np.nan
    count = int(sweep.seeds["first_reward"].notna().sum())
    return (text + f", the default: 90 % of the way from the untrained policy's reward "
            f"({number(sweep.untrained)}, the mean first-bin reward of all {count} complete "
            f"seeds) to the best value's mean final score ({number(final)}).")


def metric_notes(bootstrap: int, min_seeds: int = 2, raced: bool = False) -> str:
    """What every interval and test of a sweep's summary is, each named once, for values needing
    ``min_seeds`` complete seeds (``bootstrap``: the report option's resamples of the bootstrap-t
    interval of a mean); ``raced``: what a dropped value's row shows."""
    race = (" Raced: a value the race dropped is never best, tied, selected or any answer of "
            "the verdict; its adjusted p is that of the race's look that dropped it, at the "
            "race's per-look alpha (the rule is in the verdict), and the survivors are "
            "compared on all their seeds." if raced else "")
    return (f"Final score, training time and AUC intervals: {interval_name(bootstrap)}. "
            f"Learning-curve bands: {BAND_NAME}, at every n. IQM: "
            f"{iqm_interval_name()}. {AUC_NAME[0].upper()}{AUC_NAME[1:]}. Steps and "
            "seconds to threshold: restricted mean over the seeds with a curve, a seed that "
            "never reached the threshold counted at its curve's last point (a lower bound of "
            "the mean time when reached is below n); reached: seeds that reached it of the "
            "complete seeds. Final IQR: interquartile range of the complete seeds' final scores "
            "(needs 2 seeds); rescaled: the IQR divided by its expected share of the true IQR "
            "at n for normal data, comparable across n, which decides the most repeatable. "
            f"Welch p vs best: {TEST_NAME}. Adjusted p and the '\u2248 best' marks: "
            f"{HOLM_NAME}. Best, ties, most sample-efficient, fastest and most repeatable count "
            f"only values with at least report.min_seeds = {min_seeds} complete seeds. "
            f"P(best > value): {p_improvement_name()}. Answer: best; equivalent (shown within "
            "the margin of the best, compare.margin in score units); worse (shown below the "
            "best by more than the margin, or dropped by a race); undecided (neither); left "
            f"out (too few seeds); {answers_name()}.{race}")


def few_seeds_note(sweep: Sweep) -> str | None:
    """The measured coverage of the intervals drawn from fewer than 5 seeds in this sweep, and
    of those from more where skewed data were covered less than 93 % of the time
    (:func:`kraby_study.decision.coverage.coverage_note`); None when neither is drawn here."""
    return coverage_note(int(n) for n in sweep.summary["complete"] if int(n) >= 2)


def left_out_text(sweep: Sweep) -> str | None:
    """The values left out of every comparison and answer for too few seeds, and why; None
    when none is."""
    notes = [(r["value"], note_part(r["note"], "left out: "))
             for _, r in sweep.summary.iterrows()]
    notes = [(value, note) for value, note in notes if note]
    if not notes:
        return None
    return ("Left out of the best, the ties and the verdict: "
            + "; ".join(f"{value} ({note.removeprefix('left out: ')})" for value, note in notes)
            + ".")


def race_text(sweep: Sweep) -> str | None:
    """What a raced study's race did: its rule (named once), the values it dropped and when,
    and the runs it made against the fixed design's; None for a study that did not race."""
    race = sweep.race
    if race is None:
        return None
    dropped = ", ".join(f"{_label(sweep, vi)} after round {drop.round} (adjusted p "
                        f"{_p_text(drop.p, '')})" for vi, drop in sorted(
                            sweep.dropped.items(), key=lambda item: (item[1].round, item[0])))
    state = "the race is over" if race.over else f"{race.rounds} round(s) decided so far"
    return (f"Race ({race.rules.describe()}): "
            + (f"dropped {dropped}" if dropped else "nothing dropped")
            + f"; {state}; {race.saved_text()}. Best, ties and the selection are among the "
            "survivors.")


def answers_text(sweep: Sweep) -> str:
    """The four answers in words, with the margin in score units and, when it is below what
    the seeds resolve, the warning."""
    compared = sweep.verdict.comparison
    assert compared is not None
    noun = "configuration" if sweep.kind == StudyKind.CONFIRM else "value"

    def named(values: list[int]) -> str:
        return ", ".join(_label(sweep, vi) for vi in values) or "none"

    worse = [*compared.worse, *sorted(sweep.dropped)]
    text = (f"{compared.margin_text()}: equivalent (shown within the margin of the best): "
            f"{named(compared.equivalent)}; undecided: {named(compared.undecided)}; worse "
            f"(shown below the best by more than the margin): {named(worse)} (every {noun} "
            f"answered by {answers_name(compared.alpha)})")
    warning = compared.resolution_text()
    if warning:
        return text + f"; warning: {warning}"
    if math.isfinite(compared.resolution):
        text += (f"; these seeds resolve a margin of about {compared.resolution:.3g} (median "
                 "over the values of (t + t_0.8) x the standard error of the contrast with the "
                 "best)")
    return text


def _label(sweep: Sweep, vi: int) -> str:
    return str(sweep.labels[vi])


def _final_text(row: pd.Series) -> str:
    text = f"mean {number(row['final_mean'])}"
    if np.isfinite(row["final_low"]):
        text += f", 95 % CI {_interval(row['final_low'], row['final_high'])}"
    text += f", n={row['complete']}; IQM {number(row['iqm'])}"
    if np.isfinite(row["iqm_low"]):
        text += f", 95 % trimmed-t CI {_interval(row['iqm_low'], row['iqm_high'])}"
    return text


def _auc_text(row: pd.Series) -> str:
    text = f"AUC {number(row['auc_mean'])}"
    if np.isfinite(row["auc_low"]):
        text += f", 95 % CI {_interval(row['auc_low'], row['auc_high'])}"
    return text + f", n={int(row['complete'])}"


def _reach_text(row: pd.Series) -> str:
    return (f"{number(row['seconds_to_threshold'], 3)} s, "
            f"{_steps(row['steps_to_threshold'])} env steps, restricted mean over the seeds, "
            f"{row['reached']}/{row['complete']} reached it")


def verdict(sweep: Sweep) -> str:
    """The study's verdict (:attr:`Sweep.verdict`, from
    :func:`kraby_study.decision.verdict.verdict`) in words: the best value and its ties, the most
    sample-efficient, the fastest to the threshold and the most repeatable, each with its n and
    interval."""
    result = sweep.verdict
    summary = sweep.summary
    if result.best is None:
        return "No run is complete yet, so no value can be compared."
    best = summary.iloc[result.best]
    if not sweep.parameter:
        text = f"Final score: {_final_text(best)}; {_auc_text(best)}"
        if best["reached"]:
            return text + f"; threshold reached in {_reach_text(best)}."
        return text + "; no seed reached the threshold."
    parts = []
    first = f"{_label(sweep, result.best)} best final score ({_final_text(best)}"
    compared = result.comparison
    if compared is not None and compared.fraction > 0:
        first += "; " + answers_text(sweep)
    elif result.tied:
        first += (f"; tied (not significantly worse, {PROCEDURE_NAME}): "
                  f"{', '.join(_label(sweep, vi) for vi in result.tied)}")
    elif len(sweep.values) > 1 and (summary["p_holm"].notna().any() or sweep.dropped):
        noun = "configuration" if sweep.kind == StudyKind.CONFIRM else "value"
        first += f"; every other {noun} tested is worse ({PROCEDURE_NAME})"
    parts.append(first + ")")
    if result.most_sample_efficient is not None:
        row = summary.iloc[result.most_sample_efficient]
        parts.append(f"{_label(sweep, result.most_sample_efficient)} most sample-efficient "
                     f"({_auc_text(row)})")
    if result.fastest is not None:
        row = summary.iloc[result.fastest]
        parts.append(f"{_label(sweep, result.fastest)} fastest to threshold ({_reach_text(row)}, "
                     "lowest restricted mean)")
    elif np.isfinite(sweep.threshold):
        parts.append(f"no value reached the threshold {number(sweep.threshold)}")
    if result.most_repeatable is not None:
        row = summary.iloc[result.most_repeatable]
        parts.append(f"{_label(sweep, result.most_repeatable)} most repeatable (rescaled final "
                     f"IQR {number(row['final_iqr_unbiased'], 3)}, raw "
                     f"{number(row['final_iqr'], 3)}, n={row['complete']})")
    prefix = "Confirmed verdict" if sweep.kind == StudyKind.CONFIRM else sweep.name
    text = f"{prefix}: " + "; ".join(parts) + "."
    raced = race_text(sweep)
    if raced:
        text += f" {raced}"
    left_out = left_out_text(sweep)
    if left_out:
        text += f" {left_out}"
    return text


def arms_table(sweep: Sweep) -> Table:
    """A confirm study's configurations: origin, the source's score, the confirmed score."""
    arms = arms_frame(sweep)
    rows = [[str(r["label"]), str(r["origin"]), number(r["source_score"]),
             number(r["mean"]), _interval(r["low"], r["high"]), number(r["iqm"]),
             _bootstrap_interval(r["iqm_low"], r["iqm_high"]), str(r["n"])]
            for _, r in arms.iterrows()]
    return Table(["configuration", "origin", "source's score", "confirmed mean final score",
                  "95 % CI", "confirmed IQM", "95 % trimmed-t CI", "n"], rows,
                 marks=list(arms["mark"]))


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
    row = sweep.summary.iloc[best]
    label = _label(sweep, best)
    fresh = f"the best mean final score on {row['complete']} fresh seeds"
    if winner == label:
        return f"{owner} winner {winner} is the confirmed winner: it has {fresh}."
    text = f"{owner} winner {winner} is not the confirmed winner: {label} has {fresh}."
    if winner not in sweep.labels:
        return text + f" {winner} was not retrained here."
    index = sweep.labels.index(winner)
    if index in sweep.dropped:
        return text + (f" The race dropped {winner} after round "
                       f"{sweep.dropped[index].round}.")
    mark = sweep.summary.iloc[index]["mark"]
    answer = str(sweep.summary.iloc[index].get("answer") or "")
    compared = sweep.comparison
    if compared is not None and compared.fraction > 0 and answer in ("equivalent", "undecided"):
        text += (f" {winner} is {answer} against it ({compared.margin_text()})"
                 + (": within the margin." if answer == "equivalent" else
                    ": neither shown within the margin nor below it."))
    elif mark == "tie":
        text += (f" The two cannot be told apart ({PROCEDURE_NAME}), so {winner} "
                 "may still be as good.")
    return text


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


def _tables(sweep: Sweep, folder: Path) -> list[Path]:
    summary = sweep.summary.copy()
    summary.insert(0, "parameter", sweep.parameter or "-")
    trials = sweep.trials.drop(columns=["vi"]).rename(columns={"value": sweep.name})
    curves = sweep.curves.assign(value=[sweep.labels[int(v)] for v in sweep.curves["vi"]])
    curves = curves[["value", "seed", "number", "step", "mean_reward", "wall_time", "episodes"]]
    curves = curves.rename(columns={"value": sweep.name, "number": "trial"})
    bands = sweep.bands.assign(value=[sweep.labels[int(v)] for v in sweep.bands["vi"]])
    bands = bands[["value", "step", "n", "mean", "sd", "low", "high", "wall_time"]]
    bands = bands.rename(columns={"value": sweep.name, "low": "ci_low", "high": "ci_high"})
    frames: list[tuple[str, pd.DataFrame]] = [("summary.csv", summary), ("trials.csv", trials),
                                              ("curves.csv", curves), ("curves_mean.csv", bands)]
    return write_csvs(folder, frames)


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
                     "source selected on; evaluation se: the standard error a run's score "
                     "carries from its episodes (root mean square over the seeds)"
                     if stored_eval_set(definition) == "run" else
                     "every run shares (one fixed set, as stored before runs drew their own)")
            scored = (f" Scored by evaluation: a run's final score is its deterministic "
                      f"policy's mean return over {episodes} evaluation episodes {drawn}; the "
                      f"training reward ({TRAINING_SCORE}) is shown beside it, and no answer "
                      f"reads it.")
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
    chosen = sweep.summary.index[sweep.summary["selected"].astype(bool)]
    if len(chosen):
        return f"Selected ({rule}): {sweep.labels[int(chosen[0])]}."
    if not sweep.finished:
        return f"Selected ({rule}): none until the {sweep.counts['pending']} pending run(s) end."
    return f"Selected ({rule}): none, no run is complete."


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
    figures: list[tuple[str, Any]] = [("learning_curves", sweep_plots.learning_curves),
                                      ("final_score", sweep_plots.final_score),
                                      ("wallclock", sweep_plots.wallclock)]
    if len(sweep.values) > 1:
        figures.append(("training_time", sweep_plots.training_time))
        figures += [(stem, getattr(sweep_plots, stem)) for stem in NEW_FIGURES]
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
    tables = _tables(sweep, folder)
    failed = failed_items(sweep)
    arms, winner = confirm_blocks(sweep)
    chosen = selection_text(sweep)
    failing = failed_seeds_text(sweep)
    said = Text(verdict(sweep) + (f" {chosen}" if chosen else "")
                + (f" {failing}" if failing else ""))
    details: list[Block] = [summary_table(sweep), Text(threshold_text(sweep))]
    if failed:
        details += [Text(f"Failed or pruned runs ({len(failed)}), not in the figures:"),
                    Items(failed)]
    if sweep.data.replaced:
        details.append(Text(f"{sweep.data.replaced} interrupted attempt(s) were run again; "
                            "only the later attempts count."))
    described = Text(describe_sweep(sweep))
    section: list[Block] = [Heading(f"{sweep.data.name}", 2), described, *arms, said, *winner,
                            *details]
    summary_md = folder / "summary.md"
    coverage = few_seeds_note(sweep)
    summary_md.write_text(blocks_to_markdown(
        [Heading(f"{sweep.data.name}: summary", 1), said, *winner, described, *arms, *details,
         Text(metric_notes(sweep.bootstrap, sweep.min_seeds, sweep.race is not None)),
         *([Text(coverage)] if coverage else [])]), encoding="utf-8")
    report.files += tables + [summary_md]
    report.blocks = section + images
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
    done = rows[(rows["outcome"] == Outcome.COMPLETE) & (rows["vi"] == best)]
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
