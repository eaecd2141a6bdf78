"""One PyBullet world holding any number of Kraby legs, stepped together.

Both environments are views over this class: the single env is a world of one leg and
the batched VecEnv a world of many, so their physics, start states and observations
cannot drift apart.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._bullet import p
from .config import LegConfig
from .observation import build_observations
from .robot import GRAVITY, create_ground, load_leg, skip_impossible_contacts
from .task import TARGET_CENTRE, apply_reset_options, sample_start, squared_distance

MIN_LEG_SPACING = 0.6
"""Metres between bases below which two legs (reach about 0.29 m) could touch."""

_TARGET_RADIUS = 0.01
_TARGET_RGBA = (0.1, 0.85, 0.2, 1.0)


def grid_positions(n_legs: int, spacing: float) -> np.ndarray:
    """Base positions of ``n_legs`` on a square grid, row by row, shape (n, 3)."""
    side = math.ceil(math.sqrt(n_legs))
    rows, cols = np.divmod(np.arange(n_legs), side)
    return np.stack([cols * spacing, rows * spacing, np.zeros(n_legs)], axis=1).astype(float)


def draw_start(
    rng: np.random.Generator, config: LegConfig, options: Mapping[str, Any] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The start angles and target of one episode: drawn from ``rng``, then ``options``.

    The generator is always consumed the same way, even when ``options`` fixes the start,
    so later episodes do not depend on options.
    """
    angles, target = sample_start(rng, config.reset_angle_range, config.delta)
    return apply_reset_options(options, angles, target)


