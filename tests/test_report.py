"""`kraby-study report`: figures, tables and index pages drawn from a store alone."""

from __future__ import annotations

import math
import re
import sqlite3
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import optuna
import pandas as pd
import pytest
from conftest import csv_approx, hall_bounds, sqlite_url
from optuna.distributions import FloatDistribution
from optuna.trial import TrialState, create_trial
from scipy import stats
from synthetic import (
    RACE_FINALS,
    RACE_RULES,
    RACE_VALUES,
    RACE_WALL,
    VERDICT_VALUES,
    Run,
    add_raced_sweep,
    add_search,
    add_sweep,
    add_trials,
    learning_curve,
    percentile_p,
    race_example_runs,
    verdict_runs,
    write_curves,
    yuen_p,
)

from kraby_study.answers.selected import selection_of, sweep_selection
from kraby_study.decision.comparison import compare
from kraby_study.decision.intervals import hall_interval, t_interval
from kraby_study.decision.selection import select
from kraby_study.errors import ConfigError, StoreError
from kraby_study.plan.spec import RaceRules
from kraby_study.records.attributes import StudyAttrs, TrialAttrs
from kraby_study.records.stored import Outcome
from kraby_study.report import ReportIndex, run_report, sweep_plots, write_report
from kraby_study.store.store import Store, opened

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SWEEP_FIGURES = ["learning_curves", "final_score", "wallclock", "training_time"]
SWEEP_TABLES = ["summary.csv", "summary.md", "trials.csv", "curves.csv", "curves_mean.csv"]
SEARCH_FIGURES = ["history", "importances", "slices", "parallel", "intermediate"]


def _runs(scores: dict[float, list[float | None]], times: dict[float, list[float]],
          steps: int = 4000) -> list[Run]:
    """Runs with known final scores; None is a failed run."""
    rng = np.random.default_rng(0)
    runs = []
    for value, finals in scores.items():
        for seed, (final, wall) in enumerate(zip(finals, times[value], strict=True)):
            if final is None:
                runs.append(Run(value=value, seed=seed, outcome=Outcome.FAILED, wall_time=wall,
                                failure="diverged: ValueError: nan in the actions"))
            else:
                runs.append(Run(value=value, seed=seed, final_score=final, wall_time=wall,
                                curve=learning_curve(final, steps, 40, wall, rng)))
    return runs


@pytest.fixture(scope="module")
def sweep_store(tmp_path_factory: pytest.TempPathFactory) -> str:
    """ent_coef: 2 values x 3 seeds with known scores and one failed run; gamma: 3 values,
    two runs still queued; a single-run (train) study."""
    url = sqlite_url(tmp_path_factory.mktemp("store") / "k.db")
    store = Store(url)
    try:
        add_sweep(store, "ent_coef", "ppo.ent_coef", [0.01, 0.1], _runs(
            {0.01: [1.0, 2.0, 3.0, None], 0.1: [2.0, 4.0, 9.0]},
            {0.01: [10.0, 12.0, 14.0, 3.0], 0.1: [20.0, 20.0, 26.0]}), steps=4000,
            curve_every=100)
        runs = _runs({0.8: [-1.0, -1.2], 0.9: [-0.5, -0.7], 0.95: [-0.6, -0.4]},
                     {0.8: [5.0, 6.0], 0.9: [5.0, 6.0], 0.95: [5.0, 6.0]})
        runs[-1].outcome = Outcome.PENDING
        runs[-2].outcome = Outcome.PENDING
        add_sweep(store, "gamma", "ppo.gamma", [0.8, 0.9, 0.95], runs, steps=4000,
                  curve_every=100)
        _add_train(store)
    finally:
        store.close()
    return url


def _add_train(store: Store) -> None:
    definition = {"kind": "train", "steps": 4000, "curve_every": 100}
    ledger = store.define("train-abc", StudyAttrs(kind="train", definition=definition,
                                                  fingerprint="abc", planned=2))
    rng = np.random.default_rng(1)
    for seed, final in enumerate([-0.5, -0.6]):
        attrs = TrialAttrs(key=f"s{seed}", seed=seed, final_score=final, wall_time=4.0,
                           env_steps=4000)
        add_trials(store, ledger.name, [create_trial(state=TrialState.COMPLETE, value=final,
                                                     user_attrs=attrs.stored())])
    write_curves(ledger, {n: learning_curve(-0.5, 4000, 40, 4.0, rng) for n in (0, 1)})


