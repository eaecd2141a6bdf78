"""The record schema (kraby_study.records) on hand-made Optuna trials: outcomes, which attempt
counts, tallies, the equality rule of swept values, the selected value, the best trial, and the
stored attribute names."""

from __future__ import annotations

import random
from typing import Any

import pandas as pd
import pytest
from optuna.distributions import FloatDistribution, IntDistribution
from optuna.trial import FrozenTrial, TrialState, create_trial

from kraby_study.answers.seed_scores import samples, sweep_comparison
from kraby_study.decision.comparison import CompareOptions
from kraby_study.decision.selection import select
from kraby_study.records.attributes import StudyAttrs, TrialAttrs
from kraby_study.records.stored import (
    Failure,
    Outcome,
    Tally,
    counted,
    failure,
    failure_kind,
    is_interrupted,
    latest_by_key,
    outcome,
    parse_sweep_key,
    search_key,
    sweep_key,
    tally,
    train_key,
)
from kraby_study.records.values import best_trial, ranking, swept_value, value_key

COMPLETE, PRUNED, FAIL = TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL
RUNNING, WAITING = TrialState.RUNNING, TrialState.WAITING


def trial(number: int, state: TrialState = COMPLETE, value: float | None = None,
          params: dict[str, Any] | None = None, system_attrs: dict[str, Any] | None = None,
          **attrs: Any) -> FrozenTrial:
    """A stored-looking trial: create_trial numbers every trial -1, so the number is set here."""
    if state == COMPLETE and value is None:
        value = 0.0
    distributions = {
        name: FloatDistribution(-10, 10) if isinstance(v, float) else IntDistribution(-10, 10)
        for name, v in (params or {}).items()}
    made = create_trial(state=state, value=value, params=params, distributions=distributions,
                        user_attrs=attrs, system_attrs=system_attrs)
    made.number = number
    return made


def numbers(trials: list[FrozenTrial]) -> list[int]:
    return [t.number for t in trials]


# Outcomes ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("state,reason,expected", [
    (COMPLETE, None, Outcome.COMPLETE),
    (PRUNED, None, Outcome.PRUNED),
    (FAIL, "diverged: loss is NaN at 2048 env steps", Outcome.FAILED),
    (FAIL, "error: ValueError: bad shape", Outcome.FAILED),
    (FAIL, "a reason from another tool", Outcome.FAILED),
    # Given back unfinished: the run is queued again, this attempt is no result.
    (FAIL, "interrupted: stopped by the user", Outcome.PENDING),
    # No reason: Optuna's heartbeat failed it (its owner was lost).
    (FAIL, None, Outcome.PENDING),
    (WAITING, None, Outcome.PENDING),
    (RUNNING, None, Outcome.PENDING),
])
def test_outcome_reads_the_state_and_the_failure_reason(state: TrialState, reason: str | None,
                                                        expected: Outcome) -> None:
    attrs = {} if reason is None else {"failure": reason}
    t = trial(0, state, **attrs)
    assert outcome(t) == expected
    assert is_interrupted(t) == (state == FAIL and expected == Outcome.PENDING)


# Which attempts count ----------------------------------------------------------------------------


def test_the_latest_attempt_of_each_key_counts_and_a_named_retry_replaces_a_keyless_trial() -> None:
    trials = [
        trial(0, FAIL, key="v0-s0", failure="interrupted: stopped by the user"),
        trial(1, COMPLETE, 1.0, key="v0-s1"),
        trial(2, COMPLETE, 2.0, key="v0-s0"),  # the rerun of 0: replaces it
        trial(3, FAIL),  # no key, failed by the heartbeat ...
        trial(4, COMPLETE, 3.0, key="t4", retry_of=3),  # ... and run again as 4
        trial(5, COMPLETE, 4.0),  # no key, named by no retry: counts
        trial(6, FAIL, key="v1-s0", failure="diverged: NaN"),  # the only attempt: counts
    ]
    shuffled = trials[:]
    random.Random(1).shuffle(shuffled)
    assert numbers(counted(shuffled)) == [1, 2, 4, 5, 6]  # in trial-number order
    assert {k: t.number for k, t in latest_by_key(shuffled).items()} == {
        "v0-s0": 2, "v0-s1": 1, "t4": 4, "v1-s0": 6}


