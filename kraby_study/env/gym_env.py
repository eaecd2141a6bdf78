"""``env=gym``: any registered Gymnasium environment, by its id.

A run's n_envs envs are SB3's ``DummyVecEnv`` of ``Monitor``-wrapped ``gymnasium.make(id)``,
optionally under ``VecNormalize``. They are seeded like the leg's legs (`kraby_envs.seeding`), not
by SB3's ``seed + i``: under ``streams`` env i takes child i of ``numpy.random.SeedSequence(seed)``
and draws three 64-bit words from it (``generate_state(3, numpy.uint64)``): the seed of its first
reset, of its action space and of its observation space. Gymnasium then seeds the env's own
generator from the first word and keeps that stream across later resets. Under ``offset`` env i is
seeded with ``seed + i`` for all three, as SB3 does. A run's evaluation episodes are reset with
seeds drawn from its own evaluation stream (`kraby_envs.seeding.evaluation_stream`, a child of its
seed's sequence apart from its sub-envs'), so no two runs of different seeds share a test episode; a
study with ``eval_set: fixed`` takes one set for every run
([`EVALUATION_ENTROPY`][kraby_study.env.gym_env.EVALUATION_ENTROPY]).
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Iterator, Mapping, Sequence
from functools import cache
from importlib import metadata
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from kraby_study.env.adapter import Frame
from kraby_study.env.evaluation import Evaluation, lockstep_returns
from kraby_study.errors import ConfigError, first_line

EVALUATION_ENTROPY = 0x6B726162795F6576616C
"""Entropy of the shared evaluation set (``eval_set: fixed``), and of the GIF's episodes: episode k
resets with a word of child k. A training stream is a child of SeedSequence(run seed), whose entropy
is the run's seed: no run seed below 2**80 gives this sequence."""

GIF_EPISODES = 2
"""Evaluation episodes the GIF draws."""
GIF_MAX_STEPS = 300
"""At most this many steps of each episode are drawn (a GIF of thousands of frames is no use)."""
FRAME_MS = 40
"""Duration of a frame when the env names no render fps."""
HOLD_MS = 700

ACTIONS = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)
"""Action spaces SB3's PPO takes."""
OBSERVATIONS = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)
"""Observation spaces its MlpPolicy takes (a Dict needs MultiInputPolicy, not offered)."""



def evaluation_seeds(episodes: int, seed: int | None = None) -> list[int]:
    """The reset seed of each evaluation episode of the run with seed ``seed``: a word of each
    child of its evaluation stream (`kraby_envs.seeding.evaluation_stream`); ``None``: the set every
    run shared before ([`EVALUATION_ENTROPY`][kraby_study.env.gym_env.EVALUATION_ENTROPY]). The
    first k of n are those of k."""
    from kraby_envs.seeding import evaluation_stream

    stream = (np.random.SeedSequence(EVALUATION_ENTROPY) if seed is None
              else evaluation_stream(seed))
    return [int(child.generate_state(1, np.uint64)[0]) for child in stream.spawn(episodes)]


def import_packages(packages: Sequence[str]) -> None:
    """Import the packages that register ids; ConfigError naming one that fails."""
    for name in packages:
        try:
            importlib.import_module(str(name))
        except Exception as err:  # any failure of a user's package is one line
            raise ConfigError(f"env.packages: cannot import {name!r}: "
                              f"{type(err).__name__}: {first_line(err)}") from None


def make_kwargs(env: Mapping[str, Any]) -> dict[str, Any]:
    """Keyword arguments of ``gymnasium.make`` for the settings (time limit included)."""
    kwargs = dict(env.get("kwargs") or {})
    if env.get("max_episode_steps") is not None:
        kwargs["max_episode_steps"] = int(env["max_episode_steps"])
    return kwargs


