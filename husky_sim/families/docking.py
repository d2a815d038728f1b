"""Parking and docking near walls: the goal is a pose facing a wall of posts at a small stand-off,
in a bay with side walls, approached from an angle; the robot must arrive slowly and straight
and stop short of the wall."""

from __future__ import annotations

import math
from typing import Any

from husky_sim.families.base import (
    POST_RADIUS_M,
    Draw,
    Family,
    Param,
    heading,
    pose,
    set_point_scenario,
    travel_duration_s,
)
from husky_sim.families.registry import register


def build(d: Draw) -> dict[str, Any]:
    pr = POST_RADIUS_M
    circle = d.robot.circle_radius_m
    # the wall runs along y at x = 0 (posts' surfaces there); the goal faces it (+x) from the left
    gx = -(circle + d["standoff_m"])
    half_bay = circle + 0.5 * d["bay_margin_m"]
    d.wall((pr, -3.0), (pr, 3.0), pr)
    bay_depth = d["bay_depth_m"]
    if bay_depth > 0:
        for side in (-1.0, 1.0):
            d.wall((-bay_depth, side * (half_bay + pr)), (0.0, side * (half_bay + pr)), pr)
    approach = math.radians(d["approach_deg"]) * d.sign()
    distance = d["start_distance_m"]
    sx, sy = (gx, 0.0) - distance * heading(approach)
    to_goal = math.atan2(-sy, gx - sx)
    start = pose(sx, sy, to_goal + d.uniform(-0.5, 0.5))
    return set_point_scenario(d, start, pose(gx, 0.0, 0.0), travel_duration_s(distance + 2.0))


FAMILY = register(
    Family(
        name="docking",
        summary="park facing a wall of posts at a small stand-off, in a bay, approached at an angle",
        params=(
            Param("standoff_m", 0.1, 0.8, "m", "the goal's controller circle to the wall's surface"),
            Param("bay_margin_m", 0.2, 1.5, "m", "the bay's width beyond the controller's circle"),
            Param("bay_depth_m", 0.0, 2.0, "m", "the bay's side walls' length (0: a plain wall)"),
            Param("approach_deg", 0.0, 80.0, "deg", "the start's bearing off the bay's axis"),
            Param("start_distance_m", 3.0, 7.0, "m", "start to goal"),
        ),
        guarantees="the goal pose's controller circle clears the wall and the bay by standoff_m "
        "and half the bay margin; the start faces the goal within 0.5 rad",
        build=build,
    )
)