def test_a_keyless_trial_counts_unless_a_later_trial_names_it() -> None:
    assert numbers(counted([trial(0), trial(1)])) == [0, 1]
    assert numbers(counted([trial(0), trial(1, retry_of=0)])) == [1]


def test_tally_counts_each_outcome() -> None:
    trials = [
        trial(0, COMPLETE, 1.0), trial(1, COMPLETE, 2.0),
        trial(2, FAIL, failure="diverged: NaN"),
        trial(3, PRUNED),
        trial(4, FAIL, failure="interrupted: worker died"),
        trial(5, RUNNING),
        trial(6, WAITING),
    ]
    counts = tally(trials)
    assert counts == Tally(complete=2, failed=1, pruned=1, pending=3)
    assert counts.ended == 4  # complete, failed and pruned; not pending
    assert tally([]) == Tally()


# Values and the best one -------------------------------------------------------------------------


def test_value_key_compares_numbers_by_value_and_the_rest_by_json() -> None:
    assert value_key(1) == value_key(1.0)
    assert value_key(0.5) != value_key(1)
    assert value_key("1") != value_key(1)
    assert value_key(True) != value_key(1)  # a bool is not the number 1
    assert value_key([64, 64]) == value_key([64, 64])
    assert value_key([64, 64]) != value_key([64])
    assert value_key([64, 64]) == value_key([64.0, 64.0])  # numbers inside lists too
    assert value_key({"lr": 1}) == value_key({"lr": 1.0})
    assert value_key({"a": 1, "b": 2}) == value_key({"b": 2, "a": 1})
    assert value_key("default") != value_key("with_tip")


def chosen(trials: list[FrozenTrial], name: str, values: list[Any]) -> tuple[Any, float] | None:
    """The value the final_score rule selects, and its mean; None when none is complete."""
    found = samples(trials, pd.DataFrame(columns=["number", "step", "mean_reward"]), name, values)
    vi = select("final_score", sweep_comparison(found.final, (), CompareOptions()), found.aucs,
                found.seconds)
    return None if vi is None else (values[vi], sum(found.final[vi]) / len(found.final[vi]))


def test_selection_groups_one_and_one_point_zero_as_one_value() -> None:
    trials = [
        trial(0, COMPLETE, 3.0, params={"n_epochs": 1}),
        trial(1, COMPLETE, 1.0, params={"n_epochs": 1.0}),
        trial(2, COMPLETE, 2.5, params={"n_epochs": 2}),
        trial(3, COMPLETE, 2.5, params={"n_epochs": 2}),
    ]
    # One group {1, 1.0}: mean (3 + 1) / 2 = 2 < 2.5, so 2 wins (apart, 1 would win with 3).
    # (Every value has the 2 complete seeds a selection needs: report.min_seeds.)
    assert chosen(trials, "n_epochs", [1, 2]) == (2, 2.5)
    assert chosen(trials[:2], "n_epochs", [1, 2]) == (1, 2.0)


def test_selection_takes_the_highest_mean_over_complete_trials_only() -> None:
    trials = [
        trial(0, COMPLETE, -2.0, params={"gamma": 0.5}),
        trial(1, COMPLETE, -4.0, params={"gamma": 0.5}),  # gamma 0.5: mean -3
        trial(2, COMPLETE, -1.0, params={"gamma": 0.9}),  # gamma 0.9: mean -1 ...
        trial(3, FAIL, params={"gamma": 0.9}, failure="diverged: NaN"),  # ... a failure is no 0
        trial(4, PRUNED, 9.0, params={"gamma": 0.99}),  # its last intermediate value: no score
        trial(5, RUNNING, params={"gamma": 0.99}),
        trial(6, COMPLETE, -1.0, params={"gamma": 0.9}),
    ]
    assert chosen(trials, "gamma", [0.5, 0.9, 0.99]) == (0.9, -1.0)
    assert chosen(trials[3:6], "gamma", [0.5, 0.9, 0.99]) is None
    # One complete seed is too little evidence to be selected (report.min_seeds, default 2).
    assert chosen(trials[2:], "gamma", [0.5, 0.9, 0.99]) == (0.9, -1.0)
    assert chosen(trials[2:6], "gamma", [0.5, 0.9, 0.99]) is None