def _search_store(path: Path, complete: int = 12) -> str:
    """A search made with Optuna's own ask/tell: checkpoints, pruning, one failure."""
    url = sqlite_url(path)
    store = Store(url)
    study = optuna.create_study(study_name="tpe", storage=store.storage, direction="maximize",
                                sampler=optuna.samplers.RandomSampler(seed=0))
    study.set_user_attr("kraby_kind", "search")
    for number in range(complete + 4):
        trial = study.ask()
        lr = trial.suggest_float("learning_rate", 1e-4, 1.0, log=True)
        gamma = trial.suggest_float("gamma", 0.2, 0.9999)
        epochs = trial.suggest_int("n_epochs", 1, 50)
        act = trial.suggest_categorical("activation", ["tanh", "relu"])
        score = -abs(math.log10(lr) + 2) - abs(gamma - 0.8) - 0.01 * epochs - (act == "relu")
        if number == 3:
            trial.set_user_attr("failure", "diverged: NaN loss")
            study.tell(trial, state=TrialState.FAIL)
            continue
        for step in (1000, 2000, 3000, 4000):
            trial.report(score * (2 - step / 4000), step)
            if number % 4 == 1 and step == 2000:
                trial.set_user_attr("pruned_at", step)
                break
        else:
            study.tell(trial, score)
            continue
        study.tell(trial, state=TrialState.PRUNED)
    store.close()
    return url


@pytest.fixture(scope="module")
def sweep_report(sweep_store: str, tmp_path_factory: pytest.TempPathFactory) -> ReportIndex:
    """The report of every study of ``sweep_store``, written once for the tests that read it."""
    return write_report(sweep_store, tmp_path_factory.mktemp("reports"))


def _read_summary(out: Path, study: str) -> pd.DataFrame:
    return pd.read_csv(out / study / "summary.csv", keep_default_na=False,
                       na_values=[""]).set_index("value")


def test_sweep_report_writes_every_file(sweep_report: ReportIndex) -> None:
    index = sweep_report
    out = index.out
    assert [s.name for s in index.studies] == ["ent_coef", "gamma", "train-abc"]
    for study in ("ent_coef", "gamma"):
        for stem in SWEEP_FIGURES:
            png = out / study / f"{stem}.png"
            assert png.read_bytes()[:8] == PNG_MAGIC and png.stat().st_size > 10_000
        for name in SWEEP_TABLES:
            assert (out / study / name).stat().st_size > 0
        # Scored by the training reward: no second column of it.
        assert "training reward" not in (out / study / "summary.md").read_text()
        assert "train_mean" not in _read_summary(out, study)
    # A single-run study has no value axis: curves, final score and wall-clock only.
    assert sorted(p.name for p in (out / "train-abc").glob("*.png")) == [
        "final_score.png", "learning_curves.png", "wallclock.png"]
    markdown = (out / "index.md").read_text()
    html = (out / "index.html").read_text()
    for path in index.files[2:]:
        link = f"{path.parent.name}/{path.name}"
        assert f"({link})" in markdown and f'href="{link}"' in html
    assert all(path.exists() for path in index.files)
    # No model was saved, and the index says so instead of showing an animation.
    assert "no policy animation" in markdown and not list(out.rglob("*.gif"))
    # The summary table is inline in both pages.
    assert "| ent_coef | seeds | IQM final score [95 % CI] | mean | answer |" in markdown
    assert "<table>" in html


def test_summary_numbers_equal_a_hand_computation(sweep_report: ReportIndex) -> None:
    out = sweep_report.out
    summary = _read_summary(out, "ent_coef")
    t2 = 4.302652729911275  # Student t, 97.5 % quantile, 2 degrees of freedom
    low = summary.loc[0.01]
    # [1, 2, 3] has skewness 0: Hall's interval is the Student-t one.
    assert (low["complete"], low["failed"], low["pending"]) == (3, 1, 0)
    assert low["final_mean"] == csv_approx(2.0)
    assert low["final_sd"] == csv_approx(1.0)
    assert low["final_low"] == pytest.approx(2.0 - t2 / math.sqrt(3), rel=1e-5)
    assert low["final_high"] == pytest.approx(2.0 + t2 / math.sqrt(3), rel=1e-5)
    assert low["time_mean"] == csv_approx(12.0)  # the failed run's 3 s is not a result
    high = summary.loc[0.1]
    assert (high["complete"], high["failed"]) == (3, 0)
    assert high["final_mean"] == csv_approx(5.0)
    assert high["final_sd"] == pytest.approx(math.sqrt(13.0), rel=1e-5)
    # [2, 4, 9] is right-skewed: Hall's interval (the cubic's roots), above the Student-t one.
    _, hall_low, hall_high = hall_bounds([2.0, 4.0, 9.0])
    assert (high["final_low"], high["final_high"]) == pytest.approx((hall_low, hall_high),
                                                                    rel=1e-5)
    assert high["final_high"] > 5.0 + t2 * math.sqrt(13.0 / 3.0)
    # Training time, the same interval: 20, 20, 26 s.
    assert (high["time_low"], high["time_high"]) == pytest.approx(
        hall_bounds([20.0, 20.0, 26.0])[1:], rel=1e-5)
    # Three seeds a side: no test holds its error rate there, so the other value is undecided.
    assert (high["answer"], low["answer"]) == ("best", "undecided")
    for retired in ("p_vs_best", "p_holm", "mark"):
        assert retired not in summary.columns
    text = (out / "ent_coef" / "summary.md").read_text()
    assert "- Best: 0.1, IQM final score 5 (95 % CI [" in text
    assert "Welch" not in text and "95 % Hall skewness-corrected t interval" in text
    assert "studentised bootstrap (bootstrap-t) interval (2,000 resamples" in text


