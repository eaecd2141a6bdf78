"""Behaviour of the single Kraby leg environment and its robot description."""

from __future__ import annotations

import itertools
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import kraby_envs
from kraby_envs import OBSERVATIONS, KrabyOneLegEnv, validate_env_kwargs
from kraby_envs._bullet import p
from kraby_envs.observation import TIP_TO_TARGET_SCALE
from kraby_envs.robot import (
    GROUND_CLEAR_LINKS,
    JOINT_LOWER,
    JOINT_NAMES,
    JOINT_UPPER,
    NEVER_TOUCHING_PAIRS,
    create_ground,
    load_leg,
)
from kraby_envs.task import TARGET_CENTRE, TARGET_HALF_EXTENTS, WORKSPACE_HIGH, WORKSPACE_LOW

FK_CHECKPOINTS = [
    ((0.0, 0.0, 0.0), (0.1838, 0.0110, 0.0736)),
    ((0.4, 0.0, 0.0), (0.1766, 0.0467, 0.0736)),
    ((0.0, 0.5, 0.0), (0.2412, 0.0110, 0.1099)),
    ((0.0, 0.0, 0.5), (0.2260, 0.0110, 0.0843)),
    ((-0.3, -0.6, 0.9), (0.1745, -0.0144, 0.0609)),
]


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(physicsClientId=cid)


@pytest.fixture
def env():
    environment = KrabyOneLegEnv()
    yield environment
    environment.close()


def rollout(environment: gym.Env, seed: int, actions: np.ndarray) -> np.ndarray:
    observation, _ = environment.reset(seed=seed)
    observations = [observation]
    for action in actions:
        observations.append(environment.step(action)[0])
    return np.array(observations)


# --- robot description ----------------------------------------------------------------


@pytest.mark.parametrize(("angles", "expected"), FK_CHECKPOINTS)
def test_forward_kinematics_matches_checkpoints(client, angles, expected):
    leg = load_leg(client, (0.0, 0.0, 0.0))
    for joint, angle in zip(leg.joint_indices, angles, strict=True):
        p.resetJointState(leg.body_id, joint, angle, physicsClientId=client)
    tip = p.getLinkState(leg.body_id, leg.tip_link, computeForwardKinematics=True,
                         physicsClientId=client)[4]
    assert np.linalg.norm(np.subtract(tip, expected)) < 1e-3


def test_urdf_joints_limits_and_masses_match_robot_facts(client):
    leg = load_leg(client, (0.0, 0.0, 0.0))
    infos = [p.getJointInfo(leg.body_id, j, physicsClientId=client) for j in leg.joint_indices]
    assert [info[1].decode() for info in infos] == list(JOINT_NAMES)
    assert all(info[2] == p.JOINT_REVOLUTE for info in infos)
    np.testing.assert_allclose([info[8] for info in infos], JOINT_LOWER)
    np.testing.assert_allclose([info[9] for info in infos], JOINT_UPPER)
    links = range(p.getNumJoints(leg.body_id, physicsClientId=client))
    masses = [p.getDynamicsInfo(leg.body_id, link, physicsClientId=client)[0] for link in links]
    assert sum(masses) == pytest.approx(0.163, abs=1e-6)
    tip = p.getDynamicsInfo(leg.body_id, leg.tip_link, physicsClientId=client)
    assert tip[1] == pytest.approx(0.7)  # lateral friction from docs/reference/robot.md
    assert tip[9] == pytest.approx(10000.0) and tip[8] == pytest.approx(1000.0)


def test_skipped_contact_pairs_never_come_near(client):
    # skip_impossible_contacts is exact only if these gaps stay above the 2 cm threshold.
    ground = create_ground(client)
    leg = load_leg(client, (0.0, 0.0, 0.0))
    links = leg.link_indices
    grid = [np.linspace(lo, hi, n) for lo, hi, n in zip(JOINT_LOWER, JOINT_UPPER, (5, 13, 13),
                                                        strict=True)]
    for angles in itertools.product(*grid):
        for joint, angle in zip(leg.joint_indices, angles, strict=True):
            p.resetJointState(leg.body_id, joint, angle, physicsClientId=client)
        for name in GROUND_CLEAR_LINKS:
            assert not p.getClosestPoints(ground, leg.body_id, 0.1, -1, links[name],
                                          physicsClientId=client), (name, angles)
        for first, second in NEVER_TOUCHING_PAIRS:
            assert not p.getClosestPoints(leg.body_id, leg.body_id, 0.03, links[first],
                                          links[second], physicsClientId=client), angles


# --- API conformance ------------------------------------------------------------------


@pytest.mark.parametrize("observation", OBSERVATIONS)
def test_gymnasium_check_env_passes(observation):
    # Through gym.make so the checker also sees the spec and tries the other render modes.
    environment = gym.make(kraby_envs.ENV_ID, observation=observation, render_mode="rgb_array",
                           render_width=32, render_height=24)
    gym_check_env(environment.unwrapped, skip_render_check=False)
    environment.close()


