"""`kraby-study confirm`: a search's top configurations on fresh seeds; searches start from the
known settings."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from conftest import TINY, file_digest, load, run_cli, sqlite_url
from optuna.trial import TrialState

from kraby_study.config.compose import compose_config
from kraby_study.plan.settings import resolved_settings
from kraby_study.plan.space import fitted_params
from kraby_study.records import counted

SPACE = """\
name: tiny
sampler: random
pruner: none
seed: 0
startup_trials: 1
checkpoints: 2
trials: 4
params:
  learning_rate: {path: ppo.learning_rate, type: float, low: 1.0e-4, high: 1.0e-2, log: true}
  gamma: {path: ppo.gamma, type: float, low: 0.5, high: 0.99}
"""
SEARCH = ["optuna", "search=tiny", "--workers", "2", *TINY, "budget.seeds=2"]


@pytest.fixture(scope="module")
def searched(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding a finished 4-trial search (2 seeds each) in studies/kraby.db."""
    root = tmp_path_factory.mktemp("searched")
    (root / "conf" / "search").mkdir(parents=True)
    (root / "conf" / "search" / "tiny.yaml").write_text(SPACE)
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        assert run_cli(*SEARCH) == 0
    return root


@pytest.fixture
def folder(searched: Path, workdir: Path) -> Path:
    """A copy of the searched folder as the working directory."""
    shutil.copytree(searched, workdir, dirs_exist_ok=True)
    return workdir


def test_a_new_search_evaluates_the_known_settings_first(searched: Path) -> None:
    trials = load(searched / "studies" / "kraby.db", "tiny").trials
    for trial, name in zip(trials[:2], ["tuned", "start"], strict=True):
        ppo = compose_config([*TINY, f"ppo={name}"]).ppo
        assert trial.params == {"learning_rate": ppo.learning_rate, "gamma": ppo.gamma}
        assert trial.user_attrs["settings"]["ppo"]["learning_rate"] == ppo.learning_rate


def test_known_settings_enter_a_space_only_as_far_as_it_holds_them() -> None:
    cfg = compose_config(["ppo=tuned"])  # the default space
    params = fitted_params(cfg, resolved_settings(cfg))
    assert params["gamma"] == 0.8 and params["learning_rate"] == 0.01
    assert params["nminibatches"] == 1 and params["observation"] == "default"
    narrow = compose_config(["ppo=tuned", "search.params.gamma.low=0.85"])
    assert "gamma" not in fitted_params(narrow, resolved_settings(narrow))


def test_confirm_retrains_the_top_configurations_on_fresh_seeds(
        folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = folder / "studies" / "kraby.db"
    search = counted(load(db, "tiny").trials)
    ranked = sorted((t for t in search if t.state == TrialState.COMPLETE),
                    key=lambda t: -float(t.value))
    args = ["confirm", "--study-name", "tiny", "--top", "2", "--seeds", "2", "--workers", "2",
            "--baseline", "ppo=tuned", *TINY]
    assert run_cli(*args) == 0
    study = load(db, "tiny-confirm")
    trials = study.trials
    definition = study.user_attrs["kraby_definition"]
    labels = [ranked[0].user_attrs["key"], ranked[1].user_attrs["key"], "ppo=tuned"]
    assert definition["values"] == labels and definition["source_winner"] == labels[0]
    assert [a["source_score"] for a in definition["arms"][:2]] == [ranked[0].value,
                                                                   ranked[1].value]
    assert len(trials) == 3 * 2 and all(t.state == TrialState.COMPLETE for t in trials)
    # Seeds no trial of the search used: it trained seeds 0 and 1 (2 per trial).
    used = {t.user_attrs["seed"] + i for t in search for i in range(2)}
    seeds = {t.user_attrs["seed"] for t in trials}
    assert seeds == {2, 3} and not seeds & used
    # Each arm trains its source's settings exactly; the steps are the search's budget.
    for trial in trials:
        arm = labels.index(trial.params["config"])
        settings = (ranked[arm].user_attrs["settings"] if arm < 2
                    else resolved_settings(compose_config([*TINY, "ppo=tuned"])))
        assert trial.user_attrs["settings"] == settings
        assert trial.user_attrs["env_steps"] == 512
    # Resumable: the same command has nothing left to run.
    capsys.readouterr()
    assert run_cli(*args) == 0
    assert "0 to run" in capsys.readouterr().out and len(load(db, "tiny-confirm").trials) == 6
    # best writes the confirmed winner's settings.
    assert run_cli("best", "--study-name", "tiny-confirm", "--name", "confirmed") == 0
    assert "confirm 'tiny-confirm'" in capsys.readouterr().out
    assert (folder / "conf" / "ppo" / "confirmed.yaml").is_file()


def test_baselines_alone_retrain_a_config_on_n_seeds(store_url: str) -> None:
    assert run_cli("confirm", "--baseline", "ppo=tuned", "--seeds", "2", "--workers", "2",
                   "--storage", store_url, *TINY) == 0
    trials = load(store_url, "confirm-ppo=tuned").trials
    assert sorted(t.user_attrs["seed"] for t in trials) == [0, 1]
    assert {t.params["config"] for t in trials} == {"ppo=tuned"}


@pytest.mark.parametrize("argv,message", [
    (["--study-name", "nope"], "no study named 'nope'"),
    (["--study-name", "tiny", "--top", "9"], "has 4 complete configuration(s), fewer than"),
    (["--study-name", "tiny", "confirm.top=0"], "confirm.top must be at least 1"),
    (["--study-name", "tiny", "confirm.seeds=1"], "confirm.seeds must be at least 2"),
    (["--study-name", "tiny", "--top", "0"], "--top"),
    (["--study-name", "tiny", "--seeds", "1"], "--seeds"),
    (["--baseline", "budget=quick"], "--baseline"),
    ([], "confirm needs --study-name NAME or at least one --baseline"),
])
def test_bad_confirm_input_is_one_line_and_the_store_is_untouched(
        folder: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
        message: str) -> None:
    db = folder / "studies" / "kraby.db"
    before = file_digest(db)
    capsys.readouterr()
    try:
        code = run_cli("confirm", *argv, *TINY)
    except SystemExit as exit_:  # argparse's own errors
        code = int(exit_.code or 0)
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert file_digest(db) == before


def test_a_confirm_study_defined_otherwise_is_refused(
        folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["confirm", "--study-name", "tiny", "--seeds", "2", "--workers", "2", *TINY]
    assert run_cli(*base, "--top", "1") == 0
    db = folder / "studies" / "kraby.db"
    before = file_digest(db)
    capsys.readouterr()
    assert run_cli(*base, "--top", "2") == 2
    err = capsys.readouterr().err
    assert "'tiny-confirm'" in err and "defined differently" in err and err.count("\n") == 1
    assert file_digest(db) == before
    assert sqlite_url(db)  # the store is where the search left it
