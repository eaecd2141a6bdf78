"""Any Gymnasium environment behind the env seam: settings, seeding, VecNormalize, evaluation,
every command end to end, and each bad input refused in one line."""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import load, run_cli

import kraby_conf
from kraby_study.config.compose import compose_config, composed
from kraby_study.env import adapter_for, normalizer_path
from kraby_study.env.gym_env import evaluation_seeds
from kraby_study.env.gym_vec import sub_env_seeds
from kraby_study.errors import ConfigError
from kraby_study.plan.settings import resolved_settings
from kraby_study.plan.spec import OPTIONAL_PPO, TrialSpec
from kraby_study.records.attributes import TrialAttrs
from kraby_study.records.stored import Outcome

TESTS = Path(__file__).resolve().parent
GYM = ["env=gym", "env.id=Pendulum-v1"]
TINY_PPO = ["ppo.n_envs=2", "ppo.n_steps=64", "ppo.n_epochs=2", "ppo.net_arch=[8]"]


def spec_of(overrides: list[str], steps: int = 512, **fields: object) -> TrialSpec:
    """A one-seed trial spec of a composed config."""
    cfg = compose_config(overrides)
    return TrialSpec(study="t", key="s0", seed=int(cfg.seed), steps=steps, curve_every=128,
                     settings=resolved_settings(cfg), **fields)  # type: ignore[arg-type]


# --- settings ----------------------------------------------------------------------------


def test_the_leg_is_the_default_and_its_settings_hold_no_new_key() -> None:
    settings = resolved_settings(compose_config([]))
    assert adapter_for(settings["env"]).kind == "leg"
    assert set(settings["env"]) == {"observation", "delta", "time_step", "frameskip",
                                    "max_episode_steps"}
    assert not set(OPTIONAL_PPO) & set(settings["ppo"])
    changed = resolved_settings(compose_config(["ppo.use_sde=true"]))
    assert changed["ppo"]["use_sde"] is True


def test_the_optional_ppo_defaults_are_the_schemas() -> None:
    from kraby_study.config.schema import PPOConfig

    assert {name: getattr(PPOConfig(), name) for name in OPTIONAL_PPO} == OPTIONAL_PPO


def test_a_gym_env_composes_typed_and_dry_run_names_it(
        capsys: pytest.CaptureFixture[str]) -> None:
    cfg = compose_config([*GYM, "+env.kwargs.g=9.0", "env.max_episode_steps=50"])
    assert adapter_for(cfg.env).kind == "gym"
    assert resolved_settings(cfg)["env"]["kwargs"] == {"g": 9.0}
    # budget=smoke's 4096 steps hold no 200-step episode on 32 envs: 6400 do.
    assert run_cli("run", "study=clip_range", *GYM, "budget=smoke", "budget.steps=6400",
                   "--dry-run") == 0
    out = capsys.readouterr().out
    assert f"env: gym Pendulum-v1 (gymnasium {gym.__version__})" in out


@pytest.mark.parametrize(("overrides", "message"), [
    (["env=gym"], "env=gym needs env.id=ID"),
    (["env=gym", "env.id=NoSuchEnv-v0"], "is not a registered Gymnasium id"),
    ([*GYM, "+env.kwargs.gravity_typo=3"], "cannot be made with env.kwargs"),
    ([*GYM, "env.packages=[no_such_package_36]"], "env.packages: cannot import"),
    ([*GYM, "env.max_episode_steps=0"], "env.max_episode_steps must be at least 1"),
    ([*GYM, "env.typo=1"], "env.typo"),
    (["env=gym", "env.id=CartPole-v1", "ppo.use_sde=true"], "ppo.use_sde needs continuous"),
    (["env=gym", "env.id=FrozenLake-v1", "env.normalize=true"], "env.normalize needs a Box"),
    ([*GYM, "ppo.learning_rate_schedule=lin"], "ppo.learning_rate_schedule must be one of"),
    ([*GYM, "ppo.clip_range_schedule=cosine"], "ppo.clip_range_schedule must be one of"),
    ([*GYM, "ppo.sde_sample_freq=-2"], "ppo.sde_sample_freq must be -1"),
    ([*GYM, "ppo.log_std_init=nan"], "ppo.log_std_init must be a finite number"),
    ([*GYM, "ppo.ortho_init=maybe"], "ppo.ortho_init"),
    (["report.threshold=5"], "report.threshold must be at most 0"),
])
def test_bad_gym_input_is_one_line(overrides: list[str], message: str) -> None:
    with pytest.raises(ConfigError, match=message) as caught:
        compose_config(overrides)
    assert "\n" not in str(caught.value)


