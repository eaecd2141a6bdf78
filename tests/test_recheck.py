"""A search's rechecks (search.recheck): its leaders retrained on more seeds before it ends."""

from __future__ import annotations

import re
from pathlib import Path

import optuna
import pytest
from conftest import TINY, TINY_SEARCH, load, refused_before_work, run_cli
from optuna.distributions import FloatDistribution
from optuna.trial import TrialState, create_trial

from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Outcome
from kraby_study.run import recheck as costs
from kraby_study.run.recheck import combined, first_seed, leaders, next_recheck, reserve


def _trial(number: int, scores: list[float] | None, *, key: str | None = None,
           of: int | None = None, cpu: float = 10.0, seed: int = 0, steps: int | None = None,
           state: TrialState = TrialState.COMPLETE) -> optuna.trial.FrozenTrial:
    attrs: dict[str, object] = {"key": key or f"t{number}", "seed": seed, "cpu_time": cpu}
    if steps is not None:
        attrs["env_steps"] = steps
    if scores is not None:
        attrs["scores"] = scores
    if of is not None:
        attrs["recheck_of"] = of
    value = sum(scores) / len(scores) if scores and state == TrialState.COMPLETE else None
    trial = create_trial(state=state, value=value, params={"x": 0.5},
                         distributions={"x": FloatDistribution(0, 1)}, user_attrs=attrs)
    trial.number = number
    return trial


def test_leaders_rank_a_rechecked_trial_by_all_its_seeds() -> None:
    trials = [_trial(0, [-1.0, -1.2]), _trial(1, [-0.5, -0.7]), _trial(2, [-0.8, -0.8]),
              # t1 rechecked on seeds 2 and 3: it failed there, so by 4 seeds it is last.
              _trial(3, [-0.5, -0.7, -3.0, -2.8], key="t1", of=1, seed=2)]
    top = leaders(trials, 2)
    assert [lead.trial.number for lead in top] == [2, 0]
    assert [lead.rechecked for lead in top] == [False, False]
    # So the next in line is rechecked now: the top 2 are never left unrechecked.
    assert next_recheck(trials, 2).number == 2
    assert leaders(trials, 3)[2].trial.number == 3 and leaders(trials, 3)[2].score == -1.75


def test_a_queued_or_running_recheck_holds_its_place_by_the_score_before() -> None:
    trials = [_trial(0, [-1.0]), _trial(1, [-0.5]),
              _trial(2, None, key="t1", of=1, state=TrialState.RUNNING)]
    top = leaders(trials, 2)
    assert [(lead.trial.number, lead.score, lead.rechecked) for lead in top] == [
        (2, -0.5, True), (0, -1.0, False)]
    assert next_recheck(trials, 2).number == 0
    assert next_recheck(trials, 1) is None


def test_of_leaders_tied_at_a_ceiling_the_cheaper_are_rechecked_first() -> None:
    # Four trials at 500 on their 2 seeds: 20, 4, 8 and 2 CPU s a seed.
    tied = [_trial(0, [500.0, 500.0], cpu=40.0), _trial(1, [500.0, 500.0], cpu=8.0),
            _trial(2, [500.0, 500.0], cpu=16.0), _trial(3, [500.0, 500.0], cpu=4.0)]
    assert [lead.trial.number for lead in leaders(tied, 2)] == [3, 1]
    assert next_recheck(tied, 2).number == 3
    # t3 held 500 on 3 more seeds: by 5 seeds it leads the ties it cost less than, and
    # the next cheapest (t1) is rechecked next, not the first by number.
    held = [*tied, _trial(4, [500.0] * 5, key="t3", of=3, seed=2, cpu=10.0)]
    assert [lead.trial.number for lead in leaders(held, 2)] == [4, 1]
    assert next_recheck(held, 2).number == 1


