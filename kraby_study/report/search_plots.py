"""The figures of a search: optimization history, parameter importances, slices,
intermediate values (pruned trials cut short) and parallel coordinates.

Drawn with matplotlib directly rather than ``optuna.visualization.matplotlib``, which changes
matplotlib's global style and is experimental; the content is the same.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator
from optuna.distributions import BaseDistribution, CategoricalDistribution
from optuna.trial import FrozenTrial

from kraby_study.answers.search_evidence import Search
from kraby_study.records.attributes import StudyKind
from kraby_study.records.stored import Outcome, known_number
from kraby_study.records.values import score
from kraby_study.report.search_format import is_log, numeric_array
from kraby_study.report.style import (
    BEST_COLOUR,
    FAILED_COLOUR,
    SINGLE,
    STEPS_FORMATTER,
    WIDE,
    new_figure,
    save,
)

CMAP = "viridis"
PRUNED_COLOUR = "#e67e22"


def _objective_label(search: Search) -> str:
    if search.data.kind == StudyKind.SEARCH:
        return "objective (final score)"
    return "objective value"


def _title(search: Search, what: str) -> str:
    title = f"{search.data.name}: {what}"
    if not search.finished:
        title += f"\npartly finished: {search.status()}"
    return title


def first_scores(search: Search) -> pd.DataFrame:
    """Every complete trial by its own number (``trial``), with its score on the seeds it was
    first trained on (``first``: what the search ranked it by while exploring) and its score
    now (``value``; over all its seeds when ``rechecked``), in trial order."""
    frame = search.trials
    done = frame[frame["outcome"] == Outcome.COMPLETE]
    rows = []
    for number, trial, value in zip(done["number"], done["trial"], done["value"], strict=True):
        original = search.data.rechecked.get(int(number))
        before = score(original) if original is not None else None
        rows.append({"trial": int(trial), "first": float(value if before is None else before),
                     "value": float(value), "rechecked": original is not None})
    return pd.DataFrame(rows, columns=["trial", "first", "value", "rechecked"]).sort_values(
        "trial", ignore_index=True)


def history(search: Search, path: Path) -> Path:
    """Every complete trial's score on its first seeds by trial number, and the best so far;
    a rechecked trial also at its score over all its seeds."""
    fig, (ax,) = new_figure(SINGLE)
    frame = search.trials
    done = first_scores(search)
    ax.scatter(done["trial"], done["first"], s=18, color="#3b6ea8", alpha=0.75, linewidths=0,
               label=f"complete trial ({len(done)})", zorder=3)
    again = done[done["rechecked"]]
    if len(done):
        running = (done["first"].cummax() if search.maximize else done["first"].cummin())
        # Held to the last trial, pruned or failed ones included, which also shows them all.
        last = int(frame["trial"].max())
        ax.step([*done["trial"], last], [*running, running.iloc[-1]], where="post",
                color=BEST_COLOUR, zorder=4,
                label="best so far" + (" (on first seeds)" if len(again) else ""))
    if len(again):
        ax.vlines(again["trial"], again["first"], again["value"], color="0.45", linewidth=0.9,
                  zorder=2)
        ax.scatter(again["trial"], again["value"], s=46, facecolors="none", edgecolors="black",
                   linewidths=1.0, zorder=5,
                   label=f"rechecked: over all its seeds ({len(again)})")
    for state, colour, marker in ((Outcome.PRUNED, PRUNED_COLOUR, "|"),
                                  (Outcome.FAILED, FAILED_COLOUR, "x")):
        rows = frame[frame["outcome"] == state]
        if len(rows):
            ax.scatter(rows["trial"], np.full(len(rows), 0.015),
                       transform=ax.get_xaxis_transform(), marker=marker, s=30, color=colour,
                       label=f"{state} trial ({len(rows)})", zorder=2)
    ax.set_xlabel("trial number")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(_objective_label(search))
    ax.margins(y=0.08)
    fig.legend(loc="outside lower center", ncols=3 if len(again) else 4, frameon=False)
    fig.suptitle(_title(search, "optimization history"))
    return save(fig, path)


def importances(search: Search, path: Path) -> Path:
    """Horizontal bars of the PED-ANOVA importances, most important on top."""
    assert search.importances is not None
    items = sorted(search.importances.items(), key=lambda kv: kv[1])
    fig, (ax,) = new_figure((SINGLE[0], 1.2 + 0.45 * len(items)))
    ax.barh([k for k, _ in items], [v for _, v in items], color="#3b6ea8")
    for index, (_, value) in enumerate(items):
        ax.text(value, index, f" {value:.2f}", va="center", fontsize=9)
    ax.set_xlabel("importance (PED-ANOVA, normalised to sum 1)")
    ax.set_xlim(0, max(1e-9, max(v for _, v in items)) * 1.18)
    ax.grid(axis="y", visible=False)
    fig.suptitle(_title(search, "parameter importances"))
    return save(fig, path)


def _positions(values: np.ndarray | list[object],
               distribution: BaseDistribution | None) -> tuple[np.ndarray, list[str] | None]:
    if isinstance(distribution, CategoricalDistribution):
        choices = [str(c) for c in distribution.choices]
        return np.array([choices.index(str(v)) if str(v) in choices else np.nan
                         for v in values], dtype=float), choices
    return np.asarray(values, dtype=float), None


def slices(search: Search, path: Path) -> Path:
    """Objective against each parameter, coloured by trial number."""
    done = search.trials[search.trials["outcome"] == Outcome.COMPLETE]
    count = len(search.params)
    ncols = min(3, count)
    nrows = math.ceil(count / ncols)
    fig, _ = new_figure((min(3.4 * ncols + 1.2, 12.0), 2.9 * nrows + 0.8))
    fig.clear()
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    norm = Normalize(vmin=0, vmax=max(1, int(search.trials["trial"].max() or 1)))
    mappable = None
    for index, name in enumerate(search.params):
        ax: Axes = axes[index // ncols][index % ncols]
        distribution = search.distributions.get(name)
        x, choices = _positions(done[name].tolist(), distribution)
        if choices is not None:
            x = x + np.random.default_rng(index).uniform(-0.15, 0.15, len(x))
            ax.set_xticks(range(len(choices)), choices)
            ax.set_xlim(-0.5, len(choices) - 0.5)
        elif is_log(distribution):
            ax.set_xscale("log")
        mappable = ax.scatter(x, done["value"], c=done["trial"], cmap=CMAP, norm=norm, s=16,
                              alpha=0.8, linewidths=0)
        ax.set_xlabel(name)
        if index % ncols == 0:
            ax.set_ylabel(_objective_label(search))
    for index in range(count, nrows * ncols):
        axes[index // ncols][index % ncols].set_visible(False)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes, label="trial number", shrink=0.9)
    fig.suptitle(_title(search, "objective against each parameter"))
    return save(fig, path)


def reported(search: Search, trial: FrozenTrial) -> dict[int, float]:
    """The values a trial reported at its checkpoints; a recheck's are those of the attempt
    it rechecked (the trial's first seeds), as a recheck reports none of its own."""
    original = search.data.rechecked.get(trial.number)
    if not trial.intermediate_values and original is not None:
        return dict(original.intermediate_values)
    return dict(trial.intermediate_values)


def intermediate(search: Search, path: Path) -> Path:
    """Reported values against steps; pruned trials end where they were stopped."""
    fig, (ax,) = new_figure(SINGLE)
    best = search.best
    groups: dict[str, list[np.ndarray]] = {Outcome.COMPLETE: [], Outcome.PRUNED: []}
    ends = []
    states = dict(zip(search.trials["number"], search.trials["outcome"], strict=True))
    for trial in search.data.trials:
        state = states[trial.number]
        values = reported(search, trial)
        if state not in groups or not values:
            continue
        line = np.array([[s, values[s]] for s in sorted(values)], dtype=float)
        groups[state].append(line)
        if state == Outcome.PRUNED:
            ends.append(line[-1])
    ax.add_collection(LineCollection(groups[Outcome.COMPLETE], colors="#3b6ea8", alpha=0.35,
                                     linewidths=1.0))
    ax.add_collection(LineCollection(groups[Outcome.PRUNED], colors=PRUNED_COLOUR, alpha=0.6,
                                     linewidths=1.0))
    if ends:
        end = np.array(ends)
        ax.scatter(end[:, 0], end[:, 1], marker="x", color=PRUNED_COLOUR, s=22, zorder=3)
    handles = [Line2D([], [], color="#3b6ea8", alpha=0.6,
                      label=f"complete ({len(groups['complete'])})"),
               Line2D([], [], color=PRUNED_COLOUR, marker="x",
                      label=f"pruned ({len(groups['pruned'])}), x = stopped")]
    values = reported(search, best) if best is not None else {}
    if best is not None and values:
        ax.plot(sorted(values), [values[s] for s in sorted(values)], color=BEST_COLOUR,
                linewidth=2.2, zorder=4)
        handles.append(Line2D([], [], color=BEST_COLOUR, linewidth=2.2,
                              label=f"best trial ({known_number(best)})"))
    ax.autoscale_view()
    if search.data.kind == StudyKind.SEARCH:
        ax.set_xlabel("environment steps")
        ax.xaxis.set_major_formatter(STEPS_FORMATTER)
        ax.set_ylabel("final score of each seed" if seed_scores(search)
                      else "mean episode reward at checkpoint")
    else:
        ax.set_xlabel("step")
        ax.set_ylabel("intermediate value")
    ax.legend(handles=handles, loc="best", frameon=False)
    fig.suptitle(_title(search, "intermediate values"))
    return save(fig, path)


def seed_scores(search: Search) -> bool:
    """Whether a search's intermediate values are its seeds' scores (the wilcoxon pruner's),
    not rewards at checkpoints within the first seed."""
    return search.data.definition.get("search", {}).get("pruner") == "wilcoxon"


def _normalised(search: Search, name: str, values: list[object]) -> tuple[np.ndarray, list[str]]:
    distribution = search.distributions.get(name)
    x, choices = _positions(values, distribution)
    if choices is not None:
        return x / max(1, len(choices) - 1), choices
    low, high = getattr(distribution, "low", np.nanmin(x)), getattr(distribution, "high",
                                                                     np.nanmax(x))
    if is_log(distribution):
        x, low, high = np.log10(x), math.log10(low), math.log10(high)
        labels = [f"{10 ** low:.3g}", f"{10 ** high:.3g}"]
    else:
        labels = [f"{low:.4g}", f"{high:.4g}"]
    span = (high - low) or 1.0
    return (x - low) / span, labels


def parallel(search: Search, path: Path) -> Path:
    """Each complete trial as a line across the parameter axes and the objective."""
    done = search.trials[search.trials["outcome"] == Outcome.COMPLETE].sort_values(
        "value", ascending=search.maximize)
    names = [*search.params, "objective"]
    fig, (ax,) = new_figure((min(12.0, max(WIDE[0] * 0.8, 1.1 * len(names) + 1.5)), WIDE[1]))
    columns, labels = [], []
    for name in search.params:
        column, label = _normalised(search, name, done[name].tolist())
        columns.append(column)
        labels.append(label)
    objective = numeric_array(done["value"])
    low, high = (np.nanmin(objective), np.nanmax(objective)) if len(objective) else (0.0, 1.0)
    columns.append((objective - low) / ((high - low) or 1.0))
    labels.append([f"{low:.3g}", f"{high:.3g}"])
    ys = np.column_stack(columns) if columns else np.zeros((0, 0))
    xs = np.arange(len(names), dtype=float)
    segments = [np.column_stack([xs, row]) for row in ys]
    norm = Normalize(vmin=low, vmax=high if high > low else low + 1)
    lines = LineCollection(segments, cmap=CMAP, norm=norm, linewidths=1.1, alpha=0.75)
    lines.set_array(objective)
    ax.add_collection(lines)
    for x, label in zip(xs, labels, strict=True):
        ax.axvline(x, color="black", linewidth=0.8)
        box = {"facecolor": "white", "edgecolor": "none", "pad": 1.0}
        if len(label) == 2:
            ax.text(x, -0.04, label[0], ha="center", va="top", fontsize=8.5, bbox=box)
            ax.text(x, 1.04, label[1], ha="center", va="bottom", fontsize=8.5, bbox=box)
        else:
            for index, text in enumerate(label):
                short = text if len(text) <= 13 else text[:12] + "\u2026"  # keep off next axis
                ax.text(x + 0.04, index / max(1, len(label) - 1), short, fontsize=8.5,
                        va="center", bbox=box)
    ax.set_xticks(xs, names, fontsize=9 if len(names) > 7 else None)
    ax.set_xlim(-0.3, len(names) - 0.7)
    ax.set_ylim(-0.12, 1.12)
    ax.set_yticks([])
    ax.grid(False)
    for side in ("left", "bottom"):
        ax.spines[side].set_visible(False)
    ax.tick_params(axis="x", length=0, pad=14)
    fig.colorbar(lines, ax=ax, label=_objective_label(search), shrink=0.9)
    fig.suptitle(_title(search, f"parallel coordinates of {len(done)} complete trials"))
    return save(fig, path)


def pareto(search: Search, path: Path) -> Path:
    """A two-objective search's trials, mean final score against mean cost (CPU s per seed):
    (a) every complete trial, (b) a zoom on the front and the enqueued configurations. Both
    panels join the front as a staircase, mark the enqueued configurations, draw the floor
    (the score below which a trial is infeasible, off the front) when the search has one, and
    ring the selected trial; (b) labels the front's trials by number and the enqueued ones by
    name."""
    assert search.front is not None
    fig, (whole, zoom) = new_figure(WIDE, ncols=2)
    done = search.trials[search.trials["outcome"] == Outcome.COMPLETE]
    queued = done[done["enqueued"].astype(str) != ""]
    _draw_front(whole, search, done, queued, labels=False)
    _draw_front(zoom, search, done, queued, labels=True)
    whole.set_title("(a) every complete trial", loc="left")
    zoom.set_title("(b) the front (zoom)", loc="left")
    xs = [p.cost for p in search.front.front] + [float(c) for c in queued["cost"]]
    ys = [p.score for p in search.front.front] + [float(v) for v in queued["value"]]
    x_pad = max(0.15 * (max(xs) - min(xs)), 0.02 * max(abs(x) for x in xs), 1e-9)
    y_pad = max(0.15 * (max(ys) - min(ys)), 0.02 * max(abs(y) for y in ys), 1e-9)
    zoom.set_xlim(min(xs) - x_pad, max(xs) + x_pad)
    zoom.set_ylim(min(ys) - y_pad, max(ys) + y_pad)
    for ax in (whole, zoom):
        ax.set_xlabel("cost: mean CPU seconds per seed")
    whole.set_ylabel(_objective_label(search))
    whole.margins(x=0.08, y=0.1)
    handles, names = whole.get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncols=2, frameon=False)
    fig.suptitle(_title(search, "score against cost, the front"))
    return save(fig, path)