def test_the_leg_threshold_check_does_not_apply_to_another_env() -> None:
    assert float(compose_config([*GYM, "report.threshold=-200"]).report.threshold) == -200
    assert float(compose_config([*GYM, "report.threshold=150"]).report.threshold) == 150


def test_a_package_that_registers_ids_is_imported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(TESTS))
    cfg = compose_config(["env=gym", "env.id=KrabyTestBroken-v0",
                          "env.packages=[gym_fixtures]"])
    assert cfg.env.id == "KrabyTestBroken-v0"


# --- seeding -----------------------------------------------------------------------------


def first_observations(seed: int, n_envs: int, seeding: str) -> np.ndarray:
    env = adapter_for({"id": "Pendulum-v1"}).make_vec(
        {"id": "Pendulum-v1", "kwargs": {}, "packages": []}, n_envs, seed, seeding)
    env.seed(seed)
    try:
        return env.reset()
    finally:
        env.close()


def test_each_sub_env_resets_from_its_own_child_of_the_run_seed() -> None:
    observations = first_observations(5, 3, "streams")
    children = np.random.SeedSequence(5).spawn(3)
    for index, child in enumerate(children):
        reset_seed = int(child.generate_state(3, np.uint64)[0])
        single = gym.make("Pendulum-v1")
        expected, _ = single.reset(seed=reset_seed)
        single.close()
        np.testing.assert_array_equal(observations[index], expected)
    # Runs with neighbouring seeds share no sub-env's start, unlike SB3's seed + i.
    neighbour = first_observations(6, 3, "streams")
    assert not any(np.array_equal(a, b) for a in observations for b in neighbour)
    offset, offset_next = first_observations(5, 3, "offset"), first_observations(6, 3, "offset")
    np.testing.assert_array_equal(offset[1], offset_next[0])


def test_sub_env_seeds_and_evaluation_seeds_are_apart() -> None:
    streams = sub_env_seeds(0, 4, "streams")
    assert len({s.reset for s in streams}) == 4
    assert [s.reset for s in sub_env_seeds(7, 2, "offset")] == [7, 8]
    assert evaluation_seeds(5)[:3] == evaluation_seeds(3)
    assert evaluation_seeds(5, seed=4)[:3] == evaluation_seeds(3, seed=4)
    training = {s.reset for seed in range(50) for s in sub_env_seeds(seed, 8, "streams")}
    assert not training & set(evaluation_seeds(16))
    # Each run's own test set: apart from every training stream and from every other seed's.
    own = [set(evaluation_seeds(100, seed)) for seed in range(50)]
    assert all(len(episodes) == 100 for episodes in own)
    assert not training & set().union(*own)
    assert all(not a & b for i, a in enumerate(own) for b in own[i + 1:])
    assert not set(evaluation_seeds(100)) & set().union(*own)


def episode_by_episode(model: object, resets: list[dict[str, object]],
                       make: object) -> list[float]:
    """Each episode alone, one policy call per step: the evaluation before it was stepped
    side by side."""
    env = make()  # type: ignore[operator]
    returns = []
    for reset in resets:
        observation, _ = env.reset(**reset)
        total, ended = 0.0, False
        while not ended:
            action = model.predict(observation, deterministic=True)[0]  # type: ignore[attr-defined]
            observation, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            ended = terminated or truncated
        returns.append(total)
    env.close()
    return returns


