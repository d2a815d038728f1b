"""The paper's simulation problems as plain data for kinematic runs and benchmarks.

Point stabilisation uses the frame of the authors' published code: start (0, 0, pi/2), goal
(0, 10, pi/2), obstacle (0.1, 4.7) r 0.6 m. The paper's text prints start (0, 0, 0) and goal
(10, 0, 0), for which that obstacle is not on the path; we keep the paper's weights and the
published code's frame, so the obstacle sits on the straight line to the goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from controllers import Obstacle, Reference, SetPoint


@dataclass(frozen=True)
class KinematicProblem:
    """Start (m, m, rad), reference, obstacles at t = 0, robot radius (m), duration (s)."""

    name: str
    start: tuple[float, float, float]
    reference: Reference
    obstacles: tuple[Obstacle, ...]
    robot_radius_m: float
    duration_s: float


PAPER_POINT_STABILISATION = KinematicProblem(
    name="paper_point_stabilisation",
    start=(0.0, 0.0, math.pi / 2),
    reference=SetPoint(0.0, 10.0, math.pi / 2),
    obstacles=(Obstacle(0.1, 4.7, 0.6),),
    robot_radius_m=0.25,  # the paper's robot radius
    duration_s=40.0,
)

#: Benchmark variant with 7 obstacles: the paper's one plus six more beside and across the
#: path, two of them moving, so that several constraints are near-active at once.
CLUTTERED_POINT_STABILISATION = KinematicProblem(
    name="cluttered_point_stabilisation",
    start=(0.0, 0.0, math.pi / 2),
    reference=SetPoint(0.0, 10.0, math.pi / 2),
    obstacles=(
        Obstacle(0.1, 4.7, 0.6),
        Obstacle(-1.6, 2.5, 0.4),
        Obstacle(1.5, 6.5, 0.5),
        Obstacle(-1.4, 8.0, 0.4),
        Obstacle(2.0, 2.0, 0.3),
        Obstacle(3.0, 7.5, 0.3, vx_mps=-0.3, vy_mps=0.0),
        Obstacle(-2.5, 5.5, 0.25, vx_mps=0.2, vy_mps=0.1),
    ),
    robot_radius_m=0.25,
    duration_s=40.0,
)
