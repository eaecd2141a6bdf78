"""Racing: the procedure on constructed scores, a raced sweep on a fake pool, and the commands
(bad input, resume after SIGKILL, PostgreSQL, a raced campaign)."""

from __future__ import annotations

import io
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy
import yaml
from conftest import (
    FAST_HEARTBEAT,
    SERVER,
    TINY,
    file_digest,
    fresh_database,
    has_study,
    kill_when,
    load,
    run_cli,
    spawn_cli,
    sqlite_url,
    tiny_with_steps,
    write_study_file,
)
from fake_pool import InstantExecutor
from optuna.trial import TrialState

from kraby_study.answers.raced import race_of
from kraby_study.config.compose import compose_config
from kraby_study.decision.comparison import compare
from kraby_study.decision.race import race
from kraby_study.plan.spec import RaceRules, TrialSpec
from kraby_study.plan.sweep import expand_study
from kraby_study.records.attributes import StudyAttrs, TrialAttrs, TrialResult
from kraby_study.records.stored import (
    Failure,
    Outcome,
    counted,
    failure,
    latest_by_key,
    outcome,
    parse_sweep_key,
)
from kraby_study.report import write_report
from kraby_study.run.study_run import run_plan
from kraby_study.store.store import opened

# race() -----------------------------------------------------------------------------------------


def test_the_looks_share_alpha_equally() -> None:
    rules = RaceRules(seeds=10, alpha=0.05)
    # The first look comes at round 4: no value is answered worse or equivalent below 4 seeds.
    assert rules.min_seeds == 4 and rules.looks == 7
    assert rules.look_alpha == pytest.approx(0.05 / 7)
    assert RaceRules(seeds=4).looks == 1
    # A race stored with min_seeds 3 keeps the share it began with (its look at 3 answers nothing).
    assert RaceRules(seeds=10, min_seeds=3).look_alpha == pytest.approx(0.00625)


def test_a_value_far_below_the_others_is_dropped_after_round_min_seeds() -> None:
    # Three values whose scores differ by 100 sd: after round 4 no resample of the bootstrap
    # reverses the worst's IQM contrast, so its p is the floor 1 / 2000 (Yuen's is far below
    # it); the step-down takes 2 x that over the others, Holm 3 x that: 0.003 < 0.05 / 3 looks.
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05, 0.0])),
            1: dict(enumerate([0.02, -0.08, 0.1, 0.0, -0.05])),
            2: dict(enumerate([-10.0, -10.1, -9.9, -10.05, -10.0]))}
    rules = RaceRules(seeds=6)
    state = race([0, 1, 2], runs, rules)
    assert list(state.dropped) == [2] and state.dropped[2].round == 4
    first = {v: [runs[v][i] for i in range(4)] for v in runs}
    for v in (0, 1):
        yuen = scipy.stats.ttest_ind(first[v], first[2], trim=0.25, alternative="greater")
        assert yuen.pvalue < 1 / 2000
    assert state.dropped[2].p == pytest.approx(3 * 2 / 2000)
    # The race's p is the report's at that look.
    look = compare(first, 0.0, alpha=rules.look_alpha)
    assert look.worse == [2] and state.dropped[2].p == pytest.approx(look.p_worse[2])
    # Round 5 is decided (every value left has it); round 6 is not run yet.
    assert state.rounds == 5 and not state.over and state.survivors == [0, 1]
    assert state.wanted(0, 5) and not state.wanted(2, 4)


def test_before_round_min_seeds_nothing_is_dropped() -> None:
    # 100 sd apart: a look after round 4 drops value 1 (the last line), but min_seeds 5 takes
    # none yet.
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05])),
            1: dict(enumerate([-10.0, -10.1, -9.9, -10.05]))}
    state = race([0, 1], runs, RaceRules(seeds=6, min_seeds=5))
    assert state.rounds == 4 and not state.dropped
    assert 1 in race([0, 1], runs, RaceRules(seeds=6, min_seeds=4)).dropped


