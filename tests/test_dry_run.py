"""``--dry-run`` (and Hydra's spelling, ``--cfg job``): the composed config, the plan and an
estimate, checked as the real command checks, and nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import TINY, file_digest, run_cli, sqlite_url

from kraby_study.answers.preview import Measured, estimate_line

SWEEP = ["study=clip_range", "study.values=[0.1,0.2]", "budget.seeds=2", "workers=1", *TINY]


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store holding a finished 2 values x 2 seeds smoke sweep."""
    db = tmp_path_factory.mktemp("dry") / "k.db"
    assert run_cli("run", *SWEEP, f"--storage={sqlite_url(db)}") == 0
    return db


def _nothing_written(workdir: Path) -> None:
    assert not any(workdir.iterdir()), list(workdir.iterdir())


@pytest.mark.parametrize("spelling", [["--dry-run"], ["--cfg", "job"]])
def test_a_study_with_no_store_prints_its_config_and_plan_and_creates_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str], spelling: list[str]) -> None:
    assert run_cli("run", *SWEEP, *spelling) == 0
    out = capsys.readouterr().out
    assert "\nstudy:\n" in out and "parameter: ppo.clip_range" in out
    assert "clip_range: 4 trials (2 values x 2 seeds), 512 env steps each, 2,048 in all" in out
    assert "0 trials complete, 4 to run" in out
    assert "no estimate: this store has no complete trial to measure steps/s from" in out
    _nothing_written(workdir)


