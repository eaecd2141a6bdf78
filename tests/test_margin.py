"""Issue 35's four answers on constructed data with answers worked out by hand: best,
equivalent, worse and undecided at a margin; the noisy, cheap candidate that must not be
selected; the old behaviour at margin 0; races that settle; bad input refused."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats
from synthetic import percentile_p, yuen_p

from kraby_study.config.compose import compose_config
from kraby_study.decision.comparison import Answer, CompareOptions, compare
from kraby_study.decision.front import Point, front_choice
from kraby_study.decision.race import race
from kraby_study.decision.selection import RULES, select
from kraby_study.errors import ConfigError
from kraby_study.plan.spec import RaceRules

DEVIATIONS = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
"""Five seeds' deviations from their mean: sd sqrt(10 / 4) = 1.581."""
TEN = np.linspace(-1.0, 1.0, 10)
"""Ten seeds' deviations, symmetric about 0: their IQM is their mean."""


def _five(mean: float, scale: float = 0.05) -> list[float]:
    """Five seeds at ``mean`` (their IQM too, the deviations being symmetric)."""
    return list(mean + scale * DEVIATIONS)


def test_the_four_answers_by_hand() -> None:
    # Four values of 10 seeds, their IQMs -1.0, -1.01, -1.5 and -1.12 (symmetric deviations,
    # sd 0.12 x 0.61). The margin is 0.2 x |best IQM -1.0| = 0.2 in score units; "j above g by
    # more than it" is the contrast 1.2 T_j - T_g > 0 (scores below 0). Each p is the larger of
    # the percentile bootstrap's and Yuen's (SciPy's).
    final = {g: list(m + 0.12 * TEN) for g, m in
             {"A": -1.0, "B": -1.01, "C": -1.5, "D": -1.12}.items()}
    result = compare(final, 0.2)
    assert result.best == "A" and result.margin == pytest.approx(0.2)
    # B: equivalent needs every other value's contrast 1.2 T_j - T_B < 0 shown, at 0.05 / 3:
    # p_equivalent = 3 x the largest of the three p, A's: its contrast -1.2 + 1.01 = -0.19 lies
    # about 4 standard errors below 0.
    less = [max(percentile_p(final[j], final["B"], 1.2)[1], yuen_p(final[j], final["B"], 1.2)[1])
            for j in ("A", "C", "D")]
    assert result.p_equivalent["B"] == pytest.approx(3 * max(less), rel=1e-12)
    assert 3 * max(less) < 0.05
    # C: A beats it by 0.3 beyond the margin: pi_C = 3 x p, the smallest of the pi's, x 4 by
    # Holm: worse. D: A's contrast -1.2 + 1.12 = -0.08 shows neither.
    beaten = max(percentile_p(final["A"], final["C"], 1.2)[0], yuen_p(final["A"], final["C"],
                                                                      1.2)[0])
    assert result.p_worse["C"] == pytest.approx(4 * 3 * beaten, rel=1e-12)
    assert result.p_equivalent["D"] > 0.05 and result.p_worse["D"] > 0.5
    assert result.answers == {"A": Answer.BEST, "B": Answer.EQUIVALENT, "C": Answer.WORSE,
                              "D": Answer.UNDECIDED}
    assert (result.equivalent, result.worse, result.undecided) == (["B"], ["C"], ["D"])
    # The smallest margin these seeds resolve: (t(1 - 0.05 / 3, df) + t(0.8, df)) x the
    # standard error of Yuen's test of the contrast, its df Welch's on the 6 seeds kept.
    yuen = stats.ttest_ind(1.2 * np.asarray(final["A"]), np.asarray(final["B"]),
                           equal_var=False, trim=0.25)
    se = (1.2 * -1.0 + 1.01) / yuen.statistic
    resolvable = (stats.t.ppf(1 - 0.05 / 3, yuen.df) + stats.t.ppf(0.8, yuen.df)) * se
    assert result.resolvable["B"] == pytest.approx(resolvable, rel=1e-9)
    assert not result.below_resolution and "margin 0.2 in score units" in result.margin_text()
    # At a margin below it, the comparison says so.
    assert compare(final, 0.01).below_resolution
    assert "below what these seeds resolve" in compare(final, 0.01).resolution_text()


def test_an_answer_needs_both_tests() -> None:
    # Five seeds a side: each p is the larger of the bootstrap's and Yuen's (SciPy's own).
    final = {"A": _five(-1.0), "B": _five(-1.01), "C": _five(-1.3, 0.1)}
    result = compare(final, 0.2)
    for g in ("B", "C"):
        less = [max(percentile_p(final[j], final[g], 1.2)[1], yuen_p(final[j], final[g], 1.2)[1])
                for j in final if j != g]
        assert result.p_equivalent[g] == pytest.approx(min(1.0, 2 * max(less)), rel=1e-12)
    # Here Yuen's p is the larger for B against A (the bootstrap reaches its floor, 1 / 2000).
    assert yuen_p(final["A"], final["B"], 1.2)[1] > 1 / 2000
    assert result.answers["B"] == Answer.EQUIVALENT