def _draw_front(ax: Axes, search: Search, done: pd.DataFrame, queued: pd.DataFrame,
                labels: bool) -> None:
    """One panel of [`pareto`][kraby_study.report.search_plots.pareto]: the complete trials
    (``done``), the front, the enqueued ones among them (``queued``) and the selected trial."""
    assert search.front is not None
    on_front = {p.key for p in search.front.front}
    others = done[~done["trial"].isin(on_front)]
    ax.scatter(others["cost"], others["value"], s=18, color="#3b6ea8", alpha=0.55,
               linewidths=0, label=f"complete trial ({len(done)})", zorder=2)
    front = search.front.front
    xs = [p.cost for p in front]
    ys = [p.score for p in front]
    ax.step(xs, ys, where="post", color=BEST_COLOUR, linewidth=1.4, zorder=3)
    ax.scatter(xs, ys, s=30, color=BEST_COLOUR, zorder=4,
               label=f"front ({len(front)}), joined as a staircase")
    if labels:
        for index, point in enumerate(front):
            # Alternately above and below: neighbours on the front are often close.
            ax.annotate(str(point.key), (point.cost, point.score), textcoords="offset points",
                        xytext=(5, 5 if index % 2 == 0 else -12), fontsize=8.5,
                        color=BEST_COLOUR)
    if len(queued):
        names = ", ".join(str(n) for n in queued["enqueued"])
        ax.scatter(queued["cost"], queued["value"], s=95, marker="D", facecolors="none",
                   edgecolors="black", linewidths=1.0, zorder=5,
                   label=f"enqueued ({names})")
        if labels:
            for _, row in queued.iterrows():
                ax.annotate(str(row["enqueued"]), (row["cost"], row["value"]),
                            textcoords="offset points", xytext=(8, -3), ha="left",
                            fontsize=8, color="black")
    if search.front.floor_score is not None:
        ax.axhline(search.front.floor_score, color="0.35", linestyle="--", linewidth=1.0,
                   zorder=1, label=f"floor: ppo={search.front.floor}'s score (below: "
                                   "infeasible, off the front)")
    choice = search.front.choice
    if choice is not None:
        ax.scatter([choice.chosen.cost], [choice.chosen.score], s=260, marker="*",
                   facecolors="none", edgecolors="#2e8b57", linewidths=1.4, zorder=6,
                   label=f"selected: trial {choice.chosen.key}"
                         + (f" ({choice.rule})" if choice.tested else " (best score, untested)"))