def observe_legs(
    config: LegConfig,
    state: tuple[np.ndarray, np.ndarray, np.ndarray],
    targets: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observations (k, obs_size) float32, squared tip-target distances (k,) and tips (k, 3)
    of legs in ``state`` (angles, velocities, tips) reaching for ``targets`` (k, 3)."""
    angles, velocities, tips = state
    observations = build_observations(
        config.observation, angles, velocities, tips, targets, config.max_velocity
    )
    return observations, squared_distance(tips, targets), tips


def leg_info(tip: np.ndarray, squared_distance: float) -> dict[str, Any]:
    """The ``info`` entries every env reports for a leg: tip position and distance (m)."""
    return {"tip_position": np.array(tip), "distance": math.sqrt(squared_distance)}


class LegWorld:
    """Kraby legs and their targets in a single DIRECT-mode physics client.

    Positions exchanged with callers (targets, tips) are relative to each leg's base.

    Args:
        n_legs: Number of legs.
        config: Environment configuration.
        leg_spacing: Distance between neighbouring bases on the grid (m).
        bases: Base positions (n_legs, 3) instead of the grid: a shard of a larger world
            keeps its legs where the whole world has them, so that every leg computes
            bit for bit the same motion whichever world it is simulated in.
    """

    def __init__(
        self,
        n_legs: int,
        config: LegConfig,
        leg_spacing: float = 1.0,
        bases: np.ndarray | None = None,
    ) -> None:
        if not isinstance(leg_spacing, numbers.Real) or not leg_spacing >= MIN_LEG_SPACING:
            raise ValueError(f"leg_spacing must be >= {MIN_LEG_SPACING} m, got {leg_spacing!r}")
        if bases is not None and np.shape(bases) != (n_legs, 3):
            raise ValueError(f"bases must have shape ({n_legs}, 3), got {np.shape(bases)}")
        self.n_legs = n_legs
        self.config = config
        self._client = p.connect(p.DIRECT)
        p.setGravity(0.0, 0.0, GRAVITY, physicsClientId=self._client)
        p.setTimeStep(config.time_step, physicsClientId=self._client)
        # Sorted contact pairs make a leg's contacts solve in the same order whatever else
        # is in the world: without it, a leg among 32 drifts from the same leg alone.
        p.setPhysicsEngineParameter(deterministicOverlappingPairs=1, physicsClientId=self._client)
        ground = create_ground(self._client)
        self.bases = (
            grid_positions(n_legs, leg_spacing) if bases is None else np.array(bases, dtype=float)
        )
        self.legs = [load_leg(self._client, base) for base in self.bases]
        for leg in self.legs:
            skip_impossible_contacts(self._client, leg, ground)
        # Flat argument lists, built once, keep the per-step loops free of allocations.
        self._bodies = [leg.body_id for leg in self.legs]
        self._joints = list(self.legs[0].joint_indices)
        self._tip = self.legs[0].tip_link
        self.targets = np.tile(TARGET_CENTRE, (n_legs, 1))
        # Target markers only matter to the camera; without rendering they would cost
        # a body per leg in every physics step.
        self._markers: list[int] = []
        if config.render_mode == "rgb_array":
            marker = p.createVisualShape(
                p.GEOM_SPHERE,
                radius=_TARGET_RADIUS,
                rgbaColor=_TARGET_RGBA,
                physicsClientId=self._client,
            )
            self._markers = [
                p.createMultiBody(
                    baseMass=0.0,
                    baseCollisionShapeIndex=-1,
                    baseVisualShapeIndex=marker,
                    basePosition=(base + target).tolist(),
                    physicsClientId=self._client,
                )
                for base, target in zip(self.bases, self.targets, strict=True)
            ]

    def set_config(self, config: LegConfig) -> None:
        """Applies a new configuration; the observation variant is fixed at construction."""
        if config.observation != self.config.observation:
            raise ValueError("observation cannot change after construction: it fixes the space")
        self.config = config
        p.setTimeStep(config.time_step, physicsClientId=self._client)

    def reset_leg(
        self, index: int, rng: np.random.Generator, options: Mapping[str, Any] | None = None
    ) -> None:
        """Puts leg ``index`` at rest in a fresh start pose with a fresh target.

        Args:
            index: Leg index.
            rng: The leg's random generator; always consumed the same way, even when
                ``options`` fixes the start, so later episodes do not depend on options.
            options: Optional ``joint_angles`` and ``target`` overriding the draw.
        """
        self.place_leg(index, *draw_start(rng, self.config, options))

    def place_leg(self, index: int, angles: np.ndarray, target: np.ndarray) -> None:
        """Puts leg ``index`` at rest at joint ``angles`` (3,) with ``target`` (3,)."""
        body = self._bodies[index]
        for joint, angle in zip(self._joints, angles, strict=True):
            p.resetJointState(body, joint, float(angle), 0.0, physicsClientId=self._client)
        self.targets[index] = target
        if self._markers:
            p.resetBasePositionAndOrientation(
                self._markers[index],
                (self.bases[index] + target).tolist(),
                (0.0, 0.0, 0.0, 1.0),
                physicsClientId=self._client,
            )

    def step(self, actions: np.ndarray) -> None:
        """Drives every leg for one control period.

        Args:
            actions: Shape (n, 3), clipped to [-1, 1] and scaled to target velocities.
        """
        velocities = np.clip(actions, -1.0, 1.0) * self.config.max_velocity
        forces = [self.config.max_torque] * 3
        client = self._client
        for body, target in zip(self._bodies, velocities.tolist(), strict=True):
            p.setJointMotorControlArray(
                body,
                self._joints,
                p.VELOCITY_CONTROL,
                targetVelocities=target,
                forces=forces,
                physicsClientId=client,
            )
        for _ in range(self.config.frameskip):
            p.stepSimulation(physicsClientId=client)

    def read_state(
        self, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint angles, joint velocities and tip positions (base-relative), each (k, 3)."""
        bodies = self._bodies if indices is None else [self._bodies[i] for i in indices]
        client, joints, tip = self._client, self._joints, [self._tip]
        states = np.array(
            [
                [joint[:2] for joint in p.getJointStates(body, joints, physicsClientId=client)]
                for body in bodies
            ]
        )
        links = [
            p.getLinkStates(body, tip, computeForwardKinematics=True, physicsClientId=client)[0]
            for body in bodies
        ]
        # Index 4 is the URDF frame of the tip link (index 0 would be its centre of mass).
        tips = np.array([link[4] for link in links])
        tips -= self.bases if indices is None else self.bases[list(indices)]
        return states[:, :, 0], states[:, :, 1], tips

    def observe(
        self, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Observations, squared tip-target distances and tips of the selected legs.

        Returns:
            Observations (k, obs_size) float32, squared distances (k,), tips (k, 3).
        """
        targets = self.targets if indices is None else self.targets[list(indices)]
        return observe_legs(self.config, self.read_state(indices), targets)

    def render(self, index: int) -> np.ndarray:
        """An offscreen (tiny renderer) image of leg ``index`` and its target, (H, W, 3) uint8."""
        width, height = self.config.render_width, self.config.render_height
        view = p.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=(self.bases[index] + (0.15, 0.01, 0.14)).tolist(),
            distance=0.55,
            yaw=60.0,
            pitch=-20.0,
            roll=0.0,
            upAxisIndex=2,
            physicsClientId=self._client,
        )
        projection = p.computeProjectionMatrixFOV(
            fov=50.0, aspect=width / height, nearVal=0.01, farVal=3.0, physicsClientId=self._client
        )
        _, _, rgba, _, _ = p.getCameraImage(
            width,
            height,
            viewMatrix=view,
            projectionMatrix=projection,
            renderer=p.ER_TINY_RENDERER,
            physicsClientId=self._client,
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()

    def close(self) -> None:
        """Disconnects the physics client; safe to call twice."""
        if self._client >= 0:
            p.disconnect(physicsClientId=self._client)
            self._client = -1

    def __del__(self) -> None:
        # Environments are often dropped without close(); do not leak physics clients.
        try:
            self.close()
        except Exception:  # noqa: BLE001 - pybullet may already be gone at interpreter exit
            pass
