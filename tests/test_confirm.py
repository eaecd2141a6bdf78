"""`kraby-study confirm`: a search's top configurations on fresh seeds; searches start from the
known settings."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from conftest import TINY, csv_approx, file_digest, finished_search, load, run_cli, sqlite_url
from optuna.trial import TrialState

from kraby_study.answers.configurations import confirmed_study
from kraby_study.config.compose import compose_config
from kraby_study.plan.confirm import Arm, distinct_arms
from kraby_study.plan.settings import resolved_settings
from kraby_study.plan.space import fitted_params, outside_space
from kraby_study.records.stored import counted
from kraby_study.records.values import ranking
from kraby_study.store.store import opened

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
    return finished_search(tmp_path_factory.mktemp("searched"), "tiny", SPACE, *SEARCH)


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


def test_a_known_configuration_names_what_its_space_cannot_hold(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """rl-zoo3's MountainCarContinuous-v0 settings (n_steps 8, learning rate 7.77e-05) lie
    outside a space of rollouts from 16 steps and rates from 1e-4: enqueued first, those two
    are drawn by the sampler, and the search says so instead of claiming to evaluate the
    configuration as it is."""
    zoo = compose_config(["env=gym", "env.id=MountainCarContinuous-v0", "ppo=zoo",
                          "search.params.n_steps.choices=[16,32]",
                          "search.params.learning_rate.low=1e-4"])
    assert outside_space(zoo, resolved_settings(zoo)) == {"n_steps": 8, "learning_rate": 7.77e-05}
    tuned = compose_config(["ppo=tuned"])
    assert outside_space(tuned, resolved_settings(tuned)) == {}
    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "tiny.yaml").write_text(SPACE)
    assert run_cli("optuna", "search=tiny", "--trials", "1", *TINY, "budget.seeds=1",
                   "search.params.gamma.low=0.85", "search.enqueue=[tuned]") == 0
    said = capsys.readouterr()
    assert ("evaluating ppo=tuned (outside the space, so drawn by the sampler: gamma=0.8) "
            "first" in said.out + said.err)


def test_confirm_retrains_the_top_configurations_on_fresh_seeds(
        folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = folder / "studies" / "kraby.db"
    search = counted(load(db, "tiny").trials)
    ranked = sorted((t for t in search if t.state == TrialState.COMPLETE), key=ranking)
    args = ["confirm", "--study-name", "tiny", "--top", "2", "--seeds", "2", "--workers", "2",
            "--baseline", "ppo=tuned", *TINY]
    assert run_cli(*args) == 0
    study = load(db, "tiny-confirm")
    trials = study.trials
    definition = study.user_attrs["kraby_definition"]
    tuned = resolved_settings(compose_config([*TINY, "ppo=tuned"]))
    # A top trial with the tuned settings (the search's enqueued t0) is one arm with the
    # baseline, named after both; otherwise the baseline is an arm of its own.
    labels = [t.user_attrs["key"] + (" = ppo=tuned" if t.user_attrs["settings"] == tuned else "")
              for t in ranked[:2]]
    if not any(label.endswith(" = ppo=tuned") for label in labels):
        labels.append("ppo=tuned")
    assert definition["values"] == labels and definition["source_winner"] == labels[0]
    assert [a["source_score"] for a in definition["arms"][:2]] == [ranked[0].value,
                                                                   ranked[1].value]
    assert len(trials) == len(labels) * 2
    assert all(t.state == TrialState.COMPLETE for t in trials)
    # Seeds no trial of the search used: it trained seeds 0 and 1 (2 per trial).
    used = {t.user_attrs["seed"] + i for t in search for i in range(2)}
    seeds = {t.user_attrs["seed"] for t in trials}
    # Test seeds start at 1000, apart from every tuning seed a command uses by default.
    assert seeds == {1000, 1001} and not seeds & used
    # Each arm trains its source's settings exactly; the steps are the search's budget.
    for trial in trials:
        arm = labels.index(trial.params["config"])
        settings = ranked[arm].user_attrs["settings"] if arm < 2 else tuned
        assert trial.user_attrs["settings"] == settings
        assert trial.user_attrs["env_steps"] == 512
    # Resumable: the same command has nothing left to run.
    capsys.readouterr()
    assert run_cli(*args) == 0
    assert "0 to run" in capsys.readouterr().out
    assert len(load(db, "tiny-confirm").trials) == len(labels) * 2
    # Its reproducibility page keeps the test seeds apart from the search's tuning seeds.
    assert run_cli("report", "--study-name", "tiny-confirm", "--no-policy") == 0
    page = (folder / "reports" / "tiny-confirm" / "reproducibility.md").read_text()
    assert "Test seeds (fresh seeds of this confirm study): 1000-1001 (2 seeds)." in page
    assert "Tuning seeds (of the source study 'tiny'): 0-1 (2 seeds)." in page
    assert "Test and tuning seeds are disjoint." in page
    # best writes the confirmed winner's settings.
    assert run_cli("best", "--study-name", "tiny-confirm", "--name", "confirmed") == 0
    assert "confirm 'tiny-confirm'" in capsys.readouterr().out
    assert (folder / "conf" / "ppo" / "confirmed.yaml").is_file()


def test_of_equal_search_scores_confirm_takes_the_cheaper_first(folder: Path) -> None:
    db = folder / "studies" / "kraby.db"
    # Tie the search's complete trials at one score, each later one 1 CPU s cheaper.
    with sqlite3.connect(db) as con:
        ids = [row[0] for row in con.execute(
            "SELECT trial_id FROM trials WHERE state = 'COMPLETE' ORDER BY number")]
        for k, trial_id in enumerate(ids):
            con.execute("UPDATE trial_values SET value = 1.0 WHERE trial_id = ?", (trial_id,))
            con.execute("UPDATE trial_user_attributes SET value_json = ? "
                        "WHERE trial_id = ? AND key = 'cpu_time'", (json.dumps(100.0 - k),
                                                                    trial_id))
    keys = [t.user_attrs["key"] for t in load(db, "tiny").trials
            if t.state == TrialState.COMPLETE]
    assert len(keys) >= 3
    with opened(sqlite_url(db)) as store:
        confirmed = confirmed_study(store.load("tiny"), len(keys))
    assert [arm.label for arm in confirmed.arms] == keys[::-1]
    assert [arm.source_score for arm in confirmed.arms] == [1.0] * len(keys)


def test_baselines_alone_retrain_a_config_on_n_seeds(store_url: str) -> None:
    assert run_cli("confirm", "--baseline", "ppo=tuned", "--seeds", "2", "--workers", "2",
                   "--storage", store_url, *TINY) == 0
    trials = load(store_url, "confirm-ppo=tuned").trials
    assert sorted(t.user_attrs["seed"] for t in trials) == [1000, 1001]
    assert {t.params["config"] for t in trials} == {"ppo=tuned"}


def test_confirm_name_keeps_a_second_confirm_of_the_same_baselines_apart(
        store_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Baselines alone are stored as confirm-<baselines>: the same baselines on another
    budget (or env) clash with it, and the refusal names the option that keeps them apart."""
    once = ["confirm", "--baseline", "ppo=tuned", "--seeds", "2", "--workers", "2",
            "--storage", store_url, *TINY]
    assert run_cli(*once) == 0
    capsys.readouterr()
    longer = [*once, "budget.steps=640"]
    assert run_cli(*longer) == 2
    error = capsys.readouterr().err.strip()
    assert "was defined differently" in error and "confirm: confirm.name=..." in error
    assert len(error.splitlines()) == 1
    assert run_cli(*longer, "confirm.name=tuned-640") == 0
    assert {t.user_attrs["steps"] for t in load(store_url, "tuned-640").trials} == {640}
    assert {t.user_attrs["steps"] for t in load(store_url, "confirm-ppo=tuned").trials} == {512}
    assert run_cli(*once, "confirm.name= ") == 2
    assert "confirm.name must name a study" in capsys.readouterr().err


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


