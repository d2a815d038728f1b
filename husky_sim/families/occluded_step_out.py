"""A person stepping out from behind an occluder: a pillar or a parked cart stands beside the
way, and a walker hidden behind it (from the start) steps out round its far end and across the
way when the robot arrives. The robot's lidar has a limited range and field of view and sees
nothing behind a static obstacle, so the walker is unseen until it emerges."""

from __future__ import annotations

from typing import Any

import numpy as np

from husky_sim.families.base import (
    NOMINAL_SPEED_MPS,
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
    length = d["length_m"]
    side = d.sign()
    r = d["occluder_radius_m"]
    px = d["occluder_at"] * length
    py = side * (d.robot.footprint_radius_m + d["occluder_gap_m"] + r)
    if d["cart"] >= 1:  # a parked cart: a row of three cylinders along the way
        for dx in (-r, 0.0, r):
            d.static(px + dx, py, 0.6 * r)
        half = 1.6 * r  # its half-length along the way: end discs of 0.6 r centred r out
    else:
        d.static(px, py, r)
        half = r
    centre = np.array([px, py])
    shadow = centre / np.linalg.norm(centre)  # from the start, through the occluder
    speed = d["walker_speed_mps"]
    hide = centre + shadow * (half + WALKER_RADIUS_M + 0.2)
    cross_x = px + half + d.uniform(0.0, 1.0)  # out round the occluder's far end, not through it
    t_meet = max(cross_x / NOMINAL_SPEED_MPS + d["meet_offset_s"], 2.0)
    step = np.array([cross_x, 0.0]) - hide
    wait_m = max(speed * t_meet - float(np.linalg.norm(step)), 0.0)
    behind = hide + shadow * wait_m  # it walks in the shadow towards the occluder, then out
    out = np.array([cross_x, 0.0]) + step / np.linalg.norm(step) * 20.0
    path = [tuple(map(float, q)) for q in (behind, hide, (cross_x, 0.0), out)]
    d.walker(path, speed, WALKER_RADIUS_M)
    sensing = {"range_m": d["sensing_range_m"], "fov_deg": 270.0, "occlusion": True}
    return set_point_scenario(
        d, pose(0.0, 0.0), pose(length, 0.0), travel_duration_s(length), sensing=sensing
    )


FAMILY = register(
    Family(
        name="occluded_step_out",
        summary="a walker steps out from behind a pillar or a parked cart, unseen until it emerges",
        params=(
            Param("length_m", 8.0, 12.0, "m", "start to goal, straight"),
            Param("occluder_at", 0.35, 0.65, "", "where along the way the occluder stands (fraction)"),
            Param("occluder_radius_m", 0.3, 0.8, "m", "pillar radius (a cart: three cylinders of 0.6 of it)"),
            Param("occluder_gap_m", 0.2, 1.2, "m", "from the straight line's body circle to the occluder"),
            Param("cart", 0, 1, "", "1: a parked cart instead of a pillar", integer=True),
            Param("walker_speed_mps", 0.5, 1.5, "m/s", "the walker's speed"),
            Param("meet_offset_s", -1.5, 1.5, "s", "when the walker reaches the line, after the robot would"),
            Param("sensing_range_m", 5.0, 15.0, "m", "lidar range (field of view 270 deg, occlusion on)"),
        ),
        guarantees="the straight way is free of static obstacles; the walker starts in the "
        "occluder's shadow as seen from the start and walks round the occluder, and the robot's "
        "lidar sees only what its range, field of view and line of sight allow",
        build=build,
    )
)