def test_a_round_is_decided_only_when_every_value_left_has_ended_it() -> None:
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05])), 1: dict(enumerate([0.0, 0.1, -0.1, 0.05])),
            2: dict(enumerate([-10.0, -10.1, -9.9]))}
    state = race([0, 1, 2], runs, RaceRules(seeds=5))
    assert state.rounds == 3 and not state.dropped


def test_the_race_ends_when_one_value_is_left() -> None:
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05])),
            1: dict(enumerate([-10.0, -10.1, -9.9, -10.05]))}
    state = race([0, 1], runs, RaceRules(seeds=10))
    assert state.dropped[1].round == 4 and state.over
    assert not state.wanted(0, 4)  # the winner needs no more seeds


def test_drops_follow_the_step_down_round_by_round() -> None:
    """On random data with one value 4 sd better, each drop is exactly what the procedure says
    at that round's level, on the first r seeds of the values still in the race."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(6, 10))
    x[0] += 4.0
    rules = RaceRules(seeds=10)
    runs = {v: dict(enumerate(x[v])) for v in range(6)}
    state = race(list(range(6)), runs, rules)
    alive, expected = list(range(6)), {}
    for r in range(rules.min_seeds, 11):
        if len(alive) <= 1:
            break
        look = compare({v: list(x[v, :r]) for v in alive}, 0.0, alpha=rules.look_alpha)
        for v in look.worse:
            expected[v] = r
        alive = [v for v in alive if v not in expected]
    assert {v: d.round for v, d in state.dropped.items()} == expected
    assert expected, "the constructed data drop something"


def test_identical_values_are_never_dropped() -> None:
    runs = {v: dict(enumerate([0.5, 0.7, 0.6, 0.55, 0.65])) for v in range(4)}
    state = race(list(range(4)), runs, RaceRules(seeds=5))
    assert not state.dropped and state.over and state.rounds == 5


def test_failed_runs_count_as_ended_without_a_score() -> None:
    nan = math.nan
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05])), 1: dict(enumerate([nan] * 4)),
            2: dict(enumerate([-10.0, -10.1, -9.9, -10.05]))}
    state = race([0, 1, 2], runs, RaceRules(seeds=5))
    # Round 4 is decided; value 1 has no score, so it is never tested (never dropped).
    assert state.rounds == 4 and 1 not in state.dropped and 2 in state.dropped


def test_a_value_whose_runs_diverge_is_dropped_once_the_counts_show_it() -> None:
    # 10 seeds from round 4: 7 looks at 0.05 / 7 = 0.00714 each. Value 2 diverges on every
    # seed. Its count against the best's (0 of r), one-sided Fisher, Holm over the 2 others:
    # round 5: 2 x 1/252 = 0.0079, not below; round 6: 2 x 1/924 = 0.0022, dropped.
    nan = math.nan
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05, 0.0, 0.02, 0.01])),
            1: dict(enumerate([0.02, -0.08, 0.1, 0.0, -0.05, 0.01, 0.03])),
            2: dict(enumerate([nan] * 7))}
    rules = RaceRules(seeds=10)
    at = {r: race([0, 1, 2], {v: {i: x for i, x in s.items() if i < r} for v, s in runs.items()},
                  rules, {2: set(range(r))}) for r in (4, 5, 6)}
    assert 2 not in at[4].dropped and 2 not in at[5].dropped
    drop = at[6].dropped[2]
    assert (drop.round, drop.diverged) == (6, 6)
    assert drop.p == pytest.approx(2 / 924) and drop.p < rules.look_alpha
    assert drop.why() == "6 of 6 runs diverged, adjusted p 0.002"
    # Runs that failed with an error say nothing of the value: it is not dropped for them.
    assert 2 not in race([0, 1, 2], runs, rules).dropped
    # One diverged run in four (as learning_rate 1's 3 in 10 of the racing results) decides
    # nothing: one-sided Fisher p 0.5.
    some = {0: runs[0], 1: runs[1], 2: dict(enumerate([nan, -0.2, -0.1, 0.0]))}
    assert not race([0, 1, 2], some, rules, {2: {0}}).dropped


def _yuen_dependent_p(a: list[float], b: list[float]) -> float:
    """Yuen's test for dependent trimmed means (Wilcox 2017, sec. 5.9.5), the p of "IQM of a >
    IQM of b": the IQM difference over the standard error of the winsorised pairs, on h - 1
    df, h the seeds a 25 % trim keeps."""
    n = len(a)
    h = n - 2 * (n // 4)
    wa, wb = (np.asarray(scipy.stats.mstats.winsorize(np.array(x), limits=(0.25, 0.25)))
              for x in (a, b))
    se = math.sqrt((n - 1) * np.var(wa - wb, ddof=1) / (h * (h - 1)))
    t = (scipy.stats.trim_mean(a, 0.25) - scipy.stats.trim_mean(b, 0.25)) / se
    return float(scipy.stats.t.sf(t, h - 1))


def test_a_paired_race_drops_a_value_a_seed_effect_hides_from_welch() -> None:
    """Seed i moves every value by the same 10 sd; value 2 is worse by 1 on every seed. The
    unpaired look sees two spread-out samples and keeps it; the paired look sees a difference
    of -1 on every seed, with a little noise, and drops it after round 4."""
    seed_effect = [0.0, 10.0, -10.0, 5.0, -5.0, 2.0]
    noise = {0: [0.01, -0.02, 0.0, 0.02, -0.01, 0.0], 1: [-0.01, 0.0, 0.02, -0.02, 0.01, 0.0],
             2: [0.0, 0.01, -0.01, 0.0, 0.02, -0.02]}
    runs = {v: {i: seed_effect[i] + noise[v][i] - (1.0 if v == 2 else 0.0) for i in range(6)}
            for v in range(3)}
    rules = RaceRules(seeds=6)
    welch = race([0, 1, 2], runs, rules)
    paired = race([0, 1, 2], runs, RaceRules(seeds=6, paired=True))
    assert not welch.dropped
    # An unpaired p is at least Yuen's, which the seed effect keeps above 0.3.
    for r in range(rules.min_seeds, 7):
        x = {v: [runs[v][i] for i in range(r)] for v in runs}
        for v in (0, 1):
            assert scipy.stats.ttest_ind(x[v], x[2], trim=0.25,
                                         alternative="greater").pvalue > 0.3
    assert list(paired.dropped) == [2] and paired.dropped[2].round == 4
    # No resample of the common seeds reverses the contrast (bootstrap p 1 / 2000); the pair's
    # p is the larger, Yuen's, and the step-down's is 3 (Holm) x 2 (others) x the smaller.
    first = {v: [runs[v][i] for i in range(4)] for v in runs}
    yuen = min(_yuen_dependent_p(first[v], first[2]) for v in (0, 1))
    assert yuen > 1 / 2000
    assert paired.dropped[2].p == pytest.approx(6 * yuen, rel=1e-9)
    assert paired.dropped[2].p < rules.look_alpha
    look = compare(first, 0.0, alpha=rules.look_alpha, paired=True)
    assert look.worse == [2] and paired.dropped[2].p == pytest.approx(look.p_worse[2])


def test_a_paired_look_pairs_only_the_seeds_both_values_ended() -> None:
    nan = math.nan
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05, 0.02])), 1: dict(enumerate([nan] * 5)),
            2: dict(enumerate([-10.0, -9.9, nan, -10.1, -10.05]))}
    rules = RaceRules(seeds=6, paired=True)
    state = race([0, 1, 2], runs, rules)
    # Value 1 never scored, so it is never tested. Value 2 failed seed 2: after round 4 it
    # shares 3 seeds with 0, too few for an answer; after round 5 it shares 0, 1, 3 and 4.
    assert state.rounds == 5 and 1 not in state.dropped and state.dropped[2].round == 5
    common = [0, 1, 3, 4]
    look = compare({v: [runs[v][i] for i in common] for v in (0, 2)}, 0.0,
                   alpha=rules.look_alpha, paired=True)
    assert state.dropped[2].p == pytest.approx(look.p_worse[2])
    # 100 sd apart, the bootstrap is at its floor and Yuen's p decides, Holm x 2 for 2 values.
    assert state.dropped[2].p == pytest.approx(2 * _yuen_dependent_p(
        [runs[0][i] for i in common], [runs[2][i] for i in common]), rel=1e-9)


def test_the_rules_store_pairing_and_a_race_stored_before_it_replays_unpaired() -> None:
    rules = RaceRules(seeds=10, round_seeds=tuple(range(10)), paired=True)
    assert RaceRules.of({"racing": rules.stored()}) == rules
    assert "paired by seed" in rules.describe()
    old = {"seeds": 10, "min_seeds": 3, "alpha": 0.05, "round_seeds": list(range(10))}
    unpaired = RaceRules.of({"racing": old})
    assert unpaired is not None and not unpaired.paired and unpaired.stored() == old
    assert "step-down on the IQM" in unpaired.describe()
    assert "paired" not in unpaired.describe()
    # Its min_seeds 3 predates the rule of no answer below 4 seeds: it still replays, its look
    # after round 3 drops nothing, however far apart, and the one after round 4 does.
    runs = {0: dict(enumerate([0.0, 0.1, -0.1, 0.05])),
            1: dict(enumerate([-10.0, -10.1, -9.9, -10.05]))}
    three = race([0, 1], {v: {i: runs[v][i] for i in range(3)} for v in runs}, unpaired)
    assert three.rounds == 3 and not three.dropped and not three.over
    assert race([0, 1], runs, unpaired).dropped[1].round == 4


@pytest.mark.parametrize(("extra", "paired"), [([], False), (["racing.paired=true"], True)])
def test_racing_pairs_its_looks_when_asked(
        workdir: Path, extra: list[str], paired: bool) -> None:
    plan = raced_plan(workdir, 6, *extra)
    rules = RaceRules.of(plan.definition)
    assert rules is not None and rules.paired is paired
    assert ("paired" in plan.definition["racing"]) is paired


# A raced sweep on a fake pool ----------------------------------------------------------------

SCORES = {  # value -> final score of seeds 0, 1, 2, ...
    0.1: [0.0, 0.1, -0.1, 0.05, 0.0, 0.02],
    0.2: [0.02, -0.08, 0.1, 0.0, -0.05, 0.01],
    0.3: [-10.0, -10.1, -9.9, -10.0, -10.05, -10.02],
    0.4: [0.01, 0.03, -0.02, -0.04, 0.06, 0.0],
}


def sweep_result(spec: TrialSpec) -> TrialResult:
    """The score SCORES gives the run's value and seed."""
    return TrialResult(outcome=Outcome.COMPLETE, final_score=SCORES[spec.value][spec.seed],
                       env_steps=spec.steps, wall_time=1.0)


