"""Two-objective searches (a reward and a cost): the study's directions, the front and the
choices made from it (hand-worked), a confirm study's fastest_equivalent, the report's front, and
the bad input refused."""

from __future__ import annotations

import csv
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import optuna
import pytest
from conftest import TINY, finished_search, load, run_cli
from optuna.study import StudyDirection

from kraby_study.answers.search_front import front_lines, search_front
from kraby_study.answers.selected import front_selection, selected_value
from kraby_study.config.compose import compose_config
from kraby_study.decision.comparison import CompareOptions
from kraby_study.decision.front import Point, front_choice, pareto_front, spread
from kraby_study.errors import ConfigError
from kraby_study.plan.confirm import ConfirmedStudy, confirm_rule
from kraby_study.plan.space import search_definition
from kraby_study.records.attributes import SelectRule, StudyAttrs
from kraby_study.records.definition import check_objective, stored_floor

SPACE = """\
name: two
sampler: tpe
seed: 0
startup_trials: 2
objective: [final_reward, training_time]
trials: 4
params:
  learning_rate: {path: ppo.learning_rate, type: float, low: 1.0e-4, high: 1.0e-2, log: true}
  n_epochs: {path: ppo.n_epochs, type: int, low: 1, high: 4}
"""
SEARCH = ["optuna", "search=two", "--workers", "2", *TINY, "budget.seeds=2"]


# The front and the spread choice, on constructed trials -----------------------------------------

# (number, score, cost). Trial 2 (0.8 at 6 s) is dominated by trial 1 (0.9 at 5 s); every other
# trial is on the front, which runs cheapest first: 3, 5, 1, 4, 0.
POINTS = [Point(0, 1.0, 10.0), Point(1, 0.9, 5.0), Point(2, 0.8, 6.0), Point(3, 0.5, 1.0),
          Point(4, 0.95, 8.0), Point(5, 0.7, 3.0)]


def test_the_front_is_the_trials_no_other_beats_on_both() -> None:
    assert [p.key for p in pareto_front(POINTS)] == [3, 5, 1, 4, 0]
    # Equal points are both on the front; a point equal in score but dearer is not.
    twins = [Point("a", 1.0, 2.0), Point("b", 1.0, 2.0), Point("c", 1.0, 3.0)]
    assert [p.key for p in pareto_front(twins)] == ["a", "b"]


def test_the_spread_takes_both_ends_and_evenly_spaced_places_in_cost_order() -> None:
    front = pareto_front(POINTS)  # cost order: 3, 5, 1, 4, 0 (places 0 .. 4)
    # 3 of 5: places round(i * 4 / 2) = 0, 2, 4: the best score (0), the cheapest (3), then 1.
    assert [p.key for p in spread(front, 3)] == [0, 3, 1]
    # 4 of 5: places round(i * 4 / 3) = 0, 1 (1.33), 3 (2.67), 4.
    assert [p.key for p in spread(front, 4)] == [0, 3, 5, 4]
    assert [p.key for p in spread(front, 1)] == [0]
    assert [p.key for p in spread(front, 2)] == [0, 3]
    # More asked than the front holds: all of it, best score, cheapest, then by cost.
    assert [p.key for p in spread(front, 9)] == [0, 3, 5, 1, 4]
    assert spread([], 3) == []


def test_the_cheapest_trial_equivalent_to_the_best_score_is_selected() -> None:
    front = [Point(3, 0.5, 1.0), Point(1, 0.995, 5.0), Point(0, 1.0, 10.0)]
    # Four seeds each, sd about 0.005: trial 1 within the margin (0.2 x 1.0) of trial 0, trial
    # 3 half the score.
    seeds = {0: [1.00, 1.005, 0.995, 1.0], 1: [0.99, 0.995, 1.0, 0.995],
             3: [0.50, 0.505, 0.495, 0.5]}
    choice = front_choice(front, seeds, "fastest_equivalent", CompareOptions())
    assert choice is not None and choice.tested
    assert (choice.best.key, choice.equivalent, choice.chosen.key) == (0, [1], 1)
    assert choice.rule == "fastest_equivalent" and "shown equivalent" in choice.rule_text
    # At margin 0 nothing is equivalent: the best score is the cheapest of its own set.
    at_zero = front_choice(front, seeds, "fastest_equivalent", CompareOptions(margin=0.0))
    assert at_zero is not None and at_zero.chosen.key == 0


