"""Every script in benchmarks/ runs at a smoke size and prints its result line.

A benchmark is measured, not asserted: these tests only keep the scripts working as the code
under them changes (each runs in a fresh folder, as a user would start it, and must exit 0
and print the line its page quotes). Each script is named on a page of docs/benchmarks/.
Scripts that take more than a few seconds are in the slow tier; those that need a PostgreSQL
server skip without KRABY_TEST_POSTGRES_URL.
"""

from __future__ import annotations

import math
import os
import random
import statistics
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
SERVER = os.environ.get("KRABY_TEST_POSTGRES_URL")

slow = pytest.mark.slow
# The Ray benchmarks run on test_ray.py's xdist worker, in turn: its tests count the Ray processes.
ray_group = pytest.mark.xdist_group("ray")
postgres = [pytest.mark.postgres,
            pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")]



def optuna_has_racing() -> bool:
    """Whether ``kraby-study optuna --help`` lists ``--racing`` (the racing search is built)."""
    done = subprocess.run([sys.executable, "-m", "kraby_study.cli", "optuna", "--help"],
                          capture_output=True, text=True, timeout=120)
    return "--racing" in done.stdout


# bench_methods at smoke size: the documented campaign's nine stages need 32 legs (batch_size
# 4096 divides only a rollout of 128 x 32), so its runs are cut to 1,024 steps and tiny nets.
METHODS_SMOKE = ["--cpu-budget", "10", "--confirm-seeds", "2", "--workers", "2",
                 "budget=smoke", "budget.steps=1024", "budget.curve_every=128",
                 "ppo.net_arch=[8]"]

# (script, smoke arguments, a line or lines its output must hold): the smallest run that still goes
# through every step of the script. The leg needs 1,024 steps and Pendulum-v1 1,600 before an
# episode can end in the scored last tenth of a run.
SMOKE = [
    pytest.param("paired_picks.py", ["--seeds", "0", "1", "2", "--first-means", "1", "2", "3",
                                     "--second-means", "0", "2", "1"], "paired_picks: first",
                 id="paired_picks"),
    pytest.param("bench_racing.py", ["--simulations", "2", "--smoke"],
                 "max family-wise error of a race", id="bench_racing"),
    pytest.param("bench_report.py", ["--trials", "5", "--points", "10"], "write_report:",
                 marks=slow, id="bench_report"),
    pytest.param("bench_env.py", ["--steps", "20", "--n-envs", "2"], "batched vs DummyVecEnv",
                 marks=slow, id="bench_env"),
    pytest.param("bench_train.py", ["--steps", "1024", "--skip-workers"], "goals: training speed",
                 marks=slow, id="bench_train"),
    pytest.param("bench_gym.py", ["--env", "Pendulum-v1", "--steps", "1600", "--repeats", "1"],
                 "Pendulum-v1: median ratio", marks=slow, id="bench_gym"),
    pytest.param("bench_eval_agreement.py",
                 ["--seeds", "2", "--episodes", "2", "--workers", "1", "env=gym",
                  "env.id=Pendulum-v1", "ppo=zoo", "budget=zoo", "budget.steps=1600"],
                 "agreement:", marks=slow, id="bench_eval_agreement"),
    pytest.param("bench_search.py",
                 ["--env-id", "CartPole-v1", "--cpu-budget", "2", "--sampler-seeds", "0",
                  "--confirm-seeds", "2", "--workers", "1", "budget.steps=4000",
                  "budget.seeds=1"], "bench_search:", marks=slow, id="bench_search"),
    pytest.param("bench_search.py",
                 ["--env-id", "CartPole-v1", "--cpu-budget", "2", "--sampler-seeds", "0",
                  "--confirm-seeds", "2", "--workers", "1", "--no-zoo", "budget.steps=1024",
                  "budget.seeds=1", "--samplers", "racing", "random", "--arm-overrides",
                  "racing:budget.seeds=4"], "bench_search: racing - random", marks=slow,
                 id="bench_search_racing"),
    pytest.param("bench_pruning.py", ["--trials", "3", "--seeds", "1", "--steps", "1024",
                                      "--sampler-seeds", "0", "--jobs", "1"],
                 "noise of the objective", marks=slow, id="bench_pruning"),
    pytest.param("bench_error_rates.py", ["--simulations", "10", "--coverage-simulations", "20",
                                          "--race-simulations", "5", "--workers", "1"],
                 "max family-wise error", marks=slow, id="bench_error_rates"),
    pytest.param("bench_skewed_spreads.py", ["--simulations", "10", "--workers", "1"],
                 "on 1 worker(s)", marks=slow, id="bench_skewed_spreads"),
    pytest.param("bench_startup.py", ["--repeats", "1"], "first trial line", marks=slow,
                 id="bench_startup"),
    pytest.param("bench_head.py", ["--trials", "16", "--slots", "2"],
                 "| SQLite file | stub pool |", marks=slow, id="bench_head"),
    pytest.param("bench_postgres.py", ["--smoke"], "| 2 |", marks=[slow, *postgres],
                 id="bench_postgres"),
    pytest.param("bench_ray.py", ["--rounds", "1", "--steps", "1024"], "| ray |",
                 marks=[slow, ray_group], id="bench_ray"),
    pytest.param("bench_actor_start.py", ["--actors", "1"], "started: median",
                 marks=[slow, ray_group], id="bench_actor_start"),
    pytest.param("bench_ray_fault.py", ["--steps", "1024", "--seeds", "1", "--after", "2"],
                 "node lost at", marks=[slow, ray_group], id="bench_ray_fault"),
    # A string condition is evaluated when the test runs, not when the module is collected.
    pytest.param("bench_methods.py", ["--seeds", "random=0", "racing=0", "--set",
                                      "racing:budget.seeds=4", *METHODS_SMOKE],
                 "bench_methods: racing - random confirmed IQM: mean difference",
                 marks=[slow, pytest.mark.skipif(
                     "not optuna_has_racing()",
                     reason="kraby-study optuna --help lists no --racing: the racing search "
                            "is not on this branch")], id="bench_methods_racing"),
    pytest.param("bench_zoo_rerun.py", [str(ROOT / "docs/results/pendulum_beats_zoo.yml"),
                                        "--smoke"],
                 "bench_zoo_rerun: IQM difference", marks=slow, id="bench_zoo_rerun"),
]


@pytest.mark.parametrize(("script", "args", "expected"), SMOKE)
def test_benchmark_runs_at_smoke_size(script: str, args: list[str],
                                      expected: str | tuple[str, ...], tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, str(BENCHMARKS / script), *args], cwd=tmp_path,
                            capture_output=True, text=True, timeout=900)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    for line in (expected,) if isinstance(expected, str) else expected:
        assert line in result.stdout, output[-3000:]


