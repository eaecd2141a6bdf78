"""`kraby-study optuna` and `best`: smoke search, totals, pruning, best round trip, bad input."""

from __future__ import annotations

import re
import time
from pathlib import Path

import optuna
import pytest
from conftest import TINY, load, run_cli
from optuna.trial import TrialState

from kraby_study.config.compose import compose_config
from kraby_study.errors import ConfigError
from kraby_study.plan.space import validate_search
from kraby_study.records.attributes import StudyAttrs, TrialResult
from kraby_study.records.stored import Outcome, spent_cpu
from kraby_study.run.sampling import make_pruner, sampler_seed
from kraby_study.run.search_source import (
    SearchSource,
    pruner_label,
    short_label,
    take_opening,
)
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.store import opened

TINY_SPACE = """\
name: tiny
sampler: tpe
pruner: median
seed: 0
startup_trials: 2
checkpoints: 4
objective: final_reward
eval_episodes: 4
trials: 4
params:
  learning_rate: {path: ppo.learning_rate, type: float, low: 1.0e-4, high: 1.0e-2, log: true}
  nminibatches: {path: ppo.nminibatches, type: categorical, choices: [1, 2]}
  gamma: {path: ppo.gamma, type: float, low: 0.5, high: 0.99}
"""

# Targets over the whole box (delta 1) cost about 0.36 reward per episode more than targets at
# its centre (delta 0) for any policy that has not learnt to reach: a controlled, large gap.
DELTA_SPACE = """\
name: delta
sampler: random
pruner: median
seed: 13  # the random sampler draws delta 0, 1, 0, 1, 1, 1
startup_trials: 1
pruner_startup_trials: 1
checkpoints: 4
params:
  delta: {path: env.delta, type: categorical, choices: [0.0, 1.0]}
"""


@pytest.fixture
def spaces(workdir: Path) -> Path:
    folder = workdir / "conf" / "search"
    folder.mkdir(parents=True)
    (folder / "tiny.yaml").write_text(TINY_SPACE)
    (folder / "delta.yaml").write_text(DELTA_SPACE)
    return workdir


def test_default_space_holds_every_documented_value() -> None:
    cfg = compose_config([])
    validate_search(cfg)
    params = {str(p.path): p for p in cfg.search.params.values()}
    documented = {
        "ppo.gamma": [0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.98, 0.9999],
        "ppo.clip_range": [0.1, 0.2, 0.3, 0.4],
        "ppo.learning_rate": [1e-4, 1e-3, 1e-2, 1e-1, 1.0],
        "ppo.gae_lambda": [0.8, 0.9, 0.92, 0.95, 0.98, 0.99, 1.0],
        "ppo.ent_coef": [1e-8, 1e-6, 1e-4, 0.01, 0.1],
        "ppo.n_epochs": [1, 5, 10, 20, 30, 50],
        "ppo.n_steps": [32, 64, 128, 256, 512, 1024, 2048],
    }
    for path, values in documented.items():
        p = params[path]
        for value in values:
            if p.type == "categorical":
                assert value in p.choices, (path, value)
            else:
                assert p.low <= value <= p.high, (path, value)
    assert params["ppo.learning_rate"].log and params["ppo.ent_coef"].log
    assert set(params["env.observation"].choices) == {
        "default", "with_tip", "with_tip_to_target", "sin_angles"}
    # Documented batch sizes 32..4096 at n_steps 128 x 32 legs are nminibatches 128..1.
    assert {1, 2, 4, 8, 16, 32, 64, 128} <= set(params["ppo.nminibatches"].choices)


CLIP_RANGE = "{path: ppo.clip_range, type: float, low: 0.1, high: 0.3}"