def test_sb3_check_env_passes(env):
    sb3_check_env(env, warn=True)


def test_registered_env_truncates_after_32_steps():
    environment = gym.make(kraby_envs.ENV_ID, observation="with_tip")
    environment.reset(seed=0)
    truncations = [environment.step(environment.action_space.sample())[3] for _ in range(32)]
    assert truncations == [False] * 31 + [True]
    assert environment.observation_space.shape == (12,)
    environment.close()


def test_step_before_reset_is_refused(env):
    with pytest.raises(RuntimeError):
        env.step(np.zeros(3, dtype=np.float32))


# --- seeding and reset ----------------------------------------------------------------


def test_same_seed_and_actions_give_identical_observations():
    actions = np.random.default_rng(3).uniform(-1, 1, (40, 3)).astype(np.float32)
    first, second = KrabyOneLegEnv(), KrabyOneLegEnv()
    # The second env has history: a reset must not depend on it.
    rollout(second, 99, actions[::-1])
    np.testing.assert_array_equal(rollout(first, 7, actions), rollout(second, 7, actions))
    assert not np.allclose(rollout(first, 7, actions), rollout(first, 8, actions))
    first.close()
    second.close()


def test_start_angles_stay_within_joint_limits(env):
    env.reset(seed=0)
    angles = []
    for _ in range(300):
        observation, _ = env.reset()
        angles.append(observation[0:6:2] * math.pi / 2)
    angles = np.array(angles)
    assert np.all(angles >= JOINT_LOWER - 1e-9) and np.all(angles <= JOINT_UPPER + 1e-9)
    # The coxa covers its whole range; the others keep docs/reference/robot.md's +-pi/4.
    assert angles[:, 0].min() < -0.4 and angles[:, 0].max() > 0.4
    assert np.abs(angles[:, 1:]).max() <= math.pi / 4 + 1e-9
    assert np.abs(angles[:, 1:]).max() > 0.7


def test_targets_fill_the_box_scaled_by_delta():
    environment = KrabyOneLegEnv(delta=0.5)
    environment.reset(seed=1)
    targets = np.array([environment.reset()[0][6:9] for _ in range(300)])
    assert np.all(np.abs(targets) <= 0.5 + 1e-6)
    assert np.all(np.abs(targets).max(axis=0) > 0.45)
    environment.close()


def test_reset_options_fix_the_start_state(env):
    angles, target = (0.3, -0.5, 1.2), (0.2, -0.1, 0.15)
    observation, info = env.reset(seed=0, options={"joint_angles": angles, "target": target})
    np.testing.assert_allclose(observation[0:6:2], np.array(angles) * 2 / math.pi, atol=1e-6)
    np.testing.assert_array_equal(observation[1:6:2], 0.0)
    expected_target = (np.array(target) - TARGET_CENTRE) / TARGET_HALF_EXTENTS
    np.testing.assert_allclose(observation[6:9], expected_target, atol=1e-6)
    tip = info["tip_position"]
    assert info["distance"] == pytest.approx(np.linalg.norm(tip - np.array(target)))


@pytest.mark.parametrize(
    "options",
    [
        {"joint_angles": (0.5, 0.0, 0.0)},  # coxa beyond +-0.46
        {"joint_angles": (0.0, 0.0)},
        {"joint_angles": (0.0, float("nan"), 0.0)},
        {"target": (1.0, 0.0, 0.1)},
        {"target": "here"},
        {"angles": (0.0, 0.0, 0.0)},
    ],
)
def test_bad_reset_options_raise(env, options):
    with pytest.raises(ValueError, match="joint_angles|target|angles"):
        env.reset(seed=0, options=options)


# --- observations, reward, info -------------------------------------------------------


@pytest.mark.parametrize(
    ("observation", "size"),
    [("default", 9), ("with_tip", 12), ("with_tip_to_target", 12), ("sin_angles", 9)],
)
def test_observation_variants_shape_range_and_content(observation, size):
    environment = KrabyOneLegEnv(observation=observation)
    obs, info = environment.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(20):
        obs, reward, terminated, truncated, info = environment.step(rng.uniform(-1, 1, 3))
        assert obs.shape == (size,) and obs.dtype == np.float32
        assert np.all(np.abs(obs) <= 1.0)
        assert not terminated and not truncated
        assert reward == pytest.approx(-info["distance"] ** 2)
    tip = info["tip_position"]
    target = obs[6:9] * TARGET_HALF_EXTENTS + TARGET_CENTRE
    assert info["distance"] == pytest.approx(np.linalg.norm(tip - target), abs=1e-6)
    if observation == "with_tip":
        centre, half = (WORKSPACE_LOW + WORKSPACE_HIGH) / 2, (WORKSPACE_HIGH - WORKSPACE_LOW) / 2
        np.testing.assert_allclose(obs[9:12], (tip - centre) / half, atol=1e-6)
    if observation == "with_tip_to_target":
        np.testing.assert_allclose(obs[9:12], (target - tip) / TIP_TO_TARGET_SCALE, atol=1e-5)
    environment.close()