class ScoreExecutor(InstantExecutor):
    """Runs that end at once with their SCORES."""

    def __init__(self) -> None:
        super().__init__(sweep_result)


def diverging_sweep_result(spec: TrialSpec) -> TrialResult:
    """SCORES's runs, but 0.3's diverge on every seed."""
    if spec.value == 0.3:
        return TrialResult(outcome=Outcome.FAILED, env_steps=spec.steps, wall_time=1.0,
                           failure=failure(Failure.DIVERGED, "NaN in the policy loss"))
    return sweep_result(spec)


def raced_plan(workdir: Path, seeds: int = 6, *extra: str) -> Any:
    write_study_file(workdir, "fake", "ppo.clip_range", "[0.1, 0.2, 0.3, 0.4]")
    cfg = compose_config(["study=fake", *TINY, f"budget.seeds={seeds}", "racing.enabled=true",
                          *extra])
    return expand_study(cfg)


@pytest.mark.parametrize(("workers", "extra"), [(1, []), (2, []), (2, ["racing.paired=true"])])
def test_a_raced_sweep_drops_what_the_procedure_says_and_never_runs_its_later_seeds(
        workdir: Path, workers: int, extra: list[str]) -> None:
    plan = raced_plan(workdir, 6, *extra)
    executor = ScoreExecutor()
    with opened(sqlite_url(workdir / "r.db")) as store:
        summary, counts = run_plan(store, plan, executor, workers, io.StringIO(), live=False)
        ledger = store.load("fake")
        trials = counted(ledger.trials())
        stored = ledger.attrs.race
    submitted = [(spec.value, spec.seed) for spec in executor.pools[0].submitted]
    # Rounds: no seed k + 1 starts before every value has started seed k (with two workers a
    # round's tail may start the next round, never two ahead).
    for i, (_, seed) in enumerate(submitted):
        assert all(s >= seed - 1 for _, s in submitted[i:])
    assert sorted(submitted[:4]) == [(v, 0) for v in (0.1, 0.2, 0.3, 0.4)]
    # 0.3 is 100 sd below the rest: dropped after round 4, the first look, so it ran 4 seeds
    # (one ahead at most with two workers); the three others run all six.
    ran_03 = sorted(s for v, s in submitted if v == 0.3)
    assert ran_03 == [0, 1, 2, 3] if workers == 1 else (ran_03[:4] == [0, 1, 2, 3]
                                                        and len(ran_03) <= 5)
    for value in (0.1, 0.2, 0.4):
        assert sorted(s for v, s in submitted if v == value) == list(range(6))
    assert len(submitted) == len(set(submitted)) == len(trials)
    assert all(outcome(t) == Outcome.COMPLETE for t in trials)
    # Stored: per value its seeds, its drop round and p; the race is over.
    by_value = {v["value"]: v for v in stored["values"]}
    assert by_value[0.3]["dropped_at"] == 4 and 0 < by_value[0.3]["p"] < 0.05 / 3
    assert all(by_value[v]["dropped_at"] is None for v in (0.1, 0.2, 0.4))
    assert by_value[0.1]["seeds"] == 6 and by_value[0.3]["seeds"] == len(ran_03)
    assert stored["over"] and stored["rounds"] == 6
    assert stored["runs"] == len(trials) and stored["fixed_runs"] == 24
    assert counts.planned == len(trials) == counts.complete and counts.finished
    assert summary.complete == len(trials)
    # The replay from the store agrees with what was stored.
    with opened(sqlite_url(workdir / "r.db")) as store:
        ledger = store.load("fake")
        definition = ledger.attrs.definition
        replay = race_of(definition, ledger.trials(), definition["values"])
    assert replay is not None and {v: d.round for v, d in replay.dropped.items()} == {2: 4}