def test_a_range_added_on_the_command_line_is_searched_and_stored(spaces: Path) -> None:
    """``+search.params.NAME={...}`` adds a typed range (Hydra alone cannot merge a dict into
    the typed space); the search samples it and the trial trains with it."""
    args = ["search=tiny", *TINY, "budget.seeds=1", f"+search.params.clip={CLIP_RANGE}"]
    assert run_cli("optuna", "--trials", "1", *args) == 0
    trial = load(spaces / "studies" / "kraby.db", "tiny").trials[0]
    assert set(trial.params) == {"learning_rate", "nminibatches", "gamma", "clip"}
    assert 0.1 <= trial.params["clip"] <= 0.3
    assert trial.user_attrs["settings"]["ppo"]["clip_range"] == trial.params["clip"]


def test_gym_sde_is_the_gym_space_and_gsde_s_two_ranges() -> None:
    base = ["env=gym", "env.id=MountainCarContinuous-v0", "ppo=zoo"]
    gym = compose_config([*base, "search=gym"]).search.params
    sde = compose_config([*base, "search=gym_sde"]).search.params
    assert set(sde) - set(gym) == {"log_std_init", "sde_sample_freq"}
    assert all(sde[name] == gym[name] for name in gym)
    added = compose_config([*base, "search=gym", "+search.params.log_std_init="
                            "{path: ppo.log_std_init, type: float, low: -4.0, high: 0.5}"])
    assert added.search.params.log_std_init == sde.log_std_init


def test_a_range_override_refuses_a_name_or_setting_taken_and_replaces_with_plus_plus() -> None:
    """In the default space (conf/search/ppo.yaml)."""
    with pytest.raises(ConfigError, match=r"gamma is already in the space; \+\+search"):
        compose_config(["+search.params.gamma={path: ppo.gamma, type: float, low: 0.5, "
                        "high: 0.9}"])
    twice = compose_config(["+search.params.discount={path: ppo.gamma, type: float, "
                            "low: 0.5, high: 0.9}"])
    with pytest.raises(ConfigError, match="gamma and discount both set ppo.gamma: keep one"):
        validate_search(twice)
    # ++ replaces the whole range: a float range keeps none of the categorical one's choices.
    replaced = compose_config(["++search.params.nminibatches={path: ppo.nminibatches, "
                               "type: int, low: 1, high: 4}"]).search.params.nminibatches
    assert (replaced.type, replaced.low, replaced.high, replaced.choices) == ("int", 1, 4, None)
    with pytest.raises(ConfigError, match="Key 'lo' not in 'ParamSpace'"):
        compose_config([f"+search.params.clip={CLIP_RANGE.replace('low', 'lo')}"])


