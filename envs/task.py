"""The reaching task: where targets and start poses come from, and how the tip is scored.

All positions are relative to the leg's own base, so a leg placed anywhere in a shared
world sees exactly the same task as a leg at the origin.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .robot import JOINT_LOWER, JOINT_UPPER

TARGET_CENTRE = np.array([0.219, 0.020, 0.128])
TARGET_HALF_EXTENTS = np.array([0.069, 0.153, 0.072])
"""Half-extents of the target box at ``delta = 1``."""

WORKSPACE_LOW = np.array([0.011, -0.074, 0.056])
WORKSPACE_HIGH = np.array([0.289, 0.097, 0.333])
"""Bounds of the tip positions reachable within the joint limits."""

RESET_OPTION_KEYS = ("joint_angles", "target")


def reset_angle_bounds(reset_angle_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint interval the start angles are drawn from.

    docs/reference/robot.md draws every joint in [-range, range], which for the default pi/4 is
    wider than the coxa's +-0.46 limits. We draw from the intersection of that interval with
    each joint's limits: still uniform, and always a legal pose. Clipping instead would
    pile about 41 % of the coxa starts onto its two limits.

    Args:
        reset_angle_range: Half-width of the nominal start interval (rad).

    Returns:
        Lower and upper bounds, each of shape (3,).
    """
    return np.maximum(-reset_angle_range, JOINT_LOWER), np.minimum(reset_angle_range, JOINT_UPPER)


def sample_start(
    rng: np.random.Generator, reset_angle_range: float, delta: float
) -> tuple[np.ndarray, np.ndarray]:
    """Draws the joint angles and the target for one episode.

    The draw order (3 angles, then 3 target components) is part of the seeding contract:
    a batched leg and a single env with the same seed must consume the stream identically.

    Args:
        rng: The episode's random generator.
        reset_angle_range: Half-width of the start interval, see :func:`reset_angle_bounds`.
        delta: Scale of the target box in [0, 1].

    Returns:
        Joint angles (3,) and target position relative to the base (3,).
    """
    low, high = reset_angle_bounds(reset_angle_range)
    angles = rng.uniform(low, high)
    half = TARGET_HALF_EXTENTS * delta
    target = rng.uniform(TARGET_CENTRE - half, TARGET_CENTRE + half)
    return angles, target


def _vector3(options: Mapping[str, Any], key: str) -> np.ndarray:
    try:
        value = np.asarray(options[key], dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"reset option {key!r} must be 3 numbers, got {options[key]!r}") from error
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ValueError(f"reset option {key!r} must be 3 finite numbers, got {options[key]!r}")
    return value


def apply_reset_options(
    options: Mapping[str, Any] | None, angles: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Overrides a sampled start with the ``joint_angles`` / ``target`` reset options.

    Args:
        options: ``reset(options=...)``; either key may be left out.
        angles: Sampled joint angles (3,).
        target: Sampled target (3,).

    Returns:
        The start joint angles and target.

    Raises:
        ValueError: On an unknown key, a malformed vector, angles outside the joint
            limits, or a target outside the full (``delta = 1``) target box.
    """
    if not options:
        return angles, target
    unknown = sorted(set(options) - set(RESET_OPTION_KEYS))
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; allowed: {list(RESET_OPTION_KEYS)}")
    if "joint_angles" in options:
        angles = _vector3(options, "joint_angles")
        if np.any(angles < JOINT_LOWER) or np.any(angles > JOINT_UPPER):
            raise ValueError(
                f"reset option 'joint_angles' {angles.tolist()} outside the joint limits "
                f"{JOINT_LOWER.tolist()} .. {JOINT_UPPER.tolist()}"
            )
    if "target" in options:
        target = _vector3(options, "target")
        low, high = TARGET_CENTRE - TARGET_HALF_EXTENTS, TARGET_CENTRE + TARGET_HALF_EXTENTS
        if np.any(target < low - 1e-12) or np.any(target > high + 1e-12):
            raise ValueError(
                f"reset option 'target' {target.tolist()} outside the target box "
                f"{low.round(4).tolist()} .. {high.round(4).tolist()}"
            )
    return angles, target


def squared_distance(tips: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Squared tip-target distance (m^2) per leg; the reward is its negative."""
    diff = tips - targets
    return np.einsum("ij,ij->i", diff, diff)
