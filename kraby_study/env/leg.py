"""``env=leg``: the Kraby leg (package ``kraby_envs``), the only place the orchestrator
imports it from.

Its vectorised env is the batched world of ``n_envs`` legs (split into shards stepped in
parallel); evaluation runs the deterministic policy from rest to targets drawn from the run's
own evaluation stream (`kraby_envs.rollout.evaluation_targets`; a study with ``eval_set: fixed``:
`kraby_envs.rollout.fixed_targets`, one set for every run), and the GIF draws it reaching the first
fixed targets.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from kraby_study.env.adapter import Frame
from kraby_study.env.evaluation import Evaluation, lockstep_returns
from kraby_study.errors import ConfigError

DEFAULTS: dict[str, Any] = {"observation": "default", "delta": 0.5, "time_step": 0.05 / 12,
                            "frameskip": 12, "max_episode_steps": 32}
"""The leg's settings as ``env=leg`` gives them (conf/env/leg.yaml), for settings that lack
one (a model drawn from settings stored by an older version)."""

GIF_TARGETS = 3
"""Episodes the GIF draws: the first fixed targets (the evaluation set ``eval_set: fixed``)."""
GIF_STEPS = 32
"""Env steps per target in the GIF."""
HOLD_MS = 700
"""How long the last frame of each target stays on screen."""
LOCKSTEP = 16
"""Legs stepped side by side in an evaluation (each its own physics world)."""


def leg_kwargs(env: Mapping[str, Any]) -> dict[str, Any]:
    """Keyword arguments of the leg environment (the time limit is passed separately)."""
    merged = {**DEFAULTS, **dict(env)}
    return {"observation": str(merged["observation"]), "delta": float(merged["delta"]),
            "time_step": float(merged["time_step"]), "frameskip": int(merged["frameskip"])}


class LegAdapter:
    """The leg, behind the seam (see [`EnvAdapter`][kraby_study.env.adapter.EnvAdapter])."""

    kind = "leg"
    shown = f"reaching {GIF_TARGETS} fixed targets"
    # The camera sees far more than the leg's workspace: keep its middle.
    view = (0.7, 0.48, 0.45)

    def validate(self, env: Mapping[str, Any], ppo: Mapping[str, Any] | None = None) -> None:
        from kraby_envs import validate_env_kwargs

        try:
            validate_env_kwargs(**leg_kwargs(env))
        except ValueError as err:
            raise ConfigError(f"env: {err}") from None
        steps = int(env["max_episode_steps"])
        if steps < 1:
            raise ConfigError(f"env.max_episode_steps must be at least 1, got {steps}")

    def make_vec(self, env: Mapping[str, Any], n_envs: int, seed: int, seeding: str,
                 shards: int = 1, gamma: float = 0.99) -> Any:
        from kraby_envs import make_batched

        return make_batched(n_envs=n_envs, seed=seed,
                            max_episode_steps=int(env["max_episode_steps"]), shards=shards,
                            seeding=seeding, **leg_kwargs(env))

    def evaluate(self, model: Any, env: Mapping[str, Any], episodes: int,
                 normalizer: Any = None, seed: int | None = None) -> Evaluation:
        import gymnasium as gym

        import kraby_envs
        from kraby_envs.rollout import START_ANGLES, evaluation_targets, fixed_targets

        kwargs = leg_kwargs(env)
        targets = (fixed_targets(episodes, kwargs["delta"]) if seed is None
                   else evaluation_targets(episodes, kwargs["delta"], seed))
        resets = [{"options": {"joint_angles": START_ANGLES,
                               "target": tuple(float(x) for x in target)}}
                  for target in targets]

        def make() -> Any:
            return gym.make(kraby_envs.ENV_ID, max_episode_steps=int(env["max_episode_steps"]),
                            **kwargs)

        def act(observations: np.ndarray) -> np.ndarray:
            return model.predict(observations, deterministic=True)[0]

        return Evaluation(tuple(lockstep_returns(make, resets, act, LOCKSTEP)))

    def frames(self, model: Any, env: Mapping[str, Any], size: tuple[int, int],
               normalizer: Any = None) -> Iterator[Frame]:
        import gymnasium as gym

        import kraby_envs
        from kraby_envs.rollout import fixed_targets, rollout

        kwargs = leg_kwargs(env)

        def act(observation: Any) -> Any:
            return model.predict(observation, deterministic=True)[0]

        # Rendered at twice the size: the report crops and shrinks it (anti-aliased).
        leg = gym.make(kraby_envs.ENV_ID, render_mode="rgb_array", render_width=2 * size[0],
                       render_height=2 * size[1], max_episode_steps=GIF_STEPS, **kwargs)
        period_ms = int(round(1000 * kwargs["time_step"] * kwargs["frameskip"]))
        try:
            targets = fixed_targets(GIF_TARGETS, kwargs["delta"])
            for index, target in enumerate(targets):
                for moment in rollout(leg, act, target, seed=index):
                    caption = (f"target {index + 1}/{len(targets)}  "
                               f"t={moment.step * period_ms / 1000:.2f} s  "
                               f"{100 * moment.info['distance']:.1f} cm")
                    yield Frame(leg.render(), caption,
                                HOLD_MS if moment.ended else max(period_ms, 20))
        finally:
            leg.close()

    def describe(self, env: Mapping[str, Any]) -> dict[str, str]:
        return {}

    def label(self, env: Mapping[str, Any]) -> str:
        return (f"leg (KrabyOneLeg-v0 of kraby_envs: observation {env['observation']}, "
                f"{env['max_episode_steps']}-step episodes)")

    def time_limit(self, env: Mapping[str, Any]) -> int | None:
        # Every episode of the leg lasts exactly this long: it is truncated, never terminated.
        return int(env["max_episode_steps"])


LEG = LegAdapter()