@pytest.mark.parametrize("values", [[0.2, 0.1], [0.1, 0.2]])
def test_a_tie_goes_to_the_first_value_in_the_study_order(values: list[float]) -> None:
    trials = [trial(0, COMPLETE, 1.0, params={"clip_range": 0.1}),
              trial(1, COMPLETE, 1.0, params={"clip_range": 0.2}),
              trial(2, COMPLETE, 1.0, params={"clip_range": 0.1}),
              trial(3, COMPLETE, 1.0, params={"clip_range": 0.2})]
    assert chosen(trials, "clip_range", values) == (values[0], 1.0)


def test_the_swept_value_comes_from_the_params_the_queued_params_or_the_key() -> None:
    planned = [0.1, 0.2, 0.3]
    assert swept_value(trial(0, params={"clip_range": 0.3}, key="v0-s0"), "clip_range",
                       planned) == 0.3
    # A queued trial (study.enqueue_trial) holds its value in fixed_params until it runs.
    queued = trial(1, WAITING, key="v0-s1", system_attrs={"fixed_params": {"clip_range": 0.2}})
    assert swept_value(queued, "clip_range", planned) == 0.2
    assert swept_value(trial(2, FAIL, key="v2-s0"), "clip_range", planned) == 0.3
    assert swept_value(trial(3, FAIL, key="v3-s0"), "clip_range", planned) is None
    assert swept_value(trial(4, FAIL, key="t4"), "clip_range", planned) is None


def test_selection_reads_the_value_of_a_trial_without_params_from_its_key() -> None:
    trials = [trial(0, COMPLETE, 1.0, key="v0-s0"), trial(1, COMPLETE, 5.0, key="v1-s0"),
              trial(2, COMPLETE, 1.0, key="v0-s1"), trial(3, COMPLETE, 5.0, key="v1-s1")]
    assert chosen(trials, "gamma", [0.8, 0.9]) == (0.9, 5.0)


def test_best_trial_maximises_or_minimises_over_complete_trials() -> None:
    trials = [
        trial(0, COMPLETE, 2.0),
        trial(1, COMPLETE, 3.0),
        trial(2, COMPLETE, 1.0),
        trial(3, PRUNED, 9.0),  # a pruned trial's last value is not a score
        trial(4, FAIL, failure="error: boom"),
    ]
    assert best_trial(trials).number == 1  # type: ignore[union-attr]
    assert best_trial(trials, maximize=True).number == 1  # type: ignore[union-attr]
    assert best_trial(trials, maximize=False).number == 2  # type: ignore[union-attr]
    assert best_trial(trials[3:]) is None
    assert best_trial([]) is None


