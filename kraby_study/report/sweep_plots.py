"""The figures of a sweep: learning curves (with a zoomed late panel), reward against
wall-clock time, training time, final score, sample efficiency and time to threshold against the
value, and the best value's probability of improvement over each other value.

Lines are means over the complete seeds of a value. Error bars are the 95 % intervals of those
means ([`mean_interval`][kraby_study.decision.intervals.mean_interval]: the bootstrap-t interval
from 5 seeds on, Hall's skewness-corrected t interval below), except the probability of
improvement's, which are Newcombe score-type intervals. The learning-curve bands, hundreds of points
a value, are Hall's intervals at every n (see [`kraby_study.decision`][]). In a raced study, the
curves of the values the race dropped are dashed.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from kraby_study.answers.sweep_evidence import Sweep
from kraby_study.decision.intervals import SHORT_INTERVAL_NAME, SHORT_IQM_INTERVAL_NAME
from kraby_study.decision.summary import ValueSummary
from kraby_study.records.stored import Outcome
from kraby_study.report.style import (
    BEST_COLOUR,
    FAILED_COLOUR,
    MUTED,
    SINGLE,
    STEPS_FORMATTER,
    WIDE,
    new_figure,
    save,
    sweep_colours,
)

LATE_FRACTION = 0.25
"""The zoomed panel shows the last quarter of training."""
REWARD_LABEL = "mean episode reward"
BAND_NOTE = "line: mean over seeds\nband: 95 % Hall skewness-corrected\nt interval (n >= 2)"
DROPPED_STYLE = "--"
"""The line style of a value the race dropped (its curve ends with its last seeds' steps)."""
DROPPED_NOTE = "dashed: dropped by the race"


def _title(sweep: Sweep, what: str) -> str:
    title = f"{sweep.data.name}: {what}"
    if not sweep.finished:
        title += f"\npartly finished: {sweep.status()}"
    return title


def _draw_bands(ax: Axes, sweep: Sweep, x: str) -> None:
    for value_index, group in sweep.bands.groupby("value_index", sort=True):
        colour = sweep_colours(sweep)[int(value_index)]
        style = DROPPED_STYLE if int(value_index) in sweep.dropped else "-"
        ax.plot(group[x], group["mean"], color=colour, linestyle=style,
                label=legend_label(sweep, int(value_index)))
        ax.fill_between(group[x], group["low"], group["high"], color=colour, alpha=0.18,
                        linewidth=0)


def _legend(fig: Figure, ax: Axes, sweep: Sweep, below: list[int] | None = None) -> None:
    title = f"{sweep.name} (seeds)" if sweep.parameter else "seeds"
    handles, labels = ax.get_legend_handles_labels()
    note = BAND_NOTE + (f"\n{DROPPED_NOTE}" if sweep.dropped else "")
    if below:
        handles.append(Line2D([], [], linestyle=""))
        labels.append("below the zoom (b):\n" + ", ".join(sweep.labels[i] for i in below))
    ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              frameon=False, title=f"{title}\n{note}", alignment="left")


def late_limits(bands: pd.DataFrame, start: float) -> tuple[float, float, list[int]]:
    """Y limits of the zoomed panel and the values left below them.

    The limits cover the intervals of the better half of the values (by mean reward late in
    training; all values when there are at most three) and the top of every value, so a value
    that collapsed does not squash the contenders into a line. Values whose late mean falls
    below the range are returned so the figure can name them.
    """
    late = bands[bands["step"] >= start]
    if late.empty:
        return np.nan, np.nan, []
    level = late.groupby("value_index")["mean"].mean().sort_values(ascending=False)
    keep = level.index[: max(3, int(np.ceil(len(level) / 2)))] if len(level) > 3 else level.index
    shown = late[late["value_index"].isin(keep)]
    low = np.nanmin(np.fmin(shown["low"].to_numpy(), shown["mean"].to_numpy()))
    high = np.nanmax(np.fmax(late["high"].to_numpy(), late["mean"].to_numpy()))
    below = sorted(int(i) for i in level.index if i not in keep and level[i] < low)
    pad = 0.08 * (high - low) if high > low else max(abs(high) * 0.05, 1e-6)
    return low - pad, high + pad, below


def draw_learning_curves(sweep: Sweep, path: Path) -> Path:
    """Mean reward against environment steps, whole training and zoomed on its last quarter."""
    fig, (whole, zoom) = new_figure(WIDE, ncols=2)
    last = float(sweep.bands["step"].max()) if not sweep.bands.empty else 1.0
    start = last * (1.0 - LATE_FRACTION)
    for ax in (whole, zoom):
        _draw_bands(ax, sweep, "step")
        ax.xaxis.set_major_formatter(STEPS_FORMATTER)
        ax.set_xlabel("environment steps")
    whole.set_ylabel(REWARD_LABEL)
    whole.axvspan(start, last, color=MUTED, alpha=0.08, linewidth=0)
    whole.set_title("(a) whole training", loc="left")
    zoom.set_title(f"(b) last {LATE_FRACTION:.0%} of training (zoom)", loc="left")
    zoom.set_xlim(start, last)
    low, high, below = late_limits(sweep.bands, start)
    if np.isfinite(low) and np.isfinite(high):
        zoom.set_ylim(low, high)
    _legend(fig, zoom, sweep, below)
    fig.suptitle(_title(sweep, "learning curves"))
    return save(fig, path)


