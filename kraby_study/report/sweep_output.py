"""A sweep's files (figures, CSV and Markdown tables) and its section of the index."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from kraby_study.records import Outcome
from kraby_study.report import sweep_plots
from kraby_study.report.document import Block, Heading, Image, Items, Links, Table, Text, write_csvs
from kraby_study.report.document import to_markdown as blocks_to_markdown
from kraby_study.report.results import StudyReport
from kraby_study.report.style import number, styled
from kraby_study.report.sweep_tables import Sweep
from kraby_study.stats import ALPHA, INTERVAL_NAME, TEST_NAME

MARK_TEXT = {"best": "best", "tie": "\u2248 best", "": ""}
CAPTIONS = {
    "learning_curves": "Mean episode reward against environment steps, mean over seeds with its "
                       "95 % t-interval; (b) zooms on the last quarter of training.",
    "final_score": "Final score (mean episode reward over the last 10 % of training) of every "
                   "seed; mean and 95 % t-interval beside them. Shaded: the best mean, and the "
                   "values a Welch's t-test cannot tell from it (p >= 0.05).",
    "wallclock": "Mean episode reward against wall-clock time since the start of training.",
    "training_time": "Training time of every run, with mean and 95 % t-interval.",
}


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


def summary_table(sweep: Sweep) -> Table:
    """The summary as a table of formatted cells, best and tied rows marked."""
    header = [sweep.name, "complete", "failed", "pruned", "pending", "final score", "95 % CI", "sd",
              "training time (s)", "Welch p vs best", ""]
    rows = []
    for _, row in sweep.summary.iterrows():
        rows.append([
            str(row["value"]), str(row["complete"]), str(row["failed"]), str(row["pruned"]),
            str(row["pending"]),
            number(row["final_mean"]), _interval(row["final_low"], row["final_high"]),
            number(row["final_sd"], 3),
            _with_interval(row["time_mean"], row["time_low"], row["time_high"]),
            _p_text(row["p_vs_best"], row["mark"]), MARK_TEXT[row["mark"]]])
    return Table(header, rows, marks=list(sweep.summary["mark"]))


def verdict(sweep: Sweep) -> str:
    """One sentence: which value wins, and which ones it cannot be told from."""
    best = sweep.best
    if best is None:
        return "No run is complete yet, so no value can be compared."
    row = sweep.summary.iloc[best]
    if not sweep.parameter:
        return (f"Final score {number(row['final_mean'])} (95 % CI "
                f"{_interval(row['final_low'], row['final_high'])}, n={row['complete']}).")
    text = (f"Best: {sweep.name} = {row['value']}, mean final score {number(row['final_mean'])} "
            f"(95 % CI {_interval(row['final_low'], row['final_high'])}, n={row['complete']}).")
    ties = sweep.summary.loc[sweep.summary["mark"] == "tie", "value"].tolist()
    untested = sweep.summary.loc[(sweep.summary["mark"] == "") & sweep.summary["p_vs_best"].isna()
                                 & (sweep.summary["complete"] > 0), "value"].tolist()
    if ties:
        text += (f" Not significantly different from it (Welch's t-test, p >= {ALPHA}): "
                 f"{', '.join(ties)}.")
    elif len(sweep.values) > 1:
        text += f" Every other value tested is significantly worse (Welch's t-test, p < {ALPHA})."
    if untested:
        text += f" Too few seeds to test: {', '.join(untested)}."
    return text


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
    steps = definition.get("steps")
    budget = f", {steps:,} environment steps per run" if isinstance(steps, int) else ""
    if not sweep.parameter:
        return f"Single training run, {seeds} seed(s){budget}. Status: {sweep.status()}."
    return (f"Sweep of {sweep.parameter} over {len(sweep.values)} values, {seeds} seeds each"
            f"{budget}. Status: {sweep.status()}.")


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
    images: list[Block] = []
    if (sweep.trials["outcome"] == Outcome.COMPLETE).any():
        with styled():
            for stem, draw in figures:
                path = draw(sweep, folder / f"{stem}.{fmt}")
                report.files.append(path)
                images.append(Image(f"{rel}/{path.name}", stem.replace("_", " "),
                                    CAPTIONS[stem]))
    else:
        report.notes.append("no complete run yet: no figures")
    tables = _tables(sweep, folder)
    failed = failed_items(sweep)
    section: list[Block] = [Heading(f"{sweep.data.name}", 2), Text(describe_sweep(sweep)),
                            Text(verdict(sweep)), summary_table(sweep)]
    if failed:
        section += [Text(f"Failed or pruned runs ({len(failed)}), not in the figures:"),
                    Items(failed)]
    if sweep.data.replaced:
        section.append(Text(f"{sweep.data.replaced} interrupted attempt(s) were run again; "
                            "only the later attempts count."))
    summary_md = folder / "summary.md"
    summary_md.write_text(blocks_to_markdown(
        [Heading(f"{sweep.data.name}: summary", 1), *section[1:],
         Text(f"Interval: {INTERVAL_NAME}. Ties: {TEST_NAME}, no correction for multiple "
              "comparisons.")]), encoding="utf-8")
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