def test_a_seed_that_fails_moves_the_iqm_little_and_is_counted_apart() -> None:
    # Ten seeds each; B equals A but for one seed of ten that failed (-5 against about -1).
    # Its mean is 0.4 below A's, twice the margin; its IQM is within 0.01 of A's, and it is
    # not answered worse. The failure is counted apart.
    a = list(-1.0 + 0.02 * TEN)
    b = [-5.0, *a[1:]]
    result = compare({"A": a, "B": b}, 0.2)
    assert np.mean(a) - np.mean(b) == pytest.approx(0.4, abs=0.01)
    assert abs(stats.trim_mean(a, 0.25) - stats.trim_mean(b, 0.25)) < 0.01
    assert result.best == "A" and result.answers["B"] != Answer.WORSE
    from kraby_study.decision.failed_seeds import failed_seeds, failure_line

    found = failed_seeds(b, failure_line(-8.0, float(np.mean(a))))  # below -4.5
    assert found.count == 1


def test_fewer_than_four_seeds_get_no_answer() -> None:
    # Three seeds a side: at 3 seeds the IQM is the mean and no test holds alpha on skewed
    # scores, so however far apart, the others are undecided, and the comparison says why.
    final = {"A": [-1.0, -1.01, -0.99], "B": [-1.0, -1.01, -0.99], "C": [-9.0, -9.1, -8.9]}
    result = compare(final, 0.2)
    assert result.answers == {"A": Answer.BEST, "B": Answer.UNDECIDED, "C": Answer.UNDECIDED}
    assert result.unanswered == ["B", "C"] and "fewer than 4 seeds" in result.unanswered_text()
    # A fourth seed answers them.
    final = {g: [*x, float(np.mean(x))] for g, x in final.items()}
    answered = compare(final, 0.2)
    assert answered.answers["C"] == Answer.WORSE and answered.unanswered == []


def test_margin_zero_answers_worse_by_the_iqm_step_down_and_nothing_equivalent() -> None:
    # At margin 0 the answers' step-down shows values below the best IQM, and no value is
    # equivalent: fastest_equivalent has nothing to trade for time, so it selects the best.
    rng = np.random.default_rng(35)
    for shape in ([4] * 4, [5] * 6, [10] * 3, [4, 6, 10], [5, 5, 8, 12]):
        final = {g: list(rng.normal(0.3 * g, 1.0, n)) for g, n in enumerate(shape)}
        k = len(final)
        best = max(final, key=lambda g: stats.trim_mean(final[g], 0.25))
        result = compare(final, 0.0)
        assert result.best == best and result.equivalent == []
        assert result.worse == [g for g in final if g != best and result.p_worse[g] < 0.05]
        seconds = {g: [10.0 * (k - g)] for g in final}
        assert select("fastest_equivalent", result, {}, seconds) == best
        assert select("final_score", result, {}, seconds) == best


def test_the_noisy_cheap_candidate_is_not_selected() -> None:
    # A front of two trials on 10 seeds: the best, -0.0140 with sd 0.001 at 20 CPU s per seed,
    # and a cheap one (8 CPU s) truly 0.004 worse, beyond the margin 0.2 x 0.0140 = 0.0028,
    # whose seeds spread seven times as far. Its spread hides the difference, but it shows no
    # equivalence either: the cheap trial is not selected.
    rng = np.random.default_rng(48)
    unit = rng.normal(size=10)
    unit = (unit - unit.mean()) / unit.std(ddof=1)
    best, cheap = list(-0.0140 + 0.001 * unit), list(-0.0180 + 0.007 * unit[::-1])
    seeds = {0: best, 1: cheap}
    front = [Point(1, float(np.mean(cheap)), 8.0), Point(0, float(np.mean(best)), 20.0)]
    result = compare(seeds, 0.2)
    # Equivalent: the IQM contrast 1.2 x T_best - T_cheap is about 1.2 x (-0.0140) + 0.0180 =
    # 0.0012 > 0: no evidence at all (p > 0.5).
    assert result.p_equivalent[1] > 0.5
    assert result.answers[1] == Answer.UNDECIDED
    evidence = front_choice(front, seeds, "fastest_equivalent", CompareOptions())
    assert evidence is not None and evidence.chosen.key == 0
    assert select("fastest_equivalent", result, {}, {0: [20.0], 1: [8.0]}) == 0


