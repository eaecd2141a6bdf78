"""A budget too short for the env is refused before any work: a run whose last 10 % cannot hold
the end of an episode of the env's full time limit would have no final score."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from conftest import file_digest, run_cli

from kraby_study.config.compose import compose_config
from kraby_study.config.validate import scores_a_full_episode, steps_per_env
from kraby_study.errors import ConfigError
from kraby_study.plan.sweep import expand_study
from kraby_study.plan.train import train_plan

TESTS = Path(__file__).parent
PENDULUM = ["env=gym", "env.id=Pendulum-v1"]
SMALL = ["ppo.n_steps=64", "ppo.n_epochs=2", "ppo.net_arch=[8]", "save_models=false",
         "workers=1"]
SMOKE_REFUSAL = ("budget.steps=4096 with ppo.n_envs=32 is 128 steps per env, and no episode "
                 "of the full 200 steps (Pendulum-v1's time limit) can end in the last 10 % of "
                 "them (steps 116-128), where the final score is taken: give budget.steps=6400 "
                 "(or any from 64000 on) with ppo.n_envs=32")


@pytest.mark.parametrize(("steps", "n_envs", "limit", "scored"), [
    (4096, 32, 32, True),     # the leg at budget=smoke: 128 steps per env, 4 episodes
    (4000, 32, 32, False),    # 125 steps per env: the 4th episode would end at 128
    (4096, 32, 200, False),   # Pendulum-v1 at budget=smoke (issue 40)
    (6400, 32, 200, True),    # 200 steps per env: the one episode ends at the last step
    (6368, 32, 200, False),   # 199 steps per env
    (6369, 32, 200, True),    # 200 steps per env: SB3 steps every env to past the budget
    (9600, 32, 200, False),   # 300 steps per env: the 2nd episode would end at 400
    (64000, 32, 200, True),   # 10 time limits per env always pass
    (1024, 2, 500, True),     # CartPole-v1 in the slow tests: 512 steps per env
])
def test_a_run_scores_when_a_full_episode_can_end_in_its_last_10_percent(
        steps: int, n_envs: int, limit: int, scored: bool) -> None:
    assert scores_a_full_episode(steps, n_envs, limit) is scored


def test_every_env_steps_to_the_budget_or_past_it() -> None:
    assert [steps_per_env(s, 32) for s in (6368, 6369, 6400, 6401)] == [199, 200, 200, 201]


def test_the_rule_is_what_the_final_score_counts(monkeypatch: pytest.MonkeyPatch) -> None:
    """On an env that only truncates (10-step episodes), a run gets a finite score exactly
    when the check lets it through: 9 and 12 steps per env have none, 10 and 11 one."""
    from kraby_study.plan.settings import resolved_settings
    from kraby_study.plan.spec import TrialSpec
    from kraby_study.run.trial import run_trial

    monkeypatch.syspath_prepend(str(TESTS))
    tiny = ["env=gym", "env.id=KrabyTestTiny-v0", "env.packages=[gym_fixtures]",
            "ppo.n_envs=2", "ppo.n_steps=64", "ppo.n_epochs=1", "ppo.net_arch=[8]"]
    for per_env in (9, 10, 11, 12):
        cfg = compose_config([*tiny, f"budget.steps={2 * per_env}"])
        checked = scores_a_full_episode(2 * per_env, 2, 10)
        if checked:
            train_plan(cfg)
        else:
            with pytest.raises(ConfigError, match=f"is {per_env} steps per env"):
                train_plan(cfg)
        spec = TrialSpec(study="t", key="s0", seed=0, steps=2 * per_env, curve_every=4,
                         settings=resolved_settings(cfg))
        result = run_trial(spec)
        assert (result.final_score is not None and math.isfinite(result.final_score)) \
            is checked, (per_env, result.failure)
        if not checked:
            assert "no finite score" in str(result.failure)


@pytest.mark.parametrize("overrides", [
    [*PENDULUM, "budget=smoke"],
    [*PENDULUM, "budget=smoke", "budget.steps=9600"],
    [*PENDULUM, "budget=smoke", "ppo.n_envs=16"],
    ["budget=smoke", "budget.steps=4000"],
    ["budget=smoke", "budget.steps=1000", "ppo.n_envs=8", "env.max_episode_steps=50"],
    ["env=gym", "env.id=CartPole-v1", "budget=smoke", "ppo.n_envs=8", "budget.steps=1024"],
])
def test_the_refusal_names_settings_that_work(overrides: list[str]) -> None:
    cfg = compose_config(["study=gamma", *overrides])
    with pytest.raises(ConfigError) as refused:
        expand_study(cfg)
    message = str(refused.value)
    assert "\n" not in message
    steps = re.search(r"give budget\.steps=(\d+) \(or any from (\d+) on\) with ppo\.n_envs=(\d+)",
                      message)
    assert steps is not None, message
    offers = [[f"budget.steps={steps[1]}"], [f"budget.steps={steps[2]}"]]
    other = re.search(r"or ppo\.n_envs=(\d+) with budget\.steps=(\d+)$", message)
    if other:
        offers.append([f"ppo.n_envs={other[1]}"])
    for offer in offers:
        assert expand_study(compose_config(["study=gamma", *overrides, *offer])).specs


def test_the_evaluation_objective_is_not_refused(workdir: Path) -> None:
    """Its score is the evaluation return, finite however short the run."""
    assert run_cli("optuna", "--trials", "2", *PENDULUM, "budget=smoke",
                   "search.objective=evaluation", "--dry-run") == 0
    with pytest.raises(ConfigError, match="budget.steps=4096 with ppo.n_envs=32"):
        expand_study(compose_config(["study=gamma", *PENDULUM, "budget=smoke"]))


def test_a_too_short_budget_is_refused_by_every_command_and_nothing_is_stored(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (workdir / "conf" / "campaign").mkdir(parents=True)
    (workdir / "conf" / "campaign" / "pend.yaml").write_text(
        "# @package campaign\nname: pend\ndescription: two sweeps\nstart: {}\n"
        "stages:\n  - study: clip_range\n  - study: n_envs\n")
    commands = [["run", "study=gamma"], ["train"], ["optuna", "--trials", "2"],
                ["confirm", "--baseline", "ppo=tuned"], ["run", "campaign=pend"]]

    def refused(*args: str, message: str = SMOKE_REFUSAL) -> None:
        assert run_cli(*args) == 2, args
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err

    for command in commands:
        refused(*command, *PENDULUM, "budget=smoke", *SMALL)
    assert not any(workdir.glob("studies*")), list(workdir.iterdir())
    # The command, in full: another n_envs is offered too.
    refused("run", "study=gamma", *PENDULUM, "budget=smoke",
            message=f"kraby-study: error: {SMOKE_REFUSAL}, or ppo.n_envs=20 with "
                    "budget.steps=4096\n")
    # A campaign's later stage is checked before its first runs: n_envs=64 is 100 steps per env.
    refused("run", "campaign=pend", *PENDULUM, "budget=smoke", "budget.steps=6400", *SMALL,
            message="campaign pend, stage 2 (n_envs), value 64: budget.steps=6400 with "
                    "ppo.n_envs=64 is 100 steps per env")
    # Just above the limit: 200 steps per env, the one 200-step episode ends at the last step.
    assert run_cli("train", *PENDULUM, "budget.steps=400", "ppo.n_envs=2", *SMALL) == 0
    assert re.search(r"complete, final score -\d", capsys.readouterr().out)
    store = workdir / "studies" / "kraby.db"
    before = file_digest(store)
    refused("train", *PENDULUM, "budget.steps=398", "ppo.n_envs=2", *SMALL,
            message="budget.steps=398 with ppo.n_envs=2 is 199 steps per env")
    for command in commands:
        refused(*command, *PENDULUM, "budget=smoke", *SMALL)
    assert file_digest(store) == before
