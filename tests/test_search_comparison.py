"""benchmarks/bench_search.py: two samplers' searches at equal CPU cost, each pick confirmed."""

from __future__ import annotations

import datetime
import importlib.util
import math
import re
import statistics
import sys
from pathlib import Path
from typing import Any

import optuna
import pytest
from optuna.trial import TrialState
from scipy import stats as scipy_stats

from kraby_study.records.stored import spent_cpu

optuna.logging.set_verbosity(optuna.logging.WARNING)


# Trials small enough for a test: 1,024 steps, one seed, tiny rollouts, at most 2 epochs.
TINY = ["budget.steps=1024", "budget.seeds=1", "budget.curve_every=128", "search.eval_episodes=4",
        "search.params.n_steps.choices=[8,16]", "search.params.n_epochs.high=2"]


def _benchmark(name: str) -> object:
    """The module of ``benchmarks/NAME.py``, or of ``experiments/NAME.py`` for a replay of one
    past experiment."""
    root = Path(__file__).parents[1]
    path = next(folder / f"{name}.py" for folder in (root / "benchmarks", root / "experiments")
                if (folder / f"{name}.py").exists())
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def _bench() -> object:
    return _benchmark("bench_search")


def _recorded(monkeypatch: pytest.MonkeyPatch) -> tuple[Any, list[tuple[str, ...]]]:
    """The benchmark's module with its commands recorded, not run (each search read as
    nothing, each confirm as two scores), and the list they are recorded in."""
    bench = _bench()
    commands: list[tuple[str, ...]] = []
    monkeypatch.setattr(bench, "kraby", lambda *args: commands.append(args))
    monkeypatch.setattr(bench, "read_search", lambda storage, arm: None)
    monkeypatch.setattr(bench, "read_confirm", lambda storage, name: ([-1.0, -2.0], 1.0))
    return bench, commands


def _run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, *args: str) -> str:
    """Run the benchmark on CartPole-v1 with tiny trials, one worker and 2 confirm seeds, in
    a fresh store; return the store's URL."""
    monkeypatch.chdir(tmp_path)
    url = f"sqlite:///{tmp_path / 'b.db'}"
    assert _bench().main([  # type: ignore[attr-defined]
        "--env-id", "CartPole-v1", "--confirm-seeds", "2", "--storage", url, "--workers", "1",
        *TINY, *args]) == 0
    return url


@pytest.mark.slow
def test_the_comparison_runs_both_samplers_at_equal_cost_and_confirms_each_pick(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    budget = 4.0
    url = _run(tmp_path, monkeypatch, "--cpu-budget", str(budget), "--sampler-seeds", "0", "1")
    out = capsys.readouterr().out
    for sampler in ("tpe", "random"):
        for seed in (0, 1):
            study = optuna.load_study(study_name=f"cartpole-{sampler}-s{seed}", storage=url)
            ended = [t for t in study.trials if t.state != TrialState.WAITING]
            # The budget's own count: the trials' CPU and what asking the sampler cost.
            spent = spent_cpu(ended)
            assert spent > sum(t.user_attrs["cpu_time"] for t in ended)
            # It stopped at its budget: the trials before the last had not used it up.
            assert spent >= budget > spent - spent_cpu(ended[-1:])
            assert study.user_attrs["sampler"] == sampler
            assert study.user_attrs["sampler_seed"] == seed
            confirm = optuna.load_study(study_name=f"cartpole-{sampler}-s{seed}-confirm",
                                        storage=url)
            runs = [t for t in confirm.trials if t.state == TrialState.COMPLETE]
            assert sorted(t.user_attrs["seed"] for t in runs) == [1000, 1001]
            assert re.search(rf"^\| {sampler} \| {seed} \| \d+/\d+/\d+ \| ", out, re.M)
    zoo = optuna.load_study(study_name="cartpole-zoo-confirm", storage=url)
    assert len([t for t in zoo.trials if t.state == TrialState.COMPLETE]) == 2
    last = out.strip().splitlines()[-1]
    assert re.fullmatch(r"bench_search: tpe - random confirmed mean difference -?[\d.]+ \(95 % "
                        r"t CI \[-?[\d.]+, -?[\d.]+\], 2 sampler seeds\); CPU tpe [\d,]+ s, "
                        r"random [\d,]+ s", last), last


def test_a_rechecked_trial_is_read_by_its_recheck(tmp_path: Path) -> None:
    from optuna.distributions import FloatDistribution
    from optuna.trial import create_trial

    url = f"sqlite:///{tmp_path / 'r.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_definition", {"search": {"startup_trials": 1}})
    space = {"x": FloatDistribution(0, 1)}

    def add(value: float, key: str, cpu: float, **attrs: object) -> None:
        study.add_trial(create_trial(value=value, params={"x": 0.5}, distributions=space,
                                     user_attrs={"key": key, "cpu_time": cpu, **attrs}))
    add(-1.0, "t0", 10.0)
    add(-0.5, "t1", 10.0)  # led on its own seeds ...
    add(-2.0, "t1", 20.0, recheck_of=1)  # ... and fell back when rechecked
    bench = _bench()
    arm = bench.Arm("tpe", 0, "s")  # type: ignore[attr-defined]
    bench.read_search(url, arm)  # type: ignore[attr-defined]
    assert (arm.pick, arm.search_score) == ("t0", -1.0)
    assert arm.trials == "2/0/0 (1 rechecked)" and arm.cpu == 40.0