@slow
def test_bench_methods_retrains_two_methods_picks_at_the_full_budget(tmp_path: Path) -> None:
    """A smoke comparison of the campaign, random search and TPE (bench_methods' smoke test,
    with its table and tests), then --full-budget of two of them: each pick written as a ppo
    config, retrained, and answered against the campaign's in the table's full-budget part (at smoke
    size here: the invocation's budget overrides replace budget=full's)."""
    script = [sys.executable, str(BENCHMARKS / "bench_methods.py"), "--seeds", "campaign=0",
              "random=0"]
    done = subprocess.run([*script, "tpe=0", *METHODS_SMOKE], cwd=tmp_path,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    for line in ("| method | repetition | CPU s | configurations | env steps (M) |",
                 "tpe - random confirmed IQM: mean difference",
                 " - campaign confirmed IQM: mean difference"):
        assert line in done.stdout, (done.stdout + done.stderr)[-3000:]
    # --plan prices each pick's retraining by its own confirm's CPU a run, not the average run.
    sys.path.insert(0, str(BENCHMARKS))
    import bench_methods as bm

    url = f"sqlite:///{tmp_path / 'bench_methods.db'}"
    own = bm.read_confirm(url, "leg-random-r0-confirm")
    plan = subprocess.run([*script, "--full-budget", "random", "campaign", "--plan",
                           *METHODS_SMOKE], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert plan.returncode == 0, (plan.stdout + plan.stderr)[-3000:]
    priced = next(line for line in plan.stdout.splitlines()
                  if "confirm.name=leg-full-random-r0" in line)
    assert priced.endswith(f"~{2 * own.cpu_per_run:,.0f} CPU s (its confirm's "
                           f"{own.cpu_per_run:,.1f} CPU s a run at 1,024 steps)"), priced
    full = subprocess.run([*script, "--full-budget", "random", "campaign", *METHODS_SMOKE],
                          cwd=tmp_path, capture_output=True, text=True, timeout=900)
    output = full.stdout + full.stderr
    assert full.returncode == 0, output[-3000:]
    assert "At the full budget (1,024 steps a run), the same picks on 2 fresh seeds:" \
        in full.stdout, output[-3000:]
    rows = [line for line in full.stdout.splitlines() if line.startswith(("| random | 0 | ",
                                                                           "| campaign | 0 | "))]
    assert len(rows) == 4, output[-3000:]  # each pick at the tuning budget and at the full one
    assert (tmp_path / "conf" / "ppo" / "pick_random_r0.yaml").exists()
    with open(tmp_path / "methods.csv") as handle:
        assert sum(1 for line in handle) == 1 + 5  # a header, three tuned rows and two full ones
    # --asked counts the configurations with a setting: none with a gamma nobody tried, every
    # one with the episode length all share; each out of the table's configurations.
    tuned = {line.split(" | ")[0]: int(line.split(" | ")[3]) for line in done.stdout.splitlines()
             if line.startswith(("| random | 0 | ", "| campaign | 0 | ", "| tpe | 0 | "))}
    assert len(tuned) == 3, output[-3000:]
    for setting, share in (("ppo.gamma=0.123456", 0), ("env.max_episode_steps=32", 1)):
        table = subprocess.run([*script, "--table", "--asked", setting, *METHODS_SMOKE],
                               cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert table.returncode == 0, (table.stdout + table.stderr)[-3000:]
        asked = table.stdout.split(f"| with {setting} |")[1].splitlines()[2:5]
        for line in asked:
            method, _, matching, configurations = line.split(" | ")[:4]
            assert int(configurations) == tuned[method], line
            assert int(matching) == share * int(configurations), line
    bad = subprocess.run([*script, "--table", "--asked", "n_steps=32", *METHODS_SMOKE],
                         cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert bad.returncode != 0 and "--asked takes env.KEY=VALUE" in bad.stderr


def test_every_benchmark_is_smoke_tested_and_documented() -> None:
    scripts = {path.name for path in BENCHMARKS.glob("*.py")}
    # bench_racing_sampler needs a store of measured runs: its own test writes one.
    tested = {param.values[0] for param in SMOKE} | {"bench_racing_sampler.py"}
    assert scripts == tested
    pages = "".join(page.read_text() for page in (ROOT / "docs/benchmarks").glob("*.md")
                    if page.name != "index.md")
    assert [name for name in sorted(scripts) if name not in pages] == []


@slow
def test_zoo_rerun_sets_the_confirm_of_the_same_settings_beside(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]
                                                               ) -> None:
    """bench_zoo_rerun finds in a confirm study the configurations whose stored settings are a
    handed-back file's and rl-zoo3's own (settings as a confirm stores them, composed from
    the config; a third configuration differs in gamma alone), with their seeds, scores and
    CPU seconds; a file whose settings the confirm does not hold is refused in one line."""
    pytest.importorskip("rl_zoo3")
    import csv
    import json

    import yaml
    from conftest import sqlite_url
    from optuna.distributions import CategoricalDistribution
    from optuna.trial import TrialState, create_trial
    from synthetic import add_trials, define

    from kraby_study.config.compose import compose_config
    from kraby_study.config.zoo import translate, zoo_version
    from kraby_study.plan.settings import resolved_settings
    from kraby_study.records.attributes import TrialAttrs
    from kraby_study.store.store import Store

    sys.path.insert(0, str(BENCHMARKS))
    import bench_zoo_rerun as rerun

    env_id, pick = rerun.read_entry(ROOT / "docs/results/mountaincar_pick.yml", None)
    _, zoo = rerun.zoo_entry(env_id)
    base = ["env=gym", f"env.id={env_id}", "ppo=zoo"]
    read = translate(env_id, pick)
    as_pick = [*base, *(f"ppo.{k}={json.dumps(v)}" for k, v in read.ppo.items()),
               *(f"env.{k}={json.dumps(v)}" for k, v in read.env.items())]
    settings = {"zoo": resolved_settings(compose_config(base)),
                "t34": resolved_settings(compose_config(as_pick)),
                "t7": resolved_settings(compose_config([*as_pick, "ppo.gamma=0.99"]))}
    assert settings["t34"] != settings["zoo"]
    labels = list(settings)
    url = sqlite_url(tmp_path / "k.db")
    store = Store(url)
    try:
        define(store, "mcc-confirm", "confirm", {"kind": "confirm", "parameter": "config",
                                                 "values": labels}, 6)
        add_trials(store, "mcc-confirm", [create_trial(
            state=TrialState.COMPLETE, value=10.0 * vi + seed, params={"config": label},
            distributions={"config": CategoricalDistribution(labels)},
            user_attrs=TrialAttrs(key=f"v{vi}-s{seed}", seed=1000 + seed,
                                  settings=settings[label], final_score=10.0 * vi + seed,
                                  cpu_time=5.0 + vi).stored())
            for vi, label in enumerate(labels) for seed in range(2)])
    finally:
        store.close()

    runs, found = rerun.confirm_runs(url, "mcc-confirm", env_id, {"pick": pick, "zoo": zoo})
    assert found == {"pick": "t34", "zoo": "zoo"}
    assert sorted((r.setting, r.seed, r.score, r.cpu) for r in runs) == [
        ("pick", 1000, 10.0, 6.0), ("pick", 1001, 11.0, 6.0),
        ("zoo", 1000, 0.0, 5.0), ("zoo", 1001, 1.0, 5.0)]
    other = tmp_path / "other.yml"
    other.write_text(yaml.safe_dump({env_id: {**pick, "gamma": 0.5}}))
    runs, found = rerun.confirm_runs(url, "mcc-confirm", env_id, {"other": {**pick,
                                                                             "gamma": 0.5}})
    assert (runs, found) == ([], {})
    with pytest.raises(SystemExit) as stopped:  # before anything trains
        rerun.main([str(other), "--storage", url, "--confirm", "mcc-confirm", "--folder",
                    str(tmp_path / "runs")])
    assert stopped.value.code == 2 and not (tmp_path / "runs").exists()
    assert capsys.readouterr().err == ("bench_zoo_rerun: confirm 'mcc-confirm' holds no "
                                       "configuration with the settings of other.yml for "
                                       f"{env_id}\n")

    out = tmp_path / "rows.csv"
    rerun.main([str(ROOT / "docs/results/mountaincar_pick.yml"), "--smoke", "--storage", url,
                "--confirm", "mcc-confirm", "--folder", str(tmp_path / "runs"), "--out",
                str(out)])
    table = capsys.readouterr().out
    assert ("| mountaincar_pick.yml | confirm 'mcc-confirm': t34 | 2 | 10.5 | 10.5 [10.0, 11.0] "
            "| - | 6.0 |") in table
    assert (f"| rl-zoo3 {zoo_version()} ppo.yml | confirm 'mcc-confirm': zoo | 2 | 0.5 |"
            in table)
    rows = list(csv.DictReader(out.open()))
    assert [(r["source"], r["seed"]) for r in rows] == [
        ("rerun", "500"), ("rerun", "500"), *[("confirm 'mcc-confirm': t34", s)
                                              for s in ("1000", "1001")],
        *[("confirm 'mcc-confirm': zoo", s) for s in ("1000", "1001")]]


def methods(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(BENCHMARKS / "bench_methods.py"), *args],
                          cwd=cwd, capture_output=True, text=True, timeout=300)


def test_methods_plan_names_every_command_and_refuses_bad_input(tmp_path: Path) -> None:
    """bench_methods --plan prints each repetition's tuning and confirm commands (repetition
    r: sampler seed r, tuning seeds from 100 r, its own studies, the documented start only)
    and their CPU, and starts nothing; bad input is one line and exit 2, before any work."""
    store = ["--storage", f"sqlite:///{tmp_path / 'm.db'}"]
    shown = methods("--plan", "--cpu-budget", "300", "--seeds", "campaign=0", "random=0-1",
                    *store, "budget.steps=20480", "budget.seeds=2", cwd=tmp_path)
    assert shown.returncode == 0, shown.stderr[-2000:]
    commands = [line for line in shown.stdout.splitlines() if line.startswith("$ kraby-study")]
    assert len(commands) == 6
    assert "campaign=documented campaign.name=leg-campaign-r0 seed=0" in commands[0]
    assert "confirm --study-name leg-campaign-r0-ent_coef --top 1 --seeds 10" in commands[1]
    assert commands[4].startswith("$ kraby-study optuna ")
    assert ("search.sampler=random search.name=leg-random-r1 search.seed=1 seed=100 "
            "'search.enqueue=[start]' search.cpu_budget=300") in commands[4]
    assert "a campaign repetition 108 runs x 20,480 steps" in shown.stdout
    assert not list(tmp_path.iterdir())
    for bad, message in [(["--seeds", "random=10"], "distinct repetitions from 0 to 9"),
                         (["--seeds", "random=0"], "random need --cpu-budget B"),
                         (["--seeds", "grid=0"], "--seeds 'grid=0': use METHOD=")]:
        refused = methods(*bad, *store, cwd=tmp_path)
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
        assert message in refused.stderr
        assert not list(tmp_path.iterdir())


def test_methods_checks_the_campaign_pick_and_answers_by_the_projects_decision(
        tmp_path: Path) -> None:
    """Before the campaign's confirm, the harness checks that its last stage's top value by
    IQM (what confirm --top 1 retrains) is the value the stage selected: a value whose other
    seed failed can rank first but is never selected, and the harness stops there. A pick's
    answer against the campaign's is ks.compare's, read from the pick's side."""
    from conftest import sqlite_url
    from synthetic import Run, add_sweep

    from kraby_study.records.stored import Outcome
    from kraby_study.store.store import Store

    sys.path.insert(0, str(BENCHMARKS))
    import bench_methods as bm

    url = sqlite_url(tmp_path / "k.db")
    store = Store(url)
    try:
        for repetition, failed in ((0, True), (1, False)):
            add_sweep(store, f"leg-campaign-r{repetition}-ent_coef", "ppo.ent_coef", [0.0, 0.01], [
                Run(0.0, 0, final_score=-0.1),
                Run(0.0, 1, outcome=Outcome.FAILED) if failed else Run(0.0, 1, final_score=-0.12),
                Run(0.01, 0, final_score=-0.3), Run(0.01, 1, final_score=-0.31)])
    finally:
        store.close()
    ctx = bm.Context(url, 1, [], [], 10, "leg")
    with pytest.raises(SystemExit, match=r"top value by IQM is 0 \(1 complete seed\(s\)\), "
                                         r"not its selected 0.01"):
        bm.check_campaign_top(ctx, bm.Arm("campaign", 0, "leg", ("ent_coef",)))
    bm.check_campaign_top(ctx, bm.Arm("campaign", 1, "leg", ("ent_coef",)))

    high, low = [1.0, 1.1, 0.9, 1.0, 1.05, 0.95], [0.5, 0.55, 0.45, 0.5, 0.52, 0.48]
    assert bm.against(high, low, 0.2, 0.05) == "better"
    assert bm.against(low, high, 0.2, 0.05) == "worse"
    assert bm.against(high, [h + 0.01 for h in high], 0.2, 0.05) == "equivalent"
    assert bm.against(high[:2], low[:2], 0.2, 0.05) == "undecided"  # below 4 seeds, by rule


EXPERIMENTS = sorted(path.name for path in (ROOT / "experiments").glob("*.py"))


@slow
@pytest.mark.parametrize("script", EXPERIMENTS)
def test_experiment_still_starts(script: str, tmp_path: Path) -> None:
    """The one-off analyses in experiments/ need the stores of their experiment to run; each
    still imports what it uses and parses its arguments, and is listed in the folder's index."""
    result = subprocess.run([sys.executable, str(ROOT / "experiments" / script), "--help"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert f"`{script}`" in (ROOT / "experiments/README.md").read_text()


def surrogate_data(url: str) -> None:
    """A store of measured leg runs as searches store them (a trial's resolved settings, its
    seeds' scores, its CPU): 40 configurations of the leg's search space, 2 seeds each, on a
    landscape where the default observation costs 0.15 and a learning rate away from 1e-3
    costs 0.05 a decade."""
    import optuna

    import kraby_study as ks
    from kraby_study.plan.settings import resolved_settings
    from kraby_study.plan.space import apply_params

    cfg = ks.compose(["budget.steps=20480"], command="search").cfg
    rng = random.Random(3)
    study = optuna.create_study(study_name="measured", storage=url, direction="maximize")
    for _ in range(40):
        params = {"observation": rng.choice(["default", "with_tip", "sin_angles"]),
                  "n_steps": rng.choice([32, 64, 128]), "nminibatches": rng.choice([1, 4, 8]),
                  "n_epochs": rng.randint(1, 50), "gamma": rng.uniform(0.2, 0.99),
                  "clip_range": rng.uniform(0.1, 0.4),
                  "learning_rate": 10 ** rng.uniform(-4, -1), "gae_lambda": rng.uniform(0.8, 1),
                  "ent_coef": 10 ** rng.uniform(-8, -1)}
        settings = resolved_settings(apply_params(cfg, params))
        mean = (-0.02 - 0.15 * (params["observation"] == "default")
                - 0.05 * abs(math.log10(params["learning_rate"]) + 3))
        scores = [mean + rng.gauss(0, 0.005) for _ in range(2)]
        study.add_trial(optuna.trial.create_trial(
            value=statistics.fmean(scores), user_attrs={
                "settings": settings, "scores": scores, "steps": 20480,
                "cpu_time": 2 * (0.5 + params["n_epochs"] / 50)}))


@slow
def test_racing_sampler_races_each_sampler_on_a_surrogate_of_the_measured_runs(
        tmp_path: Path) -> None:
    """The surrogate ranks configurations as the measured runs do, gives one configuration's
    seed the same score whichever search asks (and another seed another), and each arm's
    racing search (a sampler, with overrides after +) spends its CPU budget on it and is
    scored by its pick's surrogate mean; a bad arm is refused in one line before any work."""
    import csv

    sys.path.insert(0, str(BENCHMARKS))
    import bench_racing_sampler as bench

    url = f"sqlite:///{tmp_path / 'measured.db'}"
    surrogate_data(url)
    runs = bench.measured_runs(url, 20480)
    assert len(runs) == 40 and all(len(r.scores) == 2 for r in runs.values())
    surrogate = bench.Surrogate(runs, trees=50)
    rho, n = surrogate.cross_validated()
    assert n == 40 and rho > 0.6
    settings = next(iter(runs.values())).settings
    assert surrogate.score(settings, 5, 0) == surrogate.score(settings, 5, 0)
    assert surrogate.score(settings, 5, 0) != surrogate.score(settings, 6, 0)

    out = tmp_path / "rows.csv"
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / "bench_racing_sampler.py"), "--data", url,
         "--cpu-budget", "30", "--repetitions", "1", "--arms", "tpe",
         "random+racing.below=look",
         "--trees", "50", "--out", str(out)],
        cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]
    assert ("bench_racing_sampler: tpe - random+racing.below=look worth difference"
            in result.stdout)
    rows = list(csv.DictReader(out.open()))
    assert [r["arm"] for r in rows] == ["tpe", "random+racing.below=look"]
    lowest = min(surrogate.mean(r.settings) for r in runs.values())
    for row in rows:
        assert float(row["cpu"]) >= 30 and int(row["runs"]) >= 4
        assert int(row["seeds"]) >= 4 and lowest - 0.01 <= float(row["worth"]) <= 0
    # A rerun with more repetitions reads the searches already in --out and runs the rest.
    again = subprocess.run(
        [sys.executable, str(BENCHMARKS / "bench_racing_sampler.py"), "--data", url,
         "--cpu-budget", "30", "--repetitions", "2", "--arms", "tpe",
         "random+racing.below=look", "--trees", "50", "--out", str(out)],
        cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert again.returncode == 0, (again.stdout + again.stderr)[-3000:]
    assert again.stdout.count(f"(read from {out})") == 2
    more = list(csv.DictReader(out.open()))
    assert more[:2] == rows and [(r["arm"], r["repetition"]) for r in more[2:]] == [
        ("tpe", "1"), ("random+racing.below=look", "1")]
    assert ", 2 repetitions), exact two-sided Wilcoxon" in again.stdout
    other = subprocess.run(
        [sys.executable, str(BENCHMARKS / "bench_racing_sampler.py"), "--data", url,
         "--cpu-budget", "40", "--repetitions", "1", "--arms", "tpe", "random",
         "--trees", "50", "--out", str(out)],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert other.returncode == 1 and "holds searches of another setup" in other.stderr
    assert len(other.stderr.strip().splitlines()) == 1
    assert list(csv.DictReader(out.open())) == more
    for arm, message in [("annealing", "arm 'annealing': a sampler (tpe, gp, random)"),
                         ("tpe+racing.below=soon", "racing.below must be one of cap, look")]:
        bad = subprocess.run(
            [sys.executable, str(BENCHMARKS / "bench_racing_sampler.py"), "--data", url,
             "--cpu-budget", "30", "--arms", "tpe", arm, "--out", str(tmp_path / "no.csv")],
            cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert bad.returncode == 2 and message in bad.stderr
        assert not (tmp_path / "no.csv").exists()