def test_with_one_seed_a_trial_no_test_is_made_and_the_rule_falls_back_to_the_best() -> None:
    front = [Point(3, 0.5, 1.0), Point(0, 1.0, 10.0)]
    choice = front_choice(front, {0: [1.0], 3: [0.5]}, "fastest_equivalent", CompareOptions())
    assert choice is not None and not choice.tested and choice.chosen.key == 0
    assert "falls back to final_score" in choice.rule_text
    assert front_choice([], {}, "fastest_equivalent", CompareOptions()) is None


# The floor, on constructed trials ---------------------------------------------------------------


@dataclass
class _Trial:
    """A stored two-objective search trial, as the front reads it (a StoredTrial)."""

    number: int
    values: list[float] | None
    user_attrs: dict[str, Any] = field(default_factory=dict)
    state: _State = field(default_factory=lambda: _State("COMPLETE"))
    params: dict[str, Any] = field(default_factory=dict)
    system_attrs: dict[str, Any] = field(default_factory=dict)


def _trials(floor_state: str = "COMPLETE") -> list[_Trial]:
    # (score, cost): 0 is the enqueued floor (0.90 at 5 s), 1 cheap and bad (0.50 at 1 s),
    # 2 the best (1.00 at 10 s), 3 better and cheaper than the floor (0.95 at 4 s).
    floor = _Trial(0, [0.90, 5.0], {"enqueued": "ppo=tuned", "scores": [0.9, 0.9]},
                   _State(floor_state))
    if floor_state != "COMPLETE":
        floor.values = None
    return [floor, _Trial(1, [0.50, 1.0], {"scores": [0.5, 0.5]}),
            _Trial(2, [1.00, 10.0], {"scores": [1.0, 1.01, 0.99]}),
            _Trial(3, [0.95, 4.0], {"scores": [0.95, 0.96, 0.94]})]


def test_a_floor_leaves_the_trials_below_its_score_off_the_front() -> None:
    # Without a floor the front runs 1 (cheapest), 3, 2; 0 is dominated by 3 (better, cheaper).
    assert [p.key for p in search_front(_trials()).front] == [1, 3, 2]
    # With the floor ppo=tuned (trial 0, 0.90) trial 1 (0.50) is infeasible: the front is 3, 2.
    found = search_front(_trials(), "tuned")
    assert [p.key for p in found.front] == [3, 2] and len(found.points) == 4
    assert found.floor_score == pytest.approx(0.90)
    assert "floor ppo=tuned, score 0.9: 1 complete trial(s) below it" in found.floor_text
    assert "floor ppo=tuned" in front_lines(found)[1]
    # 2 against 3 (sd 0.01 each, 3 seeds): t = 0.05 / 0.00816 = 6.1, p ~ 0.002 < 0.05: worse,
    # so the best score (2) is selected, not the cheap trial a smaller family could tie.
    assert found.choice is not None and found.choice.chosen.key == 2
    # A trial exactly at the floor's score is feasible: the floor itself when nothing beats it.
    alone = [t for t in _trials() if t.number in (0, 1)]
    assert [p.key for p in search_front(alone, "tuned").front] == [0]


def test_a_floor_not_yet_measured_leaves_every_trial_eligible() -> None:
    found = search_front(_trials("RUNNING"), "tuned")
    assert found.floor_score is None and [p.key for p in found.front] == [1, 3, 2]
    assert "not measured yet" in found.floor_text
    assert search_front(_trials()).floor_text == ""


def test_a_retried_trial_is_known_on_the_front_by_its_own_number() -> None:
    # Trial 3 was interrupted and retried: attempt 7 holds it now, under its key t3, with the
    # best score (it beats trial 2 on both). The front, best's lines and the selection name it
    # trial 3, as every other command does, not 7.
    retried = _Trial(7, [1.05, 4.0], {"key": "t3", "retry_of": 3, "settings": {"n_epochs": 3},
                                      "scores": [1.05, 1.06, 1.04]})
    trials = [t for t in _trials() if t.number != 3] + [retried]
    found = search_front(trials)
    assert [p.key for p in found.front] == [1, 3]
    chosen = front_selection("two", {"search": {}}, trials)
    assert chosen is not None and chosen.description.startswith("trial 3 of search 'two'")
    assert chosen.settings == {"n_epochs": 3}
    assert any(line.startswith("  trial    3") and "selected" in line for line in chosen.front)
    assert not any(line.startswith("  trial    7") for line in chosen.front)


