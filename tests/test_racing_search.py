"""The racing search (``optuna --racing``): its decisions on made-up scores, end to end on a
deterministic fake pool, resumed after a kill, and through the CLI and the API at smoke budget."""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from conftest import (
    TINY,
    has_study,
    kill_when,
    load,
    refused_before_work,
    run_cli,
    spawn_cli,
    sqlite_url,
)
from fake_pool import InstantExecutor
from optuna.trial import TrialState

import kraby_study as ks
from kraby_study.answers.racing_search import racing_search
from kraby_study.config.compose import compose_config
from kraby_study.decision.race import Left, RunEnd, intensify
from kraby_study.plan.settings import resolved_settings
from kraby_study.plan.space import apply_params
from kraby_study.plan.spec import RaceRules, TrialSpec
from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import (
    Failure,
    Outcome,
    counted,
    failure,
    latest_by_key,
    parse_racing_key,
)
from kraby_study.run.racing_search import run_racing_search
from kraby_study.store.store import opened

RULES = RaceRules(seeds=8, round_seeds=tuple(range(8)), min_seeds=4, alpha=0.05, margin=0.2)
NOISE = [0.3, -0.5, 0.1, 0.4, -0.2, -0.1, 0.5, -0.4]
"""One seed's effect on every configuration's score (seed index -> score units)."""


def runs(config: int, level: float, seeds: int, cpu: float = 1.0,
         noise: Sequence[float] = NOISE) -> list[RunEnd[int]]:
    """``seeds`` ended runs of a configuration scoring ``level`` plus each seed's noise."""
    return [RunEnd(config, i, level + noise[i], cpu) for i in range(seeds)]


# The decision on made-up scores -----------------------------------------------------------------

def test_a_challenger_shown_worse_leaves_at_its_first_look() -> None:
    state = intensify([0, 1], runs(0, 100.0, 4) + runs(1, 20.0, 4), RULES)
    assert state.incumbent == 0
    worse = state.standings[1]
    assert worse.left == Left.WORSE and worse.seeds == 4 and worse.by == 0
    assert 0 < worse.p < RULES.look_alpha


def test_nothing_is_decided_before_min_seeds() -> None:
    state = intensify([0, 1], runs(0, 100.0, 4) + runs(1, 20.0, 3), RULES)
    assert state.standings[1].left == Left.RACING and state.incumbent == 0


def test_a_challenger_shown_better_replaces_the_incumbent() -> None:
    state = intensify([0, 1], runs(0, 100.0, 6) + runs(1, 200.0, 4), RULES)
    assert state.incumbent == 1
    assert state.standings[0].left == Left.REPLACED and state.standings[0].by == 1
    assert state.standings[0].seeds == 6 and state.standings[1].left == Left.INCUMBENT
    assert not state.standings[1].cheaper


@pytest.mark.parametrize(("cpu", "replaces"), [(0.5, True), (2.0, False)])
def test_an_equivalent_challenger_replaces_only_when_cheaper(cpu: float, replaces: bool) -> None:
    tight = [0.01, -0.02, 0.0, 0.02, -0.01, 0.01, 0.0, -0.01]
    ends = runs(0, 100.0, 8, cpu=1.0, noise=tight) + runs(1, 100.0, 4, cpu=cpu, noise=tight)
    state = intensify([0, 1], ends, RULES)
    if replaces:
        assert state.incumbent == 1 and state.standings[1].cheaper
        assert state.standings[0].left == Left.REPLACED
    else:
        assert state.incumbent == 0
        assert state.standings[1].left == Left.EQUIVALENT and state.standings[1].seeds == 4


