"""ppo=zoo and budget=zoo: rl-zoo3's published PPO settings, read as data and translated once."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from conftest import run_cli

from kraby_study.config import zoo
from kraby_study.config.compose import compose_config
from kraby_study.errors import ConfigError
from kraby_study.plan.settings import resolved_settings
from kraby_study.plan.spec import TrialSpec
from kraby_study.records import Outcome

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