@pytest.mark.parametrize("env_id", ["Pendulum-v1", "CartPole-v1"])
def test_evaluation_side_by_side_equals_episode_by_episode(env_id: str) -> None:
    # One batched forward pass per step gives each episode the actions it gets alone; the
    # returns agree to float32 rounding of the batched matrix product (Pendulum's reach -1e3).
    from stable_baselines3 import PPO

    env = {"id": env_id, "kwargs": {}, "packages": []}
    model = PPO("MlpPolicy", gym.make(env_id), seed=3, device="cpu",
                policy_kwargs={"net_arch": [16]})
    adapter = adapter_for(env)
    evaluation = adapter.evaluate(model, env, 20, seed=5)
    alone = episode_by_episode(model, [{"seed": s} for s in evaluation_seeds(20, 5)],
                               lambda: gym.make(env_id))
    assert len(evaluation.returns) == 20
    np.testing.assert_allclose(evaluation.returns, alone, rtol=1e-5, atol=1e-6)
    assert evaluation.mean == pytest.approx(np.mean(alone), rel=1e-6)
    assert evaluation.error == pytest.approx(np.std(alone, ddof=1) / np.sqrt(20), rel=1e-4)
    # More episodes than envs stepped at once: further rounds on the same envs.
    from kraby_study.env.evaluation import lockstep_returns

    resets = [{"seed": s} for s in evaluation_seeds(20, 5)]
    narrow = lockstep_returns(lambda: gym.make(env_id), resets,
                              lambda o: model.predict(o, deterministic=True)[0], width=3)
    np.testing.assert_allclose(narrow, alone, rtol=1e-5, atol=1e-6)


def test_the_legs_evaluation_side_by_side_equals_episode_by_episode() -> None:
    from stable_baselines3 import PPO

    import kraby_envs
    from kraby_envs.rollout import START_ANGLES, evaluation_targets, fixed_targets
    from kraby_study.env.leg import DEFAULTS, leg_kwargs

    env = dict(DEFAULTS)
    kwargs = leg_kwargs(env)

    def make() -> gym.Env:
        return gym.make(kraby_envs.ENV_ID, max_episode_steps=env["max_episode_steps"], **kwargs)

    model = PPO("MlpPolicy", make(), seed=1, device="cpu", policy_kwargs={"net_arch": [16]})
    adapter = adapter_for(env)
    for seed, targets in ((7, evaluation_targets(6, kwargs["delta"], 7)),
                          (None, fixed_targets(6, kwargs["delta"]))):
        resets = [{"options": {"joint_angles": START_ANGLES, "target": tuple(t)}}
                  for t in targets]
        evaluation = adapter.evaluate(model, env, 6, seed=seed)
        np.testing.assert_allclose(evaluation.returns, episode_by_episode(model, resets, make),
                                   rtol=1e-5, atol=1e-7)
    # Each run's targets are its own: apart from the fixed set and from other seeds'.
    own = evaluation_targets(6, kwargs["delta"], 7)
    assert not np.isclose(own[:, None, :], fixed_targets(6, kwargs["delta"])[None]).all(-1).any()
    assert not np.isclose(own[:, None, :],
                          evaluation_targets(6, kwargs["delta"], 8)[None]).all(-1).any()
    np.testing.assert_array_equal(evaluation_targets(3, kwargs["delta"], 7), own[:3])


# --- training, VecNormalize and evaluation ------------------------------------------------


def test_a_gym_trial_trains_in_the_envs_own_reward_units() -> None:
    from kraby_study.run.trial import run_trial

    result = run_trial(spec_of([*GYM, *TINY_PPO, "env.max_episode_steps=32"]))
    assert result.outcome == Outcome.COMPLETE
    # Pendulum's reward per step lies in [-16.3, 0]: 32-step returns, not normalised ones.
    assert -16.3 * 32 <= result.final_score <= 0
    assert result.final_score < -10


