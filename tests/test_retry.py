"""Failed runs queued again on purpose (``--retry-failed``): the same seeds and settings, the
complete runs untouched, ``list`` saying how, and the retried trial's provenance naming its
machine and the failure it retries. On a machine that lacks something until it is fixed
(gym_fixtures' NeedsFix env)."""

from __future__ import annotations

import io
import os
from pathlib import Path

import pytest
from conftest import TINY, TINY_SEARCH, load, run_cli
from gym_fixtures import FIXED, NEEDS_FIX_ID
from optuna.trial import TrialState
from synthetic import DIVERGED, Run, add_sweep

from kraby_study.answers.standing import study_standing
from kraby_study.records.attributes import PROVENANCE_PREFIX
from kraby_study.records.stored import Failure, Outcome, failure, latest_by_key
from kraby_study.run.source import retry_failed
from kraby_study.store.store import opened

TESTS = Path(__file__).resolve().parent
NEEDS_FIX = ["env=gym", f"env.id={NEEDS_FIX_ID}", "env.packages=[gym_fixtures]", *TINY,
             "ppo.n_envs=2", "ppo.n_steps=16", "budget.steps=64", "budget.curve_every=16"]


@pytest.fixture
def machine(workdir: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The file that fixes the machine (missing at first); the workers import gym_fixtures."""
    monkeypatch.syspath_prepend(str(TESTS))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(TESTS), *filter(None, [os.environ.get("PYTHONPATH")])]))
    fixed = workdir / "fixed"
    monkeypatch.setenv(FIXED, str(fixed))
    return fixed


def test_failed_runs_run_again_with_their_seeds_and_settings(
        store_url: str, machine: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sweep = ["run", "study=clip_range", "study.values=[0.1,0.2]", *NEEDS_FIX, "workers=1",
             f"storage={store_url}"]
    machine.write_text("")
    assert run_cli(*sweep, "budget.seeds=1") == 0  # seed 0 of each value, on a sound machine
    machine.unlink()
    assert run_cli(*sweep, "budget.seeds=2") == 1  # seed 1 of each, on a broken one
    before = {t.number: t for t in load(store_url, "clip_range").get_trials()}
    failed = sorted(n for n, t in before.items() if t.state == TrialState.FAIL)
    assert len(failed) == 2 and len(before) == 4
    assert all("this machine is not fixed yet" in before[n].user_attrs["failure"]
               for n in failed)
    # A rerun without the flag leaves them failed: a failure is a result.
    capsys.readouterr()
    assert run_cli(*sweep, "budget.seeds=2") == 0
    assert "2 complete, 2 failed, 0 to run" in capsys.readouterr().out
    # list says how many failed and how to run them again.
    assert run_cli("list", f"storage={store_url}") == 0
    listed = capsys.readouterr().out
    assert ("clip_range: 2 run(s) failed with an error; to run them again with the same seeds "
            "and settings: "
            "`kraby-study run study=clip_range") in listed
    assert "--retry-failed`" in listed
    # Fixed, then retried: only the failed runs train again.
    machine.write_text("")
    assert run_cli(*sweep, "budget.seeds=2", "--retry-failed") == 0
    out = capsys.readouterr().out
    assert f"2 failed trial(s) of clip_range queued again with the same seeds and settings: " \
           f"{failed[0]}, {failed[1]}" in out
    assert "clip_range: 4/4 complete, 0 failed" in out
    study = load(store_url, "clip_range")
    after = {t.number: t for t in study.get_trials()}
    for number, trial in before.items():  # every earlier attempt is as it was
        assert (after[number].state, after[number].value) == (trial.state, trial.value)
    counted = latest_by_key(study.get_trials())
    assert all(t.state == TrialState.COMPLETE for t in counted.values())
    retried = {int(t.user_attrs["retry_of"]): t for t in counted.values()
               if "retry_of" in t.user_attrs}
    assert sorted(retried) == failed
    for number, trial in retried.items():
        old = before[number]
        assert trial.params == old.params
        for attr in ("key", "seed", "settings", "steps"):
            assert trial.user_attrs[attr] == old.user_attrs[attr], attr
        assert trial.user_attrs["retried_failure"] == old.user_attrs["failure"]
        record = study.user_attrs[PROVENANCE_PREFIX + trial.user_attrs["provenance"]]
        assert record["retry_of"] == str(number)
        assert record["retried_failure"] == old.user_attrs["failure"]
        assert record["hostname"] and "--retry-failed" in record["command"]
    # Nothing failed is left: the flag again runs nothing, and list has no retry line.
    assert run_cli(*sweep, "budget.seeds=2", "--retry-failed") == 0
    assert "0 to run" in capsys.readouterr().out
    assert len(load(store_url, "clip_range").get_trials()) == 6
    assert run_cli("list", f"storage={store_url}") == 0
    assert "--retry-failed" not in capsys.readouterr().out


TWO_TRIALS = TINY_SEARCH.replace("trials: 3", "trials: 2")
"""The tiny search space, two trials."""


def test_a_search_retries_its_failed_trials_with_their_parameters(
        workdir: Path, machine: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "tiny.yaml").write_text(TWO_TRIALS)
    search = ["optuna", "search=tiny", "--workers", "1", *NEEDS_FIX]
    assert run_cli(*search) == 1
    before = load(workdir / "studies" / "kraby.db", "tiny").get_trials()
    assert [t.state for t in before] == [TrialState.FAIL] * 2
    machine.write_text("")
    capsys.readouterr()
    assert run_cli(*search, "--retry-failed") == 0
    assert "search tiny: 2 complete, 0 pruned, 0 failed of 2" in capsys.readouterr().out
    trials = load(workdir / "studies" / "kraby.db", "tiny").get_trials()
    assert len(trials) == 4  # no new configuration drawn: the two retried
    for old, new in zip(before, trials[2:], strict=True):
        assert new.state == TrialState.COMPLETE and new.params == old.params
        assert new.user_attrs["key"] == old.user_attrs["key"]
        assert new.user_attrs["retry_of"] == old.number


@pytest.mark.parametrize("command", [["run", "study=clip_range"], ["optuna"],
                                     ["confirm", "--baseline", "ppo=tuned"]])
def test_a_bad_retry_value_is_one_line_and_stores_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str], command: list[str]) -> None:
    assert run_cli(*command, *TINY, "--retry-failed", "retry_failed=maybe") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "retry_failed" in err
    assert not (workdir / "studies").exists()


def test_a_confirm_retries_its_failed_runs_on_the_same_fresh_seeds(
        store_url: str, machine: Path, capsys: pytest.CaptureFixture[str]) -> None:
    confirm = ["confirm", "--baseline", "ppo=tuned", "--seeds", "2", "--workers", "1",
               *NEEDS_FIX, f"storage={store_url}"]
    assert run_cli(*confirm) == 1  # both fresh seeds fail on the broken machine
    name = "confirm-ppo=tuned"
    before = load(store_url, name).get_trials()
    assert [t.state for t in before] == [TrialState.FAIL] * 2
    assert sorted(t.user_attrs["seed"] for t in before) == [1000, 1001]
    machine.write_text("")
    capsys.readouterr()
    assert run_cli(*confirm, "--retry-failed") == 0
    assert f"2 failed trial(s) of {name} queued again" in capsys.readouterr().out
    trials = load(store_url, name).get_trials()
    assert len(trials) == 4
    counted = latest_by_key(trials)
    assert all(t.state == TrialState.COMPLETE for t in counted.values())
    by_key = {t.user_attrs["key"]: t for t in before}
    for key, trial in counted.items():
        assert trial.user_attrs["retry_of"] == by_key[key].number
        assert trial.user_attrs["seed"] == by_key[key].user_attrs["seed"]
        assert trial.user_attrs["settings"] == by_key[key].user_attrs["settings"]


def test_a_diverged_run_is_a_result_and_is_not_queued_again(store_url: str) -> None:
    """Its seed and settings would diverge again: only the run that failed with an error is
    queued, and the command says why the diverged one is not."""
    errored = failure(Failure.ERROR, "Python package 'kraby_study' is not installed")
    runs = [Run(value=v, seed=s, final_score=-0.1 * s) for v in (0.1, 0.2) for s in range(2)]
    runs[1].outcome, runs[1].failure = Outcome.FAILED, DIVERGED
    runs[3].outcome, runs[3].failure = Outcome.FAILED, errored
    with opened(store_url) as store:
        ledger = add_sweep(store, "gamma", "ppo.gamma", [0.1, 0.2], runs)
        before = {t.user_attrs["key"]: t.number for t in ledger.trials()}
        stream = io.StringIO()
        assert retry_failed(ledger, stream) == 1
        queued = [t for t in ledger.trials() if t.state == TrialState.WAITING]
        assert [t.user_attrs["key"] for t in queued] == ["v1-s1"]
        assert queued[0].user_attrs["retry_of"] == before["v1-s1"]
        assert queued[0].user_attrs["retried_failure"] == errored
        assert stream.getvalue().splitlines() == [
            f"1 failed trial(s) of gamma queued again with the same seeds and settings: "
            f"{before['v1-s1']}",
            "1 diverged run(s) of gamma not queued again: a divergence is a result of its "
            "settings"]
        # The diverged run still counts as failed; list offers no retry once the error is
        # queued again.
        standing = study_standing(ledger)
        assert (standing.tally.failed, standing.tally.diverged) == (1, 1)
        assert standing.retry_line() is None
