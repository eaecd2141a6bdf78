"""ppo=zoo and budget=zoo: rl-zoo3's published PPO settings, read as data and translated once."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest
import synthetic
import yaml
from conftest import run_cli, sqlite_url
from synthetic import Run, add_sweep

from kraby_study.config import zoo
from kraby_study.config.compose import compose_config
from kraby_study.errors import ConfigError
from kraby_study.plan.settings import resolved_settings
from kraby_study.plan.space import apply_params, fitted_params, outside_space, validate_search
from kraby_study.plan.spec import OPTIONAL_PPO, TrialSpec
from kraby_study.records.stored import Outcome
from kraby_study.store.store import Store

CLASSIC = ["Pendulum-v1", "CartPole-v1", "MountainCar-v0", "MountainCarContinuous-v0",
           "Acrobot-v1"]
"""Every classic-control id of rl-zoo3's ppo.yml."""


def zoo_config(env_id: str, *more: str):  # noqa: ANN201 - a DictConfig
    return compose_config(["env=gym", f"env.id={env_id}", "ppo=zoo", *more])


def test_the_classic_control_entries_are_all_there() -> None:
    classic = [i for i in zoo.entries() if i.split("-")[0] in
               {"Pendulum", "CartPole", "MountainCar", "MountainCarContinuous", "Acrobot"}]
    assert sorted(classic) == sorted(CLASSIC)


def test_pendulum_reads_as_published() -> None:
    cfg = zoo_config("Pendulum-v1", "budget=zoo")
    ppo = cfg.ppo
    assert (ppo.n_envs, ppo.n_steps, ppo.n_epochs, ppo.gamma, ppo.gae_lambda) == \
        (4, 1024, 10, 0.9, 0.95)
    assert (ppo.learning_rate, ppo.ent_coef, ppo.clip_range) == (1e-3, 0.0, 0.2)
    assert ppo.use_sde is True and ppo.sde_sample_freq == 4
    assert ppo.batch_size == 64 and ppo.vf_coef == 0.5 and list(ppo.net_arch) == [64, 64]
    assert cfg.env.normalize is False
    assert (cfg.budget.steps, cfg.budget.seeds, cfg.budget.curve_every) == (100_000, 10, 2000)


def test_schedules_policy_kwargs_and_normalize_translate() -> None:
    cart = zoo_config("CartPole-v1").ppo
    assert (cart.learning_rate, cart.learning_rate_schedule) == (1e-3, "linear")
    assert (cart.clip_range, cart.clip_range_schedule) == (0.2, "linear")
    assert cart.batch_size is None  # 256 = the rollout 32 x 8: one minibatch
    car = zoo_config("MountainCarContinuous-v0")
    assert car.env.normalize is True and car.env.normalize_reward is True
    assert car.ppo.log_std_init == -3.29 and car.ppo.ortho_init is False
    # batch 256 over a rollout of 8: SB3 trains the whole rollout as one minibatch.
    assert car.ppo.batch_size is None and resolved_settings(car)["ppo"]["batch_size"] == 8
    assert zoo_config("Acrobot-v1").env.normalize is True


def test_a_command_override_wins_over_the_zoo() -> None:
    assert zoo_config("Pendulum-v1", "ppo.n_epochs=3").ppo.n_epochs == 3


@pytest.mark.parametrize(("entry", "named"), [
    ({"policy": "CnnPolicy"}, "policy CnnPolicy"),
    ({"env_wrapper": ["a.B"], "frame_stack": 4}, "env_wrapper"),
    ({"learning_rate": "cos_0.1"}, "learning_rate: 'cos_0.1'"),
    ({"learning_rate": "lin_abc"}, "learning_rate: 'lin_abc'"),
    ({"policy_kwargs": "dict(full_std=False)"}, "policy_kwargs full_std=False"),
    ({"policy_kwargs": "dict(activation_fn=nn.GELU)"}, "activation_fn='nn.GELU'"),
    ({"policy_kwargs": "dict(net_arch=dict(pi=[64], vf=[32]))"}, "net_arch="),
    ({"policy_kwargs": "__import__('os').system('touch /tmp/zoo_evaluated')"},
     "only numbers, booleans, lists, dicts"),
    ({"normalize": "{'norm_obs': False, 'norm_reward': True}"}, "without the observations"),
    ({"n_envs": 3, "n_steps": 10, "batch_size": 4}, "does not divide its rollout"),
])
def test_what_the_schema_cannot_express_is_refused_by_name(entry: dict, named: str) -> None:
    with pytest.raises(ConfigError, match="schema cannot express") as caught:
        zoo.translate("X-v0", entry)
    assert named in str(caught.value) and "\n" not in str(caught.value)
    assert not Path("/tmp/zoo_evaluated").exists()


