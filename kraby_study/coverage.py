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


def coverage_note(ns: Iterable[int]) -> str | None:
    """One sentence giving the measured coverage, per interval and distribution, of the
    intervals drawn from each of ``ns`` seeds below :data:`FEW_SEEDS`; None when there is none
    (or nothing was measured at those n)."""
    few = sorted({int(n) for n in ns if 2 <= int(n) < FEW_SEEDS})
    table = coverage_table()
    rows = table[table["n"].isin(few)]
    if rows.empty:
        return None
    parts = []
    for n, at_n in rows.groupby("n", sort=True):
        cells = []
        for interval, group in at_n.groupby("interval", sort=False):
            found = ", ".join(f"{r.coverage:.3f} {r.distribution}"
                              for r in group.itertuples(index=False))
            cells.append(f"{interval} {found}")
        simulations = int(at_n["simulations"].min())
        parts.append(f"At n = {n} (at least {simulations:,} simulations): " + "; ".join(cells))
    return ("Some 95 % intervals here are drawn from fewer than 5 seeds, where they may cover "
            "the truth less often than 95 %. Their measured coverage "
            "(benchmarks/bench_error_rates.py, kraby_study/coverage.csv) on normal and skewed "
            "data. " + ". ".join(parts) + ".")
