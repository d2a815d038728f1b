"""Clearance between the Husky's collision shapes and every obstacle, from the physics engine.

getClosestPoints is exact but costs ~15 us per obstacle, more than a physics step, so a cheap
bound filters first: the centre distance minus the obstacle radius minus the radius of a circle
that encloses the robot's footprint is a lower bound of the true distance (the body stays near
level on flat ground). Obstacles whose bound exceeds `exact_within_m` are not queried and their
bound is reported; every obstacle closer than that gets the engine's signed distance, so a
contact (distance <= 0) is never missed and any clearance below `exact_within_m` is exact.
Arena walls are half-planes n . p <= d; their bound is d - n . p - the footprint radius.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from husky_sim.sim.bullet import pybullet as p


class ClearanceMonitor:
    """Signed distance (m, negative = penetration) of the robot to each obstacle body."""

    def __init__(
        self,
        client: int,
        robot_body: int,
        obstacle_bodies: Sequence[int],
        obstacle_radii_m: Sequence[float],
        robot_bound_radius_m: float,
        exact_within_m: float = 0.5,
        walls: Sequence[tuple[int, np.ndarray, float]] = (),
    ) -> None:
        self.client = client
        self.robot = robot_body
        self.bodies = list(obstacle_bodies)
        self.radii = np.asarray(obstacle_radii_m, dtype=float)
        self.bound = robot_bound_radius_m
        self.exact_within_m = exact_within_m
        self.walls = list(walls)  # (body, inward normal, offset)
        self.queries = 0  # getClosestPoints calls made (for the benchmark)

    def _exact(self, body: int, lower_bound: float) -> float:
        self.queries += 1
        pts = p.getClosestPoints(
            self.robot, body, distance=self.exact_within_m + self.bound, physicsClientId=self.client
        )
        return min(pt[8] for pt in pts) if pts else max(lower_bound, self.exact_within_m)

    def wall_distances(self, robot_xy: np.ndarray) -> np.ndarray:
        """Per-wall clearance (m), exact below exact_within_m."""
        lower = np.array([d - float(n @ robot_xy) - self.bound for _, n, d in self.walls])
        return np.array(
            [
                self._exact(body, lb) if lb <= self.exact_within_m else lb
                for (body, _, _), lb in zip(self.walls, lower, strict=True)
            ]
        )

    def distances(self, robot_xy: np.ndarray, obstacle_xy: np.ndarray) -> np.ndarray:
        """Per-obstacle clearance (m): exact below exact_within_m, a lower bound above."""
        if not self.bodies:
            return np.zeros(0)
        lower = np.linalg.norm(obstacle_xy - robot_xy, axis=1) - self.radii - self.bound
        out = lower.copy()
        for i in np.flatnonzero(lower <= self.exact_within_m):
            out[i] = self._exact(self.bodies[i], lower[i])
        return out
