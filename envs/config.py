"""Validated keyword arguments of the Kraby environments.

:func:`validate_env_kwargs` checks a configuration without creating a physics client, so
an orchestrator can refuse a bad config before any work starts.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any

from .observation import OBSERVATIONS

RENDER_MODES: tuple[str | None, ...] = (None, "rgb_array")
MAX_RENDER_SIZE = 4096


def _number(name: str, value: Any) -> float:
    # bool is an int subclass: True as a time step is a bug, not a number.
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return float(value)


def _integer(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be in [{low}, {high}], got {value!r}")
    return int(value)


@dataclass(frozen=True)
class LegConfig:
    """Everything a user may vary in the Kraby leg environments.

    Attributes:
        observation: Observation variant, one of ``OBSERVATIONS``.
        delta: Scale of the target box, in [0, 1].
        time_step: Physics time step (s), in (0, 0.1].
        frameskip: Physics sub-steps per env step, an integer in [1, 1000].
        max_torque: Maximum motor torque (N m), > 0; by default the most the simulation
            gives each servo.
        max_velocity: Joint speed for action 1 (rad/s), > 0; also normalises velocities.
            By default the top speed of the Herkulex DRS-0101 servo.
        reset_angle_range: Half-width of the start-angle interval (rad), in [0, pi].
        render_mode: None or ``"rgb_array"``.
        render_width: Width of rendered images (pixels).
        render_height: Height of rendered images (pixels).
    """

    observation: str = "default"
    delta: float = 0.5
    time_step: float = 0.05 / 12
    frameskip: int = 12
    max_torque: float = 1.57
    max_velocity: float = 6.308
    reset_angle_range: float = math.pi / 4
    render_mode: str | None = None
    render_width: int = 320
    render_height: int = 240

    def __post_init__(self) -> None:
        if self.observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {self.observation!r}")
        checked: dict[str, Any] = {
            "delta": _number("delta", self.delta),
            "time_step": _number("time_step", self.time_step),
            "frameskip": _integer("frameskip", self.frameskip, 1, 1000),
            "max_torque": _number("max_torque", self.max_torque),
            "max_velocity": _number("max_velocity", self.max_velocity),
            "reset_angle_range": _number("reset_angle_range", self.reset_angle_range),
            "render_width": _integer("render_width", self.render_width, 1, MAX_RENDER_SIZE),
            "render_height": _integer("render_height", self.render_height, 1, MAX_RENDER_SIZE),
        }
        if not 0.0 <= checked["delta"] <= 1.0:
            raise ValueError(f"delta must be in [0, 1], got {self.delta!r}")
        if not 0.0 < checked["time_step"] <= 0.1:
            raise ValueError(f"time_step must be in (0, 0.1] seconds, got {self.time_step!r}")
        for name in ("max_torque", "max_velocity"):
            if checked[name] <= 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0.0 <= checked["reset_angle_range"] <= math.pi:
            raise ValueError(
                f"reset_angle_range must be in [0, pi] radians, got {self.reset_angle_range!r}"
            )
        if self.render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be one of {RENDER_MODES}, got {self.render_mode!r}")
        # Store plain Python numbers so configs compare and serialise predictably.
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    @property
    def control_period(self) -> float:
        """Simulated seconds per env step."""
        return self.time_step * self.frameskip

    def replace(self, **changes: Any) -> LegConfig:
        """Returns a validated copy with ``changes`` applied (see :func:`validate_env_kwargs`)."""
        return make_config(**{**dataclasses.asdict(self), **changes})


ENV_KWARGS: tuple[str, ...] = tuple(field.name for field in dataclasses.fields(LegConfig))


def make_config(**kwargs: Any) -> LegConfig:
    """Builds a :class:`LegConfig`, rejecting unknown names with a ValueError.

    Raises:
        ValueError: Naming the offending argument and what is allowed.
    """
    unknown = sorted(set(kwargs) - set(ENV_KWARGS))
    if unknown:
        raise ValueError(f"unknown env argument(s) {unknown}; allowed: {list(ENV_KWARGS)}")
    return LegConfig(**kwargs)


def validate_env_kwargs(**kwargs: Any) -> None:
    """Checks environment keyword arguments without creating a physics client.

    Raises:
        ValueError: Naming the offending argument and what is allowed.
    """
    make_config(**kwargs)
