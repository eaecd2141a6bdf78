"""A sweep (or a single-run study) as tables: one row per run, per value, per curve point.

Figures draw from the complete runs only; failed runs are counted and listed, runs still to
come are counted as pending, and nothing is dropped without a trace.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from kraby_study.records import Outcome, outcome, param_name, swept_value, value_key, value_label
from kraby_study.report.load import StudyData
from kraby_study.report.style import is_numeric, value_colours
from kraby_study.stats import compare_to_best, describe, t_interval

SINGLE_LABEL = "all seeds"
TRIAL_COLUMNS = ["number", "key", "seed", "vi", "value", "outcome", "final_score",
                 "wall_time", "env_steps", "failure", "model_path"]


@dataclass
class Sweep:
    """Everything the figures and tables of one sweep need.

    Attributes:
        data: The stored study.
        parameter: Dotted name of the swept setting ("" for a single-run study).
        name: The setting's short name (the Optuna parameter), or "all seeds".
        values: The swept values in figure order (by value when all are numbers).
        labels: How each value is written.
        colours: One colour per value, shared by every figure.
        trials: One row per counted run (columns ``TRIAL_COLUMNS``); ``vi`` indexes values.
        curves: Curve points of the complete runs, with their ``vi`` and ``seed``.
        bands: Per value and step: n, mean, sd, low, high of the reward; mean wall time.
        summary: One row per value (see :func:`summarise`).
    """

    data: StudyData
    parameter: str
    name: str
    values: list[Any]
    labels: list[str]
    colours: list[tuple[float, float, float, float]]
    trials: pd.DataFrame
    curves: pd.DataFrame
    bands: pd.DataFrame
    summary: pd.DataFrame

    @property
    def counts(self) -> dict[str, int]:
        """Runs complete, failed, pruned and pending (planned runs without a trial are
        pending)."""
        outcomes = self.trials["outcome"]
        counts = {o.value: int((outcomes == o).sum())
                  for o in (Outcome.COMPLETE, Outcome.FAILED, Outcome.PRUNED)}
        planned = max(self.data.planned or 0, len(self.trials))
        return {"planned": planned, **counts, "pending": planned - sum(counts.values())}

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
        """Index of the best value (highest mean final score), if any run is complete."""
        marked = self.summary.index[self.summary["mark"] == "best"]
        return int(marked[0]) if len(marked) else None


def ordered_values(planned: list[Any], found: list[Any]) -> list[Any]:
    """Planned values plus any other value found, sorted when all are numbers."""
    values = list(planned)
    known = {value_key(v) for v in values}
    for value in found:
        if value is not None and value_key(value) not in known:
            known.add(value_key(value))
            values.append(value)
    if is_numeric(values):
        values.sort(key=float)
    return values


def trial_frame(data: StudyData, name: str | None, values: list[Any]) -> pd.DataFrame:
    """One row per counted run; ``vi`` is the index of its value in ``values``."""
    index = {value_key(v): i for i, v in enumerate(values)}
    rows = []
    for trial in data.trials:
        attrs = trial.user_attrs
        value = swept_value(trial, name, values) if name else None
        vi = index.get(value_key(value), -1) if name else 0
        state = outcome(trial)
        rows.append({
            "number": trial.number, "key": attrs.get("key"),
            "seed": attrs.get("seed"), "vi": vi,
            "value": value_label(values[vi]) if vi >= 0 and name else
            (SINGLE_LABEL if not name else "?"),
            "outcome": state.value,
            "final_score": float(trial.value)
            if state == Outcome.COMPLETE and trial.value is not None else np.nan,
            "wall_time": attrs.get("wall_time", np.nan) if state != Outcome.PENDING else np.nan,
            "env_steps": attrs.get("env_steps", np.nan) if state != Outcome.PENDING else np.nan,
            "failure": attrs.get("failure", "") if state == Outcome.FAILED else "",
            "model_path": attrs.get("model_path"),
        })
    frame = pd.DataFrame(rows, columns=TRIAL_COLUMNS)
    for column in ("final_score", "wall_time", "env_steps"):
        frame[column] = pd.to_numeric(frame[column], errors="coerce").astype(float)
    return frame


def curve_bands(curves: pd.DataFrame) -> pd.DataFrame:
    """Mean reward and its t interval over seeds, per value and step (vectorised)."""
    if curves.empty:
        return pd.DataFrame(columns=["vi", "step", "n", "mean", "sd", "low", "high", "wall_time"])
    grouped = curves.groupby(["vi", "step"], sort=True).agg(
        n=("mean_reward", "count"), mean=("mean_reward", "mean"), sd=("mean_reward", "std"),
        wall_time=("wall_time", "mean"))
    grouped["low"], grouped["high"] = t_interval(grouped["mean"], grouped["sd"], grouped["n"])
    return grouped.reset_index()


def summarise(trials: pd.DataFrame, labels: list[str]) -> pd.DataFrame:
    """One row per value: run counts, final score and training time (mean, sd, interval), the
    Welch p-value against the best value, and a mark: ``best``, ``tie`` (not significantly
    different from the best) or empty.
    """
    done = trials[trials["outcome"] == Outcome.COMPLETE]
    score = describe(done, "vi", "final_score")
    time = describe(done, "vi", "wall_time")
    counts = pd.crosstab(trials["vi"], trials["outcome"])
    scores = {int(vi): group["final_score"].tolist() for vi, group in done.groupby("vi")}
    best, pvalues = compare_to_best(scores)
    rows = []
    for vi, label in enumerate(labels):
        count = counts.loc[vi] if vi in counts.index else pd.Series(dtype=int)
        p = pvalues.get(vi, np.nan)
        mark = "best" if vi == best else ("tie" if np.isfinite(p) and p >= 0.05 else "")
        s = score.loc[vi] if vi in score.index else None
        t = time.loc[vi] if vi in time.index else None
        steps = done.loc[done["vi"] == vi, "env_steps"]
        rows.append({
            "value": label,
            "complete": int(count.get(Outcome.COMPLETE, 0)),
            "failed": int(count.get(Outcome.FAILED, 0)),
            "pruned": int(count.get(Outcome.PRUNED, 0)),
            "pending": int(count.get(Outcome.PENDING, 0)),
            "final_mean": s["mean"] if s is not None else np.nan,
            "final_sd": s["sd"] if s is not None else np.nan,
            "final_low": s["low"] if s is not None else np.nan,
            "final_high": s["high"] if s is not None else np.nan,
            "time_mean": t["mean"] if t is not None else np.nan,
            "time_low": t["low"] if t is not None else np.nan,
            "time_high": t["high"] if t is not None else np.nan,
            "env_steps": float(steps.mean()) if len(steps) else np.nan,
            "p_vs_best": p,
            "mark": mark,
        })
    return pd.DataFrame(rows)


def build_sweep(data: StudyData) -> Sweep:
    """The tables of a sweep study, or of a single-run study (one value, several seeds)."""
    definition = data.definition
    if data.kind == "sweep":
        parameter = str(definition["parameter"])
        name: str | None = param_name(parameter)
        planned = list(definition.get("values", []))
        found = [swept_value(t, name, planned) for t in data.trials]
        values = ordered_values(planned, found)
        labels = [value_label(v) for v in values]
    else:
        parameter, name, values, labels = "", None, [SINGLE_LABEL], [SINGLE_LABEL]
    trials = trial_frame(data, name, values)
    if (trials["vi"] < 0).any():  # a run whose value cannot be read: show it, do not drop it
        values, labels = values + ["?"], labels + ["?"]
        trials.loc[trials["vi"] < 0, "vi"] = len(values) - 1
    complete = trials[trials["outcome"] == Outcome.COMPLETE][["vi", "seed", "number"]]
    curves = data.curves.merge(complete, on="number", how="inner")
    return Sweep(data=data, parameter=parameter, name=name or SINGLE_LABEL, values=values,
                 labels=labels, colours=value_colours(values), trials=trials, curves=curves,
                 bands=curve_bands(curves), summary=summarise(trials, labels))


def legend_label(sweep: Sweep, vi: int) -> str:
    """A value as the legends write it: its label and the seeds behind its mean."""
    row = sweep.summary.iloc[vi]
    text = f"{row['value']}  (n={row['complete']}"
    for name in (Outcome.FAILED, Outcome.PRUNED):
        if row[name]:
            text += f", {row[name]} {name}"
    return text + ")"