def test_a_raced_sweep_drops_a_value_whose_every_run_diverges(workdir: Path) -> None:
    # 10 seeds: 0.3 diverges on each; against the best's 0 of r (Fisher, Holm over 3 others)
    # round 6 gives 3 x 1/924 = 0.0032 < 0.05 / 7, so it runs 6 seeds, not 10.
    scores = {v: [*s, *s[:4]] for v, s in SCORES.items()}
    plan = raced_plan(workdir, 10)
    executor = InstantExecutor(lambda spec: diverging_sweep_result(spec) if spec.value == 0.3
                               else TrialResult(outcome=Outcome.COMPLETE,
                                                final_score=scores[spec.value][spec.seed],
                                                env_steps=spec.steps, wall_time=1.0))
    with opened(sqlite_url(workdir / "d.db")) as store:
        run_plan(store, plan, executor, 1, io.StringIO(), live=False)
        ledger = store.load("fake")
        stored = ledger.attrs.race
        found = race_of(ledger.attrs.definition, ledger.trials(), [0.1, 0.2, 0.3, 0.4])
    submitted = [(spec.value, spec.seed) for spec in executor.pools[0].submitted]
    assert sorted(s for v, s in submitted if v == 0.3) == list(range(6))
    by_value = {v["value"]: v for v in stored["values"]}
    assert (by_value[0.3]["dropped_at"], by_value[0.3]["diverged"]) == (6, 6)
    assert found is not None and found.dropped[2].diverged == 6
    assert all("diverged" not in by_value[v] for v in (0.1, 0.2, 0.4))
    # The report says why it left.
    index = write_report(sqlite_url(workdir / "d.db"), workdir / "out", policy=False)
    text = (index.out / "fake" / "summary.md").read_text()
    assert "dropped 0.3 after round 6 (6 of 6 runs diverged, adjusted p 0.003)" in text