def test_an_id_without_an_entry_and_a_leg_config_are_refused_in_one_line() -> None:
    with pytest.raises(ConfigError, match="publishes no PPO settings for 'HalfCheetah-v5'"):
        zoo_config("HalfCheetah-v5")
    with pytest.raises(ConfigError, match="ppo=zoo is rl-zoo3's settings for a Gymnasium id"):
        compose_config(["ppo=zoo"])
    with pytest.raises(ConfigError, match="choose env=gym env.id=ID"):
        compose_config(["budget=zoo"])


def test_without_rl_zoo3_the_extra_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    real = zoo.importlib.util.find_spec
    monkeypatch.setattr(zoo.importlib.util, "find_spec",
                        lambda name, *a: None if name == "rl_zoo3" else real(name, *a))
    zoo.entries.cache_clear()
    try:
        with pytest.raises(ConfigError, match=r"pip install 'kraby-study\[zoo\]'"):
            zoo_config("Pendulum-v1")
    finally:
        zoo.entries.cache_clear()


def test_best_zoo_writes_what_was_read(workdir: Path) -> None:
    assert run_cli("best", "--zoo", "env=gym", "env.id=CartPole-v1") == 0
    written = workdir / "conf" / "ppo" / "zoo_CartPole-v1.yaml"
    body = yaml.safe_load(written.read_text())
    assert body["ppo"]["learning_rate_schedule"] == "linear" and body["ppo"]["n_envs"] == 8
    loaded = compose_config(["env=gym", "env.id=CartPole-v1", "ppo=zoo_CartPole-v1"])
    assert resolved_settings(loaded) == resolved_settings(zoo_config("CartPole-v1"))


EVERY_KIND = {"normalize": zoo.NORM_REWARD_OFF, "n_envs": 2, "n_timesteps": 3000,
              "policy": "MlpPolicy", "n_steps": 64, "batch_size": 32, "learning_rate": "lin_3e-4",
              "clip_range": "lin_0.3", "use_sde": True, "sde_sample_freq": 8,
              "policy_kwargs": "dict(log_std_init=-2, ortho_init=False, "
                               "activation_fn=nn.ReLU, net_arch=[32, 16])"}
"""An entry using every key and string the translation reads (no published one does)."""


def _means_the_same(key: str, written: Any, published: Any) -> bool:
    """Whether a written value is a published one up to formatting (1e-3 and 0.001, a float
    and an int of the same value, spaces in a dict(...) string)."""
    if isinstance(published, str) or isinstance(written, str):
        return str(written).replace(" ", "") == str(published).replace(" ", "")
    return float(written) == float(published) if key != "use_sde" else written == published


@pytest.mark.parametrize("env_id", CLASSIC)
def test_the_round_trip_gives_every_classic_control_entry_back(env_id: str) -> None:
    published = zoo.entries()[env_id]
    settings = zoo.translate(env_id, published)
    written = zoo.to_entry(settings)
    # What is compared: translated again, the written entry is the same settings (every ppo
    # setting, normalize, the budget).
    assert zoo.translate(env_id, written) == settings
    # And key by key: every published key is written, meaning the same value ...
    rollout = settings.ppo["n_steps"] * settings.ppo["n_envs"]
    assert set(published) <= set(written)
    for key, value in published.items():
        if key == "batch_size" and value >= rollout:
            # A batch of at least the rollout is one minibatch of it: written as the rollout.
            assert written[key] == rollout, key
        else:
            assert _means_the_same(key, written[key], value), (key, written[key], value)
    # ... and every key rl-zoo3 left out is written at the default it left in force.
    for key in set(written) - set(published):
        assert _means_the_same(key, written[key], zoo.SB3_DEFAULTS[key]), key