def test_of_equal_scores_the_surer_then_the_cheaper_trial_ranks_first() -> None:
    # Three trials at the ceiling: 10 CPU s per seed, 3 per seed (6 over 2 seeds), unknown.
    tied = [trial(0, COMPLETE, 500.0, cpu_time=20.0, scores=[500.0, 500.0]),
            trial(1, COMPLETE, 500.0),
            trial(2, COMPLETE, 500.0, cpu_time=6.0, scores=[500.0, 500.0]),
            trial(3, COMPLETE, 499.0, cpu_time=1.0, scores=[499.0, 499.0])]
    assert best_trial(tied).number == 2  # type: ignore[union-attr]
    assert [t.number for t in sorted(tied, key=ranking)] == [2, 0, 1, 3]
    assert ranking(tied[2]) == (-500.0, -2, 3.0, 2)
    # A tie that held on more seeds (a recheck's) ranks before a cheaper one on fewer.
    rechecked = trial(5, COMPLETE, 500.0, cpu_time=50.0, scores=[500.0] * 5)
    assert best_trial([*tied, rechecked]).number == 5  # type: ignore[union-attr]
    assert ranking(rechecked) == (-500.0, -5, 10.0, 5)
    # Of equal costs (or none), the earlier; minimising, the lowest score still comes first.
    assert best_trial([trial(4, COMPLETE, 1.0), trial(5, COMPLETE, 1.0)]).number == 4  # type: ignore[union-attr]
    assert best_trial(tied, maximize=False).number == 3  # type: ignore[union-attr]


# Stored attributes -------------------------------------------------------------------------------


def test_trial_attrs_store_only_the_fields_that_are_set() -> None:
    attrs = TrialAttrs(key="v0-s1", seed=1, final_score=0.0, env_steps=0, retry_of=None)
    # 0 and 0.0 are values, not "unset": only None is left out.
    assert attrs.stored() == {"key": "v0-s1", "seed": 1, "final_score": 0.0, "env_steps": 0}
    assert TrialAttrs().stored() == {}


def test_trial_attrs_read_back_from_a_trial_ignoring_unknown_attributes() -> None:
    attrs = TrialAttrs(key="t3", seed=7, settings={"ppo": {"gamma": 0.9}}, steps=4096,
                       failure="diverged: NaN", retry_of=2)
    stored = trial(3, FAIL, **attrs.stored(), dashboard_note="not ours")
    assert TrialAttrs.of(stored) == attrs


def test_study_attrs_are_stored_under_prefixed_names_but_for_the_sampler() -> None:
    attrs = StudyAttrs(kind="search", definition={"kind": "search", "steps": 4096},
                       fingerprint="abc123", planned=20, sampler="tpe", sampler_seed=3)
    stored = attrs.stored()
    assert stored == {
        "kraby_kind": "search",
        "kraby_definition": {"kind": "search", "steps": 4096},
        "kraby_fingerprint": "abc123",
        "kraby_planned": 20,
        "sampler": "tpe",
        "sampler_seed": 3,
    }
    assert StudyAttrs.of({**stored, "other_tool": 1}) == attrs
    assert StudyAttrs().stored() == {}
    assert StudyAttrs.of({}) == StudyAttrs()


# Keys and failure reasons ------------------------------------------------------------------------


def test_sweep_keys_round_trip_and_other_keys_parse_to_none() -> None:
    assert sweep_key(3, 12) == "v3-s12"
    assert parse_sweep_key(sweep_key(3, 12)) == (3, 12)
    assert parse_sweep_key(sweep_key(0, 0)) == (0, 0)
    assert parse_sweep_key("t3") is None
    assert parse_sweep_key(search_key(3)) is None
    assert parse_sweep_key(train_key(3)) is None
    assert parse_sweep_key("v3-s12x") is None
    assert parse_sweep_key(None) is None


@pytest.mark.parametrize("kind", list(Failure))
def test_a_failure_reason_names_its_kind(kind: Failure) -> None:
    reason = failure(kind, "ValueError: a detail with a colon")
    assert reason == f"{kind.value}: ValueError: a detail with a colon"
    assert failure_kind(reason) == kind


def test_a_failure_reason_is_one_line() -> None:
    reason = failure(Failure.ERROR, "Traceback:\n  File x\n\tValueError:  bad\n")
    assert reason == "error: Traceback: File x ValueError: bad"
    assert failure_kind(reason) == Failure.ERROR


def test_a_reason_naming_no_kind_has_none() -> None:
    assert failure_kind(None) is None
    assert failure_kind("") is None
    assert failure_kind("boom: it broke") is None
