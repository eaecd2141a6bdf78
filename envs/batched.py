"""``KrabyBatchedVecEnv``: many Kraby legs in one physics world, as an SB3 ``VecEnv``.

All legs share one PyBullet client and one ``stepSimulation`` per sub-step; their bases
sit on a grid far enough apart that they never touch. With ``shards > 1`` the grid is
split into that many shards stepped in parallel, one process each (see
:mod:`kraby_envs.sharded`). Leg ``i`` draws its starts and targets from its own stream
(:mod:`kraby_envs.seeding`) and behaves exactly like a ``KrabyOneLegEnv`` whose generator is
that stream, driven by the same actions.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from .config import ENV_KWARGS, LegConfig, make_config
from .observation import observation_space
from .seeding import check_scheme, leg_generator, leg_streams
from .sharded import ShardedWorld
from .world import draw_start, leg_info


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


class KrabyBatchedVecEnv(VecEnv):
    """``n_envs`` Kraby legs simulated in one PyBullet world (or one per shard).

    Episodes end after ``max_episode_steps`` (a time limit, never a terminal state); the
    leg is then reset at once and its step ``info`` carries ``terminal_observation``,
    ``TimeLimit.truncated = True`` and ``episode = {"r", "l", "t"}`` exactly as SB3's
    ``VecMonitor`` writes it, so no monitor wrapper is needed. Every ``info`` also holds
    ``tip_position`` and ``distance`` like the single env.

    Args:
        n_envs: Number of legs.
        max_episode_steps: Episode length.
        leg_spacing: Distance between neighbouring bases (m), at least 0.6.
        shards: Shards that step the legs in parallel, one process each, this process's
            included (at most ``n_envs`` are used); 1 keeps every leg in this process.
            Every leg moves bit for bit the same for any number.
        seeding: How ``seed(s)`` gives each leg its stream: ``streams`` (child ``i`` of
            ``SeedSequence(s)``) or ``offset`` (``s + i``); see :mod:`kraby_envs.seeding`.
        **env_kwargs: Keyword arguments of :class:`kraby_envs.KrabyOneLegEnv`.

    Raises:
        ValueError: When an argument is invalid; the message names it.
    """

    def __init__(
        self,
        n_envs: int = 32,
        *,
        max_episode_steps: int = 32,
        leg_spacing: float = 1.0,
        shards: int = 1,
        seeding: str = "streams",
        **env_kwargs: Any,
    ) -> None:
        n_envs = _positive_int("n_envs", n_envs)
        self.seeding = check_scheme(seeding)
        self.max_episode_steps = _positive_int("max_episode_steps", max_episode_steps)
        self.config: LegConfig = make_config(**env_kwargs)
        self.render_mode = self.config.render_mode
        shards = _positive_int("shards", shards)
        self._world = ShardedWorld(n_envs, self.config, leg_spacing, shards)
        self._rngs: list[np.random.Generator | None] = [None] * n_envs
        self._streams: list[np.random.SeedSequence | None] = [None] * n_envs
        self._actions = np.zeros((n_envs, 3))
        # float32 sums and int32 lengths, as VecMonitor accumulates them.
        self._episode_returns = np.zeros(n_envs, dtype=np.float32)
        self._episode_lengths = np.zeros(n_envs, dtype=np.int32)
        self._t_start = time.time()
        super().__init__(
            n_envs,
            observation_space(self.config.observation),
            spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32),
        )

    # --- configuration -------------------------------------------------------------

    def set_config(self, **changes: Any) -> None:
        """Changes configuration values for every leg (see ``KrabyOneLegEnv.set_config``)."""
        for fixed in ("observation", "render_mode"):
            if fixed in changes and changes[fixed] != getattr(self.config, fixed):
                raise ValueError(f"{fixed} cannot change after construction")
        self.config = self.config.replace(**changes)
        self._world.set_config(self.config)

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Gives every leg a new stream from the run's ``seed`` at the next reset, by the
        env's seeding scheme; None picks a fresh base seed. Returns the seed each leg's
        stream comes from: ``seed + i`` (offset) or ``seed`` itself (streams)."""
        if seed is None:
            # OS entropy rather than SB3's draw from the global numpy state.
            seed = int(np.random.SeedSequence().entropy) % 2**63  # type: ignore[arg-type]
        self._streams = list(leg_streams(int(seed), self.num_envs, self.seeding))
        offset = self.seeding == "offset"
        self._seeds = [int(seed) + i if offset else int(seed) for i in range(self.num_envs)]
        return self._seeds

    # --- stepping ------------------------------------------------------------------

    def _reset_legs(self, indices: list[int]) -> None:
        starts = []
        for index in indices:
            stream = self._streams[index]
            if stream is not None:
                self._rngs[index] = leg_generator(stream)
                self._streams[index] = None
            elif self._rngs[index] is None:
                self._rngs[index] = leg_generator(np.random.SeedSequence())
            starts.append(draw_start(self._rngs[index], self.config, self._options[index]))  # type: ignore[arg-type]
        self._world.place_legs(indices, starts)
        self._episode_returns[indices] = 0.0
        self._episode_lengths[indices] = 0

    def reset(self) -> VecEnvObs:
        """Resets every leg, using the seeds and options set since the last reset."""
        self._reset_legs(list(range(self.num_envs)))
        self._reset_seeds()
        self._reset_options()
        observations, squared, tips = self._world.observe()
        self.reset_infos = [leg_info(tip, d2) for tip, d2 in zip(tips, squared, strict=True)]
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=float).reshape(self.num_envs, 3)

    def step_wait(self) -> VecEnvStepReturn:
        self._world.step(self._actions)
        observations, squared, tips = self._world.observe()
        rewards = (-squared).astype(np.float32)
        self._episode_returns += rewards
        self._episode_lengths += 1
        dones = self._episode_lengths >= self.max_episode_steps
        infos = [leg_info(tip, d2) for tip, d2 in zip(tips, squared, strict=True)]
        if dones.any():
            finished = np.flatnonzero(dones).tolist()
            elapsed = round(time.time() - self._t_start, 6)
            for index in finished:
                infos[index]["terminal_observation"] = observations[index]
                infos[index]["TimeLimit.truncated"] = True
                infos[index]["episode"] = {
                    "r": self._episode_returns[index],
                    "l": self._episode_lengths[index],
                    "t": elapsed,
                }
            self._reset_legs(finished)
            observations = observations.copy()
            observations[finished] = self._world.observe(finished)[0]
        return observations, rewards, dones, infos

    # --- rendering and lifecycle ---------------------------------------------------

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One (H, W, 3) uint8 image per leg when ``render_mode == "rgb_array"``."""
        if self.render_mode != "rgb_array":
            gym.logger.warn("get_images() needs render_mode='rgb_array'; nothing rendered")
            return [None] * self.num_envs
        return [self._world.render(index) for index in range(self.num_envs)]

    def close(self) -> None:
        self._world.close()

    # --- SB3 attribute and method access -------------------------------------------
    # The legs share one configuration, so attributes are world-wide: get_attr repeats
    # the value per index and set_attr/set_config must address every leg.

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        # A missing name raises AttributeError, which SB3's has_attr relies on.
        value = getattr(self.config if attr_name in ENV_KWARGS else self, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._require_all(indices, f"set_attr({attr_name!r})")
        if attr_name not in ENV_KWARGS:
            raise AttributeError(f"{attr_name!r} is not settable; settable: {list(ENV_KWARGS)}")
        self.set_config(**{attr_name: value})

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Calls ``render`` per leg, or ``set_config`` once for the whole world."""
        selected = list(self._get_indices(indices))
        if method_name == "render":
            return [self._world.render(index) for index in selected]
        if method_name == "set_config":
            self._require_all(indices, "env_method('set_config')")
            self.set_config(*method_args, **method_kwargs)
            return [None] * len(selected)
        raise AttributeError(
            f"env_method supports 'render' and 'set_config', not {method_name!r}"
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def _require_all(self, indices: VecEnvIndices, what: str) -> None:
        selected: Iterable[int] = self._get_indices(indices)
        if sorted(selected) != list(range(self.num_envs)):
            raise ValueError(f"{what} applies to every leg of the shared world; pass indices=None")


def make_batched(
    n_envs: int = 32,
    seed: int | None = 0,
    max_episode_steps: int = 32,
    shards: int = 1,
    seeding: str = "streams",
    **env_kwargs: Any,
) -> KrabyBatchedVecEnv:
    """Builds the batched VecEnv, every leg on its own stream of ``seed``.

    Args:
        n_envs: Number of legs.
        seed: Base seed, or None for OS entropy.
        max_episode_steps: Episode length.
        shards: Shards that step the legs in parallel, one process each (at most
            ``n_envs`` are used); 1 keeps every leg in this process.
        seeding: ``streams`` or ``offset`` (:mod:`kraby_envs.seeding`).
        **env_kwargs: ``leg_spacing`` and the keyword arguments of ``KrabyOneLegEnv``.

    Returns:
        The VecEnv, seeded for its first reset.
    """
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer)):
        raise ValueError(f"seed must be an integer or None, got {seed!r}")
    env = KrabyBatchedVecEnv(
        n_envs, max_episode_steps=max_episode_steps, shards=shards, seeding=seeding,
        **env_kwargs
    )
    env.seed(seed)
    return env