def test_a_race_run_again_runs_nothing(workdir: Path) -> None:
    plan = raced_plan(workdir)
    with opened(sqlite_url(workdir / "r.db")) as store:
        run_plan(store, plan, ScoreExecutor(), 1, io.StringIO(), live=False)
        executor = ScoreExecutor()
        out = io.StringIO()
        run_plan(store, plan, executor, 1, out, live=False)
    assert executor.pools[0].submitted == []
    assert "0 to run" in out.getvalue() and "race fake: 22 of 24 runs (92 %)" in out.getvalue()


def test_a_dropped_values_queued_retry_is_withdrawn(workdir: Path) -> None:
    """A retry queued for a value the race then drops never runs and is not left pending."""
    plan = raced_plan(workdir)
    with opened(sqlite_url(workdir / "r.db")) as store:
        ledger = store.define(plan.name, StudyAttrs(kind="sweep", definition=plan.definition,
                                                    fingerprint=plan.fingerprint))
        # Seed 4 of 0.3 queued ahead (as a round's tail would, then given back).
        spec = next(s for s in plan.specs if s.value == 0.3 and s.seed == 4)
        ledger.queue({"clip_range": 0.3}, TrialAttrs(key=spec.key, seed=spec.seed))
        run_plan(store, plan, ScoreExecutor(), 1, io.StringIO(), live=False)
        trials = store.load("fake").trials()
    queued = [t for t in trials if t.user_attrs.get("key") == spec.key]
    assert len(queued) == 1 and queued[0].state == TrialState.PRUNED
    assert "withdrawn" in queued[0].user_attrs["failure"]


