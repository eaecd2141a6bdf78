"""``KrabyOneLegEnv``: one Kraby leg reaching for a random target (Gymnasium API)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .config import LegConfig, make_config
from .observation import observation_space
from .world import LegWorld, leg_info

_DEFAULTS = LegConfig()


class KrabyOneLegEnv(gym.Env[np.ndarray, np.ndarray]):
    """One leg of the Kraby hexapod, bolted to its body, moving its tip onto a target.

    - Action: 3 values in [-1, 1] (coxa, femur, tibia); each joint is velocity-controlled
      towards ``action * max_velocity`` with at most ``max_torque``.
    - Observation: see :mod:`kraby_envs.observation` for the variants and normalisations.
    - Reward: minus the squared tip-target distance (m^2), every step.
    - Episodes: no terminal state; registered as ``KrabyOneLeg-v0`` with a 32-step limit.
    - Reset: the leg starts at rest. Each joint angle is uniform in
      ``[-reset_angle_range, reset_angle_range]`` intersected with the joint's limits, so
      with the default pi/4 the coxa is uniform in its own +-0.46 rad (see
      :func:`kraby_envs.task.reset_angle_bounds`). The target is uniform in the box of
      centre (0.219, 0.020, 0.128) m and half-extents (0.069, 0.153, 0.072) m x ``delta``.
      ``reset(options={"joint_angles": (c, f, t), "target": (x, y, z)})`` fixes either
      part (angles within the joint limits, target within the ``delta = 1`` box).
    - ``info`` of reset and step: ``tip_position`` (3,) and ``distance`` (m).

    Args:
        observation: Observation variant, one of ``kraby_envs.OBSERVATIONS``.
        delta: Scale of the target box, in [0, 1].
        time_step: Physics time step (s).
        frameskip: Physics sub-steps per env step.
        max_torque: Maximum motor torque (N m).
        max_velocity: Joint speed commanded by action 1 (rad/s).
        reset_angle_range: Half-width of the start-angle interval (rad).
        render_mode: None or ``"rgb_array"`` (offscreen tiny renderer).
        render_width: Width of rendered images (pixels).
        render_height: Height of rendered images (pixels).

    Raises:
        ValueError: When an argument is invalid; the message names it.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        *,
        observation: str = _DEFAULTS.observation,
        delta: float = _DEFAULTS.delta,
        time_step: float = _DEFAULTS.time_step,
        frameskip: int = _DEFAULTS.frameskip,
        max_torque: float = _DEFAULTS.max_torque,
        max_velocity: float = _DEFAULTS.max_velocity,
        reset_angle_range: float = _DEFAULTS.reset_angle_range,
        render_mode: str | None = _DEFAULTS.render_mode,
        render_width: int = _DEFAULTS.render_width,
        render_height: int = _DEFAULTS.render_height,
    ) -> None:
        self.config = make_config(
            observation=observation,
            delta=delta,
            time_step=time_step,
            frameskip=frameskip,
            max_torque=max_torque,
            max_velocity=max_velocity,
            reset_angle_range=reset_angle_range,
            render_mode=render_mode,
            render_width=render_width,
            render_height=render_height,
        )
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.config.control_period)}
        self.observation_space = observation_space(observation)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self._world = LegWorld(1, self.config)
        self._has_reset = False

    def set_config(self, **changes: Any) -> None:
        """Changes configuration values (e.g. ``delta`` for a curriculum) from the next step.

        ``observation`` and ``render_mode`` are fixed at construction.

        Raises:
            ValueError: On an invalid value or a fixed argument.
        """
        for fixed in ("observation", "render_mode"):
            if fixed in changes and changes[fixed] != getattr(self.config, fixed):
                raise ValueError(f"{fixed} cannot change after construction")
        self.config = self.config.replace(**changes)
        self._world.set_config(self.config)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts an episode; see the class docstring for the start distribution."""
        super().reset(seed=seed)
        self._world.reset_leg(0, self.np_random, options)
        self._has_reset = True
        observations, squared, tips = self._world.observe()
        return observations[0], leg_info(tips[0], squared[0])

    def step(
        self, action: np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Advances one control period (``frameskip`` physics steps)."""
        if not self._has_reset:
            raise RuntimeError("call reset() before step()")
        self._world.step(np.asarray(action, dtype=float).reshape(1, 3))
        observations, squared, tips = self._world.observe()
        return observations[0], -float(squared[0]), False, False, leg_info(tips[0], squared[0])

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """Returns an (H, W, 3) uint8 image of the leg and its target (green sphere)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode='rgb_array'; nothing rendered")
            return None
        return self._world.render(0)

    def close(self) -> None:
        """Releases the physics client."""
        self._world.close()
