"""Behaviour of the batched world of legs as an SB3 VecEnv."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnv

from kraby_envs import KrabyBatchedVecEnv, KrabyOneLegEnv, make_batched
from kraby_envs._bullet import p
from kraby_envs.seeding import leg_generator, leg_streams
from kraby_envs.task import TARGET_CENTRE, TARGET_HALF_EXTENTS


@pytest.fixture
def venv():
    environment = make_batched(n_envs=4, seed=11)
    yield environment
    environment.close()


def random_actions(n_steps: int, n_envs: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, (n_steps, n_envs, 3)).astype(np.float32)


def single_reset(env: KrabyOneLegEnv, seed: int, leg: int, n_envs: int, seeding: str):
    """A single env reset as leg ``leg`` of a batched run with ``seed`` starts."""
    if seeding == "offset":
        return env.reset(seed=seed + leg)
    env.np_random = leg_generator(leg_streams(seed, n_envs, seeding)[leg])
    return env.reset()


@pytest.mark.parametrize(("observation", "seeding"), [
    ("default", "streams"), ("with_tip_to_target", "streams"), ("default", "offset")])
def test_each_leg_matches_a_single_env_over_several_episodes(observation, seeding):
    # 8 legs and these seeds hit self-collisions, where contact order once made legs drift.
    n_envs, seed, episodes = 8, 5, 3
    venv = make_batched(n_envs=n_envs, seed=seed, observation=observation, seeding=seeding)
    singles = [KrabyOneLegEnv(observation=observation) for _ in range(n_envs)]
    batched_obs = venv.reset()
    single_obs = np.stack([single_reset(env, seed, i, n_envs, seeding)[0]
                           for i, env in enumerate(singles)])
    np.testing.assert_allclose(batched_obs, single_obs, atol=1e-4)
    for t, actions in enumerate(random_actions(32 * episodes, n_envs)):
        batched_obs, rewards, dones, infos = venv.step(actions)
        results = [env.step(actions[i]) for i, env in enumerate(singles)]
        single_obs = np.stack([r[0] for r in results])
        np.testing.assert_allclose(rewards, [r[1] for r in results], rtol=1e-4, atol=1e-7)
        assert dones.tolist() == [(t + 1) % 32 == 0] * n_envs
        if dones.all():
            terminal = np.stack([info["terminal_observation"] for info in infos])
            np.testing.assert_allclose(terminal, single_obs, atol=1e-4)
            # The single envs continue their own random streams, as the legs do.
            single_obs = np.stack([env.reset()[0] for env in singles])
        np.testing.assert_allclose(batched_obs, single_obs, atol=1e-4, err_msg=f"step {t}")
    venv.close()
    for env in singles:
        env.close()


def test_episode_info_as_vec_monitor_writes_it(venv):
    assert isinstance(venv, VecEnv)
    venv.reset()
    returns = np.zeros(4, dtype=np.float32)
    for t, actions in enumerate(random_actions(32, 4)):
        _, rewards, dones, infos = venv.step(actions)
        returns += rewards
        assert all({"tip_position", "distance"} <= set(info) for info in infos)
        if t < 31:
            assert not dones.any() and not any("episode" in info for info in infos)
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is True
        assert info["terminal_observation"].shape == venv.observation_space.shape
        episode = info["episode"]
        assert set(episode) == {"r", "l", "t"}
        assert episode["r"] == pytest.approx(returns[i]) and episode["l"] == 32
        assert episode["t"] >= 0.0
        assert -5.0 < episode["r"] < 0.0


def test_sb3_ppo_logs_episodes_without_a_monitor():
    venv = make_batched(n_envs=4, seed=0)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1,
                policy_kwargs={"net_arch": [8]}, seed=0, device="cpu")
    model.learn(total_timesteps=256)
    assert len(model.ep_info_buffer) >= 4
    assert all(info["l"] == 32 for info in model.ep_info_buffer)
    venv.close()


def test_seed_reseeds_the_next_reset(venv):
    first = venv.reset()
    again = venv.reset()
    assert not np.allclose(first, again)
    assert venv.seed(11) == [11] * 4
    np.testing.assert_array_equal(venv.reset(), first)


def first_draws(seed: int, seeding: str, n_envs: int = 4) -> np.ndarray:
    """Six numbers from each leg's stream after its first reset (its starts drawn)."""
    venv = make_batched(n_envs=n_envs, seed=seed, seeding=seeding)
    venv.reset()
    draws = np.stack([rng.uniform(size=6) for rng in venv._rngs])  # type: ignore[union-attr]
    venv.close()
    return draws


