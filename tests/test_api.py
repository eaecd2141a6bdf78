"""The Python API as a notebook user meets it: the commands' configs, a run into a store read
back as typed objects and frames, the four answers over any seed scores, and the command line
printing what the API returns."""

from __future__ import annotations

import io
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY, run_cli, sqlite_url
from synthetic import add_search, add_sweep, sweep_runs

import kraby_study as ks
from kraby_study.decision.comparison import compare as decision_compare
from kraby_study.store.store import Store


def test_each_command_composes_with_its_own_defaults() -> None:
    assert ks.compose([]).cfg.budget.name == "full"
    assert ks.compose([], command="search").cfg.budget.name == "quick"
    assert ks.compose(["budget=smoke"], command="confirm").cfg.budget.name == "smoke"
    trained = ks.compose([], command="train")
    assert trained.choices["ppo"] == "tuned" and trained.overrides[0] == "ppo=tuned"
    gym = ks.compose(["env=gym", "env.id=Pendulum-v1"], command="search")
    assert gym.choices["search"] == "gym"


def test_bad_input_raises_one_line_before_any_work(workdir: Path) -> None:
    with pytest.raises(ks.ConfigError) as err:
        ks.compose(["ppo.gamma=high"])
    assert "\n" not in str(err.value) and "ppo.gamma" in str(err.value)
    with pytest.raises(ks.ConfigError, match="racing is for run, optuna and confirm"):
        ks.compose(["racing.enabled=true"], command="train")
    with pytest.raises(ks.ConfigError, match="command 'sweep'"):
        ks.compose([], command="sweep")
    with pytest.raises(ks.ConfigError, match="not supported|database URL|sqlite"):
        ks.open_store("mysql://x/y")
    assert not (workdir / "studies").exists()


def test_a_config_composed_for_another_command_is_refused(workdir: Path) -> None:
    config = ks.compose(["study=gamma"])
    with pytest.raises(ks.ConfigError, match="composed for run, not search"):
        ks.search(config)
    with pytest.raises(ks.ConfigError, match="nothing to preview"):
        ks.preview(ks.compose([], command="report"))
    assert not (workdir / "studies").exists()


