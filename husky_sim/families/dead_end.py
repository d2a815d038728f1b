"""Dead ends and goals behind the robot: a U-shaped trap of posts opens towards the robot with
the goal beyond its closed end, so the straight way leads into the U; or the robot starts inside
the U facing its closed end with the goal behind it, so it must turn round in the U."""

from __future__ import annotations

import math
from typing import Any

from husky_sim.families.base import (
    POST_RADIUS_M,
    Draw,
    Family,
    Param,
    pose,
    set_point_scenario,
    travel_duration_s,
)
from husky_sim.families.registry import register


def build(d: Draw) -> dict[str, Any]:
    depth = d["u_depth_m"]
    half = d.robot.circle_radius_m + 0.5 * d["u_width_margin_m"]  # inner half-width, surface to centre
    pr = POST_RADIUS_M
    opening = d["u_distance_m"]
    base = opening + depth
    d.wall((opening, -half - pr), (base + pr, -half - pr), pr)
    d.wall((opening, half + pr), (base + pr, half + pr), pr)
    d.wall((base + pr, -half - pr), (base + pr, half + pr), pr)
    lateral = d.uniform(-0.5, 0.5)
    if d["goal_behind"] >= 1:
        start = pose(base - d.robot.circle_radius_m - 0.1, 0.0, 0.0)
        goal = pose(d.uniform(-2.0, 0.0), lateral, math.pi)
        way = base + 2.0
    else:
        start = pose(0.0, 0.0, 0.0)
        goal = pose(base + pr + d["goal_beyond_m"], lateral, 0.0)
        way = base + 2 * half + d["goal_beyond_m"] + 3.0
    return set_point_scenario(d, start, goal, travel_duration_s(way))


FAMILY = register(
    Family(
        name="dead_end",
        summary="a U-shaped trap on the straight way, or a start inside it with the goal behind",
        params=(
            Param("u_depth_m", 1.5, 3.5, "m", "the U's arms, opening to closed end"),
            Param("u_width_margin_m", 0.2, 1.5, "m", "the U's inner width beyond the controller's circle"),
            Param("u_distance_m", 1.5, 4.0, "m", "start to the U's opening"),
            Param("goal_beyond_m", 1.5, 3.0, "m", "the goal beyond the U's closed end"),
            Param("goal_behind", 0, 1, "", "1: start inside the U facing its end, goal behind", integer=True),
        ),
        guarantees="a way round the U exists for the body; inside, the U is wide enough for the "
        "controller's circle to turn round",
        build=build,
    )
)