def test_neighbouring_seeds_share_no_leg_stream():
    # Streams: no leg of run 12 starts like any leg of run 11 (the episodes differ).
    ours, neighbour = first_draws(11, "streams"), first_draws(12, "streams")
    assert not np.isin(neighbour, ours).any()
    # Offset, the scheme before streams: run 12's legs 0-2 are run 11's legs 1-3.
    ours, neighbour = first_draws(11, "offset"), first_draws(12, "offset")
    np.testing.assert_array_equal(neighbour[:3], ours[1:])


def test_neighbouring_runs_start_apart():
    # What a leg observes first: start angles and target. Streams share no leg's, offset
    # shares three of four between runs 11 and 12.
    for seeding, shared in (("streams", 0), ("offset", 3)):
        runs = [make_batched(n_envs=4, seed=seed, seeding=seeding) for seed in (11, 12)]
        first, second = (run.reset() for run in runs)
        same = sum(any(np.array_equal(b, a) for a in first) for b in second)
        assert same == shared, seeding
        for run in runs:
            run.close()


def test_offset_streams_are_gymnasium_seeds():
    # A study stored before streams resumes bit for bit: offset leg i is reset(seed=s + i).
    from gymnasium.utils import seeding

    for leg, stream in enumerate(leg_streams(7, 3, "offset")):
        expected, _ = seeding.np_random(7 + leg)
        assert leg_generator(stream).random(5).tolist() == expected.random(5).tolist()


def test_an_unknown_scheme_is_refused():
    with pytest.raises(ValueError, match="seeding must be one of streams, offset"):
        make_batched(n_envs=2, seeding="sequential")


def test_legs_never_touch_each_other():
    venv = make_batched(n_envs=9, seed=0, delta=1.0)
    venv.reset()
    world = venv._world._local
    legs = set(world._bodies)
    for actions in random_actions(64, 9, seed=1):
        venv.step(actions * 2.0)
        for contact in p.getContactPoints(physicsClientId=world._client):
            a, b = contact[1], contact[2]
            assert a == b or not (a in legs and b in legs), "two legs touched"
    venv.close()


def test_reset_options_apply_per_leg(venv):
    venv.set_options({"joint_angles": (0.1, 0.2, 0.3), "target": tuple(TARGET_CENTRE)})
    observations = venv.reset()
    np.testing.assert_allclose(observations[:, 0:6:2] * np.pi / 2, [[0.1, 0.2, 0.3]] * 4,
                               atol=1e-6)
    np.testing.assert_allclose(observations[:, 6:9], 0.0, atol=1e-6)


def test_attributes_and_methods(venv):
    assert venv.get_attr("delta") == [0.5] * 4
    assert venv.get_attr("observation", indices=[1, 2]) == ["default"] * 2
    assert venv.has_attr("max_velocity") and not venv.has_attr("no_such_thing")
    venv.set_attr("delta", 0.0)
    observations = venv.reset()
    np.testing.assert_allclose(observations[:, 6:9], 0.0, atol=1e-6)
    venv.env_method("set_config", delta=1.0)
    venv.reset()
    targets = venv._world.targets
    assert np.all(np.abs(targets - TARGET_CENTRE) <= TARGET_HALF_EXTENTS + 1e-9)
    with pytest.raises(ValueError, match="observation"):
        venv.set_attr("observation", "with_tip")
    with pytest.raises(ValueError, match="indices"):
        venv.set_attr("delta", 0.3, indices=[0])
    with pytest.raises(AttributeError):
        venv.env_method("fly")
    assert venv.env_is_wrapped(object) == [False] * 4


def test_render_images():
    venv = make_batched(n_envs=2, seed=0, render_mode="rgb_array",
                        render_width=48, render_height=32)
    venv.reset()
    images = venv.get_images()
    assert len(images) == 2
    for image in images:
        assert image.shape == (32, 48, 3) and image.dtype == np.uint8
        assert np.any(np.any(image != image[0, 0], axis=2))
    tiled = venv.render()
    assert tiled.ndim == 3 and tiled.shape[2] == 3 and tiled.dtype == np.uint8
    assert venv.env_method("render", indices=[1])[0].shape == (32, 48, 3)
    venv.close()


