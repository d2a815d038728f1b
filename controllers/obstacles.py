"""Circular obstacles as the controller sees them, their prediction over the horizon, and the
reduction of many obstacles to the NLP's fixed number of slots.

Slot policy: an NLP is built for `obstacle_slots` obstacles. With fewer obstacles the unused slots
are parked PARKING_DISTANCE_M away from the robot with radius 0, where their constraints are
inactive. With more, the `obstacle_slots` obstacles with the smallest surface distance
(centre distance minus radius) to the robot are kept, and the rest are ignored for this step.
Surface distance now is what a constraint of the first predicted steps binds on, costs one pass
over the obstacles (a thousand in a large world), and is stable from step to step. Its limit: a
fast mover still far off can lose its slot to near static posts until it is near; judging by the
smallest predicted distance over the horizon would keep it, but would change which obstacles
husky-cbf (6 slots) already sees on shipped scenarios with more obstacles than that.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.config import ObstaclePrediction

#: Distance (m) at which unused obstacle slots are parked: far beyond any horizon's reach.
PARKING_DISTANCE_M = 100.0


@dataclass(frozen=True)
class Obstacle:
    """A circle at (x, y) (m) with a radius (m) moving at constant velocity (vx, vy) (m/s)."""

    x_m: float
    y_m: float
    radius_m: float
    vx_mps: float = 0.0
    vy_mps: float = 0.0

    def __post_init__(self) -> None:
        if not self.radius_m >= 0:
            raise ValueError(f"radius_m: must be >= 0 m, got {self.radius_m}")

    def position_after(self, dt_s: float | np.ndarray) -> np.ndarray:
        """Constant-velocity position (m) dt_s seconds from now; shape (2,) or (len(dt), 2)."""
        dt = np.asarray(dt_s, dtype=float)
        return np.stack([self.x_m + self.vx_mps * dt, self.y_m + self.vy_mps * dt], axis=-1)


def surface_distance(position_xy: np.ndarray, obstacle: Obstacle) -> float:
    """Distance (m) from a point to the obstacle's boundary (negative inside)."""
    return float(np.hypot(position_xy[0] - obstacle.x_m, position_xy[1] - obstacle.y_m)) - (obstacle.radius_m)


def select_nearest(obstacles: Sequence[Obstacle], position_xy: np.ndarray, count: int) -> list[Obstacle]:
    """The `count` obstacles nearest (by surface distance, as surface_distance works it out) to
    position_xy, in their given order; on ties, the earlier ones."""
    if len(obstacles) <= count:
        return list(obstacles)
    data = np.array([(o.x_m, o.y_m, o.radius_m) for o in obstacles])
    distance = np.hypot(position_xy[0] - data[:, 0], position_xy[1] - data[:, 1]) - data[:, 2]
    chosen = np.sort(np.argsort(distance, kind="stable")[:count])
    return [obstacles[i] for i in chosen.tolist()]


def predict_obstacles(
    obstacles: Sequence[Obstacle],
    robot_xy: np.ndarray,
    slots: int,
    tau_s: float,
    horizon: int,
    mode: ObstaclePrediction,
) -> tuple[np.ndarray, np.ndarray]:
    """Obstacle centres over the horizon, shape (slots, N+1, 2), and radii, shape (slots,).

    `constant-velocity` moves each obstacle by its velocity times k tau; `frozen` keeps every
    predicted step at the current position, as the paper's p(k) does.
    """
    chosen = select_nearest(obstacles, robot_xy, slots)
    offsets = tau_s * np.arange(horizon + 1) if mode == "constant-velocity" else np.zeros(horizon + 1)
    centres = np.empty((slots, horizon + 1, 2))
    radii = np.zeros(slots)
    n = len(chosen)
    if n:  # all chosen obstacles at once: x + v dt, as Obstacle.position_after computes it
        data = np.array([(o.x_m, o.y_m, o.vx_mps, o.vy_mps, o.radius_m) for o in chosen])
        centres[:n] = data[:, None, 0:2] + data[:, None, 2:4] * offsets[None, :, None]
        radii[:n] = data[:, 4]
    centres[n:] = np.asarray(robot_xy, dtype=float) + [PARKING_DISTANCE_M, 0.0]
    return centres, radii