def test_vecnormalize_statistics_are_saved_and_used_by_evaluation(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    from kraby_study.run.trial import run_trial

    model = tmp_path / "m.zip"
    spec = spec_of([*GYM, *TINY_PPO, "env.normalize=true", "env.max_episode_steps=32"],
                   model_path=str(model), objective="evaluation", eval_episodes=3)
    result = run_trial(spec)
    assert result.outcome == Outcome.COMPLETE
    stats = normalizer_path(model)
    assert stats.is_file()
    with stats.open("rb") as handle:
        normalizer = pickle.load(handle)
    # Statistics that moved from their start: a count of every observation trained on.
    assert normalizer.obs_rms.count > 512
    env = spec.settings["env"]
    policy = PPO.load(str(model), device="cpu")
    adapter = adapter_for(env)
    # The run's own episodes (its seed's evaluation stream), on normalised observations.
    scored = adapter.evaluate(policy, env, 3, normalizer, seed=spec.seed)
    assert scored.mean == pytest.approx(result.final_score)
    assert result.eval_errors == [pytest.approx(scored.error)]
    assert adapter.evaluate(policy, env, 3, None, seed=spec.seed).mean != pytest.approx(
        result.final_score)
    assert adapter.evaluate(policy, env, 3, normalizer).mean != pytest.approx(
        result.final_score)


def test_linear_schedules_reach_sb3_as_functions_of_progress() -> None:
    from kraby_study.run.trial import build_model, make_env

    spec = spec_of([*GYM, *TINY_PPO, "ppo.learning_rate_schedule=linear",
                    "ppo.clip_range_schedule=linear", "ppo.use_sde=true",
                    "ppo.sde_sample_freq=4", "ppo.log_std_init=-1", "ppo.ortho_init=false"])
    env = make_env(spec, 0)
    try:
        model = build_model(spec, env, 0)
        assert model.lr_schedule(1.0) == pytest.approx(1e-3)
        assert model.lr_schedule(0.25) == pytest.approx(2.5e-4)
        assert model.clip_range(0.5) == pytest.approx(0.1)
        assert model.use_sde and model.sde_sample_freq == 4
        assert model.policy.ortho_init is False
        assert float(model.policy.log_std.detach().mean()) == pytest.approx(-1.0)
    finally:
        env.close()


# --- commands ----------------------------------------------------------------------------


def test_the_policy_gif_draws_the_first_evaluation_episodes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from PIL import Image

    from kraby_study.env.gym_env import GIF_EPISODES
    from kraby_study.report.policy import render_policy
    from kraby_study.run.trial import run_trial

    monkeypatch.syspath_prepend(str(TESTS))
    model = tmp_path / "m.zip"
    spec = spec_of(["env=gym", "env.id=KrabyTestTiny-v0", "env.packages=[gym_fixtures]",
                    "env.normalize=true", *TINY_PPO], model_path=str(model))
    assert run_trial(spec).outcome == Outcome.COMPLETE
    gif = render_policy(str(model), spec.settings, tmp_path / "policy.gif")
    # Each 10-step episode: its reset and its 10 steps, one frame each.
    assert Image.open(gif).n_frames == GIF_EPISODES * 11


def test_an_unwritable_output_folder_is_refused_before_any_run(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = run_cli("run", "study=clip_range", "budget=smoke",
                   "tensorboard_dir=/proc/forbidden/tb")
    err = capsys.readouterr().err
    assert code == 2 and "tensorboard_dir /proc/forbidden/tb cannot be written" in err
    assert len(err.strip().splitlines()) == 1
    assert not (workdir / "studies").exists()
    blocker = workdir / "file"
    blocker.write_text("")
    assert run_cli("train", "budget=smoke", f"models_dir={blocker}/models") == 2
    assert "models_dir" in capsys.readouterr().err
    # A folder that can be written is left as it was: nothing made by the check stays.
    assert run_cli("run", "study=clip_range", *GYM, "budget=smoke", "budget.steps=6400",
                   f"models_dir={workdir}/a/b", "--dry-run") == 0
    assert not (workdir / "a").exists()


def test_runs_that_end_in_errors_make_the_command_fail_and_say_how_many(
        workdir: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.syspath_prepend(str(TESTS))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(TESTS), *filter(None, [os.environ.get("PYTHONPATH")])]))
    code = run_cli("run", "study=clip_range", "env=gym", "env.id=KrabyTestBroken-v0",
                   "env.packages=[gym_fixtures]", "budget=smoke", "budget.seeds=1",
                   "budget.steps=64", "ppo.n_envs=2", "ppo.n_steps=16", "save_models=false",
                   "workers=1")
    captured = capsys.readouterr()
    assert code == 1
    assert "0/4 complete, 4 failed" in captured.out
    assert "4 run(s) ended in an error (not a divergence)" in captured.err


