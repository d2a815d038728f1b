"""A crowd: four to twelve walkers cross the area between start and goal in every direction, each
passing a random point of the area at a random time, on paths that turn once."""

from __future__ import annotations

import math
from typing import Any

from husky_sim.families.base import (
    NOMINAL_SPEED_MPS,
    WALKER_RADIUS_M,
    Draw,
    Family,
    Param,
    pose,
    set_point_scenario,
    travel_duration_s,
    turning_path,
)
from husky_sim.families.registry import register


def build(d: Draw) -> dict[str, Any]:
    length, half = d["length_m"], d["area_half_width_m"]
    for _ in range(int(d["walkers"])):
        point = (d.uniform(2.0, length - 1.0), d.uniform(-half, half))
        t_pass = d.uniform(0.5, 1.5) * point[0] / NOMINAL_SPEED_MPS
        speed = d.uniform(0.3, d["speed_max_mps"])
        direction = d.uniform(-math.pi, math.pi)
        turn = d.uniform(-0.8, 0.8)
        d.walker(turning_path(point, direction, speed * t_pass, 25.0, turn), speed, WALKER_RADIUS_M)
    return set_point_scenario(d, pose(0.0, 0.0), pose(length, 0.0), travel_duration_s(1.5 * length))


FAMILY = register(
    Family(
        name="crowd",
        summary="walkers cross the area between start and goal in every direction",
        params=(
            Param("length_m", 8.0, 14.0, "m", "start to goal, straight"),
            Param("area_half_width_m", 1.5, 4.0, "m", "half-width of the area the walkers pass through"),
            Param("walkers", 4, 12, "", "walkers", integer=True),
            Param("speed_max_mps", 0.5, 1.5, "m/s", "fastest walker (each 0.3 m/s up to it)"),
        ),
        guarantees="open ground: a way always exists; every walker passes through the area within "
        "half to one and a half times the robot's nominal time to its point, and none is within the "
        "robot's circle in the first second",
        build=build,
    )
)