def test_a_two_objective_search_is_read_by_its_fronts_best_score(tmp_path: Path) -> None:
    from optuna.distributions import FloatDistribution
    from optuna.trial import create_trial

    url = f"sqlite:///{tmp_path / 'c.db'}"
    study = optuna.create_study(study_name="s", storage=url,
                                directions=["maximize", "minimize"])
    study.set_user_attr("kraby_definition", {"search": {"startup_trials": 1}})
    space = {"x": FloatDistribution(0, 1)}
    for number, (score, cost) in enumerate([(500.0, 30.0), (500.0, 12.0), (480.0, 5.0),
                                            (500.0, 20.0)]):
        study.add_trial(create_trial(values=[score, cost], params={"x": 0.5},
                                     distributions=space,
                                     user_attrs={"key": f"t{number}", "cpu_time": 2 * cost}))
    bench = _bench()
    arm = bench.Arm("tpe", 0, "s")  # type: ignore[attr-defined]
    bench.read_search(url, arm)  # type: ignore[attr-defined]
    # The best score is shared by three trials; the front holds the cheapest of them.
    assert (arm.pick, arm.search_score) == ("t1", 500.0)
    assert arm.trials == "4/0/0" and arm.cpu == 134.0
    assert arm.after_start == "3 trials, 0 pruned, 1 distinct setting of no categorical parameter"


def test_after_the_random_start_a_search_counts_its_distinct_categorical_settings(
        tmp_path: Path) -> None:
    from optuna.distributions import CategoricalDistribution, FloatDistribution
    from optuna.trial import create_trial

    url = f"sqlite:///{tmp_path / 'd.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_definition", {"search": {"startup_trials": 2}})
    space = {"n": CategoricalDistribution([8, 16]), "s": CategoricalDistribution(["a", "b"]),
             "x": FloatDistribution(0, 1)}
    drawn = [(8, "a", TrialState.COMPLETE), (16, "b", TrialState.COMPLETE),  # the start
             (8, "a", TrialState.PRUNED), (8, "a", TrialState.COMPLETE),
             (8, "b", TrialState.PRUNED), (8, "a", TrialState.PRUNED)]
    for number, (n, kind, state) in enumerate(drawn):
        # The float differs in every trial: only the categorical settings are counted.
        study.add_trial(create_trial(
            state=state, value=-1.0 if state == TrialState.COMPLETE else None,
            intermediate_values={1: -1.0}, params={"n": n, "s": kind, "x": number / 10},
            distributions=space, user_attrs={"key": f"t{number}", "cpu_time": 1.0}))
    bench = _bench()
    arm = bench.Arm("tpe", 0, "s")  # type: ignore[attr-defined]
    bench.read_search(url, arm)  # type: ignore[attr-defined]
    assert arm.after_start == "4 trials, 3 pruned, 2 distinct settings of n, s"


def test_after_the_gp_samplers_start_a_search_counts_the_trials_it_modelled(
        tmp_path: Path) -> None:
    from optuna.distributions import FloatDistribution
    from optuna.trial import create_trial

    url = f"sqlite:///{tmp_path / 'g.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_definition", {"search": {"startup_trials": 2, "sampler": "gp"}})
    space = {"x": FloatDistribution(0, 1)}
    # Trial 2 started before the start's second trial ended: still a random draw, unmarked.
    for number, modelled in enumerate([False, False, False, True, True]):
        marks = {"gp:relative_params:0": '{"x": 0.5}'} if modelled else {}
        study.add_trial(create_trial(value=-1.0, params={"x": number / 10},
                                     distributions=space, system_attrs=marks,
                                     user_attrs={"key": f"t{number}", "cpu_time": 1.0}))
    bench = _bench()
    arm = bench.Arm("gp", 0, "s")  # type: ignore[attr-defined]
    bench.read_search(url, arm)  # type: ignore[attr-defined]
    assert arm.after_start == "2 trials, 0 pruned, 1 distinct setting of no categorical parameter"


@pytest.mark.slow
def test_with_cost_each_search_has_two_objectives_and_its_pick_is_the_one_confirmed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    url = _run(tmp_path, monkeypatch, "--cpu-budget", "3", "--sampler-seeds", "0", "--no-zoo",
               "--cost")
    out = capsys.readouterr().out
    for sampler in ("tpe", "random"):
        study = optuna.load_study(study_name=f"cartpole-{sampler}-s0", storage=url)
        assert len(study.directions) == 2
        picked = re.search(rf"^\| {sampler} \| 0 \| [^|]+\| [^|]+\| (t\d+) \|", out, re.M)
        assert picked is not None
        trial = next(t for t in study.trials if t.user_attrs.get("key") == picked.group(1))
        confirm = optuna.load_study(study_name=f"cartpole-{sampler}-s0-confirm", storage=url)
        assert all(t.user_attrs["settings"]["ppo"] == trial.user_attrs["settings"]["ppo"]
                   for t in confirm.trials)
    assert re.search(r"^The picks' CPU s per run, tpe / random by sampler seed: [\d.]+ "
                     r"\(geometric mean [\d.]+\)$", out, re.M)


@pytest.mark.parametrize(("extra", "enqueued"), [([], None),
                                                 (["--enqueue"], "search.enqueue=[]"),
                                                 (["--enqueue", "zoo"], "search.enqueue=[zoo]")])
def test_every_search_evaluates_the_enqueued_configs_first(
        monkeypatch: pytest.MonkeyPatch, extra: list[str], enqueued: str | None) -> None:
    bench, commands = _recorded(monkeypatch)
    assert bench.main(["--env-id", "Pendulum-v1", "--cpu-budget", "10",
                       "--sampler-seeds", "0", "1", "--no-zoo", *extra]) == 0
    searches = [c for c in commands if c[0] == "optuna"]
    assert [c[c.index("--sampler") + 1] for c in searches] == ["tpe", "random"] * 2
    if enqueued is None:  # the search's own default: the ppo config it trains with, zoo
        assert all("ppo=zoo" in c and not any(a.startswith("search.enqueue=") for a in c)
                   for c in searches)
    else:
        assert all(enqueued in c and sum(a.startswith("search.enqueue=") for a in c) == 1
                   for c in searches)


ROOT = Path(__file__).parents[1]