@pytest.mark.slow
def test_a_gym_sweep_search_confirm_and_report_end_to_end(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 512 steps per env: a 500-step episode can end in the last 10 % (the final score's).
    cart = ["env=gym", "env.id=CartPole-v1", "budget=smoke", "budget.steps=1024",
            "budget.curve_every=256", "ppo.n_envs=2", "ppo.n_steps=32", "ppo.n_epochs=2",
            "ppo.net_arch=[16]", "workers=2"]
    assert run_cli("run", "study=clip_range", *cart) == 0
    assert run_cli("optuna", "--trials", "3", *cart, "search.objective=evaluation",
                   "search.eval_episodes=3", "search.enqueue=[zoo]") == 0
    assert run_cli("confirm", "--study-name", "ppo_search", "--top", "1", "--seeds", "2",
                   "--baseline", "ppo=zoo", *cart) == 0
    assert run_cli("report", "--out", "out", "--no-policy") == 0
    out = capsys.readouterr().out
    assert "ppo_search-confirm" in out
    summary = (workdir / "out" / "clip_range" / "summary.csv").read_text()
    assert "clip_range" in summary or "0.1" in summary
    record = (workdir / "out" / "ppo_search" / "reproducibility.md").read_text()
    assert "| env_id | CartPole-v1 |" in record and "| env_package | gymnasium |" in record
    # A search's page says what its sampler spent choosing its trials; a sweep's has none.
    assert "CPU seconds the search's sampler spent choosing the trials" in record
    assert "sampler spent" not in (workdir / "out" / "clip_range" /
                                   "reproducibility.md").read_text()
    # CartPole's returns are episode lengths, 8 to 500: the curves are in its own units.
    import pandas as pd

    curves = pd.read_csv(workdir / "out" / "clip_range" / "curves.csv")
    reward = next(c for c in curves.columns if "reward" in c)
    assert curves[reward].between(8, 500).all()
    # A gym space's parameters are all numbers: the top table still writes whole numbers.
    top = (workdir / "out" / "ppo_search" / "top_trials.md").read_text()
    first = next(line for line in top.splitlines() if line.startswith("| 1 |"))
    assert ".0 |" not in first
    # The confirm of the evaluation search holds the training reward beside its score.
    assert "train_mean, train_sd, train_low, train_high" in (
        workdir / "out" / "ppo_search-confirm" / "summary.md").read_text()


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # beside test_ray.py, which counts the Ray processes
def test_a_gym_campaign_race_train_and_ray_run(workdir: Path) -> None:
    cart = ["env=gym", "env.id=CartPole-v1", "budget=smoke", "budget.steps=1024",
            "budget.curve_every=256", "ppo.n_envs=2", "ppo.n_steps=32", "ppo.n_epochs=2",
            "ppo.net_arch=[16]", "save_models=false", "workers=2"]
    (workdir / "conf" / "campaign").mkdir(parents=True)
    (workdir / "conf" / "campaign" / "cart.yaml").write_text(
        "# @package campaign\nname: cart\ndescription: two sweeps on CartPole-v1\nstart: {}\n"
        "stages:\n  - study: clip_range\n  - study: gamma\n")
    assert run_cli("run", "campaign=cart", *cart) == 0
    db = workdir / "studies" / "kraby.db"
    # The second stage ran with the first's selected clip_range, on the gym env.
    gamma = load(db, "cart-gamma").get_trials()[0].user_attrs
    assert gamma["settings"]["env"]["id"] == "CartPole-v1"
    assert run_cli("run", "study=clip_range", "--racing", "budget.seeds=4", *cart) == 0
    assert run_cli("run", "study=clip_range", "executor=ray", "study.name=on_ray", *cart) == 0
    assert len(load(db, "on_ray").get_trials()) == 8
    # train on a normalised env saves the model and its VecNormalize statistics.
    assert run_cli("train", "env=gym", "env.id=Pendulum-v1", "ppo=zoo", "budget.steps=8192",
                   "env.normalize=true") == 0
    assert list(workdir.glob("**/s0.zip")) and list(workdir.glob("**/s0.vecnormalize.pkl"))


def test_the_ppo_config_a_search_starts_from_is_the_one_hydra_chose(workdir: Path) -> None:
    """A working folder's own conf/config.yaml, which Hydra takes as the primary config,
    chooses the default ppo config too."""
    assert composed(["env=gym"], check=False).ppo == "start"
    packaged = (Path(kraby_conf.__file__).parent / "config.yaml").read_text()
    assert "  - ppo: start\n" in packaged
    (workdir / "conf").mkdir()
    (workdir / "conf" / "config.yaml").write_text(
        packaged.replace("  - ppo: start\n", "  - ppo: tuned\n"))
    assert composed(["env=gym"], check=False).ppo == "tuned"
    assert composed(["env=gym", "env.id=Pendulum-v1", "ppo=zoo"]).ppo == "zoo"


def test_a_gym_search_starts_from_the_ppo_config_it_trains_with(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cart = ["env=gym", "env.id=CartPole-v1", "budget=smoke", "budget.steps=1024",
            "budget.curve_every=256", "budget.seeds=1", "ppo.n_envs=2", "ppo.n_steps=32",
            "ppo.n_epochs=1", "ppo.net_arch=[16]", "save_models=false", "workers=1",
            # Scored on evaluation episodes, every drawn setting has a score at this budget.
            "search.objective=evaluation", "search.eval_episodes=4"]
    db = workdir / "studies" / "kraby.db"

    def enqueued(name: str) -> list[str | None]:
        return [TrialAttrs.of(t).enqueued for t in load(db, name).trials]

    assert run_cli("optuna", "--trials", "1", "--study-name", "warm", "ppo=zoo", *cart) == 0
    assert "search warm: evaluating ppo=zoo first" in capsys.readouterr().out
    assert enqueued("warm") == ["ppo=zoo"]
    assert run_cli("optuna", "--trials", "1", "--study-name", "cold", "search.enqueue=[]",
                   *cart) == 0
    assert "first" not in capsys.readouterr().out and enqueued("cold") == [None]
    # A stored search resumes with what it stored: no refusal, nothing queued again.
    for name, ppo in (("warm", "ppo=zoo"), ("cold", "ppo=start")):
        assert run_cli("optuna", "--trials", "2", "--study-name", name, ppo, *cart) == 0
        assert enqueued(name)[0] == ("ppo=zoo" if name == "warm" else None)
        assert len(enqueued(name)) == 2
    # Resumed, the sampler draws from a seed of its own, not the first command's trials again.
    first, second = load(db, "cold").trials
    assert first.params != second.params
    # Without ppo=..., the command trains with conf/config.yaml's default and starts there.
    assert run_cli("optuna", "--trials", "1", "--study-name", "plain", *cart) == 0
    assert enqueued("plain") == ["ppo=start"]