def test_smoke_search_and_the_total_over_invocations(
        spaces: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["search=tiny", "--workers", "2", *TINY, "budget.seeds=1"]
    assert run_cli("optuna", "--trials", "2", *args) == 0
    db = spaces / "studies" / "kraby.db"
    study = load(db, "tiny")
    assert len(study.trials) == 2
    assert study.user_attrs["sampler"] == "tpe" and study.user_attrs["sampler_seed"] == 0
    trial = study.trials[0]
    assert set(trial.params) == {"learning_rate", "nminibatches", "gamma"}
    ppo = trial.user_attrs["settings"]["ppo"]
    assert ppo["batch_size"] == 128 // trial.params["nminibatches"]
    assert ppo["gamma"] == trial.params["gamma"]
    assert len(trial.intermediate_values) >= 2
    assert set(trial.intermediate_values) <= {128, 256, 384, 512}
    # --trials is the study's total: 2, then 3 (one more), then 3 again (none).
    assert run_cli("optuna", "--trials", "3", *args) == 0
    assert len(load(db, "tiny").trials) == 3
    capsys.readouterr()
    assert run_cli("optuna", "--trials", "3", *args) == 0
    assert "0 to run" in capsys.readouterr().out
    assert len(load(db, "tiny").trials) == 3


def test_a_cpu_budget_stops_the_search_before_its_trial_total(
        spaces: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["search=tiny", "--workers", "1", "--pruner", "none", *TINY, "budget.seeds=1"]
    # A budget far below one trial's CPU time: the first trial runs, then none.
    assert run_cli("optuna", "--trials", "4", "--cpu-budget", "0.001", *args) == 0
    out = capsys.readouterr().out
    db = spaces / "studies" / "kraby.db"
    # (The second of the warm start's two configurations stays queued for a later command.)
    trials = [t for t in load(db, "tiny").trials if t.state != TrialState.WAITING]
    assert len(trials) == 1 and trials[0].state == TrialState.COMPLETE
    spent = trials[0].user_attrs["cpu_time"]
    assert spent > 0.001
    assert "until 0 CPU s are used (0 so far)" in out
    # Its progress lines show the budget used, not an ETA over the trial total.
    # (The line is printed at the trial's last checkpoint, a moment before its CPU seconds are
    # stored, so the two may round to neighbouring whole seconds.)
    line = next(x for x in out.splitlines() if x.startswith("[1/4]"))
    shown = re.search(r"steps/s, ([\d,]+) of 0 CPU s used$", line)
    assert shown is not None and "ETA" not in line, line
    assert abs(int(shown.group(1).replace(",", "")) - spent) <= 1
    # The summary counts what asking the sampler cost too (suggest_cpu), every stored trial's.
    used = spent_cpu(load(db, "tiny").trials)
    assert spent <= used < spent + 1
    assert f"{used:,.0f} of its 0 CPU s used, 1 of 4 trials (stopped by the CPU budget)" in out
    # Its plan ended at the budget: list counts the trial it ran and the queued one.
    assert load(db, "tiny").user_attrs["kraby_cpu_budget"] == 0.001
    assert run_cli("list", "--storage", f"sqlite:///{db}") == 0
    assert re.search(r"^tiny +search +1/2 ", capsys.readouterr().out, re.M)
    # A rerun under the same budget starts nothing; a larger one tops the study up to its
    # total, and the budget is not part of the search's definition.
    assert run_cli("optuna", "--trials", "4", "--cpu-budget", "0.001", *args) == 0
    assert [t.state for t in load(db, "tiny").trials] == [TrialState.COMPLETE,
                                                          TrialState.WAITING]
    capsys.readouterr()
    assert run_cli("optuna", "--trials", "4", "--cpu-budget", "100000", *args) == 0
    trials = load(db, "tiny").trials
    assert len(trials) == 4 and all(t.state == TrialState.COMPLETE for t in trials)
    assert "stopped by the CPU budget" not in capsys.readouterr().out


def test_a_trial_of_three_seeds_reports_its_first_seed_then_each_seed_score(
        spaces: Path) -> None:
    assert run_cli("optuna", "--trials", "1", "search=tiny", "--pruner", "none", "--workers",
                   "1", *TINY, "budget.seeds=3") == 0
    trial = load(spaces / "studies" / "kraby.db", "tiny").trials[0]
    steps = set(trial.intermediate_values)
    # Every 128 steps of the first seed but its end, then after seeds 1 and 2 (not the last).
    assert {512, 1024} <= steps <= {128, 256, 384, 512, 1024}
    assert trial.user_attrs["env_steps"] == 3 * 512
    # CPU seconds of the whole trial: positive, and at most the wall time of the worker and
    # its leg-stepping processes (shards) all busy, plus the little spent outside training.
    assert 0 < trial.user_attrs["cpu_time"] <= trial.user_attrs["wall_time"] * 3 + 1
    assert all(-2.0 < v < 0.0 for v in trial.intermediate_values.values())


def test_median_pruner_stops_bad_trials_in_a_controlled_case(spaces: Path) -> None:
    args = ["search=delta", "--trials", "6", "--workers", "1", *TINY,
            "budget.seeds=2", "budget.steps=1024"]
    assert run_cli("optuna", *args) == 0
    study = load(spaces / "studies" / "kraby.db", "delta")
    trials = study.get_trials()
    pruned = [t for t in trials if t.state == TrialState.PRUNED]
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    assert complete and pruned
    assert all(t.params["delta"] == 1.0 for t in pruned)
    first_good = min(t.number for t in complete if t.params["delta"] == 0.0)
    late_bad = [t for t in trials if t.params["delta"] == 1.0 and t.number > first_good]
    assert late_bad and all(t.state == TrialState.PRUNED for t in late_bad)
    for trial in pruned:
        # Stopped during its first seed: a pruned trial spends less than one seed's budget.
        assert trial.user_attrs["pruned_at"] <= 1024
        assert trial.user_attrs["env_steps"] < 2 * 1024
        assert max(trial.intermediate_values) == trial.user_attrs["pruned_at"]


def test_each_command_on_a_search_takes_the_next_opening_and_its_own_seed(
        tmp_path: Path) -> None:
    with opened(f"sqlite:///{tmp_path}/k.db") as store:
        ledger = store.define("s", StudyAttrs(kind="search"))
        assert [take_opening(ledger) for _ in range(3)] == [0, 1, 2]
        assert ledger.attrs.openings == 3
        # A search stored before openings were counted takes its trial count, as its resumes
        # did: here 2 trials.
        old = _one_done(_one_done(store.define("old", StudyAttrs(kind="search")),
                                  ((512, -0.2),)), ((512, -0.3),))
        assert take_opening(old) == 2 and take_opening(old) == 3
    # The first command draws from the seed itself, so a new search reproduces as before.
    seeds = [sampler_seed(7, opening) for opening in range(4)]
    assert seeds[0] == 7 and len(set(seeds)) == 4


def test_the_gp_sampler_starts_as_random_search_then_follows_its_model() -> None:
    from kraby_study.run.sampling import make_sampler

    def draws(sampler: optuna.samplers.BaseSampler, n: int) -> list[float]:
        study = optuna.create_study(direction="maximize", sampler=sampler)
        # A peak at x = 0.8 with a little noise that depends on the trial, as seeds add.
        study.optimize(lambda t: -(t.suggest_float("x", 0.0, 1.0) - 0.8) ** 2
                       + 0.001 * ((t.number * 7) % 3), n_trials=n)
        return [t.params["x"] for t in study.trials]

    cfg = compose_config(["search.sampler=gp", "search.seed=3", "search.startup_trials=4"])
    gp = make_sampler(cfg)
    assert isinstance(gp, optuna.samplers.GPSampler)
    # It learns nothing from a pruned trial, so it prunes none unless told to.
    assert isinstance(make_pruner(cfg), optuna.pruners.NopPruner)
    assert isinstance(make_pruner(compose_config(["search.sampler=gp", "search.pruner=median"])),
                      optuna.pruners.MedianPruner)
    with_gp = draws(gp, 12)
    at_random = draws(make_sampler(compose_config(["search.sampler=random",
                                                   "search.seed=3"])), 12)
    # Its start is random search's of the same seed; after it, its model's choices.
    assert with_gp[:4] == at_random[:4] and with_gp[4:] != at_random[4:]
    distance = [sum(abs(x - 0.8) for x in xs[4:]) / 8 for xs in (with_gp, at_random)]
    assert distance[0] < 0.1 < distance[1]


def test_checkpoint_prunes_a_trial_below_the_median_at_equal_steps(tmp_path: Path) -> None:
    cfg = compose_config(["search.startup_trials=1", "budget=smoke",
                          f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        ledger = _one_done(store.define("s", StudyAttrs(kind="search"),
                                        pruner=optuna.pruners.MedianPruner(n_startup_trials=1)),
                           ((512, -0.2), (1024, -0.1)))
        source = SearchSource(ledger, cfg)
        good, bad = ledger.ask({}), ledger.ask({})
        assert source.checkpoint(good.number, 512, -0.15) is True
        assert source.checkpoint(bad.number, 512, -0.9) is False


def test_a_cpu_budget_counts_what_the_running_trials_have_used(tmp_path: Path) -> None:
    cfg = compose_config(["budget=smoke", "search.cpu_budget=100", "save_models=false",
                          f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        source = SearchSource(store.define("s", StudyAttrs(kind="search")), cfg)
        first = source.next_trial()
        assert first is not None
        source.using(first[0], 100, 60.0)
        second = source.next_trial()  # 60 of 100 used
        assert second is not None
        source.using(second[0], 100, 45.0)
        # What asking the sampler cost counts too (a small part here).
        asked = sum(t.user_attrs["suggest_cpu"] for t in source.ledger.trials())
        assert 0 < asked < 1
        # Nothing has ended, yet the two running trials have used the budget: none starts.
        assert source.spent() == pytest.approx(105.0 + asked) and source.next_trial() is None
        assert source.used_text() == "105 of 100 CPU s used"
        # An ended trial counts by its stored CPU time, no longer by its last report.
        source.record(first[0], first[1], TrialResult(outcome=Outcome.COMPLETE,
                                                      final_score=-0.1, cpu_time=61.0))
        assert source.spent() == pytest.approx(106.0 + asked) and source.next_trial() is None
        # A trial given back (Ctrl-C) counts nothing; 61 of 100 used, so the next one starts.
        source.requeue(second[0], second[1], "interrupted")
        assert source.spent() == pytest.approx(61.0 + asked) and source.next_trial() is not None


class _DearSampler(optuna.samplers.RandomSampler):
    """Random search that spends at least 0.3 CPU s on each trial it is asked for."""

    def sample_relative(self, study: optuna.Study, trial: optuna.trial.FrozenTrial,
                        search_space: dict[str, object]) -> dict[str, object]:
        start = time.process_time()
        while time.process_time() - start < 0.3:
            pass
        return {}


def test_a_cpu_budget_counts_what_the_sampler_spent_asking(tmp_path: Path) -> None:
    cfg = compose_config(["budget=smoke", "search.cpu_budget=0.5", "save_models=false",
                          f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        source = SearchSource(store.define("s", StudyAttrs(kind="search"),
                                           sampler=_DearSampler(seed=0)), cfg)
        assert source.next_trial() is not None and source.next_trial() is not None
        # No trial has trained, yet two asks of 0.3 CPU s or more used the 0.5 CPU s.
        assert all(t.user_attrs["suggest_cpu"] >= 0.3 for t in source.ledger.trials())
        assert source.spent() >= 0.6 and source.next_trial() is None


def _one_done(ledger: StudyLedger, values: tuple[tuple[int, float], ...]) -> StudyLedger:
    """The study with one complete trial that reported these (step, value) checkpoints."""
    done = ledger.ask({})
    for step, value in values:
        ledger.checkpoint(done.number, step, value)
    ledger.record(done.number, TrialResult(outcome=Outcome.COMPLETE, final_score=-0.1))
    return ledger


@pytest.mark.parametrize("warmup,kept_at_512", [(0.25, True), (0.0, False)])
def test_no_trial_is_pruned_during_the_warmup(tmp_path: Path, warmup: float,
                                              kept_at_512: bool) -> None:
    # 8 checkpoints of 512 steps; a quarter of the 4,096-step seed is 1,024 steps of warm-up.
    cfg = compose_config(["budget.steps=4096", "search.checkpoints=8", "search.startup_trials=1",
                          "search.pruner_startup_trials=1", f"search.warmup={warmup}",
                          f"storage=sqlite:///{tmp_path}/k.db"])
    with opened(cfg.storage) as store:
        ledger = _one_done(store.define("s", StudyAttrs(kind="search"), pruner=make_pruner(cfg)),
                           ((512, -0.1), (1024, -0.1), (1536, -0.1)))
        source = SearchSource(ledger, cfg)
        bad = ledger.ask({})
        assert source.checkpoint(bad.number, 512, -0.9) is kept_at_512
        if kept_at_512:
            assert source.checkpoint(bad.number, 1024, -0.9) is False


def test_best_round_trip(spaces: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("optuna", "--trials", "2", "search=tiny", "--workers", "1", *TINY,
                   "budget.seeds=1") == 0
    study = load(spaces / "studies" / "kraby.db", "tiny")
    best = study.best_trial
    capsys.readouterr()
    assert run_cli("best", "--study-name", "tiny") == 0
    out = capsys.readouterr().out
    assert f"trial {best.number}" in out
    written = spaces / "conf" / "ppo" / "best_tiny.yaml"
    assert written.is_file()
    from kraby_study.plan.settings import resolved_settings

    cfg = compose_config(["ppo=best_tiny"])
    # Stored settings leave out the optional PPO settings at their defaults, as resolving does.
    assert resolved_settings(cfg)["ppo"] == best.user_attrs["settings"]["ppo"]
    swept = compose_config(["ppo=best_tiny", "study=ent_coef"])
    assert swept.ppo.gamma == 0.8  # the study's own settings still apply on top
    assert compose_config(["ppo=best_tiny", "study=observation"]).ppo.gamma == best.params[
        "gamma"]


def test_best_of_a_sweep_writes_the_best_value(workdir: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("run", "study=observation", "budget.seeds=2", "workers=2", *TINY) == 0
    capsys.readouterr()
    assert run_cli("best", "--study-name", "observation", "--name", "obs") == 0
    out = capsys.readouterr().out
    assert out.startswith("best: observation=")
    cfg = compose_config(["ppo=obs"])
    assert cfg.env.observation in out


@pytest.mark.parametrize("argv,message", [
    (["--trials", "0"], "--trials"),
    (["--trials", "abc"], "--trials"),
    (["--cpu-budget", "0"], "--cpu-budget"),
    (["--cpu-budget", "inf"], "--cpu-budget"),
    (["search.cpu_budget=-5"], "search.cpu_budget must be a positive number"),
    (["--sampler", "grid"], "--sampler"),
    (["--pruner", "sometimes"], "--pruner"),
    (["search.params.gamma.low=0.99", "search.params.gamma.high=0.5"], "above high"),
    (["search.params.learning_rate.low=0"], "log range"),
    (["search.params.nminibatches.choices=[3]"], "nminibatches 3"),
    (["search.pruner_startup_trials=-1"], "pruner_startup_trials"),
    (["search.warmup=1"], "search.warmup"),
    (["search.warmup=-0.25"], "search.warmup"),
    (["budget=quick", "--pruner", "wilcoxon"], "budget.seeds=3 at search.wilcoxon_p=0.1"),
    (["budget.seeds=4", "--pruner", "wilcoxon"], "budget.seeds=5 or more"),
    (["budget.seeds=1", "--pruner", "wilcoxon"], "budget.seeds=1 never leaves any to stop"),
    (["search.wilcoxon_p=0"], "search.wilcoxon_p"),
    (["search.wilcoxon_p=1", "--pruner", "wilcoxon"], "search.wilcoxon_p"),
    (["search.sampler=gpx"], "unknown sampler 'gpx': choose tpe, random, nsga2, gp"),
])
def test_bad_search_input_is_refused_before_anything_runs(
        workdir: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
        message: str) -> None:
    with pytest.raises(SystemExit) if argv[0].startswith("--") else _no_exit() as caught:
        code = run_cli("optuna", *argv)
    code = caught.value.code if isinstance(caught, pytest.ExceptionInfo) else code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (workdir / "studies").exists()


class _no_exit:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def test_evaluation_objective_scores_the_deterministic_policy(spaces: Path) -> None:
    assert run_cli("optuna", "--trials", "1", "search=tiny", "--workers", "1", *TINY,
                   "budget.seeds=1", "search.objective=evaluation",
                   "search.eval_episodes=3") == 0
    trial = load(spaces / "studies" / "kraby.db", "tiny").trials[0]
    assert trial.state == TrialState.COMPLETE
    # The evaluation is its own number: not the training reward of the last 10 %.
    from kraby_envs.rollout import fixed_targets
    assert trial.value < 0 and trial.value == trial.user_attrs["final_score"]
    assert trial.user_attrs["train_reward"] < 0
    assert trial.value != trial.user_attrs["train_reward"]
    assert fixed_targets(3, 0.5).shape == (3, 3)
    assert (fixed_targets(3, 0.5) == fixed_targets(3, 0.5)).all()


def test_evaluation_is_deterministic_for_a_model(tmp_path: Path) -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO

    import kraby_envs
    from kraby_study.env import adapter_for
    from kraby_study.plan.settings import resolved_settings

    settings = resolved_settings(compose_config(["ppo=tuned"]))
    env = gym.make(kraby_envs.ENV_ID)
    model = PPO("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": [8]})
    evaluate = adapter_for(settings["env"]).evaluate
    for seed in (None, 3):  # the fixed set of studies stored before; a run's own
        first = evaluate(model, settings["env"], 4, seed=seed)
        assert first == evaluate(model, settings["env"], 4, seed=seed)
        assert len(first.returns) == 4 and -2.0 < first.mean < 0
    assert evaluate(model, settings["env"], 4, seed=3) != evaluate(model, settings["env"], 4)


# The wilcoxon pruner races a trial's seeds: a trial's seed scores are constructed here (the
# training is faked), by the delta its configuration draws, seed by seed (5 seeds).
RACE_SPACE = """\
name: race
sampler: random
pruner: wilcoxon
params:
  delta: {path: env.delta, type: categorical, choices: [0.0, 0.5, 1.0]}
"""
SEED_SCORES = {
    0.0: [-0.10, -0.12, -0.11, -0.09, -0.13],  # the best (mean -0.11)
    1.0: [-0.30, -0.33, -0.29, -0.35, -0.31],  # worse on every seed: p = 1/2^4 after 4 seeds
    # Worse on average and on 3 of its first 4 seeds (by 0.04, 0.02, 0.03; better by 0.01 on
    # the third): p = 2/16 = 0.125 after 4 seeds, not below 0.1, so it runs every seed.
    0.5: [-0.14, -0.14, -0.10, -0.12, -0.12],
}


def test_wilcoxon_pruner_stops_the_seeds_of_a_trial_worse_on_the_same_seeds(
        workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from kraby_study.records.attributes import TrialAttrs
    from kraby_study.run import trial as trial_module
    from kraby_study.run.sampling import distributions, make_sampler
    from kraby_study.run.trial import run_trial

    def learn(spec: object, seed: int, recorder: object, shards: int) -> object:
        return trial_module._Seed(env_steps=spec.steps)  # type: ignore[attr-defined]

    def score(spec: object, run: object, seed: int) -> None:
        delta = spec.settings["env"]["delta"]  # type: ignore[attr-defined]
        index = len(trained[spec.key])  # type: ignore[attr-defined]
        run.score = run.train_reward = SEED_SCORES[delta][index]  # type: ignore[attr-defined]
        trained[spec.key].append(run.score)  # type: ignore[attr-defined]

    trained: dict[str, list[float]] = {}
    monkeypatch.setattr(trial_module, "_learn", learn)
    monkeypatch.setattr(trial_module, "_score", score)
    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "race.yaml").write_text(RACE_SPACE)
    cfg = compose_config(["search=race", "budget=smoke", "budget.steps=1000", "budget.seeds=5",
                          "save_models=false", f"storage=sqlite:///{workdir}/k.db"])
    validate_search(cfg)
    with opened(cfg.storage) as store:
        ledger = store.define("race", StudyAttrs(kind="search"), sampler=make_sampler(cfg),
                              pruner=make_pruner(cfg))
        for delta in (0.0, 1.0, 0.5):
            ledger.queue({"delta": delta}, TrialAttrs())
        source = SearchSource(ledger, cfg)
        assert distributions(cfg).keys() == {"delta"}
        for _ in SEED_SCORES:
            claimed = source.next_trial()
            assert claimed is not None
            number, spec = claimed
            assert spec.seed_scores and spec.checkpoint_every is None
            trained[spec.key] = []
            result = run_trial(spec, lambda step, value, n=number: source.checkpoint(
                n, step, value))
            ledger.record(number, result)
        best, worse, kept = sorted(ledger.trials(), key=lambda t: t.number)
    steps = [1000, 2000, 3000, 4000, 5000]
    # Each seed's own score at the env steps of its end, the last seed's too.
    assert best.state == TrialState.COMPLETE
    assert best.intermediate_values == dict(zip(steps, SEED_SCORES[0.0], strict=True))
    assert best.value == pytest.approx(-0.11)
    # Stopped after its 4th seed, the first at which p can fall below 0.1 (not after 2 or 3).
    assert worse.state == TrialState.PRUNED
    assert worse.user_attrs["pruned_at"] == 4000 and worse.user_attrs["env_steps"] == 4000
    assert worse.intermediate_values == dict(zip(steps[:4], SEED_SCORES[1.0][:4],
                                                 strict=True))
    # Worse on average but not significantly: it ran all its seeds and has its score.
    assert kept.state == TrialState.COMPLETE and kept.user_attrs["env_steps"] == 5000
    assert kept.value == pytest.approx(sum(SEED_SCORES[0.5]) / 5)
    assert len(kept.intermediate_values) == 5


def test_a_wilcoxon_search_reports_whole_seeds_only(spaces: Path) -> None:
    assert run_cli("optuna", "--trials", "1", "search=tiny", "--pruner", "wilcoxon",
                   "--workers", "1", *TINY, "budget.seeds=5") == 0
    trial = load(spaces / "studies" / "kraby.db", "tiny").trials[0]
    assert trial.state == TrialState.COMPLETE
    # No checkpoint within a seed: one value per seed, at the env steps of its end.
    assert set(trial.intermediate_values) == {512, 1024, 1536, 2048, 2560}
    assert trial.value == pytest.approx(sum(trial.intermediate_values.values()) / 5)


def test_the_wilcoxon_threshold_is_in_the_definition_of_wilcoxon_searches_only() -> None:
    from kraby_study.plan.space import search_definition, wilcoxon_seeds

    assert "wilcoxon_p" not in search_definition(compose_config([]))["search"]
    racing = compose_config(["search.pruner=wilcoxon", "budget.seeds=5"])
    assert search_definition(racing)["search"]["wilcoxon_p"] == 0.1
    pruner = make_pruner(racing)
    assert isinstance(pruner, optuna.pruners.WilcoxonPruner)
    assert [wilcoxon_seeds(p) for p in (0.3, 0.25, 0.1, 0.05, 0.01)] == [2, 3, 4, 5, 7]


@pytest.mark.parametrize(("overrides", "label"), [
    (["search.pruner=none"], "no pruner"),
    (["search.pruner=median"], "median pruner"),
    (["search.pruner=wilcoxon"], "wilcoxon pruner (a trial's seeds against the best's, p < 0.1, "
                                 "from 4 seeds)"),
])
def test_the_start_line_names_the_pruner_in_words(overrides: list[str], label: str) -> None:
    assert pruner_label(compose_config(overrides)) == label


def test_progress_labels_keep_a_value_near_one_off_one() -> None:
    label = short_label({"gamma": 0.9999, "learning_rate": 0.000123456, "clip_range": 0.2}, "t0")
    assert label == "gamma=0.9999 lr=0.000123 clip=0.2 (t0)"
    assert short_label({"gamma": 0.999999}, "t1") == "gamma=0.999999 (t1)"
