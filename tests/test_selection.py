"""The selection rules (kraby_study.decision.selection) on constructed data, checked by hand."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from optuna.distributions import FloatDistribution
from optuna.trial import FrozenTrial, TrialState, create_trial

from kraby_study.answers.seed_scores import samples, sweep_comparison
from kraby_study.decision.comparison import MARGIN, CompareOptions
from kraby_study.decision.selection import select
from kraby_study.errors import ConfigError
from kraby_study.records.attributes import SelectRule

# Three values of n_epochs: 30 is best, 10 within the margin of it on 6 seeds, 1 far worse; 30
# is the slowest, 1 the fastest, 10 in between.
FINAL = {0: [-0.50, -0.52, -0.51, -0.49, -0.53, -0.50],
         1: [-0.200, -0.202, -0.198, -0.201, -0.199, -0.200],
         2: [-0.190, -0.191, -0.189, -0.190, -0.192, -0.188]}
SECONDS = {0: [10.0, 11.0, 12.0], 1: [30.0, 31.0, 29.0], 2: [90.0, 95.0, 85.0]}
AUCS = {0: [-0.6, -0.6, -0.6], 1: [-0.3, -0.35, -0.4], 2: [-0.33, -0.34, -0.35]}


def chosen(rule: str, final: dict, aucs: dict, seconds: dict, dropped: tuple = (),
           margin: float = MARGIN) -> object:
    """The value ``rule`` selects from the study's one comparison, as a stored sweep does."""
    comparison = sweep_comparison(final, dropped, CompareOptions(margin=margin))
    return select(rule, comparison, aucs, seconds)


def test_the_three_rules_on_constructed_data() -> None:
    comparison = sweep_comparison(FINAL, (), CompareOptions())
    assert comparison.best == 2  # IQM -0.190 beats -0.200 and -0.51
    assert comparison.equivalent == [1] and comparison.worse == [0]
    assert chosen("final_score", FINAL, AUCS, SECONDS) == 2
    # Of the best and the value shown equivalent to it, 10 trains in 30 s against 90 s.
    assert chosen("fastest_equivalent", FINAL, AUCS, SECONDS) == 1
    # 1 is the fastest of all, but it is worse than the best: never selected.
    assert chosen("auc", FINAL, AUCS, SECONDS) == 2  # mean AUC -0.34 against -0.35 and -0.6


def test_fastest_equivalent_is_the_best_value_when_nothing_is_equivalent() -> None:
    final = {0: [1.0, 1.01, 0.99, 1.0], 1: [5.0, 5.01, 4.99, 5.0]}
    seconds = {0: [1.0, 1.0, 1.0], 1: [100.0, 100.0, 100.0]}
    assert chosen("fastest_equivalent", final, {}, seconds) == 1
    # At margin 0 no value is equivalent: the best.
    assert chosen("fastest_equivalent", FINAL, AUCS, SECONDS, margin=0.0) == 2


def test_no_complete_run_selects_nothing_and_nan_never_wins() -> None:
    for rule in SelectRule:
        assert chosen(rule, {}, {}, {}) is None
    assert chosen("final_score", {0: [math.nan] * 2, 1: [-1.0, -2.0]}, {}, {}) == 1
    assert chosen("auc", {0: [1.0, 1.0], 1: [0.0, 0.0]}, {0: [math.nan], 1: [-1.0]}, {}) == 1


def test_an_unknown_rule_is_one_line() -> None:
    with pytest.raises(ConfigError, match="study.select must be one of final_score, auc, "
                                          "fastest_equivalent, got 'best'"):
        SelectRule.check("best")


def test_the_retired_rule_is_refused_in_a_config_and_read_as_today_s_when_stored() -> None:
    with pytest.raises(ConfigError, match="study.select: fastest_tied is retired; use "
                                          "fastest_equivalent"):
        SelectRule.check("fastest_tied")
    assert SelectRule.of("fastest_tied") == SelectRule.FASTEST_EQUIVALENT
    assert SelectRule.of("fastest_equivalent") == SelectRule.FASTEST_EQUIVALENT
    assert SelectRule.of(None) == SelectRule.FINAL_SCORE


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
    assert chosen("auc", found.final, found.aucs, found.seconds) == 0
    assert chosen("final_score", found.final, found.aucs, found.seconds) == 0


def test_a_value_a_race_dropped_is_never_selected_by_any_rule() -> None:
    # Dropping the best (30) leaves 10 the best of the survivors under every rule.
    for rule in SelectRule:
        assert chosen(rule, FINAL, AUCS, SECONDS, dropped=(2,)) == 1
    # Dropping the equivalent 10 leaves fastest_equivalent nothing to trade for time.
    assert chosen("fastest_equivalent", FINAL, AUCS, SECONDS, dropped=(1,)) == 2
    assert chosen("final_score", FINAL, AUCS, SECONDS, dropped=(0, 1, 2)) is None


def test_the_comparison_takes_the_dropped_values_by_their_index_in_values() -> None:
    trials = [_trial(n, score, gamma, 10.0) for n, (score, gamma) in enumerate(
        [(-1.0, 0.8), (-1.1, 0.8), (-0.5, 0.9), (-0.6, 0.9)])]
    for values, dropped, best in (([0.8, 0.9], (), 1), ([0.8, 0.9], (1,), 0),
                                  ([0.9, 0.8], (1,), 0)):
        found = samples(trials, None, "gamma", values)
        assert sweep_comparison(found.final, dropped, CompareOptions()).best == best
