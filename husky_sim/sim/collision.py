"""Clearance between the Husky's collision shapes and every obstacle and wall, from the physics
engine, every physics step.

getClosestPoints is exact but costs up to ~20 us per body, a third of a physics step, so a cheap
bound filters first: the centre distance minus the obstacle radius minus the radius of a circle
that encloses the robot's footprint is a lower bound of the true distance (the body stays near
level on flat ground); an arena wall is a half-plane n . p <= d with bound d - n . p - that
radius. A body whose bound exceeds `exact_within_m` is not queried and its bound stands for its
clearance; a closer one gets the engine's signed distance, so a contact (distance <= 0) is never
missed and any clearance below `exact_within_m` is exact.

The closed loop needs only the smallest clearance of a control period, which lets `smallest` ask
less and get the same number: bodies are taken nearest bound first; one whose bound is at least
the smallest clearance so far cannot lower it and is not queried; and once that smallest
clearance is in (0, exact_within_m], a query asks only for closest points below it. The engine
then returns the same distance (bit for bit: the suite's logs are unchanged) with fewer points to
work out, or none when the body cannot lower it. A penetration is always asked with the full
threshold: the engine's penetration depths depend on it.

From NUMPY_FROM obstacles on, their bounds are worked out together with numpy (the same
arithmetic as one at a time, so the same numbers) and only the bodies the walk can reach are
ordered: those whose bound is within exact_within_m, then the nearest beyond it, whose bound ends
the walk, so a step's cost no longer grows with a Python loop and a sort over every obstacle;
below NUMPY_FROM, numpy's per-call overheads cost more than the loop (`husky-sim bench-sim`
times both worlds).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from husky_sim.sim.bullet import pybullet as p

#: Obstacles from which `smallest` works out their bounds with numpy (fewer: a Python loop, which
#: is faster for a handful of bodies than numpy's per-call overheads).
NUMPY_FROM = 32


class ClearanceMonitor:
    """Signed distance (m, negative = penetration) of the robot to the nearest obstacle or wall."""

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
        self.radii = [float(r) for r in obstacle_radii_m]
        self.bound = robot_bound_radius_m
        self.exact_within_m = exact_within_m
        # each wall: its body, inward normal n and offset d (inside where n . p <= d)
        self.walls = [(body, (float(n[0]), float(n[1])), float(d)) for body, n, d in walls]
        self.queries = 0  # getClosestPoints calls made (for the benchmark and tests)
        self._radii = np.array(self.radii, dtype=float)
        self._obstacle_ids = np.array(self.bodies, dtype=np.int64)

    def smallest(self, robot_xy: Sequence[float], obstacle_xy: np.ndarray, below: float = math.inf) -> float:
        """The smallest clearance (m) of the robot at `robot_xy` to the obstacles (centres
        `obstacle_xy`, shape (n, 2)) and walls, or `below` if that is smaller: exact where it is
        at most exact_within_m, else the smallest bound. `below` carries the smallest clearance of
        the physics steps before (a control period's running minimum)."""
        x, y = float(robot_xy[0]), float(robot_xy[1])
        if len(self.bodies) < NUMPY_FROM:
            walk = []  # (lower bound m, body), every body
            for (ox, oy), radius, body in zip(obstacle_xy.tolist(), self.radii, self.bodies, strict=True):
                dx, dy = ox - x, oy - y
                walk.append((math.sqrt(dx * dx + dy * dy) - radius - self.bound, body))
            for body, (nx, ny), d in self.walls:
                walk.append((d - (nx * x + ny * y) - self.bound, body))
            walk.sort()  # nearest bound first (ties by body id)
        else:
            centres = np.asarray(obstacle_xy, dtype=float).reshape(-1, 2)
            if len(centres) != len(self.bodies):
                raise ValueError(f"obstacle_xy: {len(centres)} centres for {len(self.bodies)} obstacles")
            dx, dy = centres[:, 0] - x, centres[:, 1] - y
            walk = self._walk(x, y, np.sqrt(dx * dx + dy * dy) - self._radii - self.bound)
        best = below
        for lower, body in walk:
            if lower >= best:
                break  # this body and all after it are at least `best` away
            if lower > self.exact_within_m:
                best = lower
                continue
            exact_below = 0.0 < best <= self.exact_within_m  # no closest point beyond it matters
            reach = best if exact_below else self.exact_within_m + self.bound
            self.queries += 1
            points = p.getClosestPoints(self.robot, body, distance=reach, physicsClientId=self.client)
            if points:
                best = min(best, min(point[8] for point in points))
            elif not exact_below:  # beyond the reach of any body point within exact_within_m
                best = min(best, max(lower, self.exact_within_m))
        return best

    def _walk(self, x: float, y: float, bounds: np.ndarray) -> list[tuple[float, int]]:
        """(bound m, body) of the bodies `smallest` may reach from (x, y) (m), nearest bound first
        (ties by body id), given the obstacles' bounds (m): every obstacle and wall within
        exact_within_m, then the nearest beyond it (if it is reached, its bound is the smallest
        clearance, and every body after it is at least that far)."""
        inside = bounds <= self.exact_within_m
        walk = list(zip(bounds[inside].tolist(), self._obstacle_ids[inside].tolist(), strict=True))
        beyond: tuple[float, int] | None = None
        if not inside.all():
            rest = np.where(inside, np.inf, bounds)
            ties = np.flatnonzero(rest == rest.min())
            j = int(ties[np.argmin(self._obstacle_ids[ties])])
            beyond = (float(rest[j]), int(self._obstacle_ids[j]))
        for body, (nx, ny), d in self.walls:
            wall = (d - (nx * x + ny * y) - self.bound, body)
            if wall[0] <= self.exact_within_m:
                walk.append(wall)
            elif beyond is None or wall < beyond:
                beyond = wall
        walk.sort()
        return walk if beyond is None else [*walk, beyond]