def _quoted_commands() -> list[tuple[str, list[str]]]:
    """Every bench_search command the docs quote, as (page, arguments); a placeholder sampler
    seed ``S`` is read as 0."""
    found = []
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for line in page.read_text().splitlines():
            words = line.strip().split()
            if words[:2] == ["python", "benchmarks/bench_search.py"]:
                found.append((str(page.relative_to(ROOT)),
                              ["0" if w == "S" else w for w in words[2:]]))
    return found


QUOTED = _quoted_commands()


@pytest.mark.parametrize(("page", "argv"), QUOTED, ids=[f"{p}:{i}" for i, (p, _) in
                                                        enumerate(QUOTED)])
def test_every_quoted_command_still_runs_the_searches_it_ran(
        monkeypatch: pytest.MonkeyPatch, page: str, argv: list[str]) -> None:
    """The commands the results quote name the same stored studies and run the same searches
    as when they were measured (a sampler's arm with every command's overrides), so a rerun
    continues them; a planned racing arm races with its own overrides in place of the
    common ones of the same key."""
    bench, commands = _recorded(monkeypatch)
    assert bench.main(argv) == 0
    args = bench.parse(argv)
    tag = args.tag or args.env_id.split("-")[0].lower()
    env = ["env=gym", f"env.id={args.env_id}", "ppo=zoo", "budget=zoo", *args.overrides]
    flags = {"racing": ["--racing", "--sampler", "tpe"],
             "racing-gp": ["--racing", "--sampler", "gp"],
             "racing-random": ["--racing", "--sampler", "random"]}
    own = {arm: [o.split(":", 1)[1] for o in args.arm_overrides if o.startswith(f"{arm}:")]
           for arm in args.samplers}

    def arm_env(arm: str) -> list[str]:
        keys = {o.split("=")[0] for o in own[arm]}
        return [o for o in env if o.split("=")[0] not in keys] + own[arm]
    common = ["--storage", args.storage, "--workers", str(args.workers), "save_models=false"]
    objective = (["--objective", "evaluation,training_time", "--floor", "none"] if args.cost
                 else ["--objective", "evaluation"])
    queue = [] if args.enqueue is None else [f"search.enqueue=[{','.join(args.enqueue)}]"]
    expected = [("optuna", *objective, *flags.get(sampler, ["--sampler", sampler]), "--seed",
                 str(seed), "--cpu-budget", f"{args.cpu_budget:g}", "--trials", "100000",
                 "--study-name", f"{tag}-{sampler}-s{seed}", *queue, *common, *arm_env(sampler))
                for seed in args.sampler_seeds for sampler in args.samplers]
    assert [c for c in commands if c[0] == "optuna"] == expected
    confirms = [c for c in commands if c[0] == "confirm" and "--study-name" in c]
    assert confirms == [("confirm", "--study-name", f"{tag}-{sampler}-s{seed}", "--top", "1",
                         "--seeds", str(args.confirm_seeds), *common, *arm_env(sampler))
                        for seed in args.sampler_seeds for sampler in args.samplers]


def test_a_racing_arm_races_on_its_own_overrides_and_the_other_arm_on_the_common_ones(
        monkeypatch: pytest.MonkeyPatch) -> None:
    bench, commands = _recorded(monkeypatch)
    assert bench.main([
        "--env-id", "MountainCarContinuous-v0", "--cpu-budget", "10", "--tag", "mccrace",
        "--no-zoo", "search=gym_sde", "budget.seeds=2", "--samplers", "racing-gp", "random",
        "--arm-overrides", "racing-gp:budget.seeds=8", "racing-gp:racing.min_seeds=4",
        "--sampler-seeds", "3"]) == 0
    (racing, racing_confirm, random, _) = commands
    tail = ["search=gym_sde", "budget.seeds=8", "racing.min_seeds=4"]
    assert racing[:8] == ("optuna", "--objective", "evaluation", "--racing", "--sampler", "gp",
                          "--seed", "3")
    assert "mccrace-racing-gp-s3" in racing and list(racing[-3:]) == tail
    assert racing_confirm[:3] == ("confirm", "--study-name", "mccrace-racing-gp-s3")
    assert "--racing" not in racing_confirm and list(racing_confirm[-3:]) == tail
    assert "--racing" not in random and "mccrace-random-s3" in random
    assert list(random[-2:]) == ["search=gym_sde", "budget.seeds=2"]


@pytest.mark.parametrize(("extra", "error"), [
    (["--samplers", "racing", "random", "--arm-overrides", "budget.seeds=8"],
     "--arm-overrides takes ARM:KEY=VALUE, not 'budget.seeds=8'"),
    (["--samplers", "racing", "random", "--arm-overrides", "tpe:budget.seeds=8"],
     "--arm-overrides names arm 'tpe', not one of --samplers racing random"),
    (["--samplers", "racing", "random", "budget.seeds=2"],
     "--samplers takes arm names, not 'budget.seeds=2'"),
    (["--samplers", "racing", "random", "--cost"], "--cost searches on two objectives"),
    (["--samplers", "random", "random"], "--samplers names random twice"),
])
def test_bad_arms_are_refused_in_one_line_before_anything_runs(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        extra: list[str], error: str) -> None:
    bench = _bench()
    monkeypatch.setattr(bench, "kraby", lambda *args: pytest.fail("a command ran"))
    with pytest.raises(SystemExit) as stopped:
        bench.main(["--env-id", "CartPole-v1", "--cpu-budget", "10",  # type: ignore[attr-defined]
                    *extra])
    assert stopped.value.code == 2
    assert f": error: {error}" in capsys.readouterr().err