def draw_wallclock(sweep: Sweep, path: Path) -> Path:
    """Mean reward against the wall-clock time at which the seeds reached each step."""
    fig, (ax,) = new_figure((WIDE[0] * 0.75, WIDE[1]))
    _draw_bands(ax, sweep, "wall_time")
    ax.set_xlabel("wall-clock time since the start of training (s, mean over seeds)")
    ax.set_ylabel(REWARD_LABEL)
    ax.set_xlim(left=0)
    _legend(fig, ax, sweep)
    fig.suptitle(_title(sweep, "reward against wall-clock time"))
    return save(fig, path)


def _value_axis(ax: Axes, sweep: Sweep) -> None:
    positions = np.arange(len(sweep.values))
    ax.set_xticks(positions, sweep.labels)
    ax.set_xlim(-0.6, len(sweep.values) - 0.4)
    # Long labels (a confirm study's configurations) would overlap, in half-width panels too.
    if max((len(label) for label in sweep.labels), default=0) * len(sweep.labels) > 40:
        ax.tick_params(axis="x", labelrotation=25)
        for label in ax.get_xticklabels():
            label.set_horizontalalignment("right")
    ax.set_xlabel(sweep.parameter)
    ax.grid(axis="x", visible=False)


def _seed_points(ax: Axes, sweep: Sweep, points: pd.DataFrame, column: str) -> None:
    rng = np.random.default_rng(0)  # fixed jitter: a rerun draws the same figure
    for value_index, group in points.groupby("value_index", sort=True):
        values = group[column].dropna()
        jitter = rng.uniform(-0.12, 0.12, len(values))
        ax.scatter(int(value_index) - 0.1 + jitter, values, s=16,
                   color=sweep_colours(sweep)[int(value_index)],
                   alpha=0.55, linewidths=0, zorder=2)


def _mean_mark(ax: Axes, sweep: Sweep, value_index: int, mean: float, low: float,
               high: float) -> None:
    if not np.isfinite(mean):
        return
    err = None
    if np.isfinite(low) and np.isfinite(high):
        err = [[mean - low], [high - mean]]
    ax.errorbar(value_index + 0.18, mean, yerr=err, fmt="o",
                color=sweep_colours(sweep)[value_index],
                markeredgecolor="black", markeredgewidth=0.6, markersize=7, capsize=4,
                elinewidth=1.6, zorder=3)


def _seeds_and_means(ax: Axes, sweep: Sweep, column: str,
                     location: Callable[[ValueSummary], tuple[float, float, float]],
                     points: pd.DataFrame | None = None) -> None:
    """Every complete seed's ``column`` (from ``points``, by default the complete runs) as a
    point, and each value's ``location`` (mean or IQM, low, high) beside them."""
    if points is None:
        points = sweep.trials[sweep.trials["outcome"] == Outcome.COMPLETE]
    _seed_points(ax, sweep, points, column)
    for value_index, row in enumerate(sweep.rows):
        _mean_mark(ax, sweep, value_index, *location(row))


def _failed_marks(ax: Axes, sweep: Sweep) -> bool:
    for value_index, count in enumerate(r.failed for r in sweep.rows):
        if count:
            ax.annotate(f"x {count} failed", (int(value_index), 0.02),
                        xycoords=("data", "axes fraction"),
                        ha="center", va="bottom", fontsize=9, color=FAILED_COLOUR)
    return any(r.failed for r in sweep.rows)


MEAN_MARK = f"mean, {SHORT_INTERVAL_NAME}"
IQM_MARK = f"IQM, {SHORT_IQM_INTERVAL_NAME}"
"""The final-score figure's mark: the answers are about the IQM."""


def _legend_entries(extra: list[Line2D | Patch], mark: str = MEAN_MARK
                    ) -> list[Line2D | Patch]:
    return [Line2D([], [], marker="o", linestyle="", color=MUTED, alpha=0.55, markersize=5,
                   label="one seed"),
            Line2D([], [], marker="o", linestyle="-", color=MUTED, markeredgecolor="black",
                   markersize=7, label=_two_lines(mark)), *extra]


def _two_lines(label: str) -> str:
    """A legend label broken before its first parenthesis, so two legend columns fit the
    figure's width."""
    return label.replace(" (", "\n(", 1)


