"""Dense static clutter with a guaranteed passage: cylinders of mixed sizes fill a field between
start and goal, except along a winding passage wide enough for the body, so the way exists but
runs between obstacles the whole time."""

from __future__ import annotations

import math
from typing import Any

from husky_sim.families.base import (
    Draw,
    Family,
    Param,
    distance_to_polyline,
    pose,
    set_point_scenario,
    travel_duration_s,
)
from husky_sim.families.registry import register

#: Gap (m) kept between two cylinders of the field, and between a cylinder and the start or goal
#: beyond the controller's circle.
SPACING_M = 0.05


def build(d: Draw) -> dict[str, Any]:
    length, half_width = d["length_m"], d["field_half_width_m"]
    passage_half = d.robot.footprint_radius_m + 0.5 * d["passage_margin_m"]
    lateral = half_width - passage_half - 0.2
    passage = [(0.0, 0.0)]
    for i in (1, 2, 3):
        passage.append((length * i / 4, d.uniform(-lateral, lateral)))
    passage.append((length, 0.0))
    count = int(round(d["density_per_m2"] * (length - 3.0) * 2 * half_width))
    placed: list[tuple[float, float, float]] = []
    keep = d.robot.circle_radius_m + 0.3
    for _ in range(40 * count):
        if len(placed) == count:
            break
        r = d.uniform(0.5 * d["radius_max_m"], d["radius_max_m"])
        x, y = d.uniform(1.5, length - 1.5), d.uniform(-half_width, half_width)
        if distance_to_polyline((x, y), passage) < passage_half + r:
            continue
        if min(math.hypot(x, y), math.hypot(x - length, y)) < keep + r:
            continue
        if any(math.hypot(x - px, y - py) < r + pr + SPACING_M for px, py, pr in placed):
            continue
        placed.append((x, y, r))
    for x, y, r in placed:
        d.static(x, y, r)
    return set_point_scenario(d, pose(0.0, 0.0), pose(length, 0.0), travel_duration_s(1.3 * length))


FAMILY = register(
    Family(
        name="static_clutter",
        summary="dense static cylinders with one winding passage wide enough for the body",
        params=(
            Param("length_m", 8.0, 14.0, "m", "start to goal, straight"),
            Param("field_half_width_m", 2.5, 4.0, "m", "the clutter's half-width across the way"),
            Param("density_per_m2", 0.25, 0.6, "1/m^2", "cylinders per square metre of field"),
            Param("radius_max_m", 0.2, 0.5, "m", "largest cylinder radius (smallest: half of it)"),
            Param(
                "passage_margin_m", 0.2, 1.0, "m", "passage width beyond the body's circumscribed diameter"
            ),
        ),
        guarantees="a passage at least the body's circumscribed diameter plus passage_margin_m wide "
        "winds through the field from start to goal; the clutter fills the rest",
        build=build,
    )
)