def test_a_dry_run_shows_each_searchs_plan_and_stores_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    assert _bench().main([  # type: ignore[attr-defined]
        "--env-id", "MountainCarContinuous-v0", "--cpu-budget", "1200", "--storage",
        f"sqlite:///{tmp_path / 'd.db'}", "--no-zoo", "search=gym_sde", "budget.seeds=2",
        "--samplers", "racing", "random", "--arm-overrides", "racing:budget.seeds=8",
        "--sampler-seeds", "0", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert ("racing search: tpe sampler asks each challenger, which trains 4 seeds side by side"
            in out)
    assert "up to 8 (budget.seeds)" in out
    assert ("mountaincarcontinuous-random-s0: until its 1,200 CPU s (search.cpu_budget) are "
            "used, at most 100,000 trials (search.trials, each 2 seeds") in out
    assert out.strip().splitlines()[-1] == ("bench_search: dry run of 2 searches; each pick "
                                            "would be confirmed on 5 fresh seeds")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_racing_arm_confirms_its_incumbent_and_a_rerun_continues_the_stored_studies(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from kraby_study.answers.racing_search import racing_search

    argv = ["--cpu-budget", "4", "--sampler-seeds", "0", "--no-zoo", "--samplers", "racing",
            "--arm-overrides", "racing:budget.seeds=4"]
    url = _run(tmp_path, monkeypatch, *argv)
    out = capsys.readouterr().out
    study = optuna.load_study(study_name="cartpole-racing-s0", storage=url)
    found = racing_search(study.user_attrs["kraby_definition"], study.trials)
    assert found is not None and found.incumbent is not None
    inc = found.incumbent
    runs = sum(c.seeds for c in found.configurations)
    assert inc.seeds >= 4 and study.user_attrs["kraby_definition"]["racing"]
    assert re.search(rf"^\| racing \| 0 \| {len(found.configurations)} configurations, {runs} "
                     rf"runs \| [\d,]+ \| {inc.key} \({inc.seeds} seeds\) \| {inc.iqm:.1f} \| ",
                     out, re.M), out
    confirm = optuna.load_study(study_name="cartpole-racing-s0-confirm", storage=url)
    assert len(confirm.trials) == 2
    assert all(t.user_attrs["settings"] == inc.settings for t in confirm.trials)
    stored = {name: len(optuna.load_study(study_name=name, storage=url).trials)
              for name in ("cartpole-racing-s0", "cartpole-racing-s0-confirm")}
    _run(tmp_path, monkeypatch, *argv)
    again = capsys.readouterr().out
    assert stored == {name: len(optuna.load_study(study_name=name, storage=url).trials)
                      for name in stored}
    assert again.split("\nCartPole-v1: ")[1] == out.split("\nCartPole-v1: ")[1]


def test_the_budget_replay_drops_the_trials_started_once_running_ones_used_the_budget(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from datetime import datetime, timedelta

    from optuna.distributions import FloatDistribution
    from optuna.trial import FrozenTrial

    url = f"sqlite:///{tmp_path / 'r.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_cpu_budget", 10.0)
    zero = datetime(2026, 1, 1)
    # Two workers: a (0-8 s) and b (0-6 s) start together; at 6 s b has ended (6 CPU s) and a
    # has used 6 of its 8, so c (6-9 s) and d (8-10 s) start only under the old rule.
    for start, end in ((0, 8), (0, 6), (6, 9), (8, 10)):
        study.add_trial(FrozenTrial(
            number=0, trial_id=0, state=TrialState.COMPLETE, value=1.0, values=None,
            params={"x": 0.5}, distributions={"x": FloatDistribution(0, 1)},
            user_attrs={"cpu_time": float(end - start)}, system_attrs={},
            intermediate_values={}, datetime_start=zero + timedelta(seconds=start),
            datetime_complete=zero + timedelta(seconds=end)))
    replay = _benchmark("budget_replay")
    spans = replay.spans_of(study)  # type: ignore[attr-defined]
    assert [(s.start - spans[0].start, s.cpu) for s in replay.kept(spans, 10.0)] == [  # type: ignore[attr-defined]
        (0.0, 8.0), (0.0, 6.0)]
    # Had the budget been larger than the 12 CPU s used at 6 s, c would start.
    assert len(replay.kept(spans, 12.5)) == 3  # type: ignore[attr-defined]
    assert replay.main([url]) == 0  # type: ignore[attr-defined]
    out = capsys.readouterr().out
    assert "| s | 10 | 19 | 14 | 2 |" in out
    assert out.strip().splitlines()[-1] == (
        "budget_replay: 1 searches; overshoot of the budget mean 90.0 % -> 40.0 %, "
        "largest 90.0 % -> 40.0 %; 2 trials fewer")


def test_the_reserve_replay_cuts_exploring_where_a_dear_running_trial_would_take_the_rechecks(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from datetime import datetime, timedelta

    from optuna.distributions import FloatDistribution
    from optuna.trial import FrozenTrial

    url = f"sqlite:///{tmp_path / 'r.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_cpu_budget", 60.0)
    study.set_user_attr("kraby_definition", {"seeds": 1})
    zero = datetime(2026, 1, 1)
    # (start s, end s, CPU s, score), one seed of 100 env steps each. At 30 s, t0 has ended
    # (10 spent, 10 to recheck it on 1 seed) and t1 has trained 20 of its 100 steps in 20
    # CPU s: it could use 80 more, so the rule starts neither t2 nor t3 (without it: 10 + 20
    # + 10 < 60). t2 would have been the pick.
    for number, (start, end, cpu, value) in enumerate(
            ((0, 10, 10, 1.0), (10, 110, 100, 0.5), (30, 40, 10, 2.0), (40, 50, 10, 0.1))):
        study.add_trial(FrozenTrial(
            number=number, trial_id=number, state=TrialState.COMPLETE, value=value,
            values=None, params={"x": 0.5}, distributions={"x": FloatDistribution(0, 1)},
            user_attrs={"key": f"t{number}", "cpu_time": float(cpu), "steps": 100,
                        "env_steps": 100, "scores": [value]},
            system_attrs={}, intermediate_values={},
            datetime_start=zero + timedelta(seconds=start),
            datetime_complete=zero + timedelta(seconds=end)))
    replay = _benchmark("reserve_replay")
    assert replay.main([url, "--recheck", "1", "--recheck-seeds", "1"]) == 0  # type: ignore[attr-defined]
    out = capsys.readouterr().out
    assert "| s | 4 | 130 | 2 | 20 | t2 | t2 (in the cut) |" in out
    assert out.strip().splitlines()[-1] == (
        "reserve_replay: 1 searches; the rule ends exploring before 20 of 130 explored CPU s "
        "(15.4 %); 1 picks found after it")
    with pytest.raises(SystemExit) as stop:
        replay.main([url, "--studies", "nope"])  # type: ignore[attr-defined]
    assert stop.value.code == 2 and "no study 'nope'" in capsys.readouterr().err


# Published confirmed means (docs/results/index.md, Pendulum-v1 at 1,200 CPU s, sampler seeds 0-9):
# TPE without the pruner, and random search.
UNPRUNED = ["-163.8", "-168.5", "-151.1", "-151.9", "-153.6", "-179.3", "-154.1", "-152.6",
            "-162.0", "-200.6"]
RANDOM = ["-627.5", "-191.4", "-154.1", "-151.9", "-148.4", "-192.4", "-162.0", "-159.8",
          "-158.4", "-301.9"]


def test_paired_picks_tests_the_published_differences_with_the_tie_dropped(
        capsys: pytest.CaptureFixture[str]) -> None:
    paired = _benchmark("paired_picks")
    assert paired.main(["--seeds", *map(str, range(10)),  # type: ignore[attr-defined]
                        "--first-means", *UNPRUNED, "--second-means", *RANDOM,
                        "--margin", "38.5"]) == 0
    out = capsys.readouterr().out
    assert "| 3 | -151.9 | -151.9 | 0 |" in out
    assert "| 0 | -163.8 | -627.5 | +463.7 |" in out
    assert "Wilcoxon signed-rank p 0.000977 (n 10)" in out  # 1 / 1024: every shifted one above
    assert out.strip().splitlines()[-1] == (
        "paired_picks: first - second +61.0 (median +7.6; 95 % t CI [-42.6, 164.7]); "
        "Wilcoxon p 0.0195 (greater, n 9, 1 zero)")


def test_paired_picks_keeps_the_leg_iqms_to_the_decimals_asked(
        capsys: pytest.CaptureFixture[str]) -> None:
    paired = _benchmark("paired_picks")
    # The leg's confirmed IQMs (docs/benchmarks/methods.md, repetitions 0-1 and a tie): at the
    # default 0.1 every difference would round to 0 and leave nothing to test.
    args = ["--seeds", "0", "1", "2", "--first-means", "-0.0440", "-0.0449", "-0.0300",
            "--second-means", "-0.0201", "-0.0278", "-0.0300"]
    assert paired.main([*args, "--decimals", "4"]) == 0  # type: ignore[attr-defined]
    out = capsys.readouterr().out
    assert "| 0 | -0.0440 | -0.0201 | -0.0239 |" in out and "| 2 | -0.0300 | -0.0300 | 0 |" in out
    assert out.strip().splitlines()[-1].endswith("Wilcoxon p 1 (greater, n 2, 1 zero)")
    assert paired.main(args) == 0  # type: ignore[attr-defined]
    assert capsys.readouterr().out.strip().splitlines()[-1].endswith("(greater, n 0, 3 zero)")
    with pytest.raises(SystemExit) as stop:
        paired.main([*args, "--decimals", "-1"])  # type: ignore[attr-defined]
    assert stop.value.code == 2 and "--decimals must be between 0 and 12" in capsys.readouterr().err


def test_paired_picks_reads_stored_confirms_to_the_published_precision(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'p.db'}"
    # Arm a's pick at seed 0 confirms 0.04 below arm b's: a tie at the published precision.
    scores = {("a", 0): [10.0, 12.0], ("b", 0): [10.04, 12.04], ("a", 1): [5.0, 7.0],
              ("b", 1): [1.0, 2.0]}
    for (arm, seed), values in scores.items():
        study = optuna.create_study(study_name=f"{arm}-s{seed}-confirm", storage=url)
        for fresh, value in enumerate(values):
            study.add_trial(optuna.trial.create_trial(
                value=value, user_attrs={"seed": 1000 + fresh, "final_score": value,
                                         "cpu_time": 1.0}))
    paired = _benchmark("paired_picks")
    assert paired.main(["--seeds", "0", "1", "--first", "a", "--second", "b",  # type: ignore[attr-defined]
                        "--storage", url]) == 0
    out = capsys.readouterr().out
    assert "| 0 | 11.0 | 11.0 | 0 |" in out and "| 1 | 6.0 | 1.5 | +4.5 |" in out
    assert "Trial 0 is not the same work in any pair's two searches" in out  # no search stored
    assert out.strip().endswith("Wilcoxon p 0.5 (greater, n 1, 1 zero)")


def test_paired_picks_shows_what_the_same_work_cost_in_each_arm(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'p.db'}"
    same = {"settings": {"gamma": 0.99}, "seed": 0, "scores": [1.5, 2.5]}
    first_trials = {("a", 0): (same, 30.0), ("b", 0): (same, 20.0),  # the same work
                    ("a", 1): (same, 30.0), ("b", 1): ({**same, "scores": [1.5, 2.4]}, 10.0)}
    for (arm, seed), (attrs, cpu) in first_trials.items():
        study = optuna.create_study(study_name=f"{arm}-s{seed}", storage=url)
        study.add_trial(optuna.trial.create_trial(value=2.0, user_attrs={**attrs, "cpu_time": cpu}))
        confirm = optuna.create_study(study_name=f"{arm}-s{seed}-confirm", storage=url)
        # The picks: the same settings at seed 0, other settings in b at seed 1.
        picked = {"gamma": 0.9 if (arm, seed) == ("b", 1) else 0.99}
        confirm.add_trial(optuna.trial.create_trial(
            value=2.0, user_attrs={"seed": 1000, "final_score": 2.0, "cpu_time": cpu,
                                   "settings": picked}))
    assert _benchmark("paired_picks").main(  # type: ignore[attr-defined]
        ["--seeds", "0", "1", "--first", "a", "--second", "b", "--storage", url]) == 0
    out = capsys.readouterr().out
    assert ("The same work (trial 0) in each pair's searches, CPU s first / second: seed 0 30 / "
            "20; first over second: geometric mean 1.50 (1.50 to 1.50, 1 pair)") in out
    # The picks' costs: seed 0's confirms are the same settings (a tie, though 1.5 times the
    # CPU), seed 1's are not; geometric mean of 1.5 and 3.0.
    assert ("The picks' CPU s a run, first / second: seed 0 30.0 / 20.0, seed 1 30.0 / 10.0; "
            "first over second: geometric mean 2.12; exact one-sided Wilcoxon signed-rank p 1 "
            "that the first's are cheaper (n 1, 1 same pick)") in out


def test_paired_picks_refuses_means_that_do_not_match_the_seeds(
        capsys: pytest.CaptureFixture[str]) -> None:
    paired = _benchmark("paired_picks")
    with pytest.raises(SystemExit) as stop:
        paired.main(["--seeds", "0", "1", "--first-means", "1", "--second-means",  # type: ignore[attr-defined]
                     "1", "2"])
    assert stop.value.code == 2
    assert "--first-means needs one mean per seed (2)" in capsys.readouterr().err


def test_the_pruner_replay_judges_each_trial_against_those_complete_and_kept_by_then(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Five unpruned trials of 100 env steps (pruner from step 50, 2 complete trials first),
    started at the given seconds, each taking 10 s."""
    url = f"sqlite:///{tmp_path / 'r.db'}"
    study = optuna.create_study(study_name="np", storage=url, direction="maximize")
    study.set_user_attr("kraby_definition", {
        "steps": 100, "seeds": 1,
        "search": {"pruner": "none", "pruner_startup_trials": 2, "warmup": 0.5,
                   "checkpoints": 4}})
    zero = datetime.datetime(2026, 11, 29, 12, 0, 0)
    trials = [(0, {25: 1.0, 50: 5.0, 75: 6.0}, 10.0),
              (0, {25: 1.0, 50: 4.0, 75: 5.0}, 8.0),
              (20, {25: 0.0, 50: 1.0, 75: 1.0}, 9.0),   # below the median of t0, t1: stopped
              (1, {25: 0.0, 50: 0.0, 75: 0.0}, -1.0),   # nothing complete by its checkpoints
              (40, {25: 3.0, 50: 3.0, 75: 3.0}, 7.0)]   # stopped only if t2 is left out
    for start, values, value in trials:
        study.add_trial(optuna.trial.FrozenTrial(
            number=0, trial_id=0, state=TrialState.COMPLETE, value=value,
            datetime_start=zero + datetime.timedelta(seconds=start),
            datetime_complete=zero + datetime.timedelta(seconds=start + 10), params={},
            distributions={}, user_attrs={}, system_attrs={}, intermediate_values=values))
    replay = _benchmark("pruner_replay")
    assert replay.main([url, "np", "--good", "9"]) == 0  # type: ignore[attr-defined]
    out = capsys.readouterr().out
    assert "| np | 5 | 2: t2 (50), t4 (50) | 1 | no (t0) |" in out
    assert out.strip().splitlines()[-1] == (
        "pruner_replay: 1 search; the median pruner stops 2 of 5 complete trials; 1 of them "
        "ended at 9 or better; 0 of the 1 pick among them")


def test_the_pruner_replay_refuses_a_search_that_ran_with_a_pruner(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'r.db'}"
    study = optuna.create_study(study_name="pruned", storage=url)
    study.set_user_attr("kraby_definition", {"steps": 100, "seeds": 1,
                                             "search": {"pruner": "median"}})
    with pytest.raises(SystemExit) as stop:
        _benchmark("pruner_replay").main([url, "pruned"])  # type: ignore[attr-defined]
    assert stop.value.code == 2


def test_the_cost_replay_stops_trials_dearer_per_step_than_the_first_complete_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Trials of 2 seeds x 100 env steps, 4 checkpoints: the first at 25 env steps."""
    url = f"sqlite:///{tmp_path / 'c.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_definition", {"steps": 100, "seeds": 2,
                                             "search": {"checkpoints": 4}})
    # (state, value, CPU s, env steps, rechecked trial): CPU s per step 0.01 for t0.
    trials = [("COMPLETE", 5.0, 2.0, 200, None),
              ("COMPLETE", 8.0, 4.0, 200, None),    # 2 x t0's: under the cap
              ("COMPLETE", 9.0, 10.0, 200, None),   # 5 x: stopped, 0.05 x 25 = 1.25 CPU s
              ("PRUNED", None, 2.0, 50, None),      # 4 x, past the first checkpoint: stopped
              ("PRUNED", None, 2.0, 20, None),      # 10 x, but pruned before it: not
              ("COMPLETE", 7.0, 20.0, 200, 0)]      # a recheck reports no checkpoint: not
    for state, value, cpu, steps, of in trials:
        attrs = {"cpu_time": cpu, "env_steps": steps,
                 **({} if of is None else {"recheck_of": of})}
        study.add_trial(optuna.trial.create_trial(
            state=TrialState[state], value=value, user_attrs=attrs))
    replay = _benchmark("cost_replay")
    assert replay.main([url, "s", "--cap", "3", "--good", "8"]) == 0  # type: ignore[attr-defined]
    out = capsys.readouterr().out
    assert "| s | 0.01 | 2: t2 (5.0), t3 (4.0) | 12, 2 | 40 | 1 | yes (t2) |" in out
    assert out.strip().splitlines()[-1] == (
        "cost_replay: 1 search at cap 3; it stops 2 of 6 trials; they used 12 of the 40 CPU s "
        "the search used, 2 up to their first checkpoint; 1 of them ended at 8 or better; 1 of "
        "the 1 pick among them")


def test_the_cost_replay_of_a_share_stops_trials_projected_past_it_but_enqueued_ones(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Trials of 2 seeds x 100 env steps under a budget of 100 CPU s: a share of 0.25 stops a
    trial projected past 25 CPU s, at its first checkpoint (25 env steps)."""
    url = f"sqlite:///{tmp_path / 'c.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("kraby_definition", {"steps": 100, "seeds": 2,
                                             "search": {"checkpoints": 4}})
    study.set_user_attr("kraby_cpu_budget", 100.0)
    # (state, value, CPU s, env steps, enqueued as): CPU s per step 0.2 for t0.
    trials = [("COMPLETE", 5.0, 40.0, 200, "ppo=zoo"),  # past 25, but enqueued: not
              ("COMPLETE", 8.0, 20.0, 200, None),       # 20 projected: not
              ("COMPLETE", 9.0, 30.0, 200, None),       # 30: stopped, 0.15 x 25 = 3.75 CPU s
              ("PRUNED", None, 15.0, 100, None)]        # 0.15 x 200 = 30: stopped
    for state, value, cpu, steps, enqueued in trials:
        attrs = {"cpu_time": cpu, "env_steps": steps,
                 **({} if enqueued is None else {"enqueued": enqueued})}
        study.add_trial(optuna.trial.create_trial(
            state=TrialState[state], value=value, user_attrs=attrs))
    replay = _benchmark("cost_replay")
    assert replay.main([url, "s", "--share", "0.25"]) == 0  # type: ignore[attr-defined]
    out = capsys.readouterr().out
    assert "| s | 0.2 | 2: t2 (0.7), t3 (0.7) | 45, 8 | 105 | 1 | yes (t2) |" in out
    assert out.strip().splitlines()[-1].startswith(
        "cost_replay: 1 search at share 0.25; it stops 2 of 4 trials; they used 45 of the 105")


@pytest.mark.parametrize("rule", [["--cap", "0"], ["--share", "0"], ["--share", "1.5"],
                                  ["--cap", "3", "--share", "0.5"], []])
def test_the_cost_replay_refuses_a_rule_that_is_not_one_positive_cap(
        tmp_path: Path, rule: list[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        _benchmark("cost_replay").main(  # type: ignore[attr-defined]
            [f"sqlite:///{tmp_path / 'c.db'}", "s", *rule])
    assert stop.value.code == 2


def test_paired_picks_refuses_a_confirm_still_running(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'p.db'}"
    for arm in ("a", "b"):
        study = optuna.create_study(study_name=f"{arm}-s0-confirm", storage=url)
        study.add_trial(optuna.trial.create_trial(
            value=1.0, user_attrs={"seed": 1000, "final_score": 1.0, "cpu_time": 1.0}))
    optuna.load_study(study_name="b-s0-confirm", storage=url).ask()  # a run still training
    with pytest.raises(SystemExit, match=r"b-s0-confirm is not finished \(1 of 2 runs"):
        _benchmark("paired_picks").main(  # type: ignore[attr-defined]
            ["--seeds", "0", "--first", "a", "--second", "b", "--storage", url])


def test_the_sampler_cost_replay_suggests_each_trial_from_those_ended_before_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from optuna.distributions import FloatDistribution

    url = f"sqlite:///{tmp_path / 'c.db'}"
    study = optuna.create_study(study_name="s", storage=url, direction="maximize")
    study.set_user_attr("sampler_seed", 4)
    zero = datetime.datetime(2026, 12, 2, 5, 0, 0)
    # Two workers: t2 (4-9 s) starts while t1 runs (0-5 s), so only t0 has ended before it.
    for start, end, state in ((0, 4, TrialState.COMPLETE), (0, 5, TrialState.PRUNED),
                              (4, 9, TrialState.COMPLETE), (5, 8, TrialState.COMPLETE),
                              (9, 12, TrialState.COMPLETE)):
        study.add_trial(optuna.trial.FrozenTrial(
            number=0, trial_id=0, state=state, value=float(end) if state.name == "COMPLETE"
            else None, params={"x": end / 20}, distributions={"x": FloatDistribution(0, 1)},
            user_attrs={"cpu_time": 2.0}, system_attrs={},
            intermediate_values={} if state.name == "COMPLETE" else {1: 0.0},
            datetime_start=zero + datetime.timedelta(seconds=start),
            datetime_complete=zero + datetime.timedelta(seconds=end)))
    cost = _benchmark("sampler_cost")
    seen: list[int] = []
    add_trials = optuna.Study.add_trials
    monkeypatch.setattr(optuna.Study, "add_trials",
                        lambda self, trials: (seen.append(len(trials)),
                                              add_trials(self, trials))[1])
    assert cost.main(["--storage", url, "s", "--samplers", "gp", "random",  # type: ignore[attr-defined]
                      "--startup", "2"]) == 0
    # t2 from t0; t3 from t0, t1 (t2 still running); t4 from t0-t3; for each sampler.
    assert seen == [1, 2, 4, 1, 2, 4]
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split(":")[0] for line in lines[:2]] == ["s gp", "s random"]
    assert all("3 suggestions" in line and "of its trials' 10 CPU s" in line
               for line in lines[:2])
    assert re.fullmatch(r"sampler_cost: gp [\d.]+ CPU s, random [\d.]+ CPU s over 3 "
                        r"suggestions", lines[-1])
    with pytest.raises(SystemExit) as stop:
        cost.main(["--storage", url, "missing"])  # type: ignore[attr-defined]
    assert stop.value.code == 2


def _tied_search(url: str, name: str, trials: list[tuple[float, list[float], float, str]],
                 confirmed: dict[str, list[float]]) -> None:
    """A search of (score, intermediate values, CPU s, setting) trials, and a confirm of
    configurations by key, as ``confirm --top N confirm.name=NAME-ties`` stores them."""
    from optuna.distributions import CategoricalDistribution, FloatDistribution
    from optuna.trial import create_trial

    study = optuna.create_study(study_name=name, storage=url, direction="maximize")
    for number, (value, curve, cpu, setting) in enumerate(trials):
        study.add_trial(create_trial(
            value=value, intermediate_values=dict(enumerate(curve, start=1)),
            params={"x": 0.5}, distributions={"x": FloatDistribution(0, 1)},
            user_attrs={"key": f"t{number}", "cpu_time": cpu, "scores": [value, value],
                        "settings": {"x": setting}}))
    ties = optuna.create_study(study_name=f"{name}-ties", storage=url, direction="maximize")
    keys = list(confirmed)
    for key, values in confirmed.items():
        for fresh, value in enumerate(values):
            ties.add_trial(create_trial(
                value=value, params={"config": key},
                distributions={"config": CategoricalDistribution(keys)},
                user_attrs={"seed": 1000 + fresh, "final_score": value}))


def test_tie_breaks_picks_among_the_trials_tied_at_the_top_by_each_rule(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 't.db'}"
    # Trials 1, 2 and 4 tie at 500; trial 3 repeats trial 1's setting and is not a new tie.
    _tied_search(url, "a-s0", [(300.0, [100, 300], 4.0, "p"), (500.0, [100, 500], 10.0, "q"),
                               (500.0, [400, 500], 12.0, "r"), (500.0, [450, 500], 2.0, "q"),
                               (500.0, [200, 500], 6.0, "s")],
                 {"t1": [500.0, 400.0], "t2": [500.0, 500.0], "t4": [300.0, 310.0]})
    _tied_search(url, "b-s0", [(500.0, [50, 500], 8.0, "p"), (490.0, [490, 490], 1.0, "q")],
                 {"t0": [480.0, 500.0]})
    breaks = _benchmark("tie_breaks")
    assert breaks.main(["--storage", url, "--arms", "a", "b",  # type: ignore[attr-defined]
                        "--seeds", "0"]) == 0
    out = capsys.readouterr().out
    assert "| a-s0 | 500.0 | 3 | 418.3 [305.0, 500.0] | t1: 450.0 | t2: 500.0 | t4: 305.0 |" \
        in out
    assert "| b-s0 | 500.0 | 1 | 490.0 [490.0, 490.0] | t0: 490.0 | t0: 490.0 | t0: 490.0 |" \
        in out
    assert "tie_breaks first: a - b -40.0; --first-means 450.0 --second-means 490.0" in out
    assert "tie_breaks curve: a - b +10.0; --first-means 500.0 --second-means 490.0" in out
    # A tied trial the confirm did not retrain stops the analysis with its key.
    _tied_search(url, "c-s0", [(500.0, [1], 1.0, "p"), (500.0, [2], 1.0, "q")],
                 {"t0": [500.0]})
    with pytest.raises(SystemExit, match="c-s0-ties has no complete run of t1"):
        breaks.main(["--storage", url, "--arms", "c", "--seeds", "0"])  # type: ignore[attr-defined]


def test_the_method_comparison_tests_the_best_search_against_the_campaign_at_a_shift() -> None:
    """bench_methods' second planned test: the search method with the highest mean confirmed
    IQM, paired with the campaign by repetition, one-sided Student t against a shift of
    -margin x |the campaign's mean IQM| (checked against the t statistic written out)."""
    bench: Any = _benchmark("bench_methods")

    def result(method: str, repetition: int, iqm: float, cpu: float = 100.0) -> Any:
        confirmed = bench.Confirmed(name=f"{method}{repetition}", label="c", settings={},
                                    source_score=iqm, steps=1024, seeds=[1000], scores=[iqm],
                                    iqm=iqm, low=iqm, high=iqm, failed_runs=0,
                                    failed_seeds="0/1", cpu_per_run=1.0)
        return bench.Result(bench.Arm(method, repetition, "t", ()),
                            bench.Cost(cpu, 1, 1, 1), confirmed)

    campaign = [-1.0, -1.2, -0.8, -1.0]
    random_iqms = [-1.05, -1.1, -0.95, -1.3]  # mean -1.1: the best search method
    tpe = [-1.5, -1.4, -1.6]  # mean -1.5
    rows = ([result("campaign", r, v) for r, v in enumerate(campaign)]
            + [result("random", r, v) for r, v in enumerate(random_iqms)]
            + [result("tpe", r, v) for r, v in enumerate(tpe)])
    best, differences, shift, p, mean = bench.against_campaign(rows, 0.2)
    assert best == "random" and math.isclose(mean, -1.1)
    assert differences == pytest.approx([-0.05, 0.1, -0.15, -0.3])
    assert shift == pytest.approx(-0.2)  # -0.2 x |mean(-1, -1.2, -0.8, -1)|
    shifted = [d - shift for d in differences]
    t = statistics.fmean(shifted) / (statistics.stdev(shifted) / math.sqrt(len(shifted)))
    assert p == pytest.approx(float(scipy_stats.t.sf(t, len(shifted) - 1)))
    # Without the campaign, or with one pair, there is no test.
    assert bench.against_campaign(rows[4:], 0.2) is None
    assert math.isnan(bench.against_campaign([rows[0], rows[4]], 0.2)[3])