@pytest.mark.parametrize("space", ["gym", "gym_sde"])
@pytest.mark.parametrize("env_id", CLASSIC)
def test_the_gym_space_holds_every_classic_control_entry_as_it_is(env_id: str,
                                                                  space: str) -> None:
    """Enqueued first (search.enqueue=[zoo]), rl-zoo3's settings are evaluated as published:
    every searched value lies in the default gym space (and in gym_sde, which adds gSDE's two
    settings), and the trial they make trains the same settings."""
    cfg = zoo_config(env_id, "budget=zoo", f"search={space}")
    settings = resolved_settings(cfg)
    assert outside_space(cfg, settings) == {}
    params = fitted_params(cfg, settings)
    assert set(params) == set(cfg.search.params)
    assert resolved_settings(apply_params(cfg, params)) == settings


def test_a_searched_batch_size_at_or_above_the_rollout_is_the_whole_rollout() -> None:
    cfg = zoo_config("CartPole-v1", "search=gym")  # 8 envs
    params = {"n_steps": 16, "batch_size": 512}
    assert apply_params(cfg, params).ppo.batch_size is None  # one minibatch of 128
    assert apply_params(cfg, {"n_steps": 16, "batch_size": 32}).ppo.batch_size == 32
    validate_search(cfg)
    bad = zoo_config("CartPole-v1", "search=gym",
                     "search.params.batch_size.choices=[24]")
    with pytest.raises(ConfigError, match="batch_size 24 does not divide the rollout 8 x 8"):
        validate_search(bad)
    one = zoo_config("CartPole-v1", "search=gym", "search.params.batch_size.choices=[1]")
    with pytest.raises(ConfigError, match="batch sizes must be whole numbers >= 2"):
        validate_search(one)


def test_the_round_trip_holds_for_every_key_and_string_the_translation_reads() -> None:
    settings = zoo.translate("Pendulum-v1", EVERY_KIND)
    written = zoo.to_entry(settings)
    assert zoo.translate("Pendulum-v1", written) == settings
    assert written["policy_kwargs"] == EVERY_KIND["policy_kwargs"].replace("-2", "-2.0")
    assert (written["normalize"], written["learning_rate"], written["clip_range"]) == \
        (zoo.NORM_REWARD_OFF, "lin_0.0003", "lin_0.3")


@pytest.mark.parametrize(("change", "named"), [
    ({"learning_rate_schedule": "cosine"}, "learning_rate_schedule 'cosine'"),
    ({"activation": "gelu"}, "activation 'gelu'"),
    ({"gamma": None}, "lack gamma"),
])
def test_what_rl_zoo3_cannot_write_is_refused_by_name(change: dict, named: str) -> None:
    read = zoo.zoo_settings("Pendulum-v1")
    ppo = {k: v for k, v in {**read.ppo, **change}.items() if v is not None}
    with pytest.raises(ConfigError, match=named):
        zoo.to_entry(zoo.ZooSettings(read.env_id, ppo, read.env, read.n_timesteps, "x"))


def _loaded_by_rl_zoo3(path: Path, env_id: str, logs: Path) -> tuple[Any, dict[str, Any],
                                                                     dict[str, Any]]:
    """rl-zoo3's own reading of a -conf file: its ExperimentManager's read_hyperparameters,
    then its preprocessing (schedules, policy_kwargs, normalize, n_envs, n_timesteps), as
    rl_zoo3.train does before it builds the model: (manager, as read, as preprocessed)."""
    from rl_zoo3.exp_manager import ExperimentManager

    manager = ExperimentManager(argparse.Namespace(), "ppo", env_id, str(logs),
                                config=str(path))
    read, _ = manager.read_hyperparameters()
    processed, *_ = manager._preprocess_hyperparams(dict(read))
    return manager, dict(read), processed


