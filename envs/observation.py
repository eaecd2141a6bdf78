"""The four observation variants, shared by the single and the batched environment.

Every variant starts with the joint block ``[a0, v0, a1, v1, a2, v2]`` (coxa, femur,
tibia) followed by the normalised target; two variants append a further 3-vector.
All values are float32 in [-1, 1]:

- angle: ``angle * 2 / pi`` (the femur and tibia limits +-1.57 map to about +-1), or
  ``sin(angle)`` in the ``sin_angles`` variant;
- velocity: ``clip(velocity / max_velocity, -1, 1)``;
- target: ``(target - TARGET_CENTRE) / TARGET_HALF_EXTENTS``, the full (``delta = 1``) box,
  so a given position reads the same whatever ``delta`` is; with ``delta = 0.5`` targets
  fill [-0.5, 0.5];
- tip (``with_tip``): ``(tip - centre) / half_extents`` of the reachable workspace box;
- tip-to-target (``with_tip_to_target``): ``(target - tip) / 0.3 m``, one scale for all
  three axes so the vector keeps its direction; every component of a reachable gap is
  below 0.28 m.

Positions are relative to the leg's base. Everything is clipped to [-1, 1] as a guard
against small joint-limit overshoots.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from .task import TARGET_CENTRE, TARGET_HALF_EXTENTS, WORKSPACE_HIGH, WORKSPACE_LOW

OBSERVATIONS: tuple[str, ...] = ("default", "with_tip", "with_tip_to_target", "sin_angles")
"""Observation variants, in the order of docs/reference/robot.md's observation study."""

TIP_TO_TARGET_SCALE = 0.3
"""Metres mapped to 1 in the tip-to-target vector."""

_WORKSPACE_CENTRE = (WORKSPACE_LOW + WORKSPACE_HIGH) / 2
_WORKSPACE_HALF = (WORKSPACE_HIGH - WORKSPACE_LOW) / 2
_SIZES = {"default": 9, "with_tip": 12, "with_tip_to_target": 12, "sin_angles": 9}


def observation_size(variant: str) -> int:
    """Number of values in an observation of ``variant``."""
    return _SIZES[variant]


def observation_space(variant: str) -> spaces.Box:
    """The Box space of one observation of ``variant``."""
    return spaces.Box(-1.0, 1.0, shape=(observation_size(variant),), dtype=np.float32)


def build_observations(
    variant: str,
    angles: np.ndarray,
    velocities: np.ndarray,
    tips: np.ndarray,
    targets: np.ndarray,
    max_velocity: float,
) -> np.ndarray:
    """Builds the observations of several legs at once.

    Args:
        variant: One of :data:`OBSERVATIONS`.
        angles: Joint angles (rad), shape (n, 3).
        velocities: Joint velocities (rad/s), shape (n, 3).
        tips: Tip positions relative to each base (m), shape (n, 3).
        targets: Target positions relative to each base (m), shape (n, 3).
        max_velocity: Joint speed that maps to 1.

    Returns:
        Array of shape (n, observation_size(variant)), float32, within [-1, 1].
    """
    out = np.empty((angles.shape[0], _SIZES[variant]))
    out[:, 0:6:2] = np.sin(angles) if variant == "sin_angles" else angles * (2 / np.pi)
    out[:, 1:6:2] = velocities / max_velocity
    out[:, 6:9] = (targets - TARGET_CENTRE) / TARGET_HALF_EXTENTS
    if variant == "with_tip":
        out[:, 9:12] = (tips - _WORKSPACE_CENTRE) / _WORKSPACE_HALF
    elif variant == "with_tip_to_target":
        out[:, 9:12] = (targets - tips) / TIP_TO_TARGET_SCALE
    np.clip(out, -1.0, 1.0, out=out)
    return out.astype(np.float32)
