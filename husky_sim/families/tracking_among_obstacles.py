"""Tracking a path among static and moving obstacles: a circular reference with static cylinders
on or beside it and walkers crossing it; the robot starts on the reference and must track it,
go round what stands on it and give way to what crosses it (the tracking criterion of
husky_sim.sim.metrics.judge_tracking)."""

from __future__ import annotations

import math
from typing import Any

from husky_sim.families.base import (
    WALKER_RADIUS_M,
    Draw,
    Family,
    Param,
    heading,
    pose,
    scenario_data,
    turning_path,
)
from husky_sim.families.registry import register

#: The reference is judged after this long (s), and within this RMSE (m): the shipped crossing
#: scenario's criterion, for references that run through obstacles.
SETTLE_S = 10.0
RMSE_M = 0.5
#: Longest run (s): one lap or this, whichever is shorter, plus the settle time.
MAX_LAP_S = 60.0


def build(d: Draw) -> dict[str, Any]:
    radius, speed = d["circle_radius_m"], d["reference_speed_mps"]
    rate = speed / radius
    lap_s = min(2 * math.pi / rate, MAX_LAP_S)
    for k in range(int(d["statics"])):
        angle = math.radians(60.0) + (k + d.uniform(0.1, 0.9)) * math.radians(280.0) / max(d["statics"], 1)
        r = d.uniform(0.2, d["static_radius_max_m"])
        c = (radius + d.uniform(-0.4, 0.4)) * heading(angle)
        d.static(float(c[0]), float(c[1]), r)
    for _ in range(int(d["walkers"])):
        t_meet = d.uniform(0.2, 0.9) * lap_s
        angle = rate * t_meet
        point = radius * heading(angle)
        direction = angle + math.pi + d.uniform(-0.6, 0.6)  # inwards across the circle
        walk = d["walker_speed_mps"]
        path = turning_path(tuple(point), direction, walk * t_meet, 25.0, d.uniform(-0.5, 0.5))
        d.walker(path, walk, WALKER_RADIUS_M)
    start = pose(radius, -d.uniform(0.0, 0.6), math.pi / 2)
    circle = {"radius_m": round(radius, 3), "angular_rate_radps": round(rate, 5)}
    success = {"tracking_rmse_m": RMSE_M, "tracking_settle_s": SETTLE_S}
    return scenario_data(d, start, {"circle": circle}, lap_s + SETTLE_S, success=success)


FAMILY = register(
    Family(
        name="tracking_among_obstacles",
        summary="track a circle with static cylinders on it and walkers crossing it",
        params=(
            Param("circle_radius_m", 2.0, 4.0, "m", "the reference circle's radius"),
            Param("reference_speed_mps", 0.15, 0.4, "m/s", "the reference's speed along the circle"),
            Param("statics", 0, 3, "", "static cylinders on or beside the circle", integer=True),
            Param("static_radius_max_m", 0.25, 0.5, "m", "largest static radius"),
            Param("walkers", 0, 3, "", "walkers crossing the circle", integer=True),
            Param("walker_speed_mps", 0.3, 1.2, "m/s", "walking speed"),
        ),
        guarantees="at least 80 % of the reference is where the body can be, all of it reachable "
        "from the start; each walker crosses the reference where the reference is at that time",
        build=build,
    )
)