def draw_training_time(sweep: Sweep, path: Path) -> Path:
    """Training time of each run against the value, with mean and interval."""
    fig, (ax,) = new_figure(SINGLE)
    _seeds_and_means(ax, sweep, sweep.time_attr,
                     lambda r: (r.time_mean, r.time_low, r.time_high))
    _value_axis(ax, sweep)
    ax.set_ylabel(f"training time per run ({sweep.time_unit})")
    ax.set_ylim(bottom=0)
    _failed_marks(ax, sweep)
    fig.legend(handles=_legend_entries([]), loc="outside lower center", ncols=2, frameon=False)
    fig.suptitle(_title(sweep, "training time"))
    return save(fig, path)


ANSWER_SHADES = {"best": (BEST_COLOUR, 0.18), "equivalent": (BEST_COLOUR, 0.07),
                 "undecided": (MUTED, 0.12)}
"""How the final-score figure shades a value's column by its answer (written above it, so the
legend needs no entry for the shades); worse stays unshaded."""


def _answers(sweep: Sweep) -> pd.Series:
    """Each value's answer against the best, as the summary's answer column writes it; empty
    for a study of one value, which is trivially the best."""
    answers = pd.Series([r.answer for r in sweep.rows], dtype=str)
    return answers if len(sweep.values) > 1 else answers.map(lambda _: "")


def _shade_answers(ax: Axes, answers: pd.Series) -> None:
    """Shade each value's column by its answer and write the answer above it."""
    for value_index, answer in answers.items():
        colour, alpha = ANSWER_SHADES.get(answer, (None, 0.0))
        if colour is not None:
            ax.axvspan(int(value_index) - 0.45, int(value_index) + 0.45, color=colour, alpha=alpha,
                       linewidth=0, zorder=0)
        if answer:
            ax.annotate(answer, (int(value_index), 0.98), xycoords=("data", "axes fraction"),
                        ha="center", va="top", fontsize=9, color="#333333")
    if answers.astype(bool).any():
        ax.margins(y=0.15)


def draw_final_score(sweep: Sweep, path: Path) -> Path:
    """Final score of each seed against the value, with each value's IQM (what the answers are
    about) and its interval; each value's column shaded by its answer against the best (best,
    equivalent, undecided; worse unshaded), the answer written above it."""
    several = len(sweep.values) > 1
    fig, (ax,) = new_figure(SINGLE if several else (SINGLE[0] * 0.6, SINGLE[1]))
    _shade_answers(ax, _answers(sweep))
    _seeds_and_means(ax, sweep, "final_score", lambda r: (r.iqm, r.iqm_low, r.iqm_high))
    _value_axis(ax, sweep)
    ax.set_ylabel("final score (mean evaluation return,\ndeterministic policy)"
                  if sweep.by_evaluation else
                  "final score (mean episode reward,\nlast 10 % of training)")
    if _failed_marks(ax, sweep):
        ax.margins(y=0.15)
    fig.legend(handles=_legend_entries([], IQM_MARK), loc="outside lower center",
               ncols=2 if several else 1, frameon=False)
    fig.suptitle(_title(sweep, "final score"))
    return save(fig, path)


def draw_sample_efficiency(sweep: Sweep, path: Path) -> Path:
    """AUC (mean reward over the whole learning curve) of each seed against the value."""
    several = len(sweep.values) > 1
    fig, (ax,) = new_figure(SINGLE if several else (SINGLE[0] * 0.6, SINGLE[1]))
    _seeds_and_means(ax, sweep, "auc", lambda r: (r.auc_mean, r.auc_low, r.auc_high),
                     points=sweep.seeds)
    _value_axis(ax, sweep)
    ax.set_ylabel("AUC: mean episode reward\nover the whole learning curve")
    if _failed_marks(ax, sweep):
        ax.margins(y=0.12)
    fig.legend(handles=_legend_entries([]), loc="outside lower center",
               ncols=2 if several else 1, frameon=False)
    fig.suptitle(_title(sweep, "sample efficiency (area under the learning curve)"))
    return save(fig, path)


def _threshold_text(sweep: Sweep) -> str:
    if not np.isfinite(sweep.threshold):
        return "no threshold (no learning curve)"
    how = "default" if sweep.threshold_default else "set by report.threshold"
    return f"threshold: mean episode reward >= {sweep.threshold:.4g} ({how})"