def test_sin_angles_variant_reads_the_same_state_as_default():
    default, sines = KrabyOneLegEnv(), KrabyOneLegEnv(observation="sin_angles")
    a, _ = default.reset(seed=5)
    b, _ = sines.reset(seed=5)
    np.testing.assert_allclose(b[0:6:2], np.sin(a[0:6:2] * math.pi / 2), atol=1e-6)
    np.testing.assert_array_equal(a[6:9], b[6:9])
    default.close()
    sines.close()


def test_actions_drive_joints_and_are_clipped():
    env_one, env_big = KrabyOneLegEnv(), KrabyOneLegEnv()
    start = {"joint_angles": (0.0, 0.0, 0.0), "target": tuple(TARGET_CENTRE)}
    env_one.reset(seed=0, options=start)
    env_big.reset(seed=0, options=start)
    obs_one = env_one.step(np.array([0.0, 1.0, -1.0]))[0]
    obs_big = env_big.step(np.array([0.0, 5.0, -5.0]))[0]
    np.testing.assert_array_equal(obs_one, obs_big)
    assert obs_one[2] > 0.05 and obs_one[4] < -0.05  # femur up, tibia down
    assert obs_one[3] > 0.5  # femur near its commanded top speed
    env_one.close()
    env_big.close()


def test_untrained_policy_scores_about_minus_half():
    environment = gym.make(kraby_envs.ENV_ID)
    environment.reset(seed=0)
    environment.action_space.seed(0)
    returns, total, done = [], 0.0, False
    while len(returns) < 10:
        _, reward, _, done, _ = environment.step(environment.action_space.sample())
        total += reward
        if done:
            returns.append(total)
            total = 0.0
            environment.reset()
    assert -2.0 < np.mean(returns) < -0.1
    environment.close()


# --- rendering ------------------------------------------------------------------------


def test_render_returns_an_image_of_leg_and_target():
    environment = KrabyOneLegEnv(render_mode="rgb_array", render_width=96, render_height=64)
    environment.reset(seed=0)
    image = environment.render()
    assert image.shape == (64, 96, 3) and image.dtype == np.uint8
    background = image[0, 0]
    assert np.any(np.any(image != background, axis=2))
    red, green, blue = (image[..., i].astype(int) for i in range(3))
    assert np.any((green > 150) & (red < 100) & (blue < 100)), "green target sphere not visible"
    environment.close()


def test_render_without_mode_returns_none(env):
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


# --- argument validation --------------------------------------------------------------

BAD_ARGUMENTS = [
    ("observation", "pixels"),
    ("delta", 1.5),
    ("delta", -0.1),
    ("delta", "half"),
    ("time_step", 0.0),
    ("time_step", float("inf")),
    ("frameskip", 0),
    ("frameskip", 2.5),
    ("frameskip", True),
    ("max_torque", -1.0),
    ("max_velocity", 0),
    ("reset_angle_range", -0.1),
    ("reset_angle_range", 4.0),
    ("render_mode", "human"),
    ("render_width", 0),
    ("render_height", 10_000),
]


@pytest.mark.parametrize(("name", "value"), BAD_ARGUMENTS)
def test_bad_argument_raises_value_error_naming_it(name, value):
    with pytest.raises(ValueError, match=name):
        KrabyOneLegEnv(**{name: value})


@pytest.mark.parametrize(("name", "value"), BAD_ARGUMENTS)
def test_validate_env_kwargs_refuses_without_physics(monkeypatch, name, value):
    def no_physics(*args, **kwargs):
        raise AssertionError("validation must not create a physics client")

    monkeypatch.setattr(p, "connect", no_physics)
    with pytest.raises(ValueError, match=name):
        validate_env_kwargs(**{name: value})
    validate_env_kwargs(observation="with_tip", delta=1, frameskip=np.int64(4))


def test_unknown_argument_is_named():
    with pytest.raises(ValueError, match="speed"):
        validate_env_kwargs(speed=3)


def test_set_config_changes_delta_but_not_observation(env):
    env.set_config(delta=0.0)
    observation, _ = env.reset(seed=0)
    np.testing.assert_allclose(observation[6:9], 0.0, atol=1e-6)
    with pytest.raises(ValueError, match="observation"):
        env.set_config(observation="with_tip")
    with pytest.raises(ValueError, match="delta"):
        env.set_config(delta=2.0)
