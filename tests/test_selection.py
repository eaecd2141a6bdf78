"""The selection rules (kraby_study.decision.selection) on constructed data, checked by hand."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from optuna.distributions import FloatDistribution
from optuna.trial import FrozenTrial, TrialState, create_trial

from kraby_study.answers.seed_scores import samples, selected_index
from kraby_study.decision.selection import select
from kraby_study.decision.verdict import holm_vs_best
from kraby_study.errors import ConfigError
from kraby_study.records.attributes import SelectRule

# Three values of n_epochs: 30 is best, 10 is statistically tied with it (its seeds overlap 30's),
# 1 is far worse; 30 is the slowest, 1 the fastest, 10 in between.
FINAL = {0: [-0.50, -0.52, -0.51], 1: [-0.20, -0.22, -0.30], 2: [-0.19, -0.20, -0.21]}
SECONDS = {0: [10.0, 11.0, 12.0], 1: [30.0, 31.0, 29.0], 2: [90.0, 95.0, 85.0]}
AUCS = {0: [-0.6, -0.6, -0.6], 1: [-0.3, -0.35, -0.4], 2: [-0.33, -0.34, -0.35]}


def test_the_three_rules_on_constructed_data() -> None:
    best, p_holm = holm_vs_best(FINAL)
    assert best == 2  # mean -0.20 beats -0.24 and -0.51
    assert p_holm[1] >= 0.05 > p_holm[0]  # 10 is tied with 30, 1 is not
    assert select("final_score", FINAL, AUCS, SECONDS) == 2
    # Of the tied values {30, 10}, 10 trains in 30 s against 90 s: the documented compromise.
    assert select("fastest_tied", FINAL, AUCS, SECONDS) == 1
    # 1 is the fastest of all, but it is not tied with the best: never selected.
    assert select("auc", FINAL, AUCS, SECONDS) == 2  # mean AUC -0.34 against -0.35 and -0.6


def test_fastest_tied_is_the_best_value_when_nothing_is_tied() -> None:
    final = {0: [1.0, 1.01, 0.99], 1: [5.0, 5.01, 4.99]}
    seconds = {0: [1.0, 1.0, 1.0], 1: [100.0, 100.0, 100.0]}
    assert select("fastest_tied", final, {}, seconds) == 1


def test_fastest_tied_ignores_a_value_with_too_few_seeds_to_test() -> None:
    # One seed gives no Welch test (NaN p), so that value is not tied, however fast.
    final = {0: [1.0], 1: [5.0, 5.2, 4.8]}
    seconds = {0: [1.0], 1: [100.0, 100.0, 100.0]}
    assert select("fastest_tied", final, {}, seconds) == 1


def test_no_complete_run_selects_nothing_and_nan_never_wins() -> None:
    for rule in SelectRule:
        assert select(rule, {}, {}, {}) is None
    assert select("final_score", {0: [math.nan] * 2, 1: [-1.0, -2.0]}, {}, {}) == 1
    assert select("auc", {0: [1.0, 1.0], 1: [0.0, 0.0]}, {0: [math.nan], 1: [-1.0]}, {}) == 1


def test_an_unknown_rule_is_one_line() -> None:
    with pytest.raises(ConfigError, match="study.select must be one of final_score, auc, "
                                          "fastest_tied, fastest_equivalent, got 'best'"):
        SelectRule.check("best")


def _trial(number: int, value: float, gamma: float, wall: float) -> FrozenTrial:
    made = create_trial(state=TrialState.COMPLETE, value=value, params={"gamma": gamma},
                        distributions={"gamma": FloatDistribution(0.0, 1.0)},
                        user_attrs={"key": f"v{number}", "wall_time": wall})
    made.number = number
    return made


def test_samples_group_stored_trials_by_value_with_auc_and_time() -> None:
    trials = [_trial(0, -1.0, 0.8, 10.0), _trial(1, -3.0, 0.8, 20.0), _trial(2, -2.0, 0.9, 5.0)]
    curves = pd.DataFrame({"number": [0, 0, 1, 1, 2, 2], "step": [2, 1, 1, 2, 1, 2],
                           "mean_reward": [-1.0, -3.0, -2.0, -4.0, -5.0, -1.0]})
    found = samples(trials, curves, "gamma", [0.8, 0.9])
    assert found.final == {0: [-1.0, -3.0], 1: [-2.0]}
    assert found.seconds == {0: [10.0, 20.0], 1: [5.0]}
    # AUC is the mean of a run's curve in step order: (-3 - 1) / 2, (-2 - 4) / 2, (-5 - 1) / 2.
    assert found.aucs == {0: [-2.0, -3.0], 1: [-3.0]}
    assert select("auc", found.final, found.aucs, found.seconds) == 0
    assert select("final_score", found.final, found.aucs, found.seconds) == 0


def test_a_value_a_race_dropped_is_never_selected_by_any_rule() -> None:
    # Dropping the best (30) leaves 10 the best of the survivors under every rule.
    for rule in SelectRule:
        assert select(rule, FINAL, AUCS, SECONDS, dropped=[2]) == 1
    # Dropping the tied 10 leaves fastest_tied no tie to trade for time: the best, 30.
    assert select("fastest_tied", FINAL, AUCS, SECONDS, dropped=[1]) == 2
    assert select("final_score", FINAL, AUCS, SECONDS, dropped=[0, 1, 2]) is None


def test_selected_index_takes_the_dropped_values_by_their_index_in_values() -> None:
    trials = [_trial(n, score, gamma, 10.0) for n, (score, gamma) in enumerate(
        [(-1.0, 0.8), (-1.1, 0.8), (-0.5, 0.9), (-0.6, 0.9)])]
    assert selected_index(trials, None, "gamma", [0.8, 0.9], "final_score") == 1
    assert selected_index(trials, None, "gamma", [0.8, 0.9], "final_score", dropped=[1]) == 0
    assert selected_index(trials, None, "gamma", [0.9, 0.8], "final_score", dropped=[1]) == 0