def test_statistics_edge_cases() -> None:
    low, high = t_interval([1.0, 1.0], [0.5, 0.5], [1, 4])
    assert math.isnan(low[0]) and math.isnan(high[0])  # one seed: no interval
    assert high[1] == pytest.approx(1.0 + stats.t.ppf(0.975, 3) * 0.25)
    low, high = hall_interval([1.0, 1.0], [0.5, 0.5], [1, 4], [0.0, 0.0])
    assert math.isnan(low[0]) and math.isnan(high[0])
    assert high[1] == pytest.approx(1.0 + stats.t.ppf(0.975, 3) * 0.25)


def test_partly_finished_study_says_so(sweep_report: ReportIndex) -> None:
    report = sweep_report.studies[1]
    assert report.name == "gamma" and not report.finished
    assert report.status == "4/6 complete, 2 pending"
    assert "partly finished: 4/6 complete, 2 pending" in sweep_report.markdown.read_text()
    summary = _read_summary(sweep_report.out, "gamma")
    assert summary.loc[0.95, "complete"] == 0 and summary.loc[0.95, "pending"] == 2
    assert summary.loc[0.9, "answer"] == "best"


def test_failed_runs_are_listed(sweep_report: ReportIndex) -> None:
    out = sweep_report.out
    line = "ent_coef = 0.01, seed 3 (trial 3): diverged: ValueError: nan in the actions"
    assert line in (out / "index.md").read_text()
    assert line in (out / "ent_coef" / "summary.md").read_text()
    trials = pd.read_csv(out / "ent_coef" / "trials.csv")
    failed = trials[trials["outcome"] == "failed"]
    assert failed[["ent_coef", "seed"]].values.tolist() == [[0.01, 3]]


def test_svg_on_request(sweep_store: str, tmp_path: Path) -> None:
    index = write_report(sweep_store, tmp_path / "r", study="gamma", fmt="SVG", policy=False)
    figures = [p for p in index.files if p.suffix in (".png", ".svg")]
    assert figures and all(p.suffix == ".svg" for p in figures)
    assert figures[0].read_text().lstrip().startswith("<?xml")


def test_search_report(tmp_path: Path) -> None:
    url = _search_store(tmp_path / "s.db")
    out = tmp_path / "r"
    index = write_report(url, out)
    (report,) = index.studies
    assert report.status == "16/16 trials done: 11 complete, 4 pruned, 1 failed"
    for stem in SEARCH_FIGURES:
        assert (out / "tpe" / f"{stem}.png").read_bytes()[:8] == PNG_MAGIC
    top = pd.read_csv(out / "tpe" / "top_trials.csv")
    assert len(top) == 10 and top["value"].is_monotonic_decreasing
    study = optuna.load_study(study_name="tpe", storage=url)
    assert top["value"].iloc[0] == csv_approx(study.best_value)
    trials = pd.read_csv(out / "tpe" / "trials.csv")
    pruned = trials[trials["outcome"] == "pruned"]
    assert len(pruned) == 4 and (pruned["pruned_at"] == 2000).all()
    markdown = (out / "index.md").read_text()
    assert "trial 3 (" in markdown and "diverged: NaN loss" in markdown
    assert f"Best: trial {study.best_trial.number}" in markdown


def test_search_report_ranks_equal_scores_by_their_cpu_seconds_per_seed(tmp_path: Path) -> None:
    # Four trials reach the ceiling, at 9, 4 and 6 CPU s per seed and one without a cost;
    # the pick and the top table take the cheapest first, then by cost, then by number.
    url = sqlite_url(tmp_path / "c.db")
    store = Store(url)
    study = optuna.create_study(study_name="ceiling", storage=store.storage,
                                direction="maximize")
    study.set_user_attr("kraby_kind", "search")
    for value, cpu in [(500.0, 18.0), (500.0, None), (500.0, 8.0), (480.0, 1.0), (500.0, 12.0)]:
        trial = study.ask()
        trial.suggest_float("learning_rate", 1e-4, 1e-2, log=True)
        if cpu is not None:
            trial.set_user_attr("cpu_time", cpu)
            trial.set_user_attr("scores", [value, value])
        study.tell(trial, value)
    store.close()
    out = tmp_path / "r"
    write_report(url, out)
    top = pd.read_csv(out / "ceiling" / "top_trials.csv")
    assert list(top["number"]) == [2, 4, 0, 1, 3]
    assert list(top["training_time"].iloc[:3]) == [4.0, 6.0, 9.0]
    assert "Best: trial 2" in (out / "index.md").read_text()
    table = (out / "ceiling" / "top_trials.md").read_text()
    assert "| CPU s per seed |" in table and "on more seeds, then the one with fewer CPU s" in table