def test_arms_with_the_same_settings_are_one_arm_with_every_name() -> None:
    tuned = {"ppo": {"gamma": 0.8}}
    arms = [Arm("t0", tuned, "trial 0", -0.1), Arm("t3", {"ppo": {"gamma": 0.5}}, "trial 3", -0.2),
            Arm("ppo=tuned", dict(tuned), "the config ppo=tuned"),
            Arm("ppo=tuned", dict(tuned), "the config ppo=tuned")]
    merged = distinct_arms(arms)
    assert [a.label for a in merged] == ["t0 = ppo=tuned", "t3"]
    assert merged[0].origin == "trial 0; the config ppo=tuned"
    assert merged[0].source_score == -0.1 and merged[0].settings == tuned


def test_a_search_trial_equal_to_a_baseline_is_trained_once(folder: Path) -> None:
    # t1 is the enqueued start config: the search's base settings with start's own values.
    assert run_cli("confirm", "--study-name", "tiny", "--top", "4", "--seeds", "2",
                   "--baseline", "ppo=start", "--baseline", "ppo=start", *TINY) == 0
    study = load(folder / "studies" / "kraby.db", "tiny-confirm")
    labels = study.user_attrs["kraby_definition"]["values"]
    assert "t1 = ppo=start" in labels and len(labels) == 4
    assert len(study.trials) == 4 * 2


