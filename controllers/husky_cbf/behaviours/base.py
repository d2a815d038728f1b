"""The interface every husky-cbf behaviour implements: it reads a `Situation` and may propose a
`Target` for the NMPC to track instead of the reference (`Behaviour.propose`); the arbiter
(arbiter.py) chooses among the proposals."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np

from controllers.obstacles import Obstacle

#: A trajectory slower than this (m/s) now will not come to the robot: the robot is brought onto
#: it as onto a set-point's point (behaviours.approach.PointApproach), and may wait there for movers
SLOW_REFERENCE_MPS = 0.1


class ReferenceKind(Enum):
    """What the robot is asked to do: reach a set-point, stay with a trajectory too slow to come
    to it (SLOW_REFERENCE_MPS), or track a trajectory."""

    SET_POINT = "set-point"
    SLOW_TRAJECTORY = "slow trajectory"
    TRAJECTORY = "trajectory"

    @classmethod
    def of(cls, set_point: bool, speed_mps: float) -> ReferenceKind:
        """The kind of a reference that is a set-point or not, moving at `speed_mps` now."""
        if set_point:
            return cls.SET_POINT
        return cls.SLOW_TRAJECTORY if speed_mps < SLOW_REFERENCE_MPS else cls.TRAJECTORY


@dataclass(frozen=True)
class Target:
    """Where to go now (m, m, rad) and the path it was taken from ((K, 2), m)."""

    x_m: float
    y_m: float
    heading_rad: float
    path: np.ndarray

    @property
    def state(self) -> np.ndarray:
        """[x, y, heading] (m, m, rad)."""
        return np.array([self.x_m, self.y_m, self.heading_rad])


@dataclass(frozen=True)
class Situation:
    """What a behaviour judges, once per control step.

    pose: the measured pose [x, y, theta] (m, m, rad); estimate: the filtered pose on which the
    set-point approach decides (localisation.PoseFilter); speed_mps: the commanded speed where the
    plan starts; kind: the reference's kind; goal: where the robot is going [x, y, heading] (the
    set-point, or the tracking goal ahead on a trajectory); reference_state, reference_speed_mps:
    the reference now, and its speed; obstacles: as measured; circles: the obstacles inflated by
    the robot's disc radius and margin, not swept (movers.MoverModel.body_circles); command: the
    last command sent [v, omega] (m/s, rad/s); t: the time (s)."""

    pose: np.ndarray
    estimate: np.ndarray
    speed_mps: float
    kind: ReferenceKind
    goal: np.ndarray
    reference_state: np.ndarray
    reference_speed_mps: float
    obstacles: Sequence[Obstacle]
    circles: np.ndarray
    command: np.ndarray
    t: float


class Behaviour(Protocol):
    """One behaviour: a target to track instead of the reference, or None; and a reset (a new run)."""

    def propose(self, situation: Situation) -> Target | None: ...

    def reset(self) -> None: ...


def nearer_way(heading_rad: float, theta_rad: float) -> float:
    """`heading_rad` or its opposite, whichever is nearer to the robot's heading `theta_rad` (rad),
    in (-pi, pi]: the same axis, driven forwards or backwards."""
    if math.cos(heading_rad - theta_rad) < 0.0:
        heading_rad += math.pi
    return float(math.remainder(heading_rad, 2 * math.pi))