def test_campaign_and_tuned_at_the_full_budget_are_not_equivalent() -> None:
    # docs/results/index.md: 10 seeds each, -0.0140 (sd 0.0032) against ppo=tuned's -0.0216
    # (sd 0.0041). The default margin is 0.2 x the campaign's |IQM| (0.0029 here), below their
    # difference 0.0076, so tuned can never be shown within it: p_equivalent >= 0.5 whatever
    # the seeds' noise.
    unit = np.random.default_rng(34).normal(size=10)
    unit = (unit - unit.mean()) / unit.std(ddof=1)
    final = {"campaign": list(-0.0140 + 0.0032 * unit),
             "tuned": list(-0.0216 + 0.0041 * unit[::-1])}
    result = compare(final, CompareOptions().margin)
    assert result.margin == pytest.approx(0.2 * abs(stats.trim_mean(final["campaign"], 0.25)))
    assert result.p_equivalent["tuned"] > 0.5
    assert result.answers["tuned"] == Answer.WORSE
    # Only a margin above their difference (0.54 of the best's |mean|) could.
    assert compare(final, 0.5).answers["tuned"] != Answer.EQUIVALENT


def test_rules_are_named_objects() -> None:
    assert [str(name) for name in RULES] == ["final_score", "auc", "fastest_equivalent"]
    assert all(rule.description and rule.name == name for name, rule in RULES.items())
    # A value with too few seeds is never selected, by any rule (one clamp, in the comparison).
    final = {0: [1.0], 1: [0.5, 0.6, 0.55]}
    for name in RULES:
        assert select(name, compare(final, 0.2), {0: [9.0], 1: [1.0] * 3},
                      {0: [1.0], 1: [9.0] * 3}) == 1
    assert compare(final, 0.2, min_seeds=1).min_seeds == 2


def test_a_race_settles_what_is_shown_equivalent_and_ends() -> None:
    # Three values, 6 seeds, looks from round 4 at 0.05 / 3 each, margin 0.2 x |-1|. After
    # round 4: 1 is within 0.003 of 0 (settled), 2 is 1.0 below (dropped); only the best is
    # left racing, so the race is over after 12 runs.
    runs = {0: dict(enumerate([-1.00, -1.001, -0.999, -1.0005, -1.0, -1.0])),
            1: dict(enumerate([-1.0022, -1.0012, -1.0032, -1.0018])),
            2: dict(enumerate([-2.0, -2.001, -1.999, -2.0005]))}
    state = race([0, 1, 2], runs, RaceRules(seeds=6, min_seeds=4, margin=0.2))
    assert state.over and state.rounds == 4
    assert list(state.dropped) == [2] and list(state.settled) == [1]
    assert state.settled[1].answer == Answer.EQUIVALENT and state.settled[1].round == 4
    assert state.survivors == [0] and state.candidates == [0, 1]
    assert not state.wanted(1, 4) and not state.wanted(0, 4)
    # At margin 0 the race of earlier releases: nothing is settled, 0 and 1 race on.
    old = race([0, 1, 2], runs, RaceRules(seeds=6, min_seeds=4))
    assert old.settled == {} and list(old.dropped) == [2] and not old.over
    # A race stored with min_seeds 3 looks at round 3 too, and answers nothing there.
    stored = race([0, 1, 2], runs, RaceRules(seeds=6, min_seeds=3, margin=0.2))
    assert stored.dropped[2].round == 4 and stored.settled[1].round == 4
    # The rules store the margin, and a race stored without one replays at margin 0.
    rules = RaceRules(seeds=6, round_seeds=tuple(range(6)), min_seeds=4, margin=0.2)
    assert rules.stored()["margin"] == 0.2 and RaceRules.of({"racing": rules.stored()}) == rules
    assert "margin" not in RaceRules(seeds=6, round_seeds=tuple(range(6))).stored()


@pytest.mark.parametrize(("override", "message"), [
    ("compare.margin=-0.1", "compare.margin must be at least 0"),
    ("compare.margin=1.5", "compare.margin is a fraction of the best's |IQM|: at most 1"),
    ("compare.select=cheapest", "compare.select must be one of final_score, auc"),
    ("study.select=cheapest", "study.select must be one of final_score, auc"),
])
def test_bad_comparison_settings_are_refused(override: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("|", r"\|")):
        compose_config(["study=gamma", override])


def test_options_come_from_the_config() -> None:
    cfg = compose_config(["compare.margin=0.1", "report.min_seeds=3",
                          "compare.select=fastest_equivalent"])
    assert CompareOptions.of(cfg) == CompareOptions(margin=0.1, min_seeds=3,
                                                    select="fastest_equivalent")
    assert CompareOptions.of(SimpleNamespace()) == CompareOptions()


def test_low_measured_coverage_is_printed_from_five_seeds_on() -> None:
    # From 5 seeds on, the rows of kraby_study/coverage.csv below 0.93 (lognormal sigma 1, a
    # failing seed) are printed beside intervals from that many seeds; the others are not.
    from kraby_study.decision.coverage import LOW, coverage_note, coverage_table

    table = coverage_table()
    at_ten = table[table["n"] == 10]
    low = at_ten[at_ten["coverage"] < LOW]
    assert set(low["distribution"]) >= {"lognormal 1", "failing seed 0.1"}
    note = coverage_note([10, 10])
    assert note is not None and "At n = 10 " in note
    for row in at_ten.itertuples(index=False):
        assert (f"{row.coverage:.3f} {row.distribution}" in note) == (row.coverage < LOW)
