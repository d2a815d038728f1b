"""An episode's first contact, classified: which body the robot touched, and whether the robot was
moving (the collision is its fault) or standing still when it was hit (passive motion safety:
a robot at rest cannot be blamed for what walks into it).

The first contact is the first physics step whose clearance is <= 0 (husky_sim.sim.collision).
Its speeds are those going into that step: the engine resolves the contact within the step, so
afterwards a robot that was hit has been pushed, and one that drove into a post has been stopped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

#: A robot whose planar speed (m/s) going into its first contact is above this was moving: the
#: collision is its fault; at or below, it was standing still when hit.
AT_FAULT_SPEED_MPS = 0.05
#: Obstacles asked for the touched body at a first contact: those with the smallest lower bound
#: of their clearance (centre distance minus radius), nearest first; the walls are always asked.
CANDIDATE_OBSTACLES = 4


@dataclass(frozen=True)
class Contact:
    """The first contact of an episode (units in the names)."""

    t_s: float  # sim time of the physics step (or, on the kinematic plant, control step) it began
    obstacle: int | None  # index in the world's obstacle order; None: an arena wall
    robot_speed_mps: float  # |planar velocity| of the robot going into the contact
    relative_speed_mps: float  # |robot velocity - the touched body's velocity| (a wall stands still)

    @property
    def at_fault(self) -> bool:
        """The robot was moving (above AT_FAULT_SPEED_MPS) when the contact began."""
        return self.robot_speed_mps > AT_FAULT_SPEED_MPS


def classify(
    t_s: float,
    obstacle: int | None,
    robot_velocity_mps: tuple[float, float],
    obstacle_velocity_mps: tuple[float, float] = (0.0, 0.0),
) -> Contact:
    """The contact with `obstacle` (None: a wall) at t_s (s), from the planar velocities (m/s,
    world frame) of the robot and of the touched body."""
    vx, vy = robot_velocity_mps
    ox, oy = obstacle_velocity_mps
    return Contact(t_s, obstacle, math.hypot(vx, vy), math.hypot(vx - ox, vy - oy))


def planar_velocity(client: int, body: int) -> tuple[float, float]:
    """A body's planar linear velocity (m/s, world frame) as the engine has it (its base frame)."""
    from husky_sim.sim.bullet import pybullet as p  # here: the kinematic plant needs no engine

    linear, _ = p.getBaseVelocity(body, physicsClientId=client)
    return float(linear[0]), float(linear[1])


def touched_body(
    client: int,
    robot_body: int,
    robot_xy: Sequence[float],
    obstacle_bodies: Sequence[int],
    obstacle_xy: Sequence[Sequence[float]],
    obstacle_radii_m: Sequence[float],
    wall_bodies: Sequence[int],
) -> int | None:
    """The obstacle (its index) or wall (None) whose engine distance to the robot is smallest:
    asked of the CANDIDATE_OBSTACLES obstacles with the smallest bound and every wall (ties: the
    obstacle first, then the lower index). Without any engine point within 0.05 m, the obstacle
    with the smallest bound (None without obstacles)."""
    from husky_sim.sim.bullet import pybullet as p

    x, y = float(robot_xy[0]), float(robot_xy[1])
    bounds = sorted(
        (math.hypot(ox - x, oy - y) - radius, i)
        for i, ((ox, oy), radius) in enumerate(zip(obstacle_xy, obstacle_radii_m, strict=True))
    )
    candidates: list[tuple[int, int | None]] = [
        (obstacle_bodies[i], i) for _, i in bounds[:CANDIDATE_OBSTACLES]
    ]
    candidates += [(body, None) for body in wall_bodies]
    best: tuple[float, int, int] | None = None  # (distance m, walls after obstacles, index)
    found: int | None = None
    for body, index in candidates:
        points = p.getClosestPoints(robot_body, body, distance=0.05, physicsClientId=client)
        if not points:
            continue
        key = (min(point[8] for point in points), index is None, -1 if index is None else index)
        if best is None or key < best:
            best, found = key, index
    if best is None:
        return bounds[0][1] if bounds else None
    return found
