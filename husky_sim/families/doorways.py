"""Doorways and narrow passages: the way to the goal leads through a channel walled with posts
and across a cross wall whose one or two doors are sized from the robot's width; a door may be a
short corridor (its jambs extended) rather than a hole in the wall."""

from __future__ import annotations

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
    length, half = d["length_m"], d["channel_half_width_m"]
    wall_x = 0.5 * length
    door = 2 * d.robot.footprint_radius_m + d["door_margin_m"]
    depth = d["door_depth_m"]
    doors = [d["door_offset_m"]]
    if d["doors"] >= 2:
        other = -doors[0] + (1.0 if doors[0] <= 0 else -1.0) * d.uniform(0.0, 1.0)
        if abs(other - doors[0]) > door + 1.0:
            doors.append(other)
    doors = sorted(max(min(c, half - 0.5 * door - 0.4), -half + 0.5 * door + 0.4) for c in doors)
    pr = POST_RADIUS_M
    d.wall((-2.0, -half - pr), (length + 2.0, -half - pr), pr)
    d.wall((-2.0, half + pr), (length + 2.0, half + pr), pr)
    edges = [-half]
    for c in doors:
        edges += [c - 0.5 * door - pr, c + 0.5 * door + pr]
    edges.append(half)
    for lo, hi in zip(edges[::2], edges[1::2], strict=True):
        if hi - lo > 1e-6:
            d.wall((wall_x, lo), (wall_x, hi), pr)
    if depth > 0:
        for c in doors:
            for side in (-1.0, 1.0):
                y = c + side * (0.5 * door + pr)
                d.wall((wall_x - 0.5 * depth, y), (wall_x + 0.5 * depth, y), pr)
    goal = pose(length, d.uniform(-0.5 * half, 0.5 * half))
    return set_point_scenario(d, pose(0.0, 0.0), goal, travel_duration_s(length + 2 * half))


FAMILY = register(
    Family(
        name="doorways",
        summary="a channel walled with posts, crossed by a wall with one or two doors sized from the robot",
        params=(
            Param("length_m", 6.0, 12.0, "m", "start to the goal's x; the cross wall stands halfway"),
            Param("channel_half_width_m", 2.0, 4.0, "m", "the channel's half-width (wall surface to centre)"),
            Param("door_margin_m", 0.15, 1.0, "m", "door width beyond the body's circumscribed diameter"),
            Param("door_offset_m", -1.5, 1.5, "m", "the first door's centre off the straight line"),
            Param("door_depth_m", 0.0, 2.0, "m", "how far the door's jambs run along the way (0: a hole)"),
            Param("doors", 1, 2, "", "doors in the cross wall", integer=True),
        ),
        guarantees="every door is at least the body's circumscribed diameter plus 0.15 m wide; "
        "the walls leave no other way",
        build=build,
    )
)
