"""The report's metrics per value, its verdict and its three comparison figures, checked
against hand computations on a store of hand-made curves and scores."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from conftest import csv_approx, hall_bounds, newcombe_bounds, sqlite_url
from optuna.distributions import CategoricalDistribution
from optuna.trial import TrialState, create_trial
from scipy import stats
from synthetic import Run, add_sweep, add_trials, write_curves

from kraby_study.records.attributes import StudyAttrs, TrialAttrs
from kraby_study.records.stored import Outcome
from kraby_study.report import ReportIndex, write_report
from kraby_study.store.store import Store

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
NEW_FIGURES = ["sample_efficiency", "time_to_threshold", "improvement"]
BOOTSTRAP = 1000
"""report.bootstrap of the fixture's report: resamples of the bootstrap-t interval of a mean
(every value here has fewer than 5 seeds, so Hall's interval is printed)."""
STEPS = (100, 200, 300, 400)

# learning_rate: final scores per value; 0.01 is the best (mean 5.5).
FINALS = {0.001: [1.0, 2.0, 3.0, 10.0], 0.01: [4.0, 5.0, 6.0, 7.0], 0.1: [0.5],
          0.3: [2.8, 3.0, 3.2]}
WALL = {0.001: 4.0, 0.01: 12.0, 0.1: 4.0, 0.3: 8.0}
"""Training time of every seed of a value; curve point i is at (i + 1) / 4 of it."""
FAILED_CURVE = [(100, 50.0, 1.0), (200, 60.0, 2.0)]
"""The failed run's curve: counted anywhere, it would move the untrained reward."""


def _rewards(value: float, final: float) -> list[float]:
    """Hand-made curves, every one starting at 0 (so the untrained reward is 0). 0.3 learns
    early (twice its final score from the second point on), the others climb to their final
    score."""
    if value == 0.3:
        return [0.0, 2 * final, 2 * final, final]
    return [0.0, final / 2, final, final]


def _curve(value: float, final: float) -> list[tuple[int, float, float]]:
    wall = WALL[value]
    return [(step, reward, wall * (i + 1) / 4)
            for i, (step, reward) in enumerate(zip(STEPS, _rewards(value, final), strict=True))]


def _add_confirm(store: Store) -> None:
    """A confirm study as the confirm command stores it: labels as values (given in an order
    that sorting would change), the search's winner t12 losing to t7 on fresh seeds."""
    labels = ["tuned", "t7", "t12"]
    cpu = {"tuned": 2.0, "t7": 6.0, "t12": 3.0}  # CPU seconds per run; each run's wall is 4 s
    finals = {"tuned": [-0.05, -0.06, -0.04], "t7": [-0.010, -0.012, -0.011],
              "t12": [-0.03, -0.028, -0.032]}
    arms = [{"label": "tuned", "source_score": None, "origin": "ppo config 'tuned'"},
            {"label": "t7", "source_score": -0.0201, "origin": "trial 7 of search 'ppo_search'"},
            {"label": "t12", "source_score": -0.0123,
             "origin": "trial 12 of search 'ppo_search'"}]
    definition = {"kind": "confirm", "parameter": "config", "values": labels,
                  "source": "ppo_search", "source_winner": "t12", "arms": arms,
                  "steps": 400, "curve_every": 100}
    ledger = store.define("confirm_ppo_search", StudyAttrs(
        kind="confirm", definition=definition, fingerprint="x", planned=9))
    distribution = CategoricalDistribution(labels)
    curves = {}
    number = 0
    for vi, label in enumerate(labels):
        for seed, final in enumerate(finals[label]):
            attrs = TrialAttrs(key=f"v{vi}-s{seed}", seed=100 + seed, final_score=final,
                               wall_time=4.0, cpu_time=cpu[label] + seed, env_steps=400)
            add_trials(store, ledger.name, [create_trial(
                state=TrialState.COMPLETE, value=final, params={"config": label},
                distributions={"config": distribution}, user_attrs=attrs.stored())])
            curves[number] = [(s, final * (1 + 4 / s), s / 100) for s in STEPS]
            number += 1
    write_curves(ledger, curves)


@pytest.fixture(scope="module")
def store_url(tmp_path_factory: pytest.TempPathFactory) -> str:
    """learning_rate: 4 values with hand-made curves, one failed run, one value with a single
    complete seed; a sweep with no complete run; a confirm study."""
    url = sqlite_url(tmp_path_factory.mktemp("metrics") / "k.db")
    store = Store(url)
    try:
        runs = [Run(value=value, seed=seed, final_score=final, wall_time=WALL[value],
                    curve=_curve(value, final))
                for value, finals in FINALS.items() for seed, final in enumerate(finals)]
        runs.append(Run(value=0.001, seed=4, outcome=Outcome.FAILED, wall_time=2.0,
                        failure="diverged: ValueError: nan in the actions", curve=FAILED_CURVE))
        add_sweep(store, "learning_rate", "ppo.learning_rate", list(FINALS), runs, steps=400,
                  curve_every=100)
        add_sweep(store, "waiting", "ppo.gamma", [0.9, 0.99],
                  [Run(value=v, seed=0, outcome=Outcome.PENDING) for v in (0.9, 0.99)])
        _add_confirm(store)
    finally:
        store.close()
    return url


@pytest.fixture(scope="module")
def report(store_url: str, tmp_path_factory: pytest.TempPathFactory) -> ReportIndex:
    options = SimpleNamespace(bootstrap=BOOTSTRAP, threshold=None)
    return write_report(store_url, tmp_path_factory.mktemp("out"), policy=False, options=options)


def _summary(out: Path, study: str = "learning_rate") -> pd.DataFrame:
    return pd.read_csv(out / study / "summary.csv", keep_default_na=False,
                       na_values=[""]).set_index("value")


def test_iqm_iqr_and_the_failed_run(report: ReportIndex) -> None:
    summary = _summary(report.out)
    low = summary.loc[0.001]
    assert (low["complete"], low["failed"]) == (4, 1)
    assert low["iqm"] == csv_approx(2.5)  # middle half of 1, 2, 3, 10
    # Tukey-McLaughlin: g = 1, winsorised [2, 2, 3, 3] (sd sqrt(1/3)), se = sd / (0.5 * 2),
    # t(0.975, 4 - 2 - 1 = 1) = 12.706.
    half = stats.t.ppf(0.975, 1) * math.sqrt(1 / 3) / (0.5 * 2)
    assert (low["iqm_low"], low["iqm_high"]) == csv_approx((2.5 - half, 2.5 + half))
    assert low["iqm_low"] <= 2.5 <= low["iqm_high"]
    assert low["final_iqr"] == csv_approx(4.75 - 1.75)  # linear quartiles
    best = summary.loc[0.01]
    assert best["iqm"] == csv_approx(5.5) and best["final_iqr"] == csv_approx(1.5)
    assert summary.loc[0.3, "final_iqr"] == csv_approx(0.2)
    # The failed run is listed, and nowhere in the metrics.
    text = (report.out / "learning_rate" / "summary.md").read_text()
    assert "learning_rate = 0.001, seed 4 (trial 12): diverged" in text


def test_auc_is_the_mean_of_each_seed_curve(report: ReportIndex) -> None:
    summary = _summary(report.out)
    for value, finals in FINALS.items():
        aucs = [float(np.mean(_rewards(value, f))) for f in finals]
        row = summary.loc[value]
        assert row["auc_mean"] == pytest.approx(np.mean(aucs), rel=1e-5)
        if len(aucs) > 1:
            _, low, high = hall_bounds(aucs)
            assert (row["auc_low"], row["auc_high"]) == pytest.approx((low, high), rel=1e-5)
    assert summary.loc[0.3, "auc_mean"] == csv_approx(1.25 * 3.0)


def test_curve_bands_are_hall_intervals_per_value_and_step() -> None:
    from kraby_study.decision.summary import curve_bands

    rewards = {(0, 100): [1.0, 2.0, 3.0, 10.0], (0, 200): [4.0, 4.0, 4.0, 4.0],
               (1, 100): [0.5], (1, 200): [2.0, 4.0, 9.0]}
    curves = pd.DataFrame([(vi, step, r, 1.0) for (vi, step), rs in rewards.items() for r in rs],
                          columns=["value_index", "step", "mean_reward", "wall_time"])
    bands = curve_bands(curves).set_index(["value_index", "step"])
    for key, values in rewards.items():
        row = bands.loc[key]
        assert row["n"] == len(values) and row["wall_time"] == 1.0
        if len(values) < 2:
            assert math.isnan(row["low"]) and math.isnan(row["high"])
        elif np.ptp(values) == 0:
            assert (row["low"], row["high"]) == (values[0], values[0])
        else:
            assert (row["mean"], row["low"], row["high"]) == pytest.approx(hall_bounds(values))


def test_default_threshold_reached_and_never_reached(report: ReportIndex) -> None:
    summary = _summary(report.out)
    # Untrained: every complete seed's first point is 0 (the failed run's 50 does not count);
    # 90 % of the way to the best mean final score 5.5.
    threshold = 0.0 + 0.9 * 5.5
    expected, censored = {}, {}
    for value, finals in FINALS.items():
        hits, times = [], []
        for final in finals:
            curve = _curve(value, final)
            first = next(((s, t) for s, r, t in curve if r >= threshold), None)
            if first:
                hits.append(first)
            # A seed that never reached the threshold counts at its curve's last point.
            times.append(first or (curve[-1][0], curve[-1][2]))
        expected[value], censored[value] = hits, times
    assert [len(expected[v]) for v in FINALS] == [1, 3, 0, 3]
    for value, hits in expected.items():
        row = summary.loc[value]
        assert row["reached"] == len(hits)
        if hits:
            times = censored[value]
            assert row["steps_to_threshold"] == csv_approx(np.mean([s for s, _ in times]))
            assert row["seconds_to_threshold"] == csv_approx(np.mean([t for _, t in times]))
        else:
            assert math.isnan(row["steps_to_threshold"])
            assert math.isnan(row["seconds_to_threshold"])
    text = (report.out / "learning_rate" / "summary.md").read_text()
    assert "mean episode reward >= 4.95, the default" in text
    assert "- Fastest to threshold: " in text and "reached it, lowest restricted mean" in text


def test_a_single_seed_has_no_intervals(report: ReportIndex) -> None:
    row = _summary(report.out).loc[0.1]
    assert row["complete"] == 1
    assert row["iqm"] == csv_approx(0.5) and row["auc_mean"] == csv_approx(0.3125)
    for column in ("iqm_low", "iqm_high", "auc_low", "auc_high", "final_iqr", "p_worse",
                   "p_equivalent", "p_improvement_low", "p_improvement_high"):
        assert math.isnan(row[column]), column
    assert row["p_improvement"] == csv_approx(1.0)  # every best seed beats 0.5
    assert row["answer"] == "left out"  # one seed: in no comparison


def test_answers_and_probability_of_improvement(report: ReportIndex) -> None:
    summary = _summary(report.out)
    best = FINALS[0.01]
    # 0.01 has the highest IQM; 0.001 and 0.3 are compared with it at 4 and 3 seeds (0.3 has
    # fewer than 4: undecided by rule); 0.1 has one seed, fewer than report.min_seeds.
    assert list(summary["answer"]) == ["undecided", "best", "left out", "undecided"]
    for value in (0.001, 0.3):
        pairs = [(b > y) + 0.5 * (b == y) for b in best for y in FINALS[value]]
        row = summary.loc[value]
        assert row["p_improvement"] == csv_approx(np.mean(pairs))
        assert row["p_improvement_low"] <= row["p_improvement"] <= row["p_improvement_high"]
    # Newcombe's interval (method 5), from the roots of its quartic: 4 seeds against 4 at
    # 0.75; every seed of the best beats every seed of 0.3 (4 against 3): up to 1, not a point.
    assert (summary.loc[0.001, "p_improvement_low"],
            summary.loc[0.001, "p_improvement_high"]) == pytest.approx(
        newcombe_bounds(0.75, 4, 4), abs=1e-6)  # 6 significant digits: 5e-7 at most below 1
    assert (summary.loc[0.3, "p_improvement_low"],
            summary.loc[0.3, "p_improvement_high"]) == pytest.approx(
        newcombe_bounds(1.0, 4, 3), abs=1e-6)
    assert summary.loc[0.3, "p_improvement_low"] < 1.0 == summary.loc[0.3, "p_improvement_high"]
    assert summary.loc[0.001, "p_improvement"] == csv_approx(0.75)
    assert summary.loc[0.3, "p_improvement"] == csv_approx(1.0)
    assert math.isnan(summary.loc[0.01, "p_improvement"])
    text = (report.out / "learning_rate" / "summary.md").read_text()
    assert "Welch" not in text and "closed Holm step-down against the margin" in text
    assert "percentile bootstrap of the IQM contrast" in text and "P(best > value)" in text
    assert text.count("95 % Newcombe score-type interval (Newcombe 2006, method 5)") == 1
    assert "BCa" not in text  # P(improvement) and the IQM do not bootstrap any more
    assert "bootstrap-t) interval (1,000 resamples" in text  # report.bootstrap
    assert "no correction for multiple comparisons" not in report.markdown.read_text()


def test_verdict_sentence(report: ReportIndex) -> None:
    expected = ("- Best: 0.01, IQM final score 5.5 (95 % CI [",
                "n=4; mean 5.5).\n- Equivalent (within the margin of the best, 1.1 in score "
                "units): none.\n- Worse (below the best by more than the margin): none."
                "\n- Undecided (neither shown equivalent nor worse): 0.001, 0.3.\n",
                "Warning: the margin 1.1 is below what these seeds resolve",
                "- Most sample-efficient: 0.3 (AUC 3.75, 95 % CI [",
                "- Fastest to threshold: ",
                "- Most repeatable: 0.3 (rescaled final IQR ",
                "- Left out of the best and every answer: 0.1 (1 complete seed, fewer than "
                "report.min_seeds = 2).")
    summary_md = (report.out / "learning_rate" / "summary.md").read_text()
    index = report.markdown.read_text()
    for part in expected:
        assert part in summary_md and part in index, part
    verdict = summary_md.split("\n\n")[1]  # the block under the title: six lines at most
    assert verdict.startswith("- Best: 0.01") and len(verdict.splitlines()) <= 6
    waiting = (report.out / "waiting" / "summary.md").read_text()
    assert "No run is complete yet" in waiting


def test_three_figures_are_drawn_and_listed(report: ReportIndex) -> None:
    index = report.markdown.read_text()
    for stem in NEW_FIGURES:
        png = report.out / "learning_rate" / f"{stem}.png"
        assert png.read_bytes()[:8] == PNG_MAGIC and png.stat().st_size > 10_000
        assert f"(learning_rate/{stem}.png)" in index
    assert not list((report.out / "waiting").glob("*.png"))


def test_confirm_study(report: ReportIndex) -> None:
    summary = pd.read_csv(report.out / "confirm_ppo_search" / "summary.csv")
    assert summary["value"].tolist() == ["tuned", "t7", "t12"]  # the order given, not sorted
    assert summary["answer"].fillna("").tolist()[1] == "best"
    winner = ("ppo_search's winner t12 is not the confirmed winner: t7 has the best IQM final "
              "score on 3 fresh seeds.")
    text = (report.out / "confirm_ppo_search" / "summary.md").read_text()
    index = report.markdown.read_text()
    assert winner in text and winner in index
    assert "- Best: t7, IQM final score -0.011" in text
    mean, low, high = hall_bounds([-0.010, -0.012, -0.011])
    arms = text.split("| configuration | origin |")[1]  # the configurations' table
    row = next(line for line in arms.splitlines() if line.startswith("| t12 |"))
    assert "trial 12 of search 'ppo_search'" in row and "-0.0123" in row
    row = next(line for line in arms.splitlines() if line.startswith("| t7 |"))
    assert f"| -0.0201 | {mean:.4g} | [{low:.4g}, {high:.4g}] |" in row
    assert row.endswith("| 3 |")
    assert "| configuration | origin | source's score |" in index
    # A confirm's training time is the CPU seconds its fastest_tied compares, and says so; a
    # sweep's is wall-clock seconds.
    assert summary["time_mean"].tolist() == csv_approx([3.0, 7.0, 4.0])
    assert "time_high): CPU seconds per run." in text
    sweep_text = (report.out / "learning_rate" / "summary.md").read_text()
    assert "time_high): wall-clock seconds per run." in sweep_text


def test_threshold_option_changes_reach(store_url: str, report: ReportIndex,
                                        tmp_path: Path) -> None:
    options = SimpleNamespace(bootstrap=BOOTSTRAP, threshold=1.0)
    index = write_report(store_url, tmp_path / "r", study="learning_rate", policy=False,
                         options=options)
    summary = _summary(index.out)
    default = _summary(report.out)
    # Reward >= 1: 0.01 at its second point (200) in every seed; 0.001 at 300 for the seed
    # whose final score is 1, at 200 for the others; 0.1 (0, 0.25, 0.5, 0.5) never.
    assert summary.loc[0.01, "reached"] == 4 and default.loc[0.01, "reached"] == 3
    assert summary.loc[0.01, "steps_to_threshold"] == csv_approx(200)
    assert summary.loc[0.001, "reached"] == 4
    assert summary.loc[0.001, "steps_to_threshold"] == csv_approx((300 + 3 * 200) / 4)
    assert summary.loc[0.1, "reached"] == 0
    assert "mean episode reward >= 1, set by the report's option report.threshold" in (
        index.out / "learning_rate" / "summary.md").read_text()


def test_summary_intervals_are_bootstrap_t_from_five_seeds() -> None:
    # Value "six": 6 complete seeds (right-skewed scores, times and AUCs): the bootstrap-t
    # interval with report.bootstrap resamples. Value "three": 3 seeds, Hall's interval.
    from kraby_study.decision.comparison import compare
    from kraby_study.decision.intervals import bootstrap_t_interval
    from kraby_study.decision.summary import SEED_COLUMNS, add_curve_metrics, summarise

    finals = {0: [1.0, 1.5, 2.0, 2.5, 3.0, 9.0], 1: [2.0, 4.0, 9.0]}
    times = {0: [10.0, 11.0, 12.0, 13.0, 15.0, 30.0], 1: [20.0, 20.0, 26.0]}
    trials = pd.DataFrame(
        [(10 * vi + i, f"k{vi}{i}", i, vi, vi, Outcome.COMPLETE, score,
          times[vi][i], 1000.0, "", None)
         for vi, scores in finals.items() for i, score in enumerate(scores)],
        columns=["number", "key", "seed", "value_index", "value", "outcome", "final_score",
                 "wall_time", "env_steps", "failure", "model_path"])
    summary = summarise(trials, ["six", "three"], compare(finals, 0.2), bootstrap=500)
    for column, samples in (("final", finals), ("time", times)):
        assert (summary.loc[0, f"{column}_low"], summary.loc[0, f"{column}_high"]) == (
            pytest.approx(bootstrap_t_interval(samples[0], resamples=500), rel=1e-12))
        assert (summary.loc[1, f"{column}_low"], summary.loc[1, f"{column}_high"]) == (
            pytest.approx(hall_bounds(samples[1])[1:], rel=1e-9))
    aucs = {0: [0.5, 0.7, 0.6, 0.8, 0.9, 3.0], 1: [1.0, 2.0, 4.0]}
    seeds = pd.DataFrame([(vi, i, 10 * vi + i, finals[vi][i], 0.0, a, np.nan, np.nan, 400.0,
                           10.0) for vi, values in aucs.items() for i, a in enumerate(values)],
                         columns=SEED_COLUMNS)
    metrics = add_curve_metrics(summary, seeds, bootstrap=500)
    assert (metrics.loc[0, "auc_low"], metrics.loc[0, "auc_high"]) == pytest.approx(
        bootstrap_t_interval(aucs[0], resamples=500), rel=1e-12)
    assert (metrics.loc[1, "auc_low"], metrics.loc[1, "auc_high"]) == pytest.approx(
        hall_bounds(aucs[1])[1:], rel=1e-9)


def test_a_value_no_test_reaches_has_no_p_and_says_why() -> None:
    # "three" has 3 seeds, far below the best: no pair with it is tested, so it is undecided
    # with empty p's and a note; "six", as far below on 6 seeds, is tested and worse.
    from kraby_study.decision.comparison import compare
    from kraby_study.decision.summary import summarise, untested_note

    finals = {0: [-1.0, -1.02, -0.98, -1.01, -0.99, -1.0],
              1: [-5.0, -5.1, -4.9, -5.05, -4.95, -5.0], 2: [-5.0, -5.1, -4.9]}
    trials = pd.DataFrame(
        [(10 * vi + i, f"k{vi}{i}", i, vi, vi, Outcome.COMPLETE, score, 10.0, 1000.0, "", None)
         for vi, scores in finals.items() for i, score in enumerate(scores)],
        columns=["number", "key", "seed", "value_index", "value", "outcome", "final_score",
                 "wall_time", "env_steps", "failure", "model_path"])
    summary = summarise(trials, ["best", "six", "three"], compare(finals, 0.2), bootstrap=200)
    assert list(summary["answer"]) == ["best", "worse", "undecided"]
    assert summary.loc[1, "p_worse"] < 0.05 and summary.loc[1, "note"] == ""
    assert np.isnan(summary.loc[2, "p_worse"]) and np.isnan(summary.loc[2, "p_equivalent"])
    assert summary.loc[2, "note"] == untested_note()
    assert "fewer than 4 seeds" in untested_note()


def test_few_seeds_note_prints_the_measured_coverage(report: ReportIndex) -> None:
    # learning_rate has values of 4, 4, 1 and 3 complete seeds: the summary's notes give the
    # measured coverage (kraby_study/coverage.csv) of every interval at n = 3 and n = 4.
    from kraby_study.decision.coverage import coverage_table

    text = (report.out / "learning_rate" / "summary.md").read_text()
    table = coverage_table()
    mean_rows = table[table["interval"].str.startswith("mean: Hall's t below 5 seeds")]
    assert set(mean_rows["n"]) >= {2, 3, 4, 5, 10}
    for n in (3, 4):
        assert f"At n = {n} (at least 20,000 simulations)" in text
        for row in mean_rows[mean_rows["n"] == n].itertuples(index=False):
            assert f"{row.coverage:.3f} {row.distribution}" in text
    assert "At n = 1 " not in text and "At n = 5 " not in text