def test_an_empty_store_file_reads_as_no_store(workdir: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    empty = workdir / "empty.db"
    empty.touch()
    assert run_cli("run", *SWEEP, "--storage", sqlite_url(empty), "--dry-run") == 0
    assert "not in the store yet: 0 trials complete, 4 to run" in capsys.readouterr().out
    assert empty.stat().st_size == 0


def test_a_finished_study_counts_its_stored_runs_and_estimates_from_them(
        workdir: Path, finished: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = file_digest(finished)
    url = sqlite_url(finished)
    capsys.readouterr()
    assert run_cli("run", *SWEEP, "--storage", url, "--dry-run") == 0
    out = capsys.readouterr().out
    assert "in the store: 4 trials complete, 0 failed, 0 pruned; 0 to run" in out
    assert "nothing left to run" in out
    # A wider sweep of the same store: the rest estimated from the 4 measured trials.
    assert run_cli("run", "study=gamma", *TINY, "budget.seeds=2", "workers=1", "--storage", url,
                   "--dry-run") == 0
    out = capsys.readouterr().out
    assert "not in the store yet" in out
    estimate = out.strip().splitlines()[-1]
    assert estimate.startswith("about ") and "env steps/s per worker x 1 worker" in estimate
    assert estimate.endswith("measured over 4 trials of this store")
    # Another definition under the stored name is refused, as the real command refuses it.
    assert run_cli("run", *SWEEP, "study.values=[0.1,0.3]", "--storage", url,
                   "--dry-run") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "was defined differently" in err
    assert file_digest(finished) == before
    _nothing_written(workdir)


def test_optuna_and_confirm_dry_runs(workdir: Path, finished: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    before = file_digest(finished)
    url = sqlite_url(finished)
    capsys.readouterr()
    # 1024 steps on the leg's 32 envs: 32 each, one whole episode (512 would hold none).
    assert run_cli("optuna", "--trials", "6", "budget=smoke", "budget.steps=1024",
                   "budget.seeds=2", "--storage", url, "--workers", "2", "--dry-run") == 0
    out = capsys.readouterr().out
    assert "\nsearch:\n" in out
    assert ("ppo_search: 6 trials (search.trials, each 2 seeds x 1,024 env steps), 2,048 env "
            "steps each, 12,288 in all") in out
    assert "x 2 workers, measured over 4 trials" in out
    assert "\n  sampler tpe (search.seed 0; its model from trial 5 on), pruner median\n" in out
    # A CPU budget ends a search long before its trials would: the plan leads with it, and
    # the estimate times its CPU seconds at the CPU s per second the store's workers used.
    for racing in ([], ["--racing"]):
        assert run_cli("optuna", *racing, "--trials", "100000", "budget=smoke",
                       "budget.steps=1024", "budget.seeds=4", "search.cpu_budget=30",
                       "--storage", url, "--workers", "2", "--dry-run") == 0
        out = capsys.readouterr().out
        assert "ppo_search: until its 30 CPU s (search.cpu_budget) are used, at most " in out
        assert "\n  30 CPU s left to spend (the sampler's included)" in out
        line = next(x for x in out.splitlines() if x.startswith("ppo_search: "))
        assert "in all" not in line, line  # no count of env steps a budget never trains
        estimate = out.strip().splitlines()[-1]
        assert estimate.startswith("about ") and ": 30 CPU s at " in estimate, estimate
        assert estimate.endswith("CPU s/s per worker x 2 workers, measured over 4 trials of "
                                 "this store"), estimate
    # The pruner named is the one the search would use: none by default with the gp sampler.
    assert run_cli("optuna", "--trials", "6", "budget=smoke", "--storage", url,
                   "--sampler", "gp", "--seed", "3", "--dry-run") == 0
    out = capsys.readouterr().out
    assert ("\n  sampler gp (search.seed 3; its model after 5 complete trials), pruner none\n"
            in out)
    # A race needs 4 seeds a value before its first look.
    assert run_cli("confirm", "--study-name", "clip_range", "--top", "2", "--seeds", "4",
                   "--storage", url, "ppo.n_envs=4",  # the baseline's: 32 legs hold no episode
                   "--baseline", "ppo=tuned", "--cfg", "job", "--racing") == 0
    out = capsys.readouterr().out
    assert "clip_range-confirm: at most 12 trials (3 configurations x 4 seeds)" in out
    assert file_digest(finished) == before
    _nothing_written(workdir)


@pytest.mark.parametrize("args", [["run", "study=clip_range", "ppo.n_epochs=0", "--dry-run"],
                                  ["confirm", "--study-name", "nowhere", "--dry-run"],
                                  ["optuna", "--trials", "0", "--cfg", "job"]])
def test_bad_input_is_still_refused_in_one_line(
        workdir: Path, capsys: pytest.CaptureFixture[str], args: list[str]) -> None:
    try:
        code = run_cli(*args)
    except SystemExit as stop:  # refused by the argument parser
        code = int(stop.code or 0)
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error:" in err
    _nothing_written(workdir)


def test_a_campaign_names_the_inputs_its_earlier_stages_will_decide(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("run", "campaign=documented", "--dry-run") == 0
    out = capsys.readouterr().out
    assert "\ncampaign:\n" in out
    assert "documented-observation: 40 trials (4 values x 10 seeds)" in out
    assert "stage 2/9 (ppo.batch_size, select final_score)" in out
    assert "from earlier stages: env.observation from stage 1 (observation), not selected yet" \
        in out
    assert "in all: 540 trials" in out
    _nothing_written(workdir)


def test_the_estimate_reads_as_documented() -> None:
    measured = Measured(trials=80, env_steps=5_100 * 1_000, wall_time=1_000.0)
    assert estimate_line(12 * 60 * 5_100 * 2, measured, 2) == (
        "about 12 min at 5,100 env steps/s per worker x 2 workers, measured over 80 trials of "
        "this store")
    assert estimate_line(100, Measured(), 2).startswith("no estimate:")
    # A CPU-budgeted search: 1,560 CPU s at 0.65 CPU s per second of each of 2 workers.
    timed = Measured(trials=80, env_steps=5_100 * 1_000, wall_time=1_000.0, cpu_wall=1_000.0,
                     cpu_time=650.0)
    assert estimate_line(0, timed, 2, cpu_left=1_560.0) == (
        "about 20 min: 1,560 CPU s at 0.65 CPU s/s per worker x 2 workers, measured over 80 "
        "trials of this store")
    assert estimate_line(0, measured, 2, cpu_left=1_560.0) == (
        "no estimate: this store has no complete trial that stored its CPU seconds")