def test_a_cheaper_challenger_whose_iqm_trims_a_failure_does_not_replace_as_equivalent(
        ) -> None:
    # MountainCarContinuous-v0, a racing search's pair 8: rl-zoo3's settings on 8 seeds, none
    # failed, against a cheaper challenger that failed 1 of its first 4 seeds. Its IQM (92.9)
    # trims the failure, so the incumbent is within the margin of the challenger; the
    # challenger is not shown within the margin of the incumbent, and races on.
    incumbent = [93.97, 91.05, 87.19, 94.03, 92.17, 93.43, 91.0, 90.9]
    failing = [91.83, 95.26, -0.02, 94.0]
    ends = runs(0, 0.0, 8, cpu=57.0, noise=incumbent) + runs(1, 0.0, 4, cpu=43.0, noise=failing)
    state = intensify([0, 1], ends, RULES)
    assert state.incumbent == 0 and state.standings[1].left == Left.RACING
    # Without the failure the same challenger is within the margin, and replaces it.
    steady = runs(1, 0.0, 4, cpu=43.0, noise=[91.83, 95.26, 93.1, 94.0])
    state = intensify([0, 1], runs(0, 0.0, 8, cpu=57.0, noise=incumbent) + steady, RULES)
    assert state.incumbent == 1 and state.standings[1].cheaper
    assert 0 < state.standings[0].p < RULES.look_alpha


@pytest.mark.parametrize(("shift", "replaces"), [(0.05, True), (-0.05, False)])
def test_undecided_at_the_incumbents_seeds_the_higher_iqm_on_common_seeds_wins(
        shift: float, replaces: bool) -> None:
    rules = RaceRules(seeds=8, round_seeds=tuple(range(8)), min_seeds=4, alpha=0.05)  # margin 0
    wide = [30.0, -40.0, 10.0, 25.0]
    other = [w + shift for w in (25.0, 10.0, 30.0, -40.0)]  # the same seeds, reordered
    state = intensify([0, 1], runs(0, 0.0, 4, noise=wide) + runs(1, 0.0, 4, noise=other),
                      rules)
    assert (state.incumbent == 1) is replaces
    if not replaces:
        assert state.standings[1].left == Left.BELOW and state.standings[1].seeds == 4


def test_below_at_a_look_stops_a_noisy_challenger_far_below_that_no_test_shows_worse(
        ) -> None:
    # A challenger with widely spread scores far below the incumbent (the leg's c15): the
    # comparison gives no answer at 4 seeds, so at the cap rule it races on; at the look rule
    # it leaves below at its first look.
    incumbent = [-0.047, -0.055, -0.061, -0.049, -0.05, -0.056, -0.052, -0.071, -0.049, -0.053]
    spread = [-0.233, -0.229, -0.656, -0.342]
    ends = (runs(0, 0.0, 10, noise=incumbent) + runs(1, 0.0, 4, noise=spread))
    rules = RaceRules(seeds=10, round_seeds=tuple(range(10)), min_seeds=4, alpha=0.05,
                      margin=0.2)
    assert intensify([0, 1], ends, rules).standings[1].left == Left.RACING
    look = replace(rules, below="look")
    below = intensify([0, 1], ends, look).standings[1]
    assert (below.left, below.seeds, below.by) == (Left.BELOW, 4, 0)
    # Above the incumbent on the common seeds, it races on to the incumbent's count.
    above = runs(0, 0.0, 10, noise=incumbent) + runs(1, 0.0, 4, noise=[-0.04, -0.3, -0.045,
                                                                        -0.03])
    assert intensify([0, 1], above, look).standings[1].left == Left.RACING


def test_the_race_is_replayed_in_the_order_the_runs_ended() -> None:
    # c1 replaces c0; c2 then races against c1, not c0.
    ends = runs(0, 100.0, 4) + runs(1, 200.0, 4) + runs(2, 150.0, 4)
    state = intensify([0, 1, 2], ends, RULES)
    assert state.incumbent == 1 and state.standings[2].left == Left.WORSE
    assert state.standings[2].by == 1


def diverged(config: int, seeds: range) -> list[RunEnd[int]]:
    return [RunEnd(config, i, math.nan, 1.0, diverged=True) for i in seeds]