def test_search_with_too_few_trials_for_importances(tmp_path: Path) -> None:
    url = sqlite_url(tmp_path / "s.db")
    study = optuna.create_study(study_name="plain", storage=url)  # not made by kraby-study
    distributions = {"x": FloatDistribution(0.0, 1.0)}
    study.add_trial(create_trial(value=1.0, params={"x": 0.5}, distributions=distributions))
    study.add_trial(create_trial(state=TrialState.WAITING))
    index = write_report(url, tmp_path / "r")
    (report,) = index.studies
    assert any("at least 2 complete trials" in note for note in report.notes)
    assert not (tmp_path / "r" / "plain" / "importances.png").exists()
    assert (tmp_path / "r" / "plain" / "history.png").exists()
    assert "1 pending" in report.status and not report.finished


def _one_line_error(error: type[Exception], url: str, tmp_path: Path, **kwargs: object) -> str:
    with pytest.raises(error) as info:
        write_report(url, tmp_path / "r", **kwargs)  # type: ignore[arg-type]
    message = str(info.value)
    assert message and "\n" not in message
    return message


def test_bad_stores_get_a_one_line_error_and_are_never_created(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "k.db"
    assert "no study store" in _one_line_error(StoreError, sqlite_url(missing), tmp_path)
    assert not missing.exists() and not missing.parent.exists()
    empty = tmp_path / "empty.db"
    empty.write_bytes(b"")
    assert "empty" in _one_line_error(StoreError, sqlite_url(empty), tmp_path)
    assert empty.stat().st_size == 0
    junk = tmp_path / "junk.db"
    junk.write_text("these are not the studies you are looking for\n")
    assert "not a SQLite database" in _one_line_error(StoreError, sqlite_url(junk), tmp_path)
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as connection:
        connection.execute("CREATE TABLE things (x INTEGER)")
    assert "not a study store" in _one_line_error(StoreError, sqlite_url(other), tmp_path)
    bare = tmp_path / "bare.db"
    Store(sqlite_url(bare)).close()
    assert "no studies" in _one_line_error(StoreError, sqlite_url(bare), tmp_path)
    assert not (tmp_path / "r").exists()


def test_unknown_study_and_bad_format(sweep_store: str, tmp_path: Path) -> None:
    message = _one_line_error(StoreError, sweep_store, tmp_path, study="gama")
    assert "no study named 'gama'" in message and "ent_coef, gamma" in message
    assert "png or svg" in _one_line_error(ConfigError, sweep_store, tmp_path, fmt="jpg")
    assert "storage" in _one_line_error(ConfigError, "mysql://u@h/db", tmp_path)


def test_run_report_prints_where_the_report_is(sweep_store: str, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert run_report(sweep_store, tmp_path / "r", study="gamma", stream=sys.stdout,
                      policy=False) == 0
    out = capsys.readouterr().out
    assert "gamma (sweep): 4/6 complete, 2 pending [partly finished]" in out
    assert str(tmp_path / "r" / "index.html") in out


@pytest.mark.slow
def test_report_of_a_trained_store_shows_the_policy(tmp_path: Path) -> None:
    """A real (tiny) sweep, trained and reported: every figure, and the policy's GIF."""
    from kraby_study.cli import main

    url = sqlite_url(tmp_path / "k.db")
    assert main(["run", "study=clip_range", "budget=smoke", "budget.steps=512",
                 "budget.curve_every=64", "ppo.n_envs=4", "ppo.n_steps=32", "ppo.n_epochs=2",
                 "ppo.net_arch=[8]", "budget.seeds=2", "workers=1", f"storage={url}",
                 f"models_dir={tmp_path / 'models'}", "study.values=[0.1,0.2]"]) == 0
    out = tmp_path / "reports"
    index = write_report(url, out)
    gif = out / "clip_range" / "policy.gif"
    assert gif in index.files and gif.read_bytes()[:6] == b"GIF89a"
    from PIL import Image

    with Image.open(gif) as image:
        assert image.n_frames == 3 * 33 and image.size[0] == 160
    assert "clip_range/policy.gif" in (out / "index.md").read_text()
    for stem in SWEEP_FIGURES:
        assert (out / "clip_range" / f"{stem}.png").stat().st_size > 10_000


# Racing -----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def raced_store(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The example race of tests/synthetic.py: clip_range over 0.3, 0.1, 0.2 (the study file's
    order), 0.3 dropped after round 4, stored with the retired rule fastest_tied; and a fixed
    sweep beside it."""
    url = sqlite_url(tmp_path_factory.mktemp("raced") / "k.db")
    store = Store(url)
    try:
        add_raced_sweep(store, "clip_range", "ppo.clip_range", RACE_VALUES, race_example_runs(),
                        RACE_RULES, select="fastest_tied", steps=4000, curve_every=100)
        add_sweep(store, "ent_coef", "ppo.ent_coef", [0.01, 0.1], _runs(
            {0.01: [1.0, 2.0, 3.0], 0.1: [2.0, 4.0, 9.0]},
            {0.01: [10.0, 12.0, 14.0], 0.1: [20.0, 20.0, 26.0]}), steps=4000, curve_every=100)
    finally:
        store.close()
    return url


@pytest.fixture(scope="module")
def raced_report(raced_store: str, tmp_path_factory: pytest.TempPathFactory) -> ReportIndex:
    return write_report(raced_store, tmp_path_factory.mktemp("raced_out"), policy=False)


def _race_p() -> float:
    """The adjusted p of 0.3 at the look after round 4, recounted: the closed Holm step-down
    over three values at margin 0, each pair's p at 4 seeds the larger of the percentile
    bootstrap's and Yuen's (SciPy's)."""
    first = {v: RACE_FINALS[v][:4] for v in (0.1, 0.2, 0.3)}

    def beats(j: float, g: float) -> float:
        return max(percentile_p(first[j], first[g])[0], yuen_p(first[j], first[g])[0])

    pi = {g: min(1.0, 2 * min(beats(j, g) for j in first if j != g)) for g in first}
    assert pi[0.3] == min(pi.values())  # first in Holm's order: times 3
    return 3 * pi[0.3]


def test_a_raced_summary_shows_the_dropped_value_as_worse(raced_report: ReportIndex) -> None:
    summary = _read_summary(raced_report.out, "clip_range")
    assert list(summary.index) == [0.1, 0.2, 0.3]  # sorted, unlike the study file's order
    assert summary.loc[0.3, "dropped_at"] == 4
    assert summary[["dropped_at"]].loc[[0.1, 0.2]].isna().all().all()
    # 0.3: 4 complete, the run ahead of its round failed, the withdrawn retry pruned.
    assert tuple(summary.loc[0.3, ["complete", "failed", "pruned"]]) == (4, 1, 1)
    p = _race_p()
    assert 0.001 < p < RACE_RULES.look_alpha == pytest.approx(0.05 / 3)
    assert summary.loc[0.3, "note"] == (f"dropped by the race after round 4, adjusted p "
                                        f"{p:.3f}, at the race's per-look alpha 0.0167")
    # Never best; the survivors compared on all their seeds, by the usual procedure.
    assert list(summary["answer"]) == ["best", "undecided", "worse"]
    assert math.isnan(summary.loc[0.3, "p_worse"])


def test_a_dropped_value_is_never_selected(raced_store: str,
                                           raced_report: ReportIndex) -> None:
    # The study stores the retired rule fastest_tied: it selects by fastest_equivalent, among
    # the race's survivors. On their 6 seeds 0.2 (the faster) is not shown within the margin of
    # 0.1, so time cannot buy it: the best, 0.1, is selected. The dropped 0.3 is in no family.
    final = {v: [x for x in RACE_FINALS[v] if x is not None] for v in (0.1, 0.2, 0.3)}
    seconds = {v: [RACE_WALL[v]] * len(final[v]) for v in final}
    survivors = compare({v: final[v] for v in (0.1, 0.2)}, 0.2)
    assert survivors.family == [0.1, 0.2] and survivors.equivalent == []
    assert select("fastest_equivalent", survivors, {}, seconds) == 0.1
    summary = _read_summary(raced_report.out, "clip_range")
    assert summary["selected"].tolist() == [True, False, False]
    text = (raced_report.out / "clip_range" / "summary.md").read_text()
    assert "Selected (rule fastest_equivalent: " in text and "): 0.1." in text
    # The store's answers (list, best, ${winner:...}, campaigns) pick the same value.
    with opened(raced_store, create=False, writer=False) as store:
        chosen = sweep_selection(store.load("clip_range"))
        assert chosen is not None and chosen.value == 0.1 and chosen.finished
        assert chosen.rule == "fastest_equivalent" and len(chosen.trials) == 6
        shown = selection_of(store.load("clip_range"))
        assert shown is not None and shown.short.startswith("clip_range=0.1 ")


def test_a_raced_verdict_says_what_the_race_saved(raced_report: ReportIndex) -> None:
    text = (raced_report.out / "clip_range" / "summary.md").read_text()
    verdict = text.split("\n\n")[1]
    # 6 + 6 seeds of the survivors, 0.3's 4 complete and 1 failed; the withdrawn retry did
    # not run. The fixed design: 3 values x 6 seeds.
    assert "raced: 17 of 18 runs (94 %)" in text
    rule = RACE_RULES.describe()
    assert rule == ("racing from round 4 of 6: the answers' step-down on the IQM at each look, "
                    "alpha 0.05 spent equally over 3 looks (0.0167 each)")
    assert text.count(rule) == 1
    assert "dropped 0.3 after round 4 (adjusted p 0.00" in text
    assert verdict.startswith("- Best: 0.1, IQM final score ")
    # At the default margin (0.2 x |IQM 1.0025| = 0.2) the survivors' wide spread leaves 0.2
    # undecided, and the dropped value counts as worse.
    assert verdict.splitlines()[1:4] == [
        "- Equivalent (within the margin of the best, 0.201 in score units): none.",
        "- Worse (below the best by more than the margin): 0.3.",
        "- Undecided (neither shown equivalent nor worse): 0.2."]
    # The IQM's tests see past the two wide seeds: these seeds resolve a margin below it.
    assert "These seeds resolve a margin of about 0.05" in text
    # The table says where the race dropped it, and the methods what a dropped row shows.
    header = next(line for line in text.splitlines() if line.startswith("| clip_range |"))
    assert header.startswith("| clip_range | seeds | IQM final score [95 % CI] | mean | answer |")
    row = next(line for line in text.splitlines() if line.startswith("| 0.3 |"))
    assert "| worse (dropped by the race after round 4) |" in row
    assert "a value the race dropped is never best, selected" in text


def test_dropped_values_are_dashed_in_the_curve_figures(
        raced_store: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    styles: dict[str, dict[str, str]] = {}
    legends: dict[str, str] = {}
    real_save = sweep_plots.save

    def spy(fig: object, path: Path) -> Path:
        for ax in fig.axes:  # type: ignore[attr-defined]
            for line in ax.get_lines():
                if not line.get_label().startswith("_"):
                    styles.setdefault(path.stem, {})[line.get_label().split()[0]] = \
                        line.get_linestyle()
            if ax.get_legend() is not None:
                legends[path.stem] = ax.get_legend().get_title().get_text()
        return real_save(fig, path)

    monkeypatch.setattr(sweep_plots, "save", spy)
    index = write_report(raced_store, tmp_path / "r", study="clip_range", policy=False)
    for stem in ("learning_curves", "wallclock"):
        assert styles[stem] == {"0.1": "-", "0.2": "-", "0.3": "--"}, stem
        assert "dashed: dropped by the race" in legends[stem]
        png = index.out / "clip_range" / f"{stem}.png"
        assert png.read_bytes()[:8] == PNG_MAGIC
    markdown = index.markdown.read_text()
    assert markdown.count("Dashed: values dropped by the race") == 2


def test_a_fixed_study_gains_only_an_empty_dropped_at_column(raced_report: ReportIndex) -> None:
    out = raced_report.out
    summary = pd.read_csv(out / "ent_coef" / "summary.csv", keep_default_na=False)
    columns = list(summary.columns)
    assert columns[columns.index("pending") + 1] == "dropped_at"
    assert (summary["dropped_at"] == "").all()
    text = (out / "ent_coef" / "summary.md").read_text()
    section = (out / "index.md").read_text().split("## ent_coef")[1]
    for words in ("dropped after round", "dropped by the race", "raced", "Race ("):
        assert words not in text and words not in section, words


def test_a_raced_confirm_study_compares_its_surviving_configurations(tmp_path: Path) -> None:
    """The source's winner t12, dropped by the race: not the confirmed winner, and said so."""
    labels = ["tuned", "t7", "t12"]
    finals = {"tuned": [-0.012, -0.010, -0.013, -0.011, -0.012],
              "t7": [-0.010, -0.012, -0.011, -0.013, -0.009],
              "t12": [-0.30, -0.31, -0.29, -0.305]}
    rules = RaceRules(seeds=5, round_seeds=(100, 101, 102, 103, 104), min_seeds=4)
    definition = {"kind": "confirm", "parameter": "config", "values": labels,
                  "source": "ppo_search", "source_winner": "t12",
                  "arms": [{"label": label, "origin": "-", "source_score": None}
                           for label in labels],
                  "steps": 400, "curve_every": 100, "racing": rules.stored()}
    url = sqlite_url(tmp_path / "k.db")
    store = Store(url)
    try:
        ledger = store.define("ppo_search-confirm", StudyAttrs(
            kind="confirm", definition=definition, fingerprint="x", planned=14))
        distribution = optuna.distributions.CategoricalDistribution(labels)
        for vi, label in enumerate(labels):
            for index, final in enumerate(finals[label]):
                seed = rules.round_seeds[index]
                attrs = TrialAttrs(key=f"v{vi}-s{seed}", seed=seed, final_score=final,
                                   wall_time=4.0, env_steps=400)
                add_trials(store, ledger.name, [create_trial(
                    state=TrialState.COMPLETE, value=final, params={"config": label},
                    distributions={"config": distribution}, user_attrs=attrs.stored())])
    finally:
        store.close()
    index = write_report(url, tmp_path / "r", policy=False)
    summary = pd.read_csv(index.out / "ppo_search-confirm" / "summary.csv",
                          keep_default_na=False, na_values=[""]).set_index("value")
    assert list(summary.index) == labels  # a confirm study keeps its order
    assert summary.loc["t12", "dropped_at"] == 4
    assert summary["dropped_at"].isna().sum() == 2
    assert summary.loc["t7", "answer"] == "best" and summary.loc["t12", "answer"] == "worse"
    text = (index.out / "ppo_search-confirm" / "summary.md").read_text()
    assert ("ppo_search's winner t12 is not the confirmed winner: t7 has the best IQM final "
            "score on 5 fresh seeds. The race dropped t12 after round 4.") in text
    assert "raced: 14 of 15 runs (93 %)" in text
    assert "on at most 5 fresh seeds each, raced" in text


def test_a_wilcoxon_search_captions_its_intermediate_values_as_seed_scores() -> None:
    from types import SimpleNamespace

    from kraby_study.report.search_output import CAPTIONS, SEED_SCORES_CAPTION, caption

    def search(pruner: str) -> SimpleNamespace:
        return SimpleNamespace(data=SimpleNamespace(definition={"search": {"pruner": pruner}}))

    assert caption(search("wilcoxon"), "intermediate") == SEED_SCORES_CAPTION
    assert caption(search("median"), "intermediate") == CAPTIONS["intermediate"]
    assert caption(search("wilcoxon"), "history") == CAPTIONS["history"]


def test_a_report_at_margin_zero_reads_as_before(raced_store: str, tmp_path: Path) -> None:
    # compare.margin=0: no value can be equivalent, and the verdict is the earlier releases'.
    index = write_report(raced_store, tmp_path / "zero", policy=False,
                         options=SimpleNamespace(margin=0.0))
    text = (index.out / "clip_range" / "summary.md").read_text()
    verdict = text.split("\n\n")[1]
    assert verdict.splitlines()[1:4] == [
        "- Equivalent: none (margin 0: no value can be shown equivalent).",
        "- Worse (below the best): 0.3.",
        "- Undecided (neither shown equivalent nor worse): 0.2."]
    summary = _read_summary(index.out, "clip_range")
    assert list(summary["answer"]) == ["best", "undecided", "worse"]
    assert (summary["margin"] == 0).all() and summary["p_equivalent"].dropna().eq(1.0).all()


# The summary for a reader in a hurry ------------------------------------------------------------


@pytest.fixture(scope="module")
def layout_report(tmp_path_factory: pytest.TempPathFactory) -> ReportIndex:
    """A store of every kind the report draws: the sweep of every answer (a one-stage
    campaign's stage), a confirm study and a search."""
    url = sqlite_url(tmp_path_factory.mktemp("layout") / "k.db")
    store = Store(url)
    try:
        ledger = add_sweep(store, "lr", "ppo.learning_rate", VERDICT_VALUES, verdict_runs(),
                           steps=4000, curve_every=100)
        ledger.update(StudyAttrs(campaign={
            "name": "chain", "stage": 1, "description": "", "start": {"ppo.gamma": 0.9},
            "stages": [{"study": "lr", "name": "lr", "parameter": "ppo.learning_rate",
                        "select": "final_score", "documented": 0.01}]}))
        _add_confirm(store)
        add_search(store, "tpe", 12, np.random.default_rng(0), steps=4000, checkpoints=4,
                   points=20)
    finally:
        store.close()
    return write_report(url, tmp_path_factory.mktemp("layout_out"), policy=False)


def _add_confirm(store: Store) -> None:
    labels = ["tuned", "t7"]
    definition = {"kind": "confirm", "parameter": "config", "values": labels,
                  "source": "tpe", "source_winner": "t7",
                  "arms": [{"label": label, "origin": "-", "source_score": None}
                           for label in labels], "steps": 400, "curve_every": 100}
    ledger = store.define("tpe-confirm", StudyAttrs(kind="confirm", definition=definition,
                                                    fingerprint="y", planned=6))
    distribution = optuna.distributions.CategoricalDistribution(labels)
    finals = {"tuned": [-0.012, -0.010, -0.013], "t7": [-0.010, -0.012, -0.011]}
    for vi, label in enumerate(labels):
        for seed, final in enumerate(finals[label]):
            attrs = TrialAttrs(key=f"v{vi}-s{seed}", seed=seed, final_score=final,
                               wall_time=4.0, env_steps=400)
            add_trials(store, ledger.name, [create_trial(
                state=TrialState.COMPLETE, value=final, params={"config": label},
                distributions={"config": distribution}, user_attrs=attrs.stored())])


def test_the_verdict_block_says_each_answer_in_one_short_line(
        layout_report: ReportIndex) -> None:
    text = (layout_report.out / "lr" / "summary.md").read_text()
    block = text.split("\n\n")[1].splitlines()  # right under the title
    assert len(block) <= 6
    assert block[0].startswith("- Best: 0.01, IQM final score 1.002 (95 % CI [")
    assert block[0].endswith(", n=8; mean 1.001).")
    assert block[1:] == [
        "- Equivalent (within the margin of the best, 0.201 in score units): 0.02.",
        "- Worse (below the best by more than the margin): 0.05.",
        "- Undecided (neither shown equivalent nor worse): 0.1.",
        "- Failed seeds (final score below " + block[4].split("below ")[1].split(")")[0]
        + "): 0.05: 1 of 8.",
        "- Selected (rule final_score: highest IQM final score (the best)): 0.01."]
    assert all(len(line) <= 100 for line in block)
    # The margin is given once in score units; the methods name each procedure once, at the
    # end.
    assert text.count("0.201 in score units") == 1
    methods = text.split("## Methods")[1]
    assert "## Methods" not in text.split("\n\n")[2] and "Edwards and Hsu 1983" in methods
    assert text.count("Edwards and Hsu 1983") == 1 and text.count("Newcombe 2006") == 1
    assert "\u2248 best" not in text
    # The same block opens the study's section of the index, after the overview.
    index = layout_report.markdown.read_text()
    section = index.split("\n## lr\n\n")[1]
    assert section.split("\n\n")[0].splitlines() == block
    assert index.index("## lr") < index.index("## Methods")
    assert "| lr | sweep | 32/33 complete, 1 failed | best 0.01; selected 0.01 |" in index


def test_the_compact_table_reads_the_answer_column(layout_report: ReportIndex) -> None:
    text = (layout_report.out / "lr" / "summary.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| 0.")]
    assert [row.split(" | ")[4] for row in rows] == ["best", "equivalent", "worse", "undecided"]
    header = next(line for line in text.splitlines() if line.startswith("| learning_rate |"))
    assert header == ("| learning_rate | seeds | IQM final score [95 % CI] | mean | answer "
                      "| p_worse | p_equivalent | failed seeds [95 % CI of the rate] |")
    summary = _read_summary(layout_report.out, "lr")
    assert list(summary["answer"]) == ["best", "equivalent", "worse", "undecided"]
    assert list(summary["failed_seeds"]) == [0, 0, 1, 0]


def test_the_final_score_figure_shades_the_four_answers(
        layout_report: ReportIndex, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    shaded: list[list[str]] = []
    draw = sweep_plots._shade_answers
    monkeypatch.setattr(sweep_plots, "_shade_answers",
                        lambda ax, answers: shaded.append(list(answers)) or draw(ax, answers))
    sweep = layout_report.studies[0].sweep
    sweep_plots.draw_final_score(sweep, tmp_path / "final_score.png")
    assert shaded == [["best", "equivalent", "worse", "undecided"]]
    assert set(sweep_plots.ANSWER_SHADES) == {"best", "equivalent", "undecided"}  # worse: none


def _markdown_headers(text: str) -> list[list[str]]:
    """The header cells of every Markdown table of a page (a header is the line above a
    |---| separator)."""
    lines = text.splitlines()
    headers = []
    for above, line in zip(lines, lines[1:], strict=False):
        if line.startswith("|") and set(line) <= set("|-: "):
            cells = re.split(r"(?<!\\)\|", above.strip())[1:-1]
            headers.append([cell.strip() for cell in cells])
    return headers


def test_no_table_the_report_writes_has_an_empty_column_header(
        layout_report: ReportIndex) -> None:
    out = layout_report.out
    kinds = {path.parent.name for path in out.rglob("*.csv")}
    assert {"lr", "tpe-confirm", "tpe", "chain"} <= kinds  # sweep, confirm, search, campaign
    csvs = sorted(out.rglob("*.csv"))
    for path in csvs:
        header = pd.read_csv(path, nrows=0).columns
        assert not [c for c in header if not str(c).strip() or str(c).startswith("Unnamed")], \
            path
    pages = sorted(out.rglob("*.md"))
    assert len(pages) >= 4
    counted = 0
    for path in pages:
        for header in _markdown_headers(path.read_text()):
            counted += 1
            assert all(header), (path, header)
    assert counted >= 8
    html = layout_report.html.read_text()
    assert "<th></th>" not in html and html.count("<th>") > 20