@cache
def _spaces(env_id: str, kwargs_json: str, packages: tuple[str, ...]) -> tuple[Any, Any]:
    """The (observation, action) spaces of an id made once with its kwargs."""
    import_packages(packages)
    try:
        gym.spec(env_id)
    except gym.error.Error as err:
        hint = "" if packages else " (an id of another package needs env.packages=[PACKAGE])"
        raise ConfigError(f"env.id {env_id!r} is not a registered Gymnasium id: "
                          f"{first_line(err)}{hint}") from None
    try:
        made = gym.make(env_id, **json.loads(kwargs_json))
    except Exception as err:  # a wrong keyword, a missing dependency: one line either way
        raise ConfigError(f"env {env_id} cannot be made with env.kwargs "
                          f"{json.loads(kwargs_json)}: {type(err).__name__}: "
                          f"{first_line(err)}") from None
    try:
        return made.observation_space, made.action_space
    finally:
        made.close()


def env_spaces(env: Mapping[str, Any]) -> tuple[Any, Any]:
    """The observation and action spaces of the settings' env (made once per process)."""
    kwargs = json.dumps(make_kwargs(env), sort_keys=True, default=str)
    return _spaces(str(env["id"]), kwargs, tuple(str(p) for p in env.get("packages") or ()))


def _plain(value: Any) -> Any:
    """A config node's value as plain Python (dicts and lists)."""
    from omegaconf import OmegaConf

    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