# Commands ---------------------------------------------------------------------------------------

@pytest.mark.parametrize(("args", "message"), [
    (["racing.min_seeds=3"], "racing.min_seeds must be at least 4 (no value is answered worse or "
                             "equivalent with fewer seeds), got 3"),
    (["budget.seeds=3", "racing.min_seeds=4"],
     "racing.min_seeds (4) must not exceed budget.seeds (3)"),
    (["racing.alpha=0"], "racing.alpha must be in (0, 0.5]"),
    (["racing.alpha=0.6"], "racing.alpha must be in (0, 0.5]"),
])
def test_bad_racing_input_is_one_line_and_writes_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str) -> None:
    assert run_cli("run", "study=clip_range", "--racing", *TINY, *args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (workdir / "studies").exists()


def test_racing_on_a_train_run_is_refused(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A racing search's own refusals are in tests/test_racing_search.py.
    assert run_cli("train", "racing.enabled=true", *TINY) == 2
    assert "racing is for run, optuna and confirm" in capsys.readouterr().err
    assert run_cli("confirm", "--racing", "--baseline", "ppo=tuned", "--seeds", "3", *TINY) == 2
    assert "racing.min_seeds (4) must not exceed confirm.seeds (3)" in capsys.readouterr().err
    assert not (workdir / "studies").exists()


def test_a_raced_study_is_never_mixed_with_the_same_study_run_fixed(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_study_file(workdir, "mix", "ppo.clip_range", "[0.1, 0.3]")
    assert run_cli("run", "study=mix", *TINY, "budget.seeds=4") == 0
    db = workdir / "studies" / "kraby.db"
    before = file_digest(db)
    capsys.readouterr()
    assert run_cli("run", "study=mix", *TINY, "budget.seeds=4", "--racing") == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and "racing" in err
    assert len(err.strip().splitlines()) == 1 and file_digest(db) == before


@pytest.mark.parametrize("changed", ["racing.paired=true", "compare.margin=0.1"])
def test_a_race_is_never_resumed_with_another_test_or_margin(
        workdir: Path, capsys: pytest.CaptureFixture[str], changed: str) -> None:
    write_study_file(workdir, "pair", "ppo.clip_range", "[0.1, 0.3]")
    raced = ["run", "study=pair", *TINY, "budget.seeds=4", "--racing"]
    assert run_cli(*raced) == 0
    db = workdir / "studies" / "kraby.db"
    before = file_digest(db)
    capsys.readouterr()
    assert run_cli(*raced, changed) == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and "racing" in err
    assert len(err.strip().splitlines()) == 1 and file_digest(db) == before


def _race_consistent(url: str, name: str) -> dict[str, Any]:
    """The stored race agrees with its replay, no run ran twice, and no value ran past its
    drop by more than one round's tail."""
    trials = load(url, name).get_trials()
    attrs = StudyAttrs.of(load(url, name).user_attrs)
    latest = latest_by_key(trials)
    complete = [t.user_attrs["key"] for t in trials if t.state == TrialState.COMPLETE]
    assert len(complete) == len(set(complete)), complete
    replay = race_of(attrs.definition, trials, attrs.definition["values"])
    assert replay is not None and replay.over
    stored = attrs.race or {}
    assert {v: d.round for v, d in replay.dropped.items()} == {
        i: v["dropped_at"] for i, v in enumerate(stored["values"]) if v["dropped_at"]}
    for key, trial in latest.items():
        value, seed = parse_sweep_key(key) or (None, None)
        if value in replay.dropped and outcome(trial) == Outcome.COMPLETE:
            assert seed is not None and seed <= replay.dropped[value].round, key
    return stored


@pytest.mark.slow
def test_a_race_resumes_after_sigkill(workdir: Path) -> None:
    db = sqlite_url(workdir / "k.db")
    write_study_file(workdir, "rk", "ppo.clip_range", "[0.1, 0.2, 0.3]")
    args = ["run", "study=rk", "workers=2", f"storage={db}", *tiny_with_steps(2048),
            "budget.seeds=4", "--racing"]
    proc = spawn_cli(*args, cwd=workdir)
    kill_when(lambda: has_study(db, "rk") and sum(
        t.state == TrialState.COMPLETE for t in load(db, "rk").get_trials()) >= 3, proc)
    proc = spawn_cli(*args, cwd=workdir)
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out
    stored = _race_consistent(db, "rk")
    assert stored["over"] and "race rk:" in out


@pytest.mark.slow
@pytest.mark.postgres
@pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")
def test_two_commands_race_one_study_on_postgresql(workdir: Path) -> None:
    write_study_file(workdir, "rp", "ppo.clip_range", "[0.1, 0.2, 0.3]")
    with fresh_database() as url:
        args = ["run", "study=rp", "workers=1", f"storage={url}", *tiny_with_steps(1024),
                "budget.seeds=4", "--racing", *FAST_HEARTBEAT]
        procs = [spawn_cli(*args, cwd=workdir) for _ in range(2)]
        outs = [p.communicate(timeout=600)[0] for p in procs]
        for proc, out in zip(procs, outs, strict=True):
            assert proc.returncode == 0, out
        stored = _race_consistent(url, "rp")
        assert stored["over"]
        assert all("clip_range=" in out.split("raced", 1)[1] for out in outs), outs


@pytest.mark.slow
def test_a_raced_campaign_races_every_stage(workdir: Path) -> None:
    for name, parameter in (("c1", "ppo.gamma"), ("c2", "ppo.clip_range"),
                            ("c3", "ppo.ent_coef")):
        values = {"c1": "[0.5, 0.99]", "c2": "[0.1, 0.3]", "c3": "[0.0, 0.05]"}[name]
        write_study_file(workdir, name, parameter, values)
    folder = workdir / "conf" / "campaign"
    folder.mkdir(parents=True)
    (folder / "trio.yaml").write_text("# @package campaign\n" + yaml.safe_dump({
        "name": "trio", "stages": [{"study": "c1"}, {"study": "c2"}, {"study": "c3"}]}))
    assert run_cli("run", "campaign=trio", *TINY, "budget.seeds=4", "--racing") == 0
    db = sqlite_url(workdir / "studies" / "kraby.db")
    for stage in ("trio-c1", "trio-c2", "trio-c3"):
        attrs = StudyAttrs.of(load(db, stage).user_attrs)
        # The race stores the margin it began with, compare.margin's default, and
        # racing.min_seeds's default, the first round with an answer.
        assert attrs.definition["racing"] == {"seeds": 4, "min_seeds": 4, "alpha": 0.05,
                                              "round_seeds": [0, 1, 2, 3], "margin": 0.2}
        _race_consistent(db, stage)


@pytest.mark.slow
@pytest.mark.parametrize("paired", [False, True])
@pytest.mark.parametrize(("values", "seeds"), [(3, 10), (5, 10), (8, 10)])
def test_a_race_holds_its_family_wise_error_under_the_global_null(values: int, seeds: int,
                                                                   paired: bool) -> None:
    """Every value from one normal distribution, a seed giving every value the same shift (0.8
    of the variance): any drop is false. Over 1,000 races the share with a drop stays within
    alpha plus 3 Monte-Carlo standard errors, unpaired and paired."""
    rng = np.random.default_rng(20261125 + values)
    rules = RaceRules(seeds=seeds, alpha=0.05, paired=paired)
    sims = 1000
    false = 0
    for _ in range(sims):
        x = math.sqrt(0.8) * rng.normal(size=(1, seeds)) + math.sqrt(0.2) * rng.normal(
            size=(values, seeds))
        false += bool(race(list(range(values)), {v: dict(enumerate(x[v])) for v in range(values)},
                           rules).dropped)
    assert false / sims <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / sims)


def test_the_replay_races_a_stored_fixed_sweep_at_a_margin(
        workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``bench_racing.py --store`` on a complete fixed sweep: 0.2 is within 0.01 of 0.1 with
    tight seeds, so at the default margin (0.2 x |-1.0|) the first look, after round 4,
    settles it and drops 0.3 (1.0 below); the race is then over after 12 of 18 runs and selects
    0.1, within the margin of the fixed best. At margin 0 it only drops 0.3."""
    import importlib.util

    from synthetic import Run, add_sweep

    from kraby_study.store.store import Store

    spec = importlib.util.spec_from_file_location(
        "bench_racing", Path(__file__).parents[1] / "benchmarks" / "bench_racing.py")
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "bench_racing", bench)  # its dataclasses look it up
    spec.loader.exec_module(bench)
    url = sqlite_url(workdir / "fixed.db")
    store = Store(url)
    try:
        finals = {0.1: [-1.0, -1.01, -0.99, -1.0, -1.02, -0.98],
                  0.2: [-1.005, -0.995, -1.015, -1.0, -1.01, -1.02],
                  0.3: [-2.0, -2.01, -1.99, -2.0, -2.0, -2.0]}
        add_sweep(store, "fixed", "ppo.clip_range", list(finals), [
            Run(value=v, seed=s, final_score=x, wall_time=10.0)
            for v, xs in finals.items() for s, x in enumerate(xs)])
    finally:
        store.close()
    (replay,) = bench.replay_store(url, min_seeds=4, alpha=0.05)
    assert (replay.fixed_runs, replay.raced_runs) == (18, 12)
    assert replay.settled == ["0.2@4"] and replay.dropped == ["0.3@4"]
    assert replay.raced_selection == "0.1" and replay.within
    assert replay.margin == pytest.approx(0.2 * 1.0, rel=0.02)
    (old,) = bench.replay_store(url, min_seeds=4, alpha=0.05, margin=0.0)
    assert old.settled == [] and old.dropped == ["0.3@4"] and old.raced_runs == 16