def test_a_confirm_of_an_evaluation_search_scores_on_a_test_set_the_search_never_saw(
        workdir: Path) -> None:
    # Each run draws its evaluation targets from its own seed's stream: the confirm's fresh
    # seeds meet none of the targets its search selected on.
    import numpy as np
    from stable_baselines3 import PPO

    from kraby_envs.rollout import evaluation_targets
    from kraby_study.env import adapter_for
    from kraby_study.records.definition import EVAL_EPISODES
    from kraby_study.records.stored import trial_seeds

    space = SPACE.replace("name: tiny", "name: evaluated").replace("trials: 4", "trials: 2")
    finished_search(workdir, "evaluated", space, "optuna", "search=evaluated", "--workers",
                    "2", *TINY, "search.objective=evaluation", "search.eval_episodes=4")
    assert run_cli("confirm", "--study-name", "evaluated", "--top", "1", "--seeds", "2",
                   "--workers", "2", *TINY, "save_models=true") == 0
    store = workdir / "studies" / "kraby.db"
    search, study = load(store, "evaluated"), load(store, "evaluated-confirm")
    searched = search.user_attrs["kraby_definition"]["search"]
    assert searched["eval_set"] == "run" and searched["eval_episodes"] == 4
    definition = study.user_attrs["kraby_definition"]
    # The confirm's own test set: each fresh seed's episodes, today's default number.
    assert definition["objective"] == "evaluation" and definition["eval_set"] == "run"
    assert definition["eval_episodes"] == EVAL_EPISODES
    delta = float(definition["arms"][0]["settings"]["env"]["delta"])
    seen = np.concatenate([evaluation_targets(4, delta, seed) for trial in search.trials
                           for seed in trial_seeds(trial, 2)])
    for trial in study.trials:
        targets = evaluation_targets(EVAL_EPISODES, delta, trial.user_attrs["seed"])
        assert not np.isclose(targets[:, None, :], seen[None]).all(-1).any()
        # Scored by evaluation: the training reward is stored beside it and differs.
        assert trial.value == trial.user_attrs["final_score"]
        assert trial.value != trial.user_attrs["train_reward"]
        # The stored score is the saved policy's mean return on exactly those targets.
        env = trial.user_attrs["settings"]["env"]
        model = PPO.load(trial.user_attrs["model_path"], device="cpu")
        rescored = adapter_for(env).evaluate(model, env, EVAL_EPISODES,
                                             seed=trial.user_attrs["seed"])
        assert rescored.mean == pytest.approx(trial.value, rel=1e-6)
        assert trial.user_attrs["eval_errors"] == [pytest.approx(rescored.error, rel=1e-6)]
        # Each run's evaluation return sd: the sd over those episodes' returns.
        sd = float(np.std(rescored.returns, ddof=1))
        assert trial.user_attrs["eval_sds"] == [pytest.approx(sd, rel=1e-6)]
    # The report shows the training reward beside the evaluation score, per configuration.
    assert run_cli("report", "--study-name", "evaluated-confirm", "--no-policy",
                   f"out={workdir / 'reports'}") == 0
    folder = workdir / "reports" / "evaluated-confirm"
    summary = pd.read_csv(folder / "summary.csv")
    rewards = [t.user_attrs["train_reward"] for t in study.trials]
    assert summary["train_mean"].mean() == csv_approx(sum(rewards) / len(rewards))
    assert summary["final_mean"].tolist() != summary["train_mean"].tolist()
    page = (folder / "summary.md").read_text()
    assert "Scored by evaluation" in page and "the training reward (" in page
    assert "eval_se: the evaluation standard error" in page
    assert "eval_sd: the evaluation return sd" in page and "own seed's evaluation stream" in page
    assert summary["eval_se"].notna().all()
    # The sd of the returns is the se times sqrt(episodes), run by run and so value by value
    # (both are root mean squares over the seeds).
    assert summary["eval_sd"].tolist() == pytest.approx(
        (summary["eval_se"] * np.sqrt(EVAL_EPISODES)).tolist(), rel=1e-4)
    runs = pd.read_csv(folder / "trials.csv")
    assert runs["eval_sd"].notna().all()
    assert "eval_sd by value: " in page
    provenance = (folder / "reproducibility.md").read_text()
    assert "no test episode is one the source study scored a run on" in provenance
    index = (workdir / "reports" / "index.md").read_text()
    assert "Final score (the deterministic policy's mean return over the evaluation episodes)" in (
        index)


def test_a_study_stored_on_the_shared_fixed_set_resumes_on_it(workdir: Path) -> None:
    # A search stored before runs drew their own episodes has no eval_set: it resumes on the
    # fixed set it began with (the same definition), and its confirm still draws its own.
    space = SPACE.replace("name: tiny", "name: older").replace("trials: 4", "trials: 1")
    finished_search(workdir, "older", space, "optuna", "search=older", "--workers", "1",
                    *TINY, "budget.seeds=1", "search.objective=evaluation",
                    "search.eval_episodes=3", "search.eval_set=fixed")
    store = workdir / "studies" / "kraby.db"
    searched = load(store, "older").user_attrs["kraby_definition"]["search"]
    assert "eval_set" not in searched and searched["eval_episodes"] == 3
    assert run_cli("optuna", "--trials", "2", "search=older", "--workers", "1", *TINY,
                   "budget.seeds=1", "search.objective=evaluation") == 0
    assert len(load(store, "older").trials) == 2
    assert run_cli("confirm", "--study-name", "older", "--top", "1", "--seeds", "2",
                   "--workers", "1", *TINY, "search.eval_episodes=5") == 0
    definition = load(store, "older-confirm").user_attrs["kraby_definition"]
    assert definition["eval_set"] == "run" and definition["eval_episodes"] == 5