@pytest.mark.parametrize("env_id", [*CLASSIC, "every kind"])
def test_rl_zoo3_reads_every_key_of_the_written_file(env_id: str, tmp_path: Path) -> None:
    from torch import nn

    settings = (zoo.translate("Pendulum-v1", EVERY_KIND) if env_id == "every kind"
                else zoo.zoo_settings(env_id))
    path = tmp_path / "hyperparams.yml"
    entry = zoo.write_hyperparams(settings, "a test", path)
    manager, read, processed = _loaded_by_rl_zoo3(path, settings.env_id, tmp_path / "logs")
    assert read == entry  # every key written is read, as written
    ppo = settings.ppo
    assert manager.n_envs == ppo["n_envs"] and manager.n_timesteps == settings.n_timesteps
    assert manager.normalize is settings.env["normalize"]
    if settings.env["normalize"]:
        assert manager.normalize_kwargs.get("norm_reward", True) is \
            settings.env["normalize_reward"]
        assert manager.normalize_kwargs.get("norm_obs", True) is True
        assert manager.normalize_kwargs["gamma"] == ppo["gamma"]
    for key in zoo.SCHEDULED:
        linear = ppo[f"{key}_schedule"] == "linear"
        schedule = processed.pop(key)
        assert schedule(1.0) == pytest.approx(ppo[key])
        assert schedule(0.5) == pytest.approx(ppo[key] * (0.5 if linear else 1.0)), key
    kwargs = processed.pop("policy_kwargs", {})
    activations = {"tanh": nn.Tanh, "relu": nn.ReLU}
    for name, setting in zoo.POLICY_KWARGS.items():
        got = kwargs.get(name, zoo.SB3_DEFAULTS[setting])
        want = ppo[setting]
        if setting == "activation":
            assert kwargs.get(name, nn.Tanh) is activations[want]
        else:
            assert got == want, name
    batch = ppo["batch_size"] or ppo["n_steps"] * ppo["n_envs"]
    expected = {key: ppo[key] for key in zoo.NUMBERS if key != "n_envs"}
    assert processed == {**expected, "batch_size": batch, "use_sde": ppo["use_sde"],
                         "policy": "MlpPolicy"}


def _gym_sweep(store: Store, monkeypatch: pytest.MonkeyPatch, settings: dict[str, Any]) -> None:
    """A finished sweep of ppo.gamma on the given settings, 0.95 clearly the best."""
    monkeypatch.setattr(synthetic, "SETTINGS", settings)
    finals = {0.9: [-900.0, -950.0, -920.0], 0.95: [-150.0, -160.0, -170.0]}
    add_sweep(store, "gam", "ppo.gamma", list(finals), [
        Run(value=value, seed=seed, final_score=final,
            curve=[(2048, -1300.0, 1.0), (4096, final, 2.0)])
        for value, scores in finals.items() for seed, final in enumerate(scores)],
        steps=4096, curve_every=2048)