def test_a_challenger_whose_runs_diverge_leaves_once_the_counts_show_it() -> None:
    # The look's level: 0.05 over 5 looks, 0.01. 4 of 4 diverged against 0 of 5: one-sided
    # Fisher exact p = 1/126 = 0.0079, worse; against 0 of 4 it is 1/70 = 0.014, so the
    # challenger would race on, and at the incumbent's seed count it leaves below it.
    state = intensify([0, 1], runs(0, 100.0, 5) + diverged(1, range(4)), RULES)
    worse = state.standings[1]
    assert (worse.left, worse.seeds, worse.diverged) == (Left.WORSE, 4, 4)
    assert worse.p == pytest.approx(1 / 126)
    two = intensify([0, 1], runs(0, 100.0, 6) + diverged(1, range(2))
                    + runs(1, 100.0, 4)[2:], RULES)  # 2 of 4 against 0 of 6: p 0.13
    assert two.standings[1].diverged == 0


def test_an_incumbent_whose_runs_diverge_is_replaced_and_errors_are_no_evidence() -> None:
    good = runs(1, 100.0, 4)
    state = intensify([0, 1], diverged(0, range(5)) + good, RULES)
    assert state.incumbent == 1 and state.standings[0].left == Left.REPLACED
    assert state.standings[0].p == pytest.approx(1 / 126)
    # The same runs failed by an error (a machine's fault, not the settings'): no answer.
    errors = [RunEnd(0, i, math.nan, 1.0) for i in range(5)]
    assert intensify([0, 1], errors + good, RULES).standings[1].left == Left.RACING


def test_next_run_gives_first_seeds_side_by_side_then_one_at_a_time_and_caps_the_incumbent(
        ) -> None:
    rules = RaceRules(seeds=5, round_seeds=tuple(range(5)), min_seeds=4, alpha=0.05)
    fresh = intensify([0], [], rules)
    # The incumbent's first four seeds side by side; nothing more until they end.
    assert fresh.next_run({0: {0, 1}}) == (0, 2)
    assert fresh.next_run({0: {0, 1, 2, 3}}) is None and not fresh.challenge_open()
    ready = intensify([0], runs(0, 100.0, 4), rules)
    assert ready.challenge_open()
    # No challenger waits: the incumbent earns a seed, up to the cap of 5.
    assert ready.next_run({0: {0, 1, 2, 3}}) == (0, 4)
    capped = intensify([0], runs(0, 100.0, 5), rules)
    assert capped.next_run({0: set(range(5))}) is None
    # A challenger's first four side by side, then one at a time below the incumbent's count.
    racing = intensify([0, 1], runs(0, 100.0, 5) + runs(1, 100.0, 4, noise=[1, -1, 1, -1]),
                       rules)
    assert racing.standings[1].left == Left.RACING
    assert racing.next_run({0: set(range(5)), 1: {0, 1, 2, 3, 4}}) is None
    assert racing.next_run({0: set(range(5)), 1: {0, 1, 2, 3}}) == (1, 4)
    assert intensify([0, 1], runs(0, 100.0, 5), rules).next_run(
        {0: set(range(5)), 1: {0}}) == (1, 1)


# End to end on a fake pool ---------------------------------------------------------------------

SPACE = """\
name: fake
sampler: random
seed: 5
startup_trials: 2
objective: final_reward
trials: 5
enqueue: []
params:
  clip_range: {path: ppo.clip_range, type: categorical, choices: [0.1, 0.3]}
  gamma: {path: ppo.gamma, type: float, low: 0.9, high: 0.99}
"""


def fake_score(spec: TrialSpec) -> float:
    """clip_range 0.3 cannot learn here: 50 below 0.1 at every seed; gamma moves little."""
    ppo = spec.settings["ppo"]
    base = 100.0 if ppo["clip_range"] == 0.1 else 50.0
    return base + ppo["gamma"] + NOISE[(spec.seed - 0) % len(NOISE)]


def fake_result(spec: TrialSpec) -> TrialResult:
    return TrialResult(outcome=Outcome.COMPLETE, final_score=fake_score(spec),
                       env_steps=spec.steps, wall_time=1.0, cpu_time=1.0)


def racing_cfg(workdir: Path, *extra: str) -> Any:
    (workdir / "conf" / "search").mkdir(parents=True, exist_ok=True)
    (workdir / "conf" / "search" / "fake.yaml").write_text(SPACE)
    return compose_config(["search=fake", *TINY, "budget.seeds=6", "racing.enabled=true",
                           *extra])


