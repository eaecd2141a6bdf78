"""The measured coverage of the report's 95 % intervals at few seeds, read from data.

``coverage.csv`` beside this module is written by ``benchmarks/bench_error_rates.py
--write-coverage`` (columns interval, distribution, n, coverage, simulations): every number a
report prints about coverage comes from that measured table, none is typed by hand.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

COVERAGE_PATH = Path(__file__).with_name("coverage.csv")
FEW_SEEDS = 5
"""Intervals from fewer seeds than this are printed with their measured coverage."""


@functools.lru_cache(maxsize=1)
def coverage_table() -> pd.DataFrame:
    """The measured coverage table (empty, with its columns, when the file is missing)."""
    if not COVERAGE_PATH.exists():
        return pd.DataFrame(columns=["interval", "distribution", "n", "coverage",
                                     "simulations"])
    return pd.read_csv(COVERAGE_PATH)


LOW = 0.93
"""From [`FEW_SEEDS`][kraby_study.decision.coverage.FEW_SEEDS] seeds on, a measured coverage below
this is printed beside the intervals drawn from that many seeds (strongly skewed data: lognormal
sigma 1, a failing seed)."""


def _cells(at_n: pd.DataFrame) -> str:
    cells = []
    for interval, group in at_n.groupby("interval", sort=False):
        found = ", ".join(f"{r.coverage:.3f} {r.distribution}"
                          for r in group.itertuples(index=False))
        cells.append(f"{interval} {found}")
    return "; ".join(cells)


def coverage_note(ns: Iterable[int]) -> str | None:
    """One sentence giving the measured coverage, per interval and distribution, of the
    intervals drawn from each of ``ns`` seeds: every measured row below
    [`FEW_SEEDS`][kraby_study.decision.coverage.FEW_SEEDS], and from it on the rows below
    [`LOW`][kraby_study.decision.coverage.LOW]; None when there is none (or nothing was measured at
    those n)."""
    counts = sorted({int(n) for n in ns if int(n) >= 2})
    table = coverage_table()
    few = table[table["n"].isin([n for n in counts if n < FEW_SEEDS])]
    low = table[table["n"].isin([n for n in counts if n >= FEW_SEEDS])
                & (table["coverage"] < LOW)]
    if few.empty and low.empty:
        return None
    parts = []
    for n, at_n in pd.concat([few, low]).groupby("n", sort=True):
        simulations = int(at_n["simulations"].min())
        parts.append(f"At n = {n} (at least {simulations:,} simulations): {_cells(at_n)}")
    return ("Some 95 % intervals here are drawn from fewer than 5 seeds, or from seeds where "
            "skewed data were measured to be covered less than 93 % of the time; they may "
            "cover the truth less often than 95 %. Their measured coverage "
            "(benchmarks/bench_error_rates.py, kraby_study/coverage.csv) on normal and skewed "
            "data. " + ". ".join(parts) + ".")