def test_the_reserve_is_each_unchecked_leaders_cpu_per_seed_times_the_seeds() -> None:
    trials = [_trial(0, [-1.0, -1.0], cpu=30.0), _trial(1, [-0.5, -0.5], cpu=50.0),
              _trial(2, [-9.0, -9.0], cpu=1000.0)]
    assert reserve(trials, 2, seeds=3) == pytest.approx(30.0 / 2 * 3 + 50.0 / 2 * 3)
    rechecked = [*trials, _trial(3, [-0.5, -0.5, -0.4], key="t1", of=1, seed=2)]
    assert reserve(rechecked, 2, seeds=3) == pytest.approx(45.0)


def test_a_recheck_is_stored_with_the_seeds_of_its_trial() -> None:
    original = _trial(4, [-1.0, -2.0], seed=0)
    original.user_attrs.update(train_reward=-1.5, eval_errors=[0.1, 0.2])
    assert first_seed(original) == 2
    result = TrialResult(outcome=Outcome.COMPLETE, scores=[-3.0], final_score=-3.0,
                         train_reward=-3.5, eval_errors=[0.3], cpu_time=7.0, env_steps=512)
    both = combined(original, result)
    assert both.scores == [-1.0, -2.0, -3.0] and both.final_score == pytest.approx(-2.0)
    assert both.train_reward == pytest.approx((-1.5 * 2 - 3.5) / 3)
    assert both.eval_errors == [0.1, 0.2, 0.3]
    # Its cost stays its own: the search's spending counts each seed once.
    assert both.cpu_time == 7.0 and both.env_steps == 512
    failed = TrialResult(outcome=Outcome.FAILED, failure="diverged: NaN")
    assert combined(original, failed) is failed


@pytest.fixture
def space(workdir: Path) -> Path:
    folder = workdir / "conf" / "search"
    folder.mkdir(parents=True)
    (folder / "tiny.yaml").write_text(TINY_SEARCH)
    return workdir