def test_importing_the_package_loads_no_heavy_code() -> None:
    code = ("import sys, kraby_study; print(','.join(m for m in ('hydra', 'omegaconf', "
            "'optuna', 'sqlalchemy', 'pandas', 'scipy', 'torch', 'stable_baselines3') "
            "if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == ""


@pytest.fixture(scope="module")
def tiny_store(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A store holding a finished sweep run through the API: two values x two seeds."""
    folder = tmp_path_factory.mktemp("api")
    url = sqlite_url(folder / "k.db")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        config = ks.compose(["study=clip_range", "study.values=[0.1,0.3]", "budget.seeds=2",
                             "workers=1", f"storage={url}", *TINY])
        progress = io.StringIO()
        result = ks.run_sweep(config, stream=progress)
    assert "study clip_range: 4 trials" in progress.getvalue()
    assert result == ks.RunResult(study="clip_range", complete=4, failed=0, pruned=0,
                                  planned=4, interrupted=False, errors=0,
                                  message="study clip_range: 4/4 complete, 0 failed",
                                  warning=None, exit_code=0)
    assert result.finished
    return url


def test_a_run_is_read_back_as_runs_and_answers(tiny_store: str) -> None:
    store = ks.open_store(tiny_store)
    (study,) = store.studies()
    assert (study.name, study.kind, study.complete, study.planned) == ("clip_range", "sweep",
                                                                       4, 4)
    assert list(store.studies_frame()["name"]) == ["clip_range"]
    runs = store.runs("clip_range")
    assert len(runs) == 4 and {r.value for r in runs} == {"0.1", "0.3"}
    assert all(r.outcome == "complete" and r.score is not None and r.params == {} for r in runs)
    frame = runs.to_frame()
    assert list(frame["number"]) == [r.number for r in runs]
    assert {"value", "seed", "score", "env_steps"} <= set(frame.columns)
    answers = store.answers("clip_range")
    assert answers.study == "clip_range" and answers.parameter == "ppo.clip_range"
    assert answers.rule == "final_score" and answers.selected == answers.best
    # Two seeds a value: compared, but below 4 seeds no answer holds its error rate.
    assert sorted(v.answer for v in answers.values) == ["best", "undecided"]
    assert any("fewer than 4 seeds" in w for w in answers.warnings)
    table = answers.to_frame()
    assert list(table.columns) == ["value", "seeds", "iqm", "answer", "p_worse",
                                   "p_equivalent"]
    best_scores = [r.score for r in runs if r.value == answers.best]
    assert table.loc[table["answer"] == "best", "iqm"].item() == pytest.approx(
        np.mean(best_scores))


def test_the_cli_prints_what_the_api_answers(tiny_store: str, workdir: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert run_cli("best", "--study-name", "clip_range", "--storage", tiny_store) == 0
    printed = capsys.readouterr().out
    chosen = ks.best(ks.compose([f"storage={tiny_store}"], command="best"), study="clip_range")
    assert printed.splitlines()[0] == f"best: {chosen.description}"
    assert (workdir / "conf" / "ppo" / "best_clip_range.yaml").is_file()
    assert run_cli("report", "--study-name", "clip_range", "--storage", tiny_store,
                   "--no-policy", "--out", "cli") == 0
    printed = capsys.readouterr().out
    written = ks.write_report(ks.compose([f"storage={tiny_store}", "out=api"], command="report"),
                        study="clip_range", policy=False)
    assert printed.splitlines()[0] == written.lines()[0]
    assert written.html == Path("api") / "index.html" and written.html.is_file()
    assert (workdir / "cli" / "clip_range" / "summary.csv").read_text() == (
        workdir / "api" / "clip_range" / "summary.csv").read_text()


def test_a_search_has_runs_with_settings_and_no_answers(tmp_path: Path) -> None:
    url = sqlite_url(tmp_path / "s.db")
    store = Store(url)
    try:
        add_search(store, "tpe", 6, np.random.default_rng(1))
    finally:
        store.close()
    opened = ks.open_store(url)
    runs = opened.runs("tpe")
    assert len(runs) == 6 and all(r.value is None for r in runs)
    assert any(r.params for r in runs)
    assert "param_learning_rate" in runs.to_frame().columns
    with pytest.raises(ks.StoreError, match="is a search"):
        opened.answers("tpe")
    with pytest.raises(ks.StoreError, match="no study named 'other'"):
        opened.runs("other")


def test_stored_answers_are_the_reports(tmp_path: Path) -> None:
    """A sweep's answers at 6 seeds, and at another margin, are the comparison's of its scores."""
    url = sqlite_url(tmp_path / "w.db")
    store = Store(url)
    runs = sweep_runs([0.5, 0.8, 0.9, 0.99], 6, 10, 4000, np.random.default_rng(3), failed=1)
    try:
        add_sweep(store, "gamma", "ppo.gamma", [0.5, 0.8, 0.9, 0.99], runs, steps=4000,
                  curve_every=400)
    finally:
        store.close()
    scores: dict[str, list[float]] = {}
    for run in runs:
        if run.final_score is not None:
            scores.setdefault(str(run.value), []).append(run.final_score)
    for margin in (0.2, 0.05):
        answers = ks.open_store(url).answers("gamma", margin=margin)
        expected = decision_compare(scores, margin=margin)
        assert {v.value: v.answer for v in answers.values} == {
            g: a.value for g, a in expected.answers.items()}
        assert answers.best == expected.best and answers.margin == margin
        assert {v.value: v.seeds for v in answers.values} == {g: len(s)
                                                             for g, s in scores.items()}


def test_compare_answers_any_scores_as_the_decision_layer_does() -> None:
    rng = np.random.default_rng(0)
    scores = {"low": list(rng.normal(0, 1, 8)), "high": list(rng.normal(5, 1, 8)),
              "near": list(rng.normal(5, 1, 8)), "few": [4.0]}
    found = ks.compare(scores, margin=0.3)
    expected = decision_compare(scores, margin=0.3)
    assert found.best == expected.best in ("high", "near")
    assert [v.value for v in found.values] == ["low", "high", "near", "few"]
    assert found.answer("low") == "worse"
    assert found.answer("few") == "too few seeds"
    assert {v.value: v.answer for v in found.values if v.value != "few"} == {
        g: a.value for g, a in expected.answers.items()}
    assert found.margin_units == pytest.approx(expected.margin)
    low = next(v for v in found.values if v.value == "low")
    assert low.p_worse == pytest.approx(expected.p_worse["low"])
    assert low.iqm == pytest.approx(float(np.mean(sorted(scores["low"])[2:6])))
    few = next(v for v in found.values if v.value == "few")
    assert few.p_worse is None and few.seeds == 1
    frame = found.to_frame()
    assert list(frame["answer"]) == [v.answer for v in found.values]
    assert math.isnan(frame.loc[frame["value"] == found.best, "p_worse"].item())
    with pytest.raises(KeyError):
        found.answer("missing")


def test_a_train_run_returns_its_score_and_the_cli_prints_it(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = sqlite_url(workdir / "t.db")
    result = ks.train(ks.compose([f"storage={url}", *TINY], command="train"),
                      stream=io.StringIO())
    assert result.exit_code == 0 and result.complete == 1 and result.score is not None
    assert result.message == (f"train {result.study} seed 0: complete, final score "
                              f"{result.score:.4g} over 512 steps")
    capsys.readouterr()
    assert run_cli("train", f"--storage={url}", "seed=1", *TINY) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith(f"train {result.study} seed 1: "
                                                               "complete, final score")
