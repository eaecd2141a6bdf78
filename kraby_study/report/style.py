"""One look for every figure: sizes, fonts, colours per value, number formats, saving.

Figures are built on ``matplotlib.figure.Figure`` directly (the Agg canvas, no pyplot), so a
report neither opens windows nor changes the caller's matplotlib state.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from kraby_study.errors import ConfigError
from kraby_study.records.attributes import StudyKind
from kraby_study.records.values import is_numeric

if TYPE_CHECKING:
    from kraby_study.answers.sweep_evidence import Sweep

DPI = 150
WIDE = (10.0, 4.2)
"""Two panels side by side, or one panel and a legend."""
SINGLE = (6.4, 4.2)
"""One panel."""

RC: dict[str, Any] = {
    "font.size": 11,
    "axes.titlesize": 12,
    "axes.labelsize": 11,
    "xtick.labelsize": 10,
    "ytick.labelsize": 10,
    "legend.fontsize": 9.5,
    "legend.title_fontsize": 10,
    "figure.titlesize": 13,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.grid": True,
    "grid.color": "#d9d9d9",
    "grid.linewidth": 0.6,
    "axes.axisbelow": True,
    "lines.linewidth": 1.8,
    "savefig.dpi": DPI,
    "svg.hashsalt": "kraby-study",
}

BEST_COLOUR = "#c0392b"
FAILED_COLOUR = "#c0392b"
MUTED = "#7f7f7f"


@contextmanager
def styled() -> Iterator[None]:
    """Apply the report's matplotlib settings for the figures drawn inside."""
    with matplotlib.rc_context(RC):
        yield


def new_figure(size: tuple[float, float] = SINGLE, ncols: int = 1,
               **kwargs: Any) -> tuple[Figure, list[Axes]]:
    """A figure with ``ncols`` panels in a row, laid out with constrained layout."""
    fig = Figure(figsize=size, layout="constrained")
    axes = fig.subplots(1, ncols, squeeze=False, **kwargs)[0]
    return fig, list(axes)


def save(fig: Figure, path: Path) -> Path:
    """Write a figure (format from the suffix) without timestamps, so reruns are identical."""
    metadata = {"Software": None} if path.suffix == ".png" else {"Date": None}
    fig.savefig(path, dpi=DPI, metadata=metadata)
    fig.clear()
    return path


def value_colours(values: Sequence[Any]) -> list[tuple[float, float, float, float]]:
    """One colour per value, in order: a sequential map for numbers, distinct hues otherwise.

    The same list is used by every figure of a study, so a value keeps its colour.
    """
    count = len(values)
    if is_numeric(values):
        cmap = matplotlib.colormaps["viridis"]
        positions = np.linspace(0.0, 0.88, count) if count > 1 else np.array([0.45])
        return [tuple(cmap(p)) for p in positions]
    cmap = matplotlib.colormaps["tab10" if count <= 10 else "tab20"]
    return [tuple(cmap(i % cmap.N)) for i in range(count)]


def sweep_colours(sweep: Sweep) -> list[tuple[float, float, float, float]]:
    """The colours of a sweep's values (a confirm study's by their labels), the same in every
    figure of the study."""
    return value_colours(sweep.labels if sweep.data.kind == StudyKind.CONFIRM else sweep.values)


def steps_label(value: float, _pos: Any = None) -> str:
    """Environment steps the way a reader counts them: 0, 500, 50k, 1.5M."""
    magnitude = abs(value)
    if magnitude >= 1e6:
        return f"{value / 1e6:g}M"
    if magnitude >= 1e3:
        return f"{value / 1e3:g}k"
    return f"{value:g}"


STEPS_FORMATTER = FuncFormatter(steps_label)


def number(value: float | None, digits: int = 4) -> str:
    """A number for a table cell, with a dash for missing ones."""
    if value is None or not np.isfinite(value):
        return "-"
    return f"{value:.{digits}g}"


def check_format(fmt: str) -> str:
    """The figure format, lower case; ConfigError unless png or svg."""
    value = str(fmt).lower().lstrip(".")
    if value not in ("png", "svg"):
        raise ConfigError(f"report format must be png or svg, got {fmt!r}")
    return value

