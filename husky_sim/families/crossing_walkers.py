"""Crossing pedestrians on turning paths: one to four walkers cross the robot's way to its goal,
each timed to reach the straight line when the robot, at the nominal speed, would be there; their
paths turn before and after the crossing, so a constant-velocity prediction is wrong at times."""

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
    length = d["length_m"]
    count = int(d["walkers"])
    turn = math.radians(d["turn_deg"])
    for k in range(count):
        x = length * (0.3 + 0.5 * (k + d.uniform(0.0, 1.0)) / count)
        t_meet = max(x / NOMINAL_SPEED_MPS + d["meet_offset_s"], 1.5)
        speed = d["speed_mps"] * d.uniform(0.8, 1.0)
        side = d.sign()
        direction = -side * math.pi / 2 + d.uniform(-0.5, 0.5)
        bend = turn * d.sign()
        path = turning_path((x, d.uniform(-0.3, 0.3)), direction, speed * t_meet, 25.0, bend)
        d.walker(path, speed, WALKER_RADIUS_M)
    return set_point_scenario(d, pose(0.0, 0.0), pose(length, 0.0), travel_duration_s(length))


FAMILY = register(
    Family(
        name="crossing_walkers",
        summary="walkers on turning paths cross the way, timed to meet the robot",
        params=(
            Param("length_m", 8.0, 14.0, "m", "start to goal, straight, in open ground"),
            Param("walkers", 1, 4, "", "walkers crossing", integer=True),
            Param("speed_mps", 0.3, 1.5, "m/s", "walking speed (each walker 80 to 100 % of it)"),
            Param("turn_deg", 0.0, 60.0, "deg", "each walker's turn before and after crossing"),
            Param("meet_offset_s", -2.0, 2.0, "s", "when a walker reaches the line, after the robot would"),
        ),
        guarantees="open ground: a way always exists; every walker reaches the straight line within "
        "meet_offset_s of the robot at the nominal speed, and none is within the robot's circle "
        "in the first second",
        build=build,
    )
)