def test_a_search_rechecks_its_leaders_and_picks_by_all_their_seeds(
        space: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["search=tiny", "--workers", "2", *TINY, "budget.seeds=1", "--recheck", "2",
            "search.recheck_seeds=1"]
    assert run_cli("optuna", "--dry-run", *args) == 0
    assert ("then its top 2 rechecked on 1 more seed(s) each, and the next in line for each "
            "that drops out (search.recheck)") in capsys.readouterr().out
    assert run_cli("optuna", *args) == 0
    out = capsys.readouterr().out
    assert "then its top 2 rechecked on 1 more seed(s) each" in out
    db = space / "studies" / "kraby.db"
    trials = load(db, "tiny").trials
    explored = [t for t in trials if "recheck_of" not in t.user_attrs]
    rechecks = [t for t in trials if "recheck_of" in t.user_attrs]
    assert len(explored) == 3 and len(rechecks) >= 2
    by_number = {t.number: t for t in trials}
    for recheck in rechecks:
        original = by_number[recheck.user_attrs["recheck_of"]]
        assert recheck.user_attrs["key"] == original.user_attrs["key"]
        assert recheck.params == original.params
        assert recheck.user_attrs["seed"] == 1  # the seed after the trial's own (0)
        scores = recheck.user_attrs["scores"]
        assert scores[0] == original.user_attrs["scores"][0] and len(scores) == 2
        assert recheck.value == pytest.approx(sum(scores) / 2)
        assert f"({original.user_attrs['key']}) recheck, seed 1: complete" in out
    # The top 2 by all their seeds are rechecked, and the search's pick is the best of them.
    final = {t.user_attrs["key"]: t for t in trials}  # the latest attempt of each key
    complete = sorted((t for t in final.values() if t.state == TrialState.COMPLETE),
                      key=lambda t: -t.value)
    assert all("recheck_of" in t.user_attrs for t in complete[:2])
    assert re.search(r"leaders by all their seeds: t\d [-\d.e]+ \(2 seeds\); t\d", out)
    assert run_cli("best", "--study-name", "tiny", "--storage", f"sqlite:///{db}",
                   "--name", "picked") == 0
    best_out = capsys.readouterr().out
    # The pick is named as the search and its leaders name it (its key), not by the number
    # of the attempt that rechecked it.
    picked = int(complete[0].user_attrs["key"][1:])
    assert picked != complete[0].number
    assert f"trial {picked} of search 'tiny'" in best_out
    assert "over 2 seeds (rechecked)" in best_out
    assert f"best trial {picked} (" in out
    # A rerun finds its leaders rechecked and the total reached: nothing more runs.
    assert run_cli("optuna", *args) == 0
    assert len(load(db, "tiny").trials) == len(trials)
    # A confirm's fresh seeds avoid the rechecks' seeds too.
    assert run_cli("confirm", "--study-name", "tiny", "--top", "1", "--seeds", "2",
                   "confirm.seed=0", "--dry-run", *TINY, "--storage", f"sqlite:///{db}") == 0
    assert "seeds 2-3" in capsys.readouterr().out


def test_rechecks_come_out_of_the_cpu_budget(space: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    # A budget below one trial: the first trial is the only one explored (nothing is spent
    # before it). Its recheck starts past the budget, since the search picks only a rechecked
    # trial, and nothing else does.
    args = ["search=tiny", "--workers", "1", *TINY, "budget.seeds=1", "--recheck", "1",
            "--cpu-budget", "0.001"]
    assert run_cli("optuna", *args) == 0
    out = capsys.readouterr().out
    trials = load(space / "studies" / "kraby.db", "tiny").trials
    assert len(trials) == 2 and "recheck_of" not in trials[0].user_attrs
    assert trials[1].user_attrs["recheck_of"] == 0
    assert re.search(r"leaders by all their seeds: t0 [-\d.e]+ \(3 seeds\)\n", out)


@pytest.mark.parametrize("argv,message", [
    (["search.recheck=-1"], "search.recheck must be >= 0"),
    (["search.recheck=2", "search.recheck_seeds=0"], "search.recheck_seeds >= 1"),
    (["--recheck", "2", "--objective", "final_reward,training_time"],
     "search.recheck needs one objective"),
    (["--recheck", "2", "--pruner", "wilcoxon", "budget.seeds=5"], "already races"),
])
def test_a_recheck_that_cannot_run_is_refused_before_anything_runs(
        workdir: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
        message: str) -> None:
    assert message in refused_before_work(workdir, capsys, "optuna", *argv)


@pytest.mark.parametrize("budget,exploring", [(130.0, True), (110.0, False), (None, True)])
def test_exploring_stops_when_what_is_left_pays_for_the_rechecks(
        tmp_path: Path, budget: float | None, exploring: bool) -> None:
    from kraby_study.config.compose import compose_config
    from kraby_study.records.attributes import StudyAttrs
    from kraby_study.run.search_source import SearchSource
    from kraby_study.store.store import opened

    cfg = compose_config(["budget=smoke", "search.recheck=2", "search.recheck_seeds=2",
                          f"search.cpu_budget={'null' if budget is None else budget}",
                          f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        source = SearchSource(store.define("s", StudyAttrs(kind="search")), cfg)
        # 60 CPU s spent; rechecking the two leaders on 2 more seeds each costs 2 x 30 more.
        trials = [_trial(0, [-1.0, -1.0], cpu=30.0), _trial(1, [-2.0, -2.0], cpu=30.0)]
        assert source.exploring(trials) is exploring
        # Once the total is reached, exploring ends whatever the budget.
        source.total = 2
        assert source.exploring(trials) is False


def test_the_report_says_over_how_many_seeds_each_top_trial_scored(
        space: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import pandas as pd

    assert run_cli("optuna", "search=tiny", "--workers", "1", *TINY, "budget.seeds=1",
                   "--recheck", "1", "search.recheck_seeds=2") == 0
    db = space / "studies" / "kraby.db"
    assert run_cli("report", "--storage", f"sqlite:///{db}", "--out", str(space / "r")) == 0
    top = pd.read_csv(space / "r" / "tiny" / "top_trials.csv")
    # The top trial is rechecked: 1 seed of its own and 2 more.
    assert top["seeds"].iloc[0] == 3 and set(top["seeds"].iloc[1:]) == {1}
    table = (space / "r" / "tiny" / "top_trials.md").read_text()
    assert "| rank | trial | objective | seeds |" in table
    # The top trial is named by its key, as the search's leaders name it.
    key = load(db, "tiny").trials[int(top["number"].iloc[0])].user_attrs["key"]
    assert f"| 1 | {key[1:]} |" in table
    # The CSV files name it so too (trial), beside the attempt that holds it now (number).
    assert top["trial"].iloc[0] == int(key[1:]) != top["number"].iloc[0]
    trials = pd.read_csv(space / "r" / "tiny" / "trials.csv")
    assert list(trials.loc[trials["trial"] == int(key[1:]), "number"]) == [
        top["number"].iloc[0]]
    # Its intermediate values, drawn as the best trial's line, are its first attempt's.
    from kraby_study.answers.search_evidence import build_search
    from kraby_study.answers.study_data import load_study
    from kraby_study.report.search_plots import reported
    from kraby_study.store.store import Store

    search = build_search(load_study(Store(f"sqlite:///{db}"), "tiny"))
    recheck = next(t for t in search.data.trials if t.number == top["number"].iloc[0])
    first = load(db, "tiny").trials[int(key[1:])]
    assert not recheck.intermediate_values and first.intermediate_values
    assert reported(search, recheck) == first.intermediate_values
    # The history draws it at its own number, at its first seed's score and again (a ring) at
    # its score over all three; every trial once, in trial order.
    from kraby_study.report.search_plots import first_scores

    points = first_scores(search)
    assert list(points["trial"]) == sorted(points["trial"])
    assert len(set(points["trial"])) == len(points)
    row = points[points["trial"] == int(key[1:])].iloc[0]
    assert row["rechecked"] and row["first"] == pytest.approx(first.value)
    assert row["value"] == pytest.approx(recheck.value) != pytest.approx(first.value)
    assert not points.loc[points["trial"] != int(key[1:]), "rechecked"].any()
    pages = [page.read_text() for page in (space / "r").rglob("*.md")]
    assert any(f"Best: trial {key[1:]}," in page for page in pages)


def test_exploring_once_ended_for_the_rechecks_does_not_start_again(tmp_path: Path) -> None:
    from kraby_study.config.compose import compose_config
    from kraby_study.records.attributes import StudyAttrs
    from kraby_study.run.search_source import SearchSource
    from kraby_study.store.store import opened

    cfg = compose_config(["budget=smoke", "search.recheck=2", "search.recheck_seeds=2",
                          "search.cpu_budget=110", f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        source = SearchSource(store.define("s", StudyAttrs(kind="search")), cfg)
        trials = [_trial(0, [-1.0, -1.0], cpu=30.0), _trial(1, [-2.0, -2.0], cpu=30.0)]
        # 60 spent + 60 to recheck both: exploring ends.
        assert source.exploring(trials) is False
        # t0's recheck has started and used nothing yet: only t1's 30 is reserved now, and
        # 60 + 30 < 110 would seem to leave room, but the rest of the budget is the rechecks'.
        running = [*trials, _trial(2, None, key="t0", of=0, state=TrialState.RUNNING)]
        assert source.exploring(running) is False


def test_a_search_whose_exploring_ended_for_its_rechecks_is_stopped_by_its_budget(
        tmp_path: Path) -> None:
    import io

    from omegaconf import DictConfig

    from kraby_study.config.compose import compose_config
    from kraby_study.records.attributes import StudyAttrs
    from kraby_study.run.search_source import SearchSource, record_budget_end
    from kraby_study.store.store import opened

    def config(budget: float) -> DictConfig:
        return compose_config(["budget=smoke", "search.recheck=2", "search.recheck_seeds=2",
                               "search.trials=100", f"search.cpu_budget={budget}",
                               f"storage=sqlite:///{tmp_path}/k.db"])

    with opened(config(110.0).storage) as store:
        ledger = store.define("s", StudyAttrs(kind="search", planned=100))
        study = optuna.load_study(study_name="s", storage=f"sqlite:///{tmp_path}/k.db")
        for trial in [_trial(0, [-1.0, -1.0], cpu=30.0), _trial(1, [-2.0, -2.0], cpu=30.0)]:
            study.add_trial(trial)
        source = SearchSource(ledger, config(110.0))
        # 60 CPU s spent + 60 to recheck both leaders: exploring ends for the rechecks.
        assert source.exploring(ledger.trials()) is False and source.explored
        for of, cpu in ((0, 15.0), (1, 15.0)):
            study.add_trial(_trial(2 + of, [-1.0 - of] * 4, key=f"t{of}", of=of, cpu=cpu))
        # The rechecks cost less than reserved: 90 of 110 CPU s used, yet the budget ended it.
        assert not source.over_budget()
        out = io.StringIO()
        record_budget_end(source, out)
        assert "90 of its 110 CPU s used, 2 of 100 trials (stopped by the CPU budget)" in (
            out.getvalue())
        assert ledger.attrs.planned == 2 and ledger.attrs.explored == 110.0
        # A later command under the same budget only rechecks (here: nothing is left) ...
        assert SearchSource(ledger, config(110.0)).exploring(ledger.trials()) is False
        # ... and one given more budget explores again.
        assert SearchSource(ledger, config(200.0)).exploring(ledger.trials()) is True


def test_a_rechecked_trials_cpu_per_seed_is_over_the_seeds_it_trained() -> None:
    from kraby_study.records.attributes import TrialAttrs

    # A recheck trained 3 seeds of 20,000 steps in 72 CPU s; its scores hold the trial's 2
    # seeds too. Its CPU per seed is 24, not 72 / 5.
    held = TrialAttrs(recheck_of=1, cpu_time=72.0, scores=[500.0] * 5, steps=20_000,
                      env_steps=60_000)
    assert held.training_time() == pytest.approx(24.0)
    assert TrialAttrs(cpu_time=40.0, scores=[500.0] * 2, steps=20_000,
                      env_steps=40_000).training_time() == pytest.approx(20.0)


def test_a_failed_attempt_is_named_by_its_trial_and_attempt() -> None:
    from types import SimpleNamespace

    import pandas as pd

    from kraby_study.report.search_output import failed_items

    trials = pd.DataFrame({"number": [4, 9], "trial": [4, 2], "outcome": ["failed", "failed"],
                           "failure": ["diverged", ""], "gamma": [0.9, 0.95]})
    search = SimpleNamespace(trials=trials, params=["gamma"], distributions={})
    assert failed_items(search) == ["trial 4 (gamma=0.9): diverged",  # type: ignore[arg-type]
                                    "trial 2, attempt 9 (gamma=0.95): failed"]


def test_a_running_trial_could_still_use_its_steps_left_at_its_own_pace_or_the_searchs()\
        -> None:
    # 10 % trained or more: its own pace (0.2 CPU s a step) over the 1,600 steps left.
    assert costs.to_spend(400, 2000, 80.0, rate=0.015) == pytest.approx(320.0)
    # Less: its start would inflate its own pace, so the search's ended trials' pace.
    assert costs.to_spend(100, 2000, 20.0, rate=0.015) == pytest.approx(28.5)
    # No ended trial to learn from: its own pace; nothing trained yet: the search's pace.
    assert costs.to_spend(100, 2000, 20.0, rate=None) == pytest.approx(380.0)
    assert costs.to_spend(0, 2000, 0.0, rate=0.015) == pytest.approx(30.0)
    assert costs.to_spend(0, 2000, 0.0, rate=None) == 0.0
    assert costs.to_spend(2000, 2000, 9.0, rate=0.1) == 0.0


def test_the_searchs_pace_is_the_median_of_its_ended_attempts() -> None:
    trials = [_trial(0, [-1.0], cpu=30.0, steps=2000), _trial(1, [-2.0], cpu=10.0, steps=500),
              _trial(2, None, cpu=5.0, steps=1000, state=TrialState.PRUNED),
              _trial(3, [-1.0, -1.0], key="t0", of=0, cpu=90.0, steps=2000)]
    # Paces 0.015, 0.02, 0.005 and 0.045 CPU s a step: the median of all four.
    assert costs.cpu_per_step(trials) == pytest.approx(0.0175)
    assert costs.cpu_per_step([_trial(0, [-1.0])]) is None


def test_once_the_budget_is_used_the_best_trial_is_still_rechecked(tmp_path: Path) -> None:
    from kraby_study.config.compose import compose_config
    from kraby_study.records.attributes import StudyAttrs
    from kraby_study.run.search_source import SearchSource
    from kraby_study.store.store import opened

    cfg = compose_config(["budget=smoke", "budget.seeds=2", "search.recheck=2",
                          "search.recheck_seeds=3", "search.cpu_budget=50",
                          "save_models=false", f"storage=sqlite:///{tmp_path}/k.db"])
    # As on MountainCarContinuous-v0 (random search, sampler seed 9): t0 and t3 rechecked,
    # t3 dropped by its recheck as the budget ran out, so t2 leads on its 2 search seeds.
    stored = [_trial(0, [92.4, 92.4]), _trial(1, [25.6, 25.6]), _trial(2, [91.3, 91.3]),
              _trial(3, [91.9, 91.9]),
              _trial(4, [92.4, 92.4, 93.6, 88.2, 86.5], key="t0", of=0, seed=2),
              _trial(5, [91.9, 91.9, 90.7, 92.6, -98.2], key="t3", of=3, seed=2)]
    with opened(cfg.storage) as store:
        ledger = store.define("s", StudyAttrs(kind="search"))
        study = optuna.load_study(study_name="s", storage=cfg.storage)
        for trial in stored:
            study.add_trial(trial)
        source = SearchSource(ledger, cfg)
        assert source.over_budget()  # 60 CPU s of 50
        claimed = source.next_trial()
        assert claimed is not None
        number, spec = claimed
        assert (spec.key, spec.seed, spec.seeds) == ("t2", 2, 3)
        assert ledger.trials()[number].user_attrs["recheck_of"] == 2
        # Past the budget only the best is rechecked: while t2's runs, nothing starts.
        assert source.next_trial() is None
        # It drops too (seeds 2-4 as in the TPE search of that seed): t0 leads, rechecked.
        source.record(number, spec, TrialResult(
            outcome=Outcome.COMPLETE, scores=[-98.3, 89.7, -41.8], final_score=-16.8,
            cpu_time=30.0, env_steps=3 * spec.steps))
        assert [lead.trial.user_attrs["key"] for lead in leaders(ledger.trials(), 2)] == [
            "t0", "t3"]
        assert source.next_trial() is None


def test_a_dear_running_trial_ends_exploring_before_it_takes_the_rechecks_share(
        tmp_path: Path) -> None:
    from kraby_study.config.compose import compose_config
    from kraby_study.records.attributes import StudyAttrs
    from kraby_study.run.search_source import SearchSource
    from kraby_study.store.store import opened

    cfg = compose_config(["budget=smoke", "budget.seeds=2", "search.recheck=2",
                          "search.recheck_seeds=2", "search.cpu_budget=300",
                          "save_models=false", f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        source = SearchSource(store.define("s", StudyAttrs(kind="search")), cfg)
        claimed = source.next_trial()
        assert claimed is not None
        number, spec = claimed
        total = spec.steps * spec.seeds
        # Two ended trials: 60 CPU s spent at 0.015 a step, 30 to recheck each.
        ended = [_trial(0, [-1.0, -1.0], cpu=30.0, steps=2000),
                 _trial(1, [-2.0, -2.0], cpu=30.0, steps=2000)]
        # Early in the running trial, the search's pace projects it: room for more.
        source.using(number, total // 20, 20.0)
        assert source.exploring(ended) is True
        # A fifth of the way in after 100 CPU s, it could use 400 more, the rechecks' share:
        # exploring ends (counting only what it has used so far, 60 + 100 + 60 < 300, it
        # would go on, and the rechecks find the budget used when it ends).
        source.using(number, total // 5, 100.0)
        assert source.exploring(ended) is False
