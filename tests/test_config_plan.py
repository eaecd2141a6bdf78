"""Composing every config, refusing bad ones, and expanding studies into trial specs."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import write_study_file

from kraby_study.compose import compose_config
from kraby_study.config import ConfigError
from kraby_study.plan import expand_study, single_run

STUDIES = {
    "observation": 4, "batch_size": 8, "n_steps": 7, "n_epochs": 6, "gamma": 8,
    "clip_range": 4, "learning_rate": 5, "gae_lambda": 7, "ent_coef": 5, "n_envs": 4,
}


def test_every_study_file_is_listed_here() -> None:
    conf = Path(__file__).resolve().parents[1] / "conf" / "study"
    assert {p.stem for p in conf.glob("*.yaml")} == set(STUDIES)


@pytest.mark.parametrize("name,n_values", sorted(STUDIES.items()))
def test_every_study_composes_and_expands_to_values_times_seeds(name: str,
                                                                 n_values: int) -> None:
    cfg = compose_config([f"study={name}"])
    plan = expand_study(cfg)
    assert len(plan.values) == n_values
    assert len(plan.specs) == n_values * 10
    assert {s.steps for s in plan.specs} == {250_000}
    assert len({s.key for s in plan.specs}) == len(plan.specs)
    assert sorted({s.seed for s in plan.specs}) == list(range(10))


def test_budget_sets_steps_and_seeds() -> None:
    plan = expand_study(compose_config(["study=gamma", "budget=smoke", "seed=5"]))
    assert len(plan.specs) == 8 * 2
    assert {s.seed for s in plan.specs} == {5, 6}
    assert {s.steps for s in plan.specs} == {4096}


def test_batch_size_study_uses_and_stores_the_documented_batches() -> None:
    plan = expand_study(compose_config(["study=batch_size"]))
    batches = sorted({s.settings["ppo"]["batch_size"] for s in plan.specs})
    assert batches == [32, 64, 128, 256, 512, 1024, 2048, 4096]
    for spec in plan.specs:
        ppo = spec.settings["ppo"]
        assert ppo["n_steps"] * ppo["n_envs"] == 4096
        assert spec.value == ppo["batch_size"]


def test_one_minibatch_studies_resolve_the_batch_to_the_whole_rollout() -> None:
    plan = expand_study(compose_config(["study=n_steps"]))
    for spec in plan.specs:
        assert spec.settings["ppo"]["batch_size"] == spec.value * 32
    plan = expand_study(compose_config(["study=n_envs"]))
    for spec in plan.specs:
        assert spec.settings["ppo"]["batch_size"] == 32 * spec.value


def test_studies_fix_the_documented_settings() -> None:
    spec = expand_study(compose_config(["study=ent_coef"])).specs[0]
    ppo = spec.settings["ppo"]
    assert (ppo["n_steps"], ppo["batch_size"], ppo["n_epochs"], ppo["gamma"],
            ppo["clip_range"], ppo["learning_rate"], ppo["gae_lambda"]) == (
        32, 1024, 30, 0.8, 0.2, 0.01, 0.95)
    tuned = compose_config(["ppo=tuned"]).ppo
    assert dict(tuned) == dict(compose_config(["study=n_envs"]).ppo)


def test_overrides_apply_after_the_study_file() -> None:
    cfg = compose_config(["study=gamma", "ppo.n_steps=64"])
    assert cfg.ppo.n_steps == 64


def test_observation_study_sweeps_the_environment() -> None:
    plan = expand_study(compose_config(["study=observation", "budget=smoke"]))
    assert [s.settings["env"]["observation"] for s in plan.specs[::2]] == [
        "default", "with_tip", "with_tip_to_target", "sin_angles"]


def test_train_plan_is_one_run_named_by_its_settings() -> None:
    a = single_run(compose_config(["ppo=tuned", "seed=3"]))
    b = single_run(compose_config(["ppo=tuned", "seed=4"]))
    c = single_run(compose_config(["ppo=tuned", "ppo.gamma=0.5"]))
    assert len(a.specs) == 1 and a.specs[0].seed == 3
    assert a.name == b.name != c.name


@pytest.mark.parametrize("overrides,expected", [
    (["ppo.ent_coeff=0.1"], "ent_coeff"),
    (["ppo.n_steps=abc"], "abc"),
    (["ppo.learning_rate=-1"], "learning_rate"),
    (["ppo.gamma=1.5"], "gamma"),
    (["ppo.batch_size=1000"], "does not divide"),
    (["workers=0"], "workers"),
    (["physics_processes=0"], "physics_processes"),
    (["study=nope"], "study/nope"),
    (["budget.seeds=0"], "budget.seeds"),
    (["env.delta=2"], "delta"),
    (["env.observation=camera"], "observation"),
    (["storage=mysql://u@h/db"], "sqlite and postgresql"),
])
def test_bad_config_is_refused_in_one_line(overrides: list[str], expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        compose_config(overrides)
    assert expected in str(err.value)
    assert "\n" not in str(err.value)


def test_a_study_value_of_the_wrong_type_is_refused(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    write_study_file(tmp_path, "mine", "ppo.n_epochs", "[1, lots]")
    monkeypatch.chdir(tmp_path)
    cfg = compose_config(["study=mine"])
    with pytest.raises(ConfigError, match="lots"):
        expand_study(cfg)


def test_a_user_study_file_in_the_working_directory_is_found(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write_study_file(tmp_path, "vf", "ppo.vf_coef", "[0.25, 0.5, 1.0]", "ppo:\n  n_steps: 32\n")
    monkeypatch.chdir(tmp_path)
    plan = expand_study(compose_config(["study=vf", "budget=smoke"]))
    assert plan.values == [0.25, 0.5, 1.0]
    assert {s.settings["ppo"]["n_steps"] for s in plan.specs} == {32}


def test_a_study_value_that_breaks_a_rule_names_the_value(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write_study_file(tmp_path, "bad", "ppo.batch_size", "[64, 100]")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match="value 100"):
        expand_study(compose_config(["study=bad"]))
