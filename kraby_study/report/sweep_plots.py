"""The figures of a sweep: learning curves (with a zoomed late panel), reward against
wall-clock time, training time and final score against the value.

Lines are means over the complete seeds of a value; bands and error bars are the 95 %
Student-t intervals of those means (see :mod:`kraby_study.stats`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from kraby_study.records import Outcome
from kraby_study.report.style import (
    BEST_COLOUR,
    FAILED_COLOUR,
    MUTED,
    SINGLE,
    STEPS_FORMATTER,
    WIDE,
    new_figure,
    save,
)
from kraby_study.report.sweep_tables import Sweep, legend_label

LATE_FRACTION = 0.25
"""The zoomed panel shows the last quarter of training."""
REWARD_LABEL = "mean episode reward"
BAND_NOTE = "line: mean over seeds\nband: 95 % t-interval (n >= 2)"


def _title(sweep: Sweep, what: str) -> str:
    title = f"{sweep.data.name}: {what}"
    if not sweep.finished:
        title += f"\npartly finished: {sweep.status()}"
    return title


def _draw_bands(ax: Axes, sweep: Sweep, x: str) -> None:
    for vi, group in sweep.bands.groupby("vi", sort=True):
        colour = sweep.colours[int(vi)]
        ax.plot(group[x], group["mean"], color=colour, label=legend_label(sweep, int(vi)))
        ax.fill_between(group[x], group["low"], group["high"], color=colour, alpha=0.18,
                        linewidth=0)


def _legend(fig: Figure, ax: Axes, sweep: Sweep, below: list[int] | None = None) -> None:
    title = f"{sweep.name} (seeds)" if sweep.parameter else "seeds"
    handles, labels = ax.get_legend_handles_labels()
    if below:
        handles.append(Line2D([], [], linestyle=""))
        labels.append("below the zoom (b):\n" + ", ".join(sweep.labels[vi] for vi in below))
    ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              frameon=False, title=f"{title}\n{BAND_NOTE}", alignment="left")


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
    level = late.groupby("vi")["mean"].mean().sort_values(ascending=False)
    keep = level.index[: max(3, int(np.ceil(len(level) / 2)))] if len(level) > 3 else level.index
    shown = late[late["vi"].isin(keep)]
    low = np.nanmin(np.fmin(shown["low"].to_numpy(), shown["mean"].to_numpy()))
    high = np.nanmax(np.fmax(late["high"].to_numpy(), late["mean"].to_numpy()))
    below = sorted(int(vi) for vi in level.index if vi not in keep and level[vi] < low)
    pad = 0.08 * (high - low) if high > low else max(abs(high) * 0.05, 1e-6)
    return low - pad, high + pad, below


def learning_curves(sweep: Sweep, path: Path) -> Path:
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


def wallclock(sweep: Sweep, path: Path) -> Path:
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
    if max((len(label) for label in sweep.labels), default=0) * len(sweep.labels) > 80:
        ax.tick_params(axis="x", labelrotation=25)
        for label in ax.get_xticklabels():
            label.set_horizontalalignment("right")
    ax.set_xlabel(sweep.parameter)
    ax.grid(axis="x", visible=False)


def _seeds_and_means(ax: Axes, sweep: Sweep, column: str, mean: str, low: str,
                     high: str) -> None:
    done = sweep.trials[sweep.trials["outcome"] == Outcome.COMPLETE]
    rng = np.random.default_rng(0)  # fixed jitter: a rerun draws the same figure
    for vi, group in done.groupby("vi", sort=True):
        jitter = rng.uniform(-0.12, 0.12, len(group))
        ax.scatter(int(vi) - 0.1 + jitter, group[column], s=16, color=sweep.colours[int(vi)],
                   alpha=0.55, linewidths=0, zorder=2)
    summary = sweep.summary
    for vi, row in summary.iterrows():
        if not np.isfinite(row[mean]):
            continue
        err = None
        if np.isfinite(row[low]):
            err = [[row[mean] - row[low]], [row[high] - row[mean]]]
        ax.errorbar(int(vi) + 0.18, row[mean], yerr=err, fmt="o", color=sweep.colours[int(vi)],
                    markeredgecolor="black", markeredgewidth=0.6, markersize=7, capsize=4,
                    elinewidth=1.6, zorder=3)


def _failed_marks(ax: Axes, sweep: Sweep) -> bool:
    failed = sweep.summary["failed"]
    for vi, count in failed.items():
        if count:
            ax.annotate(f"x {count} failed", (int(vi), 0.02), xycoords=("data", "axes fraction"),
                        ha="center", va="bottom", fontsize=9, color=FAILED_COLOUR)
    return bool(failed.any())


def _legend_entries(extra: list[Line2D | Patch]) -> list[Line2D | Patch]:
    return [Line2D([], [], marker="o", linestyle="", color=MUTED, alpha=0.55, markersize=5,
                   label="one seed"),
            Line2D([], [], marker="o", linestyle="-", color=MUTED, markeredgecolor="black",
                   markersize=7, label="mean, 95 % t-interval"), *extra]


def training_time(sweep: Sweep, path: Path) -> Path:
    """Training time of each run against the value, with mean and interval."""
    fig, (ax,) = new_figure(SINGLE)
    _seeds_and_means(ax, sweep, "wall_time", "time_mean", "time_low", "time_high")
    _value_axis(ax, sweep)
    ax.set_ylabel("training time per run (s)")
    ax.set_ylim(bottom=0)
    _failed_marks(ax, sweep)
    fig.legend(handles=_legend_entries([]), loc="outside lower center", ncols=2, frameon=False)
    fig.suptitle(_title(sweep, "training time"))
    return save(fig, path)


def final_score(sweep: Sweep, path: Path) -> Path:
    """Final score of each seed against the value; the best value and its ties shaded."""
    several = len(sweep.values) > 1
    fig, (ax,) = new_figure(SINGLE if several else (SINGLE[0] * 0.6, SINGLE[1]))
    marks = sweep.summary["mark"].copy()
    if not several:  # one value is trivially the best: nothing to mark
        marks[:] = ""
    for vi, mark in marks.items():
        if mark:
            ax.axvspan(int(vi) - 0.45, int(vi) + 0.45, color=BEST_COLOUR,
                       alpha=0.18 if mark == "best" else 0.07, linewidth=0, zorder=0)
    _seeds_and_means(ax, sweep, "final_score", "final_mean", "final_low", "final_high")
    _value_axis(ax, sweep)
    ax.set_ylabel("final score (mean episode reward,\nlast 10 % of training)")
    extra: list[Line2D | Patch] = []
    if (marks == "best").any():
        extra.append(Patch(color=BEST_COLOUR, alpha=0.3, label="best mean"))
    if (marks == "tie").any():
        extra.append(Patch(color=BEST_COLOUR, alpha=0.1,
                           label="not sig. different from best (Welch's t-test, p >= 0.05)"))
    if _failed_marks(ax, sweep):
        ax.margins(y=0.12)
    fig.legend(handles=_legend_entries(extra), loc="outside lower center",
               ncols=2 if several else 1, frameon=False)
    fig.suptitle(_title(sweep, "final score"))
    return save(fig, path)