def draw_time_to_threshold(sweep: Sweep, path: Path) -> Path:
    """Env steps (a) and seconds (b) until each seed's curve first reached the threshold:
    every seed that reached it, the mean over those seeds with its interval, and how many of
    the complete seeds reached it; values where none did are marked."""
    fig, axes = new_figure(WIDE, ncols=2)
    seeds = sweep.seeds
    panels = [("steps_to_threshold", "environment steps to threshold", "(a) env steps"),
              ("seconds_to_threshold", "seconds to threshold (wall clock)", "(b) seconds")]
    none_reached = False
    for ax, (column, label, title) in zip(axes, panels, strict=True):
        reached = seeds[seeds[column].notna()]
        _seed_points(ax, sweep, reached, column)
        for value_index, row in enumerate(sweep.rows):
            mean, low, high = (sweep.reach.at[value_index, f"{column}_{part}"]
                               for part in ("mean", "low", "high"))
            _mean_mark(ax, sweep, value_index, mean, low, high)
            if row.complete == 0:
                continue
            colour = FAILED_COLOUR if row.reached == 0 else "black"
            ax.annotate(f"{row.reached}/{row.complete}", (value_index, 1.0),
                        xycoords=("data", "axes fraction"), ha="center", va="top", fontsize=9,
                        color=colour)
            if row.reached == 0:
                none_reached = True
                ax.annotate("none\nreached", (int(value_index), 0.04),
                            xycoords=("data", "axes fraction"),
                            ha="center", va="bottom", fontsize=9, color=FAILED_COLOUR)
        _value_axis(ax, sweep)
        ax.set_ylabel(label)
        ax.set_title(title, loc="left")
        ax.autoscale_view()
        top = ax.get_ylim()[1]
        ax.set_ylim(0, top * 1.15 if top > 0 else 1.0)  # room for the k/N labels on top
        if column == "steps_to_threshold":
            ax.yaxis.set_major_formatter(STEPS_FORMATTER)
    extra: list[Line2D | Patch] = [Line2D([], [], linestyle="", label="k/N: seeds that reached "
                                          "the threshold / complete seeds")]
    if none_reached:
        extra.append(Line2D([], [], linestyle="", label="none reached: no seed of the value "
                            "reached the threshold"))
    handles = _legend_entries(extra)
    handles[0].set_label("one seed that reached the threshold")
    handles[1].set_label(_two_lines(f"mean over those seeds, {SHORT_INTERVAL_NAME}"))
    fig.legend(handles=handles, loc="outside lower center", ncols=2, frameon=False)
    fig.suptitle(_title(sweep, f"time to threshold, {_threshold_text(sweep)}"))
    return save(fig, path)


def draw_improvement(sweep: Sweep, path: Path) -> Path:
    """Probability of improvement of the best value over each other value, with its Newcombe
    score-type interval, against the value; a line at 0.5 (no improvement either way)."""
    fig, (ax,) = new_figure(SINGLE)
    best = sweep.best
    ax.axhline(0.5, color=MUTED, linestyle="--", linewidth=1.2, zorder=1)
    for value_index, row in enumerate(sweep.rows):
        if value_index == best:
            ax.annotate("best", (value_index, 0.5), ha="center", va="center", fontsize=10,
                        color=BEST_COLOUR, fontweight="bold")
            continue
        p = row.p_improvement
        if not np.isfinite(p):
            ax.annotate("n/a", (value_index, 0.5), ha="center", va="center", fontsize=9,
                        color=MUTED)
            continue
        err = None
        if np.isfinite(row.p_improvement_low) and np.isfinite(row.p_improvement_high):
            err = [[p - row.p_improvement_low], [row.p_improvement_high - p]]
        ax.errorbar(value_index, p, yerr=err, fmt="o", color=sweep_colours(sweep)[value_index],
                    markeredgecolor="black", markeredgewidth=0.6, markersize=7, capsize=4,
                    elinewidth=1.6, zorder=3)
    _value_axis(ax, sweep)
    ax.set_ylim(-0.03, 1.03)
    best_label = sweep.labels[best] if best is not None else "?"
    ax.set_ylabel("P(best > value)")
    handles: list[Line2D | Patch] = [
        Line2D([], [], marker="o", linestyle="-", color=MUTED, markeredgecolor="black",
               markersize=7, label="P(best > value) over pairs of seeds, 95 % Newcombe "
               "score-type interval"),
        Line2D([], [], color=MUTED, linestyle="--", label="0.5: neither better"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=1, frameon=False)
    fig.suptitle(_title(sweep, f"P(best > value), best = {best_label}"))
    return save(fig, path)


def legend_label(sweep: Sweep, value_index: int) -> str:
    """A value as the legends write it: its label and the seeds behind its mean (and, for a
    value the race dropped, the round after which it was)."""
    row = sweep.rows[value_index]
    text = f"{row.value}  (n={row.complete}"
    for name, count in ((Outcome.FAILED, row.failed), (Outcome.PRUNED, row.pruned)):
        if count:
            text += f", {count} {name}"
    text += ")"
    if value_index in sweep.dropped:  # a second line: the legends sit beside the axes
        text += f"\ndropped after round {sweep.dropped[value_index].round}"
    return text

