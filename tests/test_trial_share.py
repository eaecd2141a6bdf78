"""A search's cap on one trial's CPU seconds (search.trial_share): a trial projected past its
share of the CPU budget is stopped at a checkpoint and stored as pruned."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from conftest import TINY, TINY_SEARCH, load, refused_before_work, run_cli
from optuna.trial import TrialState

from kraby_study.answers.search_evidence import trial_rows
from kraby_study.config.compose import compose_config
from kraby_study.plan.space import search_definition
from kraby_study.records.attributes import StudyAttrs, TrialAttrs
from kraby_study.run.search_source import SearchSource
from kraby_study.store.store import opened

SPACE = TINY_SEARCH.replace("enqueue: []", "enqueue: [start]")
"""The tiny space with a known configuration (ppo=start) evaluated first, as a gym search
evaluates rl-zoo3's settings."""


@contextmanager
def _source(tmp_path: Path, *overrides: str) -> Iterator[SearchSource]:
    """A search source on a new store, the smoke budget on 2 seeds."""
    cfg = compose_config(["budget=smoke", "budget.seeds=2", "save_models=false",
                          f"storage=sqlite:///{tmp_path}/k.db", *overrides])
    with opened(cfg.storage) as store:
        yield SearchSource(store.define("s", StudyAttrs(kind="search")), cfg)


def test_a_trial_projected_past_its_share_of_the_budget_is_stopped(tmp_path: Path) -> None:
    with _source(tmp_path, "search.cpu_budget=400", "search.trial_share=0.25") as source:
        claimed = source.next_trial()
        assert claimed is not None
        number, spec = claimed
        total = spec.steps * spec.seeds
        # A fifth of the way in after 10 CPU s: 10 + 40 to its end, within 100 (0.25 x 400).
        source.using(number, total // 5, 10.0)
        assert source.checkpoint(number, total // 5, -1.0) is True
        # Two fifths of the way in after 60 CPU s: 60 + 90 = 150 projected, past 100.
        source.using(number, 2 * total // 5, 60.0)
        assert source.checkpoint(number, 2 * total // 5, -2.0) is False
        trial = next(t for t in source.ledger.trials() if t.number == number)
        assert trial.user_attrs["cost_stop"] == pytest.approx(150.0)
        # Its values were reported, the last before the stop, as the pruner's are.
        assert trial.intermediate_values == {total // 5: -1.0, 2 * total // 5: -2.0}


def test_an_enqueued_configuration_is_never_stopped_for_its_cost(tmp_path: Path) -> None:
    with _source(tmp_path, "search.cpu_budget=400", "search.trial_share=0.25") as source:
        first = source.next_trial()
        assert first is not None
        params = next(t.params for t in source.ledger.trials() if t.number == first[0])
        source.ledger.queue(params, TrialAttrs(enqueued="ppo=zoo"))
        claimed = source.next_trial()
        assert claimed is not None
        number, spec = claimed
        source.using(number, spec.steps * spec.seeds // 5, 1000.0)
        assert source.checkpoint(number, spec.steps, -1.0) is True
        # The first trial, sampled, is stopped at the same use.
        source.using(first[0], spec.steps * spec.seeds // 5, 1000.0)
        assert source.checkpoint(first[0], spec.steps, -1.0) is False


def test_without_a_share_no_trial_is_stopped_for_its_cost(tmp_path: Path) -> None:
    with _source(tmp_path, "search.cpu_budget=400") as source:
        claimed = source.next_trial()
        assert claimed is not None
        number, spec = claimed
        source.using(number, spec.steps * spec.seeds // 5, 1000.0)
        assert source.checkpoint(number, spec.steps, -1.0) is True
        assert "cost_stop" not in next(
            t for t in source.ledger.trials() if t.number == number).user_attrs


def test_a_search_without_a_share_keeps_the_definition_it_had_before_shares() -> None:
    plain = search_definition(compose_config(["search.cpu_budget=400"]))["search"]
    assert "trial_share" not in plain
    shared = search_definition(compose_config(["search.cpu_budget=400",
                                               "search.trial_share=0.25"]))["search"]
    assert shared["trial_share"] == 0.25


@pytest.mark.parametrize("argv,message", [
    (["search.trial_share=0.25"], "set --cpu-budget too"),
    (["--cpu-budget", "100", "search.trial_share=0"], "must be in (0, 1]"),
    (["--cpu-budget", "100", "--trial-share", "1.5"], "must be in (0, 1]"),
    (["--cpu-budget", "100", "search.trial_share=0.5", "--objective",
      "final_reward,training_time"], "do not report"),
    (["--cpu-budget", "100", "search.trial_share=0.5", "--pruner", "wilcoxon",
      "budget.seeds=5"], "do not report"),
])
def test_a_share_that_cannot_act_is_refused_before_anything_runs(
        workdir: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
        message: str) -> None:
    assert message in refused_before_work(workdir, capsys, "optuna", *argv)


def test_a_search_stops_its_dear_trials_and_keeps_its_enqueued_one(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = workdir / "conf" / "search"
    folder.mkdir(parents=True)
    (folder / "tiny.yaml").write_text(SPACE)
    # A cap of a thousandth of a CPU second: every sampled trial is past it by its first
    # checkpoint (a quarter of its first seed), ppo=start, evaluated first, is not stopped.
    args = ["search=tiny", "--workers", "1", *TINY, "budget.seeds=1", "--cpu-budget", "1000",
            "--trial-share", "0.000001"]
    assert run_cli("optuna", "--dry-run", *args) == 0
    assert "a trial projected past 0 CPU s stopped" in capsys.readouterr().out
    assert run_cli("optuna", *args) == 0
    out = capsys.readouterr().out
    assert "(search.trial_share 1e-06)" in out
    assert "3 of 3 trials; 2 stopped past 0 CPU s (search.trial_share)" in out
    # Each stopped trial's progress line says why it was pruned.
    stopped = [line for line in out.splitlines() if "pruned at 128 env steps:" in line]
    assert len(stopped) == 2
    assert all("past the cap of 0 (search.trial_share)" in line for line in stopped)
    trials = load(workdir / "studies" / "kraby.db", "tiny").trials
    assert [t.state for t in trials] == [TrialState.COMPLETE, TrialState.PRUNED,
                                         TrialState.PRUNED]
    assert trials[0].user_attrs["enqueued"] == "ppo=start"
    assert "cost_stop" not in trials[0].user_attrs
    for trial in trials[1:]:
        assert trial.user_attrs["cost_stop"] > 0.001
        assert trial.user_attrs["pruned_at"] == 128  # the first checkpoint: 512 / 4
    # The report's trial table says which trials were stopped for their cost.
    rows = trial_rows(trials, ["learning_rate", "gamma"])
    assert rows["cost_stop"].isna().tolist() == [True, False, False]
    assert (rows["cost_stop"][1:] == [t.user_attrs["cost_stop"] for t in trials[1:]]).all()
