"""A corridor with oncoming walkers: an L-shaped corridor walled with posts, the goal round the
corner, and one or two walkers coming the other way through the corner and down the robot's leg,
keeping to one side (their right where the corridor turns left). The corridor is wide enough for
the body beside a walker only when its width margin allows; otherwise the robot must give way
where it can."""

from __future__ import annotations

import math
from typing import Any

from husky_sim.families.base import (
    POST_RADIUS_M,
    WALKER_RADIUS_M,
    Draw,
    Family,
    Param,
    pose,
    set_point_scenario,
    travel_duration_s,
)
from husky_sim.families.registry import register


def build(d: Draw) -> dict[str, Any]:
    leg1, leg2 = d["leg1_m"], d["leg2_m"]
    w = 2 * d.robot.footprint_radius_m + d["width_margin_m"]  # free width, surface to surface
    h, pr = 0.5 * w, POST_RADIUS_M
    turn = d.sign()  # left (+1) or right (-1) at the corner

    # leg 1 runs along +x from x = -2 to the corner at (leg1, 0); leg 2 along turn * y
    def m(x: float, y: float) -> tuple[float, float]:
        return x, turn * y

    outer_y, inner_y = -(h + pr), h + pr
    d.wall(m(-2.0, outer_y), m(leg1 + h + pr, outer_y), pr)
    d.wall(m(leg1 + h + pr, outer_y), m(leg1 + h + pr, leg2 + 1.0), pr)
    d.wall(m(-2.0, inner_y), m(leg1 - h - pr, inner_y), pr)
    d.wall(m(leg1 - h - pr, inner_y), m(leg1 - h - pr, leg2 + 1.0), pr)
    keep = h - WALKER_RADIUS_M - 0.1  # walkers keep to one side
    for k in range(int(d["walkers"])):
        speed = d["walker_speed_mps"] * d.uniform(0.8, 1.0)
        start_along = leg2 + 1.5 + k * d.uniform(2.0, 5.0)
        # keeping to their right down leg 2 and back along leg 1 (cutting the corner)
        path = [
            m(leg1 - keep, start_along),
            m(leg1 - keep, keep),
            m(-12.0, keep),
        ]
        d.walker(path, speed, WALKER_RADIUS_M)
    goal = pose(*m(leg1, leg2 - 0.5), turn * math.pi / 2)
    duration = travel_duration_s(leg1 + leg2)
    return set_point_scenario(d, pose(0.0, 0.0), goal, duration)


FAMILY = register(
    Family(
        name="corridor_oncoming",
        summary="an L-shaped corridor walled with posts and walkers coming the other way",
        params=(
            Param("leg1_m", 4.0, 8.0, "m", "start to the corner"),
            Param("leg2_m", 3.0, 7.0, "m", "corner to the goal"),
            Param("width_margin_m", 0.5, 2.0, "m", "free width beyond the body's circumscribed diameter"),
            Param("walkers", 1, 2, "", "walkers coming the other way", integer=True),
            Param("walker_speed_mps", 0.3, 1.2, "m/s", "walking speed (each 80 to 100 % of it)"),
        ),
        guarantees="the corridor is at least the body's circumscribed diameter plus 0.5 m wide; "
        "walkers keep to one side, leaving the other, so the robot can pass by standing "
        "aside where the width margin allows",
        build=build,
    )
)
