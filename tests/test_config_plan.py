"""Composing every config, refusing bad ones, and expanding studies into trial specs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import write_study_file

from kraby_study.config.compose import compose_config
from kraby_study.errors import ConfigError
from kraby_study.plan.sweep import expand_study
from kraby_study.plan.train import train_plan
from kraby_study.records.stored import sweep_key, train_key

CONF = Path(__file__).resolve().parents[1] / "conf"
STUDY_FILES = sorted((CONF / "study").glob("*.yaml"))


def read_yaml(path: Path) -> dict[str, Any]:
    return yaml.safe_load(path.read_text())


def budget(name: str) -> dict[str, Any]:
    """A budget file: name, steps, seeds, curve_every."""
    return read_yaml(CONF / "budget" / f"{name}.yaml")


def study(name: str) -> dict[str, Any]:
    """The ``study:`` block of a study file: name, parameter, values."""
    return read_yaml(CONF / "study" / f"{name}.yaml")["study"]


def test_every_study_file_is_named_after_its_file() -> None:
    assert STUDY_FILES
    for path in STUDY_FILES:
        assert read_yaml(path)["study"]["name"] == path.stem, path.name


@pytest.mark.parametrize("name", [p.stem for p in STUDY_FILES])
def test_every_study_composes_and_expands_to_values_times_seeds(name: str) -> None:
    declared, full = study(name), budget("full")  # the default budget
    seeds = [read_yaml(CONF / "config.yaml")["seed"] + i for i in range(full["seeds"])]
    plan = expand_study(compose_config([f"study={name}"]))
    assert (plan.name, plan.parameter) == (name, declared["parameter"])
    assert plan.values == declared["values"]
    assert len(plan.specs) == len(declared["values"]) * full["seeds"]
    assert {s.steps for s in plan.specs} == {full["steps"]}
    assert {s.curve_every for s in plan.specs} == {full["curve_every"]}
    assert sorted({s.seed for s in plan.specs}) == seeds
    # One key per (value, seed), naming the value's index in the file; keys never repeat.
    assert len({s.key for s in plan.specs}) == len(plan.specs)
    assert {s.key: (s.value, s.seed) for s in plan.specs} == {
        sweep_key(i, seed): (value, seed)
        for i, value in enumerate(declared["values"]) for seed in seeds}
    # Each run trains with its value.
    root, leaf = declared["parameter"].split(".")
    for spec in plan.specs:
        assert spec.settings[root][leaf] == spec.value, spec.key


def test_budget_sets_steps_and_seeds() -> None:
    smoke = budget("smoke")
    plan = expand_study(compose_config(["study=gamma", "budget=smoke", "seed=5"]))
    assert len(plan.specs) == len(study("gamma")["values"]) * smoke["seeds"]
    assert {s.seed for s in plan.specs} == set(range(5, 5 + smoke["seeds"]))
    assert {s.steps for s in plan.specs} == {smoke["steps"]}
    assert {s.curve_every for s in plan.specs} == {smoke["curve_every"]}


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
    cfg = compose_config(["study=gamma", "ppo.n_steps=64"])  # the file sets n_steps 32
    assert cfg.ppo.n_steps == 64
    plan = expand_study(cfg)
    for spec in plan.specs:  # the runs train with it (one minibatch: the whole rollout)
        ppo = spec.settings["ppo"]
        assert (ppo["n_steps"], ppo["batch_size"]) == (64, 64 * ppo["n_envs"])
    # Another definition: the store refuses to mix it with the study's runs at n_steps 32.
    assert plan.fingerprint != expand_study(compose_config(["study=gamma"])).fingerprint


def test_observation_study_sweeps_the_environment() -> None:
    plan = expand_study(compose_config(["study=observation", "budget=smoke"]))
    assert [s.settings["env"]["observation"] for s in plan.specs[::budget("smoke")["seeds"]]] == [
        "default", "with_tip", "with_tip_to_target", "sin_angles"]


def test_train_plan_is_one_run_named_by_its_settings() -> None:
    a = train_plan(compose_config(["ppo=tuned", "seed=3"]))
    b = train_plan(compose_config(["ppo=tuned", "seed=4"]))
    c = train_plan(compose_config(["ppo=tuned", "ppo.gamma=0.5"]))
    d = train_plan(compose_config(["ppo=tuned", "seed=3", "budget.steps=8192"]))
    assert len(a.specs) == 1
    (run,) = a.specs
    assert (run.seed, run.key, run.study) == (3, train_key(3), a.name)
    assert run.steps == budget("full")["steps"]
    assert run.settings["ppo"]["gamma"] == compose_config(["ppo=tuned"]).ppo.gamma
    assert c.specs[0].settings["ppo"]["gamma"] == 0.5
    # Seeds of the same settings and budget share a study; other settings or budgets do not.
    assert a.name == b.name != c.name
    assert d.name != a.name and d.specs[0].steps == 8192


@pytest.mark.parametrize("overrides,expected", [
    (["ppo.ent_coeff=0.1"], "ent_coeff"),
    (["ppo.n_steps=abc"], "abc"),
    (["ppo.learning_rate=-1"], "learning_rate"),
    (["ppo.gamma=1.5"], "gamma"),
    (["ppo.batch_size=1000"], "does not divide"),
    (["workers=0"], "workers"),
    (["shards=0"], "shards"),
    (["study=nope"], "study/nope"),
    (["budget.seeds=0"], "budget.seeds"),
    (["env.delta=2"], "delta"),
    (["env.observation=camera"], "observation"),
    (["storage=mysql://u@h/db"], "sqlite and postgresql"),
    (["hydra.run.dir=out"], "hydra.run.dir=out: Hydra's own settings do nothing here"),
    (["+hydra.job.chdir=true"], "+hydra.job.chdir=true: Hydra's own settings"),
    (["hydra/launcher=basic"], "hydra/launcher=basic: Hydra's own settings"),
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
    assert {(s.value, s.settings["ppo"]["vf_coef"]) for s in plan.specs} == {
        (0.25, 0.25), (0.5, 0.5), (1.0, 1.0)}


def test_a_study_value_that_breaks_a_rule_names_the_value(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write_study_file(tmp_path, "bad", "ppo.batch_size", "[64, 100]")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match="value 100"):
        expand_study(compose_config(["study=bad"]))
