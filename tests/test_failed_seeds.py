"""Failed seeds: a seed whose final score lies nearer the untrained score than the best value's
mean, counted per value with an exact interval of the rate, on constructed data."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest
from conftest import sqlite_url
from synthetic import Run, add_sweep

from kraby_study.decision.failed_seeds import failed_seeds, failure_line
from kraby_study.report import write_report
from kraby_study.store.store import Store


def test_the_line_is_halfway_from_untrained_to_the_best() -> None:
    assert failure_line(-4.0, -1.0) == -2.5
    assert failure_line(20.0, 500.0) == 260.0
    # No line when the best learned nothing, or a score is missing.
    assert math.isnan(failure_line(-1.0, -1.0))
    assert math.isnan(failure_line(-1.0, -2.0))
    assert math.isnan(failure_line(math.nan, -2.0))


def test_failed_seeds_are_counted_with_the_clopper_pearson_interval() -> None:
    found = failed_seeds([-1.0, -3.0, -2.6, -2.4, math.nan, -0.5], -2.5)
    assert (found.count, found.seeds) == (2, 5)
    # Clopper-Pearson 95 % for 2 of 5: beta quantiles 0.0527 and 0.8534.
    assert (found.low, found.high) == pytest.approx((0.05274, 0.85337), abs=5e-5)
    assert found.text() == "2 of 5 (rate 95 % CI 0.05-0.85)"
    none = failed_seeds([1.0, 2.0], -2.5)
    assert none.count == 0 and none.low == 0.0 and none.high == pytest.approx(0.8419, abs=1e-4)
    assert failed_seeds([1.0], math.nan).seeds == 0


FIRST = -4.0
"""Every constructed run's first curve point: the untrained score."""
FINALS = {0.1: [-0.5, -0.6, -0.4, -0.5, -3.0],  # best (mean -1.0), one seed failed
          0.2: [-1.2, -3.6, -1.1, -3.0, -1.3],  # two failed
          0.3: [-1.5, -1.4, -1.6, -1.5, -1.5]}  # none


def test_the_report_counts_failed_seeds_and_names_the_selected_ones(tmp_path: Path) -> None:
    url = sqlite_url(tmp_path / "k.db")
    store = Store(url)
    try:
        runs = [Run(value=value, seed=seed, final_score=final,
                    curve=[(100, FIRST, 1.0), (200, final, 2.0)])
                for value, finals in FINALS.items() for seed, final in enumerate(finals)]
        add_sweep(store, "clip", "ppo.clip_range", list(FINALS), runs, steps=200,
                  curve_every=100)
    finally:
        store.close()
    out = tmp_path / "out"
    write_report(url, out, policy=False, options=SimpleNamespace(bootstrap=200, threshold=None))
    summary = pd.read_csv(out / "clip" / "summary.csv").set_index("value")
    # The line: halfway from -4 (every run's first point) to the best's mean -1.0, -2.5.
    assert summary["failed_seeds"].to_dict() == {0.1: 1, 0.2: 2, 0.3: 0}
    assert summary.loc[0.2, "failed_seeds_low"] == pytest.approx(0.0527, abs=1e-3)
    assert summary.loc[0.2, "failed_seeds_high"] == pytest.approx(0.8534, abs=1e-3)
    assert summary.loc[0.1, "selected"]
    text = (out / "clip" / "summary.md").read_text()
    assert "- Failed seeds (final score below -2.5): 0.1 (selected): 1 of 5; 0.2: 2 of 5." \
        in text
    assert "below -2.5, halfway from" in text  # the methods say what a failed seed is