def _play(venv: KrabyBatchedVecEnv, n_steps: int) -> list[np.ndarray]:
    """Everything a run of random actions shows, through a delta change and reset options."""
    seen = [venv.reset()]
    for t, actions in enumerate(random_actions(n_steps, venv.num_envs, seed=3)):
        if t == n_steps // 2:
            venv.set_attr("delta", 1.0)
            venv.set_options({"joint_angles": (0.1, -0.2, 0.3)})
            seen.append(venv.reset())
        observations, rewards, _, infos = venv.step(actions * 1.5)
        seen += [observations, rewards, np.array([info["distance"] for info in infos])]
        seen += [info["terminal_observation"] for info in infos if "terminal_observation" in info]
    return seen


def test_legs_move_bit_for_bit_the_same_in_any_number_of_shards():
    runs = []
    for shards in (1, 3):
        venv = make_batched(n_envs=8, seed=4, shards=shards)
        assert venv._world.shards == shards
        runs.append(_play(venv, 80))
        venv.close()
    assert len(runs[0]) == len(runs[1])
    for one, three in zip(*runs, strict=True):
        np.testing.assert_array_equal(one, three)


def test_a_shard_process_renders_its_legs():
    images = []
    for shards in (1, 2):
        # 3 m apart, no other leg is in the camera's view.
        venv = make_batched(n_envs=2, seed=0, shards=shards, leg_spacing=3.0,
                            render_mode="rgb_array",
                            render_width=40, render_height=30)
        venv.reset()
        images.append(venv.get_images())
        venv.close()
    # The same scene; the tiny renderer may still shade a few edge pixels differently.
    differ = np.any(images[0][1] != images[1][1], axis=2)
    assert images[1][1].shape == (30, 40, 3) and differ.mean() < 0.01


def test_shard_processes_stop_with_the_env_and_their_death_is_an_error():
    venv = make_batched(n_envs=4, seed=0, shards=2)
    venv.reset()
    shard = venv._world._remotes[0]._process
    assert shard.poll() is None
    shard.kill()
    shard.wait()
    with pytest.raises(RuntimeError, match="shard process stopped"):
        venv.step(random_actions(1, 4)[0])
    venv.close()
    other = make_batched(n_envs=4, seed=0, shards=2)
    process = other._world._remotes[0]._process
    other.close()
    assert process.poll() == 0


def _running(pid: int) -> bool:
    """Whether a process exists and has not exited (a zombie has, though not yet reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_a_shard_process_ends_quietly_when_its_owner_is_killed():
    owner = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time\n"
         "from kraby_envs import make_batched\n"
         "env = make_batched(n_envs=4, shards=2)\n"
         "env.reset()\n"
         "shard = env._world._remotes[0]\n"
         "shard.send('step', [[0.1, 0.2, 0.3]] * 2)\n"
         "shard._conn.poll(None)\n"  # the shard has answered the step (left unread)
         "print(shard._process.pid, flush=True)\n"
         "time.sleep(60)\n"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert owner.stdout is not None and owner.stderr is not None
    shard = int(owner.stdout.readline())
    # Killed with the shard's answer unread: dying so resets the pipe, which the shard must
    # take quietly.
    owner.kill()
    owner.wait()
    deadline = time.monotonic() + 10
    while _running(shard) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _running(shard)
    # The shard inherited the owner's stderr: a traceback would show here.
    assert owner.stderr.read() == ""


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_envs": 0}, "n_envs"),
        ({"n_envs": 2.5}, "n_envs"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"seed": "zero"}, "seed"),
        ({"leg_spacing": 0.2}, "leg_spacing"),
        ({"delta": 3.0}, "delta"),
        ({"observation": "pixels"}, "observation"),
        ({"wings": 2}, "wings"),
        ({"shards": 0}, "shards"),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        make_batched(**kwargs)


def test_class_is_exported_and_closes_twice(venv):
    assert isinstance(venv, KrabyBatchedVecEnv)
    venv.close()
    venv.close()
