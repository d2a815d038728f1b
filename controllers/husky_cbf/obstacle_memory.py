"""What husky-cbf remembers of obstacles its sensor no longer sees.

A sensor with a limited field of view (a Husky's lidar sees about 270 degrees) loses an obstacle
the moment the robot turns or backs away from it; the obstacle is still there. Planning and the
safety filter on what is in view alone would reverse the robot into a post it passed a second ago.
So, as a costmap's obstacle layer keeps what it marked (Nav2), the memory keeps each obstacle last
measured where the sensor cannot see now:

- a static obstacle, for as long as it stays out of view;
- a mover, predicted at its measured velocity, for at most MOVER_MEMORY_S, with its age, so that
  the safety filter grows its circle by the bound on its change of velocity over all that time.

A remembered obstacle is forgotten once it is measured again (a measurement near where it is
predicted) or once the sensor could see it and does not: it lies within the field of view and no
static obstacle in view stands between it and the robot. With a full circle of view the memory
holds nothing: every obstacle is either measured or gone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from controllers.husky_cbf.movers import is_static
from controllers.husky_cbf.planner import segment_blocked
from controllers.obstacles import Obstacle

#: A mover out of view is predicted this long (s) at most: long enough to cover a walker crossing
#: the sector behind the robot, short enough that its circle, grown by the bound on its change of
#: velocity over that time, stays of a walker's scale
MOVER_MEMORY_S = 3.0
#: A measurement of the same kind (static or moving) whose centre lies within this (m) of where
#: a remembered obstacle is predicted, plus half the mover's predicted travel, is that obstacle
#: measured again; farther, it is another (neighbouring posts of a wall stand farther apart)
SAME_OBSTACLE_M = 0.3


@dataclass(frozen=True)
class Remembered:
    """An obstacle as last measured, and when (s)."""

    obstacle: Obstacle
    measured_s: float

    def now(self, t_s: float) -> Obstacle:
        """The obstacle predicted to `t_s` at its measured velocity."""
        age = t_s - self.measured_s
        ob = self.obstacle
        return replace(ob, x_m=ob.x_m + ob.vx_mps * age, y_m=ob.y_m + ob.vy_mps * age)


class ObstacleMemory:
    """The memory (module docstring) of a sensor with a field of view of `fov_deg` (deg), centred
    on the robot's heading."""

    def __init__(self, fov_deg: float) -> None:
        self.half_fov_rad = math.radians(min(fov_deg, 360.0)) / 2.0
        self.reset()

    def reset(self) -> None:
        self._kept: list[Remembered] = []

    @property
    def remembers(self) -> bool:
        """Whether anything can be out of view at all."""
        return self.half_fov_rad < math.pi

    def update(
        self, pose: np.ndarray, measured: Sequence[Obstacle], t_s: float
    ) -> tuple[list[Obstacle], np.ndarray]:
        """The obstacles to plan with at `t_s` (s), the robot at `pose` [x, y, theta]: those
        `measured` now, then those remembered (predicted to now), and each one's age (s since it
        was measured: 0 for the measured ones)."""
        measured = list(measured)
        if not self.remembers:
            return measured, np.zeros(len(measured))
        # the measured static obstacles, which hide what lies behind them
        occluders = np.array([(o.x_m, o.y_m, o.radius_m) for o in measured if is_static(o)]).reshape(-1, 3)
        kept = [r for r in self._kept if self._still_unseen(r, pose, measured, occluders, t_s)]
        self._kept = [Remembered(o, t_s) for o in measured] + kept
        ages = np.array([0.0] * len(measured) + [t_s - r.measured_s for r in kept])
        return measured + [r.now(t_s) for r in kept], ages

    def _still_unseen(
        self,
        remembered: Remembered,
        pose: np.ndarray,
        measured: Sequence[Obstacle],
        occluders: np.ndarray,
        t_s: float,
    ) -> bool:
        """Whether a remembered obstacle is kept: not too old (a mover), not measured again, and
        out of the sensor's sight (`occluders`: the measured static circles [x, y, r], m)."""
        moving = not is_static(remembered.obstacle)
        if moving and t_s - remembered.measured_s > MOVER_MEMORY_S:
            return False
        ob = remembered.now(t_s)
        travel_m = math.hypot(ob.vx_mps, ob.vy_mps) * (t_s - remembered.measured_s)
        for seen in measured:
            off_m = math.hypot(seen.x_m - ob.x_m, seen.y_m - ob.y_m)
            if off_m < SAME_OBSTACLE_M + 0.5 * travel_m and is_static(seen) != moving:
                return False  # measured again
        return not self._in_sight(ob, pose, occluders)

    def _in_sight(self, ob: Obstacle, pose: np.ndarray, occluders: np.ndarray) -> bool:
        """Whether the sensor at `pose` would surely see `ob`: wholly within its field of view (a
        circle on its edge, or seen from a pose a latency old, may be missed), and none of the
        `occluders` (circles [x, y, r], m) between them."""
        dx, dy = ob.x_m - float(pose[0]), ob.y_m - float(pose[1])
        distance = math.hypot(dx, dy)
        if distance <= ob.radius_m:
            return True  # over the robot: nothing hides it
        bearing = math.remainder(math.atan2(dy, dx) - float(pose[2]), 2 * math.pi)
        half_width = math.asin(min(ob.radius_m / distance, 1.0))  # the circle's angular half width
        if abs(bearing) + half_width > self.half_fov_rad:
            return False
        return not segment_blocked(np.asarray(pose[:2], dtype=float), np.array([ob.x_m, ob.y_m]), occluders)