class GymAdapter:
    """A Gymnasium environment, behind the seam (see
    [`EnvAdapter`][kraby_study.env.adapter.EnvAdapter])."""

    kind = "gym"
    shown = (f"in its first {GIF_EPISODES} evaluation episodes (seeded resets, at most "
             f"{GIF_MAX_STEPS} steps each)")
    view = (1.0, 0.5, 0.5)

    def validate(self, env: Mapping[str, Any], ppo: Mapping[str, Any] | None = None) -> None:
        from omegaconf import OmegaConf

        if OmegaConf.is_config(env) and OmegaConf.is_missing(env, "id"):
            raise ConfigError("env=gym needs env.id=ID, a registered Gymnasium id (e.g. "
                              "env.id=Pendulum-v1)")
        if not str(env["id"]).strip():
            raise ConfigError("env.id must name a registered Gymnasium id, got ''")
        steps = env.get("max_episode_steps")
        if steps is not None and int(steps) < 1:
            raise ConfigError(f"env.max_episode_steps must be at least 1 (or null: the id's "
                              f"own limit), got {steps}")
        env = {**env, "kwargs": _plain(env.get("kwargs")), "packages": _plain(env.get("packages"))}
        observation, action = env_spaces(env)
        if not isinstance(observation, OBSERVATIONS):
            raise ConfigError(f"env {env['id']}: its observation space {observation} is not "
                              "one PPO's MlpPolicy takes (a Box or a discrete space)")
        if not isinstance(action, ACTIONS):
            raise ConfigError(f"env {env['id']}: its action space {action} is not one PPO "
                              "takes (Box, Discrete, MultiDiscrete or MultiBinary)")
        if bool(env.get("normalize")) and not isinstance(observation, spaces.Box):
            raise ConfigError(f"env.normalize needs a Box observation space; {env['id']} has "
                              f"{observation}")
        if ppo is not None and bool(ppo.get("use_sde", False)) \
                and not isinstance(action, spaces.Box):
            raise ConfigError(f"ppo.use_sde needs continuous (Box) actions; {env['id']} has "
                              f"{action}")

    def make_vec(self, env: Mapping[str, Any], n_envs: int, seed: int, seeding: str,
                 shards: int = 1, gamma: float = 0.99) -> Any:
        from stable_baselines3.common.monitor import Monitor
        from stable_baselines3.common.vec_env import VecNormalize

        from kraby_study.env.gym_vec import StreamSeededVecEnv

        import_packages(env.get("packages") or ())
        env_id, kwargs = str(env["id"]), make_kwargs(env)
        vec = StreamSeededVecEnv([lambda: Monitor(gym.make(env_id, **kwargs))] * n_envs,
                                 seeding)
        if bool(env.get("normalize")):
            vec = VecNormalize(vec, norm_obs=True, norm_reward=bool(env.get("normalize_reward",
                                                                               True)),
                               gamma=gamma)
        return vec

    def evaluate(self, model: Any, env: Mapping[str, Any], episodes: int,
                 normalizer: Any = None, seed: int | None = None) -> Evaluation:
        import_packages(env.get("packages") or ())
        env_id, kwargs = str(env["id"]), make_kwargs(env)

        def act(observations: np.ndarray) -> np.ndarray:
            seen = normalizer.normalize_obs(observations) if normalizer is not None \
                else observations
            return model.predict(seen, deterministic=True)[0]

        resets = [{"seed": s} for s in evaluation_seeds(episodes, seed)]
        return Evaluation(tuple(lockstep_returns(lambda: gym.make(env_id, **kwargs), resets,
                                                 act)))

    def frames(self, model: Any, env: Mapping[str, Any], size: tuple[int, int],
               normalizer: Any = None) -> Iterator[Frame]:
        import_packages(env.get("packages") or ())
        made = gym.make(str(env["id"]), render_mode="rgb_array", **make_kwargs(env))
        fps = made.metadata.get("render_fps") or 1000 / FRAME_MS
        period = max(20, int(round(1000 / float(fps))))
        seeds = evaluation_seeds(GIF_EPISODES)
        try:
            for index, seed in enumerate(seeds):
                name = f"episode {index + 1}/{len(seeds)}"
                observation, _ = made.reset(seed=seed)
                yield Frame(made.render(), f"{name}  step 0", period)
                total, step, ended = 0.0, 0, False
                while not ended:
                    observation, reward, ended = _step(made, model, observation, normalizer)
                    total += reward
                    step += 1
                    ended = ended or step >= GIF_MAX_STEPS
                    yield Frame(made.render(), f"{name}  step {step}  return {total:.4g}",
                                HOLD_MS if ended else period)
        finally:
            made.close()

    def describe(self, env: Mapping[str, Any]) -> dict[str, str]:
        import_packages(env.get("packages") or ())
        entry = gym.spec(str(env["id"])).entry_point
        module = entry.split(":", 1)[0] if isinstance(entry, str) else \
            getattr(entry, "__module__", "unknown")
        top = module.split(".", 1)[0]
        dists = metadata.packages_distributions().get(top, [])
        package = dists[0] if dists else top
        try:
            version = metadata.version(package)
        except metadata.PackageNotFoundError:
            version = "unknown"
        return {"env_id": str(env["id"]), "env_package": package, "env_version": version}

    def label(self, env: Mapping[str, Any]) -> str:
        facts = self.describe(env)
        extras = [f"kwargs {dict(_plain(env['kwargs']))}" if env.get("kwargs") else "",
                  f"{env['max_episode_steps']}-step episodes"
                  if env.get("max_episode_steps") is not None else "",
                  "VecNormalize" + ("" if env.get("normalize_reward", True) else
                                    " (observations only)") if env.get("normalize") else ""]
        shown = "; ".join(e for e in extras if e)
        return (f"gym {facts['env_id']} ({facts['env_package']} {facts['env_version']})"
                + (f": {shown}" if shown else ""))

    def time_limit(self, env: Mapping[str, Any]) -> int | None:
        if env.get("max_episode_steps") is not None:
            return int(env["max_episode_steps"])
        import_packages(env.get("packages") or ())
        registered = gym.spec(str(env["id"])).max_episode_steps
        return int(registered) if registered is not None else None


def _step(env: Any, model: Any, observation: Any, normalizer: Any) -> tuple[Any, float, bool]:
    """One step of the deterministic policy (on the observation as it learnt to see it):
    the next observation, the reward, and whether the episode ended."""
    seen = normalizer.normalize_obs(observation) if normalizer is not None else observation
    action = model.predict(seen, deterministic=True)[0]
    observation, reward, terminated, truncated, _ = env.step(action)
    return observation, float(reward), bool(terminated or truncated)


GYM = GymAdapter()