def test_best_format_zoo_writes_a_gym_study_s_selection(
        workdir: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    stored = resolved_settings(zoo_config("Pendulum-v1", "ppo.learning_rate_schedule=linear",
                                          "env.normalize=true", "env.normalize_reward=false"))
    stored["env"]["packages"] = ["my_envs"]  # a package that registers the id, as stored
    store = Store(sqlite_url(workdir / "k.db"))
    try:
        _gym_sweep(store, monkeypatch, stored)
    finally:
        store.close()
    assert run_cli("best", "--study-name", "gam", "--format", "zoo", "--storage",
                   sqlite_url(workdir / "k.db")) == 0
    path = workdir / "zoo" / "best_gam.yml"
    command = ("python -m rl_zoo3.train --algo ppo --env Pendulum-v1 -conf zoo/best_gam.yml "
               "--gym-packages my_envs")
    assert f"`{command}`" in capsys.readouterr().out
    assert f"# Train: {command}\n" in path.read_text()
    body = yaml.safe_load(path.read_text())
    assert list(body) == ["Pendulum-v1"]
    entry = body["Pendulum-v1"]
    assert entry["gamma"] == 0.95 and entry["n_timesteps"] == 4096  # the selected value, budget
    assert entry["learning_rate"] == "lin_0.001" and entry["normalize"] == zoo.NORM_REWARD_OFF
    back = zoo.translate("Pendulum-v1", entry)
    assert back.ppo == {**OPTIONAL_PPO, **stored["ppo"], "gamma": 0.95}
    assert back.env == {"normalize": True, "normalize_reward": False}
    assert not (workdir / "conf").exists()


def test_best_writes_a_gym_study_s_normalisation_into_its_ppo_config(
        workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A setting selected under ppo=zoo's VecNormalize keeps it when used as ppo=best_NAME
    without ppo=zoo: a confirm baseline or a train of it is the setting that was selected."""
    stored = resolved_settings(zoo_config("MountainCarContinuous-v0"))
    assert stored["env"]["normalize"] is True  # rl-zoo3 normalises this id
    store = Store(sqlite_url(workdir / "k.db"))
    try:
        _gym_sweep(store, monkeypatch, stored)
    finally:
        store.close()
    assert run_cli("best", "--study-name", "gam", "--storage", sqlite_url(workdir / "k.db")) == 0
    body = yaml.safe_load((workdir / "conf" / "ppo" / "best_gam.yaml").read_text())
    assert body["env"] == {"normalize": True, "normalize_reward": True}
    used = resolved_settings(compose_config(["env=gym", "env.id=MountainCarContinuous-v0",
                                             "ppo=best_gam"]))
    assert used["env"] == stored["env"]
    assert used["ppo"] == {**stored["ppo"], "gamma": 0.95}


def test_best_zoo_format_zoo_writes_rl_zoo3_s_settings_back(workdir: Path) -> None:
    assert run_cli("best", "--zoo", "--format", "zoo", "env=gym",
                   "env.id=MountainCarContinuous-v0") == 0
    body = yaml.safe_load((workdir / "zoo" / "zoo_MountainCarContinuous-v0.yml").read_text())
    read = zoo.zoo_settings("MountainCarContinuous-v0")
    assert body == {read.env_id: zoo.to_entry(read)}
    assert zoo.translate(read.env_id, body[read.env_id], read.version) == read


def _refused(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert run_cli(*args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    return err


def test_format_zoo_refuses_what_rl_zoo3_cannot_train_in_one_line_writing_nothing(
        workdir: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    url = sqlite_url(workdir / "k.db")
    store = Store(url)
    try:
        _gym_sweep(store, monkeypatch, dict(synthetic.SETTINGS))  # the leg's settings
    finally:
        store.close()
    err = _refused(capsys, "best", "--study-name", "gam", "--format", "zoo", "--storage", url)
    assert "trained the leg" in err and "--format ppo" in err
    with pytest.raises(SystemExit) as exited:
        run_cli("best", "--format", "json")
    err = capsys.readouterr().err
    assert exited.value.code == 2 and "invalid choice: 'json'" in err and err.count("\n") == 1
    err = _refused(capsys, "best", "--zoo", "--format", "zoo", "env=gym", "env.id=Pendulum-v1",
                   "+env.kwargs.g=9.81")
    assert "env.kwargs={'g': 9.81}" in err
    assert not (workdir / "zoo").exists() and not (workdir / "conf").exists()


@pytest.mark.slow
@pytest.mark.parametrize("env_id", CLASSIC)
def test_every_classic_control_entry_trains_at_smoke_budget(env_id: str) -> None:
    from kraby_study.run.trial import run_trial

    cfg = zoo_config(env_id, "budget=smoke")
    spec = TrialSpec(study="zoo", key="s0", seed=0, steps=int(cfg.budget.steps),
                     curve_every=int(cfg.budget.curve_every), settings=resolved_settings(cfg),
                     objective="evaluation", eval_episodes=2)
    result = run_trial(spec)
    assert result.outcome == Outcome.COMPLETE, result.failure
    assert result.env_steps >= 4096