def good_start(cfg: Any) -> list[tuple[str, dict[str, Any]]]:
    """The first configuration (the first incumbent): clip_range 0.1."""
    return [("ppo=good", resolved_settings(apply_params(cfg, {"clip_range": 0.1,
                                                              "gamma": 0.95})))]


def run_fake(workdir: Path, workers: int, *extra: str, db: str = "r.db",
             starts: bool = True, url: str | None = None,
             result: Callable[[TrialSpec], TrialResult] = fake_result,
             ) -> tuple[InstantExecutor, str, Any]:
    cfg = racing_cfg(workdir, *extra)
    executor = InstantExecutor(result)
    url = url or sqlite_url(workdir / db)
    out = io.StringIO()
    with opened(url) as store:
        run_racing_search(store, cfg, executor, workers, out, live=False,
                          starts=good_start(cfg) if starts else ())
        found = racing_search(store.load("fake").attrs.definition, store.load("fake").trials())
    return executor, out.getvalue(), found


@pytest.mark.parametrize("workers", [1, 2])
def test_a_challenger_that_cannot_learn_leaves_early_and_the_incumbent_earns_its_seeds(
        workdir: Path, workers: int) -> None:
    executor, out, found = run_fake(workdir, workers)
    assert found is not None and len(found.configurations) == 5
    inc = found.incumbent
    assert inc is not None and inc.params["clip_range"] == 0.1
    assert inc.seeds == 6  # the cap, budget.seeds
    bad = [c for c in found.configurations if c.params["clip_range"] == 0.3]
    assert bad, "the fixed sampler seed asks clip_range 0.3 at least once"
    for config in bad:
        assert config.standing.left == Left.WORSE and config.standing.seeds == 4
        assert config.seeds < inc.seeds
        assert f"race: {config.key} worse than" in out
    # Every run ran once; a configuration that left got no seed after its look (one worker)
    # or at most the ones already in flight (two).
    submitted = [(spec.key, spec.seed) for spec in executor.pools[0].submitted]
    assert len(submitted) == len(set(submitted))
    for config in bad:
        ran = [seed for key, seed in submitted if key.startswith(config.key + "-")]
        assert sorted(ran) == [0, 1, 2, 3]
    assert "every configuration is asked and decided" in out


def diverging_result(spec: TrialSpec) -> TrialResult:
    """clip_range 0.3 diverges on every seed."""
    if spec.settings["ppo"]["clip_range"] == 0.3:
        return TrialResult(outcome=Outcome.FAILED, env_steps=spec.steps, cpu_time=1.0,
                           failure=failure(Failure.DIVERGED, "NaN in the policy loss"))
    return fake_result(spec)


def test_a_challenger_whose_every_run_diverges_leaves_as_worse(workdir: Path) -> None:
    executor, out, found = run_fake(workdir, 1, "search.trials=6", result=diverging_result)
    bad = [c for c in found.configurations if c.params["clip_range"] == 0.3]
    assert bad and found.incumbent.params["clip_range"] == 0.1
    for config in bad:
        assert config.standing.left == Left.WORSE and config.standing.diverged
        assert config.seeds <= found.incumbent.seeds
        assert (f"race: {config.key} worse than c0 at seed {config.standing.seeds}: "
                f"{config.standing.seeds} of {config.standing.seeds} runs diverged, p") in out


def test_a_racing_search_stores_and_replays_alike_on_each_backend(
        workdir: Path, store_url: str) -> None:
    _, _, found = run_fake(workdir, 2, "search.trials=3", url=store_url)
    assert found.incumbent is not None and found.incumbent.seeds == 6
    assert len(found.configurations) == 3 and not found.state.racing


