"""The Kraby leg as a PyBullet body: physical constants, URDF loading and the ground plane.

Every number here comes from docs/reference/robot.md; the kinematic chain itself lives in
``assets/kraby_leg.urdf``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._bullet import p

URDF_PATH = Path(__file__).resolve().parent / "assets" / "kraby_leg.urdf"

JOINT_NAMES: tuple[str, str, str] = ("coxa", "femur", "tibia")
TIP_LINK_NAME = "tip"

JOINT_LOWER = np.array([-0.46, -1.57, -1.57])
JOINT_UPPER = np.array([0.46, 1.57, 1.57])

GRAVITY = -9.81

GROUND_CLEAR_LINKS: tuple[str, ...] = ("body", "servo_0", "bracket", "servo_1", "servo_2")
"""Links that stay at least 13 cm above the ground over the whole joint range."""
NEVER_TOUCHING_PAIRS: tuple[tuple[str, str], ...] = (("servo_1", "tip"), ("servo_2", "tip"))
"""Self-collision pairs at least 4.5 cm apart over the whole joint range."""

TIP_DYNAMICS: dict[str, float] = {
    "lateralFriction": 0.7,
    "rollingFriction": 0.7,
    "spinningFriction": 0.1,
    "contactStiffness": 10000.0,
    "contactDamping": 1000.0,
}


@dataclass(frozen=True)
class LegHandle:
    """Indices of one loaded leg inside a physics client.

    Attributes:
        body_id: PyBullet body unique id.
        joint_indices: Indices of the coxa, femur and tibia joints, in that order.
        tip_link: Index of the ``tip`` link.
        base_position: World position of the leg's base (the body frame), shape (3,).
        link_indices: Index of every link by name; the base, ``body``, is -1.
    """

    body_id: int
    joint_indices: tuple[int, int, int]
    tip_link: int
    base_position: np.ndarray
    link_indices: dict[str, int]


def load_leg(client: int, base_position: np.ndarray | tuple[float, float, float]) -> LegHandle:
    """Loads one leg with its body fixed at ``base_position``.

    Self-collision is on between the leg's links; PyBullet leaves out parent-child pairs.

    Args:
        client: PyBullet physics client id.
        base_position: World position of the body frame.

    Returns:
        The handle with the leg's joint and tip link indices.
    """
    base = np.asarray(base_position, dtype=float)
    body = p.loadURDF(
        str(URDF_PATH),
        basePosition=base.tolist(),
        useFixedBase=True,
        flags=p.URDF_USE_SELF_COLLISION,
        physicsClientId=client,
    )
    by_joint: dict[str, int] = {}
    by_link: dict[str, int] = {"body": -1}
    for index in range(p.getNumJoints(body, physicsClientId=client)):
        info = p.getJointInfo(body, index, physicsClientId=client)
        by_joint[info[1].decode()] = index
        by_link[info[12].decode()] = index
    joints = tuple(by_joint[name] for name in JOINT_NAMES)
    tip = by_link[TIP_LINK_NAME]
    p.changeDynamics(body, tip, physicsClientId=client, **TIP_DYNAMICS)
    # A leg resting between episodes must not fall asleep and ignore motor commands.
    p.changeDynamics(
        body, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=client
    )
    return LegHandle(body, joints, tip, base, by_link)  # type: ignore[arg-type]


def skip_impossible_contacts(client: int, leg: LegHandle, ground: int) -> None:
    """Drops collision pairs that can never come within contact distance.

    The gaps of :data:`GROUND_CLEAR_LINKS` to the ground and of
    :data:`NEVER_TOUCHING_PAIRS` stay far above Bullet's 2 cm contact threshold at every
    joint angle (a test checks it), so these pairs never produce a contact point: skipping
    them leaves the physics unchanged (bit for bit) and saves collision work.

    Args:
        client: PyBullet physics client id.
        leg: The loaded leg.
        ground: Body id of the ground plane.
    """
    links = leg.link_indices
    for name in GROUND_CLEAR_LINKS:
        p.setCollisionFilterPair(ground, leg.body_id, -1, links[name], 0, physicsClientId=client)
    for first, second in NEVER_TOUCHING_PAIRS:
        p.setCollisionFilterPair(
            leg.body_id, leg.body_id, links[first], links[second], 0, physicsClientId=client
        )


def create_ground(client: int) -> int:
    """Adds a static ground plane at z = 0 and returns its body id."""
    shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    return p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape, physicsClientId=client)