def test_only_a_two_objective_search_with_a_floor_stores_one() -> None:
    two = "search.objective=[final_reward,training_time]"
    assert search_definition(compose_config([two]))["search"]["floor"] == "tuned"
    assert search_definition(compose_config([two, "search.floor=start"]))["search"][
        "floor"] == "start"
    # One objective, or no floor: the definition (and fingerprint) it had before floors.
    assert "floor" not in search_definition(compose_config([]))["search"]
    assert "floor" not in search_definition(compose_config([two, "search.floor=null"]))["search"]
    assert stored_floor(search_definition(compose_config([two]))) == "tuned"
    assert stored_floor(search_definition(compose_config([]))) is None


# A confirm study stored with the retired rule, on constructed scores -----------------------------


@dataclass
class _State:
    name: str


@dataclass
class _Run:
    """A stored confirm run, as the selection reads it (a StoredTrial)."""

    number: int
    value: float
    params: dict[str, Any]
    user_attrs: dict[str, Any]
    state: _State = field(default_factory=lambda: _State("COMPLETE"))
    system_attrs: dict[str, Any] = field(default_factory=dict)

    @property
    def values(self) -> list[float]:
        return [self.value]


def test_a_confirm_stored_with_fastest_tied_selects_by_fastest_equivalent_in_cpu_s() -> None:
    # t3 is best, t5 within the margin of it, t7 far worse. In CPU seconds t5 is the cheapest
    # equivalent arm; in wall-clock seconds (other work on the machine) t3 would be. A study
    # stored with the retired rule fastest_tied is answered by today's rule.
    arms = {"t3": ([1.0, 1.02, 0.98, 1.0], 10.0, 1.0), "t5": ([0.99, 1.01, 0.97, 1.01], 4.0, 9.0),
            "t7": ([0.5, 0.52, 0.48, 0.5], 1.0, 1.0)}
    runs = [_Run(number=len(arms) * i + j, value=score, params={"config": label},
                 user_attrs={"key": f"v{j}-s{i}", "cpu_time": cpu, "wall_time": wall})
            for j, (label, (scores, cpu, wall)) in enumerate(arms.items())
            for i, score in enumerate(scores)]
    definition = {"kind": "confirm", "parameter": "config", "values": list(arms)}
    for stored in ("fastest_tied", "fastest_equivalent"):
        chosen = selected_value(StudyAttrs(kind="confirm", definition=definition,
                                           select=stored), runs, lambda _: None)
        assert chosen is not None and chosen.value == "t5"
        assert chosen.rule == "fastest_equivalent" and chosen.answer == "equivalent"
    best = selected_value(StudyAttrs(kind="confirm", definition=definition), runs,
                          lambda _: None)
    assert best is not None and best.value == "t3"


def test_a_confirm_of_a_front_defaults_to_fastest_equivalent() -> None:
    front = ConfirmedStudy(name="s", arms=[], used_seeds=set(), steps=1, curve_every=1,
                           env_keys=[], two_objectives=True)
    single = ConfirmedStudy(name="s", arms=[], used_seeds=set(), steps=1, curve_every=1,
                            env_keys=[])
    cfg = compose_config([])
    assert confirm_rule(cfg, front) == SelectRule.FASTEST_EQUIVALENT
    assert confirm_rule(cfg, single) == SelectRule.FINAL_SCORE
    assert confirm_rule(compose_config(["confirm.select=auc"]), front) == SelectRule.AUC
    with pytest.raises(ConfigError, match="confirm.select must be one of"):
        confirm_rule(compose_config(["confirm.select=cheapest"]), front)


def test_a_one_objective_search_keeps_its_definition() -> None:
    """The pruner's default (null) and the objective's list form change no stored search:
    one objective is still stored as one name, with the median pruner."""
    search = search_definition(compose_config(["budget=quick"]))["search"]
    assert search["objective"] == "final_reward" and search["pruner"] == "median"
    two = search_definition(compose_config(
        ["budget=quick", "search.objective=[final_reward,training_time]"]))["search"]
    assert two["objective"] == ["final_reward", "training_time"] and two["pruner"] == "none"
    # A cost given first is put after the reward: one definition, one study.
    assert check_objective(["training_time", "final_reward"]) == ["final_reward",
                                                                  "training_time"]