def test_a_search_run_again_runs_nothing_and_an_extended_one_asks_as_one_run_would(
        workdir: Path) -> None:
    _, _, whole = run_fake(workdir, 1, "search.trials=5", db="whole.db")
    run_fake(workdir, 1, "search.trials=3", db="split.db")
    again, out, _ = run_fake(workdir, 1, "search.trials=3", db="split.db")
    assert again.pools[0].submitted == [] and "3 asked" in out
    _, _, split = run_fake(workdir, 1, "search.trials=5", db="split.db")
    # Seeded from (search.seed, configurations asked): the same configurations either way.
    assert [c.params for c in split.configurations] == [c.params for c in whole.configurations]


@pytest.mark.parametrize("changed", [["compare.margin=0.1"], ["racing.enabled=false"],
                                     ["racing.below=look"]])
def test_a_racing_search_is_never_resumed_at_other_rules_nor_unraced(
        workdir: Path, capsys: pytest.CaptureFixture[str], changed: list[str]) -> None:
    run_fake(workdir, 1, "search.trials=2")
    db = workdir / "r.db"
    before = db.read_bytes()
    capsys.readouterr()
    assert run_cli("optuna", "search=fake", *TINY, "budget.seeds=6", "racing.enabled=true",
                   f"storage={sqlite_url(db)}", *changed) == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and len(err.strip().splitlines()) == 1
    assert db.read_bytes() == before


def test_best_list_confirm_and_report_read_the_incumbent(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, _, found = run_fake(workdir, 2)
    inc = found.incumbent
    url = sqlite_url(workdir / "r.db")
    capsys.readouterr()
    assert run_cli("best", "--storage", url, "--study-name", "fake", "--name", "picked") == 0
    out = capsys.readouterr().out
    assert f"configuration {inc.key} of racing search 'fake', its incumbent" in out
    assert "over 6 seed(s)" in out
    assert run_cli("list", "--storage", url) == 0
    assert f"{inc.key} (IQM {inc.iqm:.4g}, 6 seeds)" in capsys.readouterr().out
    assert run_cli("confirm", "--storage", url, "--study-name", "fake", "--top", "2",
                   "--dry-run") == 0
    assert "2 configurations x 10 seeds" in capsys.readouterr().out
    assert run_cli("report", "--storage", url, "--study-name", "fake", "--no-policy",
                   "--out", str(workdir / "rep")) == 0
    table = (workdir / "rep" / "fake" / "configurations.csv").read_text()
    assert f"{inc.key},ppo=good" in table or f"{inc.key}," in table
    assert "worse than" in table and "incumbent" in table
    summary = (workdir / "rep" / "fake" / "top_trials.md").read_text()
    assert f"Picked: configuration {inc.key}, the incumbent" in summary


# Commands at smoke budget ------------------------------------------------------------------------

TINY_RACE = ["search=fake", *TINY, "budget.seeds=4", "search.trials=2", "workers=1"]


def test_dry_run_says_what_the_racing_search_would_do_and_writes_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    racing_cfg(workdir)
    assert run_cli("optuna", "--racing", "--dry-run", *TINY_RACE, "--cpu-budget", "60") == 0
    out = capsys.readouterr().out
    assert "at most 8 runs (2 configurations (search.trials), each raced on 4 to 4 seeds)" in out
    assert "not in the store yet: 0 runs complete, at most 8 to run" in out
    assert "60 CPU s (search.cpu_budget)" in out
    assert "racing search: random sampler" in out and "compare.margin 0.2" in out
    assert "alpha 0.05 spent over 1 looks" in out and "up to 4 (budget.seeds)" in out
    assert not (workdir / "studies").exists()


@pytest.mark.parametrize(("extra", "message"), [
    (["--objective", "final_reward,training_time", "--pruner", "none"],
     "--racing races one objective"),
    (["--pruner", "wilcoxon"], "--racing stops configurations by its race: drop --pruner"),
    (["--trial-share", "0.5", "--cpu-budget", "100"], "drop --trial-share"),
    (["racing.min_seeds=5"], "racing.min_seeds (5) must not exceed budget.seeds (4)"),
    (["racing.below=soon"], "racing.below must be one of cap, look, got 'soon'"),
])
def test_bad_racing_search_input_is_one_line_and_stores_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
        message: str) -> None:
    racing_cfg(workdir)
    err = refused_before_work(workdir, capsys, "optuna", "--racing", *TINY_RACE, *extra)
    assert message in err


