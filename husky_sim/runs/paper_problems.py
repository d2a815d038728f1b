"""The paper's simulation problems for the controller's own unicycle loop (husky_sim.sim.kinematic),
as husky_sim.sim.kinematic.KinematicProblem, and a cluttered variant for the solver benchmark.

The paper's point-stabilisation problem is read from its shipped scenario file, the one place it
is written down (scenarios/paper_point_stabilisation.yaml: the frame of the authors' published
code, start (0, 0, pi/2), goal (0, 10, pi/2), obstacle (0.1, 4.7) r 0.6 m; the paper's text prints
start (0, 0, 0) and goal (10, 0, 0), for which that obstacle is not on the path), with the paper's
robot circle of 0.25 m instead of the Husky's.
"""

from __future__ import annotations

from dataclasses import replace

from controllers import Obstacle
from husky_sim.runs.scenario import load_scenario

#: The paper's simulated robot circle (m), smaller than a Husky's (husky_sim.sim.geometry).
PAPER_ROBOT_RADIUS_M = 0.25


PAPER_POINT_STABILISATION = load_scenario("paper_point_stabilisation").kinematic_problem(PAPER_ROBOT_RADIUS_M)

#: Benchmark variant with 7 obstacles: the paper's one plus six more beside and across the
#: path, two of them moving, so that several constraints are near-active at once.
CLUTTERED_POINT_STABILISATION = replace(
    PAPER_POINT_STABILISATION,
    name="cluttered_point_stabilisation",
    obstacles=(
        *PAPER_POINT_STABILISATION.obstacles,
        Obstacle(-1.6, 2.5, 0.4),
        Obstacle(1.5, 6.5, 0.5),
        Obstacle(-1.4, 8.0, 0.4),
        Obstacle(2.0, 2.0, 0.3),
        Obstacle(3.0, 7.5, 0.3, vx_mps=-0.3, vy_mps=0.0),
        Obstacle(-2.5, 5.5, 0.25, vx_mps=0.2, vy_mps=0.1),
    ),
)