# A tiny two-objective search, end to end ------------------------------------------------------


@pytest.fixture(scope="module")
def searched(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding a finished 4-trial two-objective search (2 seeds each)."""
    return finished_search(tmp_path_factory.mktemp("two"), "two", SPACE, *SEARCH)


@pytest.fixture
def folder(searched: Path, workdir: Path) -> Path:
    shutil.copytree(searched, workdir, dirs_exist_ok=True)
    return workdir


def test_the_study_has_two_directions_and_each_trial_a_score_and_a_cost(
        searched: Path) -> None:
    study = load(searched / "studies" / "kraby.db", "two")
    assert study.directions == [StudyDirection.MAXIMIZE, StudyDirection.MINIMIZE]
    assert isinstance(study.sampler, optuna.samplers.TPESampler)
    assert len(study.trials) == 4 and not any(t.intermediate_values for t in study.trials)
    # The enqueued configurations ran first, and say so.
    assert [t.user_attrs.get("enqueued") for t in study.trials[:2]] == ["ppo=tuned", "ppo=start"]
    for trial in study.trials:
        score, cost = trial.values
        seeds = trial.user_attrs["scores"]
        assert len(seeds) == 2 and score == pytest.approx(sum(seeds) / 2)
        assert cost == pytest.approx(trial.user_attrs["cpu_time"] / 2) and cost > 0
    assert study.best_trials


def test_each_trial_carries_its_floor_constraint_for_the_sampler(searched: Path) -> None:
    study = load(searched / "studies" / "kraby.db", "two")
    floor = study.trials[0]
    assert floor.user_attrs["enqueued"] == "ppo=tuned" and floor.constraints == {"floor": 0.0}
    after = 0
    for trial in study.trials[1:]:
        gap = trial.constraints["floor"]
        # Ended after the floor: the floor's score minus its own; before it: 0 (not measured).
        if trial.datetime_start > floor.datetime_complete:
            after += 1
            assert gap == pytest.approx(floor.values[0] - trial.values[0])
        else:
            assert gap in (0.0, pytest.approx(floor.values[0] - trial.values[0]))
    assert after >= 1


def test_list_best_and_progress_show_the_front(folder: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("optuna", "search=two", "--trials", "5", "--workers", "1", *TINY,
                   "budget.seeds=2") == 0
    out = capsys.readouterr().out
    assert "[5/5]" in out and "CPU s/seed" in out.split("[5/5]")[1] and "front of" in out
    assert run_cli("list") == 0
    listed = capsys.readouterr().out
    assert "front of " in listed
    assert run_cli("best", "--study-name", "two") == 0
    out = capsys.readouterr().out
    assert out.startswith("front (")
    # list reads rows without Optuna, best reads Optuna's trials: the same floored front.
    size = out.split("front (", 1)[1].split(" of ", 1)[0]
    assert f"front of {size};" in listed
    assert "floor ppo=tuned, score" in out.splitlines()[1]
    # A new two-objective search stores the evidence rule, and says its margin.
    assert "selected by fastest_equivalent" in out and "[" in out and "margin " in out
    assert (folder / "conf" / "ppo" / "best_two.yaml").is_file()


def test_the_report_draws_the_front(folder: Path) -> None:
    assert run_cli("report", "--study-name", "two", "--no-policy") == 0
    out = folder / "reports" / "two"
    assert (out / "pareto.png").stat().st_size > 0
    with (out / "pareto.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert rows and list(rows[0])[:7] == ["trial", "score", "cost", "enqueued", "best",
                                          "equivalent", "selected"]
    assert {"learning_rate", "n_epochs"} <= set(rows[0])
    assert sum(r["selected"] == "True" for r in rows) == 1
    assert float(rows[0]["score"]) >= max(float(r["score"]) for r in rows)
    summary = (out / "summary.md").read_text()
    assert "the front" in summary and "floor ppo=tuned, score" in summary
    index = (folder / "reports" / "index.md").read_text()
    assert "two/pareto.png" in index and "two/summary.md" in index
    assert run_cli("report", "--study-name", "two", "--no-policy", "--format", "svg") == 0
    assert (out / "pareto.svg").is_file()


def test_confirm_retrains_the_front_and_selects_the_cheapest_equivalent(
        folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("confirm", "--study-name", "two", "--top", "2", "--seeds", "2",
                   "--workers", "2") == 0
    study = load(folder / "studies" / "kraby.db", "two-confirm")
    assert study.user_attrs["kraby_select"] == "fastest_equivalent"
    arms = study.user_attrs["kraby_definition"]["arms"]
    assert 1 <= len(arms) <= 2 and "best score" in arms[0]["origin"]
    capsys.readouterr()
    assert run_cli("best", "--study-name", "two-confirm") == 0
    assert "selected by fastest_equivalent" in capsys.readouterr().out
    # Re-selection without retraining: another rule read instead of the stored one.
    assert run_cli("best", "--study-name", "two-confirm", "compare.select=auc") == 0
    assert "selected by auc" in capsys.readouterr().out
    assert study.user_attrs["kraby_select"] == "fastest_equivalent"
    assert run_cli("report", "--study-name", "two-confirm", "--no-policy") == 0
    summary = (folder / "reports" / "two-confirm" / "summary.md").read_text()
    assert "fastest_equivalent" in summary


# Bad input: one line, exit 2, nothing written ----------------------------------------------------


@pytest.mark.parametrize("argv,message", [
    (["search.objective=[final_reward,speed]"], "unknown objective 'speed'"),
    (["--objective", "final_reward,training_time,evaluation"], "at most two objectives"),
    (["search.objective=[final_reward,evaluation]"], "two rewards"),
    (["--objective", "training_time"], "a cost alone"),
    (["--objective", "final_reward,training_time", "--pruner", "median"],
     "Optuna cannot prune a trial with several objectives"),
    (["--objective", "final_reward,training_time", "--floor", "best"],
     "search.floor=best is not an enqueued configuration"),
    (["--objective", "final_reward,training_time", "search.enqueue=[start]"],
     "search.floor=tuned is not an enqueued configuration"),
])
def test_bad_objectives_are_refused_in_one_line(workdir: Path,
                                                capsys: pytest.CaptureFixture[str],
                                                argv: list[str], message: str) -> None:
    assert run_cli("optuna", *argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (workdir / "studies").exists()


def test_a_confirm_rule_that_is_not_one_is_refused(workdir: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("confirm", "--baseline", "ppo=tuned", "--select", "cheapest") == 2
    err = capsys.readouterr().err
    assert "confirm.select must be one of final_score, auc, fastest_equivalent" in err
    assert err.count("\n") == 1 and not (workdir / "studies").exists()


def test_resuming_a_one_objective_search_with_two_is_a_changed_definition(
        folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["optuna", "search=two", "search.name=one", "--workers", "1", *TINY,
            "budget.seeds=1", "search.enqueue=[]", "search.floor=null"]
    assert run_cli(*base, "--trials", "1", "--objective", "final_reward") == 0
    capsys.readouterr()
    assert run_cli(*base, "--trials", "2", "--objective", "final_reward,training_time") == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and "objective" in err and err.count("\n") == 1
    assert len(load(folder / "studies" / "kraby.db", "one").trials) == 1


def test_resuming_a_search_with_another_floor_is_a_changed_definition(
        folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = len(load(folder / "studies" / "kraby.db", "two").trials)
    assert run_cli(*SEARCH, "--trials", "5", "--floor", "start") == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and "floor" in err and err.count("\n") == 1
    assert len(load(folder / "studies" / "kraby.db", "two").trials) == before


def test_the_sampler_and_directions_of_a_two_objective_search() -> None:
    from kraby_study.run.sampling import directions, make_pruner, make_sampler

    cfg = compose_config(["search.objective=[final_reward,training_time]",
                          "search.sampler=nsga2"])
    assert directions(cfg) == ["maximize", "minimize"]
    assert isinstance(make_sampler(cfg), optuna.samplers.NSGAIISampler)
    assert isinstance(make_pruner(cfg), optuna.pruners.NopPruner)
    assert directions(compose_config([])) == ["maximize"]
    assert isinstance(make_pruner(compose_config([])), optuna.pruners.MedianPruner)