def test_below_at_a_look_is_refused_on_a_race_of_values(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = refused_before_work(workdir, capsys, "run", "study=gamma", *TINY, "budget.seeds=4",
                              "--racing", "racing.below=look")
    assert "racing.below=look applies to a racing search (optuna --racing) only" in err


def test_a_racing_search_stores_below_at_a_look_and_its_start_line_says_so(
        workdir: Path) -> None:
    _, out, found = run_fake(workdir, 1, "search.trials=3", "racing.below=look")
    assert found.rules.below == "look"
    assert "undecided, it leaves at any look (racing.below=look)" in out
    _, out, found = run_fake(workdir, 1, "search.trials=3", db="cap.db")
    assert found.rules.below == "cap" and "at the incumbent's seed count" in out


def test_the_api_runs_a_racing_search_and_best_reads_its_incumbent(workdir: Path) -> None:
    racing_cfg(workdir)
    config = ks.compose([*TINY_RACE, "racing.enabled=true", "search.name=api"],
                        command="search")
    out = io.StringIO()
    result = ks.search(config, stream=out)
    assert result.study == "api" and result.complete >= 8  # two configurations, 4 seeds each
    assert "picked c" in (result.message or "")
    chosen = ks.best(ks.compose([], command="best"), study="api")
    assert "its incumbent" in chosen.description
    assert "search api: 2 configurations: incumbent" in out.getvalue()


@pytest.mark.slow
def test_a_killed_racing_search_continues_where_it_stopped(workdir: Path) -> None:
    racing_cfg(workdir)
    db = sqlite_url(workdir / "k.db")
    # runs of about a second (4,096 steps): the kill comes with most of the runs still to go
    args = ["optuna", "--racing", "search=fake", *TINY, "budget.steps=4096",
            "budget.curve_every=512", "budget.seeds=5", "search.trials=3", "workers=2",
            f"storage={db}"]

    def complete() -> int:
        return sum(t.state == TrialState.COMPLETE for t in load(db, "fake").get_trials())

    proc = spawn_cli(*args, cwd=workdir)
    kill_when(lambda: has_study(db, "fake") and complete() >= 4, proc)
    before = complete()
    proc = spawn_cli(*args, cwd=workdir)
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out
    assert f"{before} runs so far" in out or "trial(s) left running" in out
    trials = load(db, "fake").get_trials()
    done = [t.user_attrs["key"] for t in trials if t.state == TrialState.COMPLETE]
    assert len(done) == len(set(done)) and len(done) > before
    latest = latest_by_key(counted(trials))
    assert all(parse_racing_key(key) is not None for key in latest)
    found = racing_search(load(db, "fake").user_attrs["kraby_definition"], trials)
    assert found is not None and len(found.configurations) == 3 and not found.state.racing
    assert found.incumbent is not None and found.incumbent.seeds == 5
    assert not math.isnan(found.incumbent.iqm)


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # beside test_ray.py, which counts the Ray processes
def test_a_racing_search_on_ray_races_as_on_local_workers(workdir: Path) -> None:
    pytest.importorskip("ray")
    racing_cfg(workdir)
    common = ["optuna", "--racing", "search=fake", *TINY, "budget.seeds=4", "search.trials=2",
              "workers=1"]
    local, ray = sqlite_url(workdir / "local.db"), sqlite_url(workdir / "ray.db")
    assert run_cli(*common, f"storage={local}") == 0
    env_ray = ["executor=ray", f"storage={ray}"]
    proc = spawn_cli(*common, *env_ray, cwd=workdir)
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out

    def raced(url: str) -> list[tuple[str, dict[str, Any], dict[int, float], str]]:
        study = load(url, "fake")
        found = racing_search(study.user_attrs["kraby_definition"], study.get_trials())
        assert found is not None
        return [(c.key, c.params, c.scores, c.left_text()) for c in found.configurations]

    assert raced(ray) == raced(local)  # the same runs, scores and moves, bit for bit
