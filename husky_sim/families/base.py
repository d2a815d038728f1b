"""What a scenario family is: a seeded generator of scenario data with named, ranged parameters.

A family draws one layout from a parameter vector and a random generator. Parameters are drawn
first, each uniformly in its range and always in the order they are declared (a parameter fixed
with `--param` still consumes its draw, so fixing one never shifts the others); the family's
`build` then places obstacles, movers, start and goal with the same generator. `build` returns
plain scenario data (the schema of husky_sim.runs.scenario), which the generator validates and
checks for feasibility (husky_sim.families.feasibility).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from husky_sim.sim.robot_description import RobotDescription

#: The margin (m) a family's scenarios add to the robot's footprint circle for the controller's
#: circle (the shipped scenarios' `radius_margin_m`).
CONTROLLER_MARGIN_M = 0.25
#: The speed (m/s) a family assumes the robot makes good along its way when it times a mover to
#: meet it: below the drive's 1 m/s, about what the NMPCs average among obstacles.
NOMINAL_SPEED_MPS = 0.6
#: A walker's radius (m): a person with swinging arms.
WALKER_RADIUS_M = 0.3
#: A wall post's radius (m); `Draw.wall` sets posts 0.1 m apart, too narrow for any robot.
POST_RADIUS_M = 0.15


@dataclass(frozen=True)
class Param:
    """One family parameter: a value in [low, high] (its unit in `unit`), drawn uniformly unless
    fixed; `integer` rounds the draw to the nearest whole number."""

    name: str
    low: float
    high: float
    unit: str
    doc: str
    integer: bool = False

    def __post_init__(self) -> None:
        if not self.low <= self.high:
            raise ValueError(f"family parameter {self.name}: low {self.low} above high {self.high}")

    def check(self, value: float) -> float:
        """`value` as this parameter holds it; a one-line ValueError naming the range if outside."""
        if not (math.isfinite(value) and self.low <= value <= self.high):
            unit = f" {self.unit}" if self.unit else ""
            raise ValueError(
                f"--param {self.name}: must be in [{self.low:g}, {self.high:g}]{unit}, got {value:g}"
            )
        return float(round(value)) if self.integer else float(value)

    def from_unit(self, u: float) -> float:
        """The value at fraction u in [0, 1] of the range (the falsifier's coordinates)."""
        value = self.low + min(max(u, 0.0), 1.0) * (self.high - self.low)
        return float(round(value)) if self.integer else float(value)

    def describe(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.name} in [{self.low:g}, {self.high:g}]{unit}: {self.doc}"


@dataclass(frozen=True)
class Robot:
    """The robot's body as a family sizes a layout from it (m): the footprint's circumscribed
    radius, its width, and the controller circle the scenarios give it."""

    footprint_radius_m: float
    width_m: float
    length_m: float

    @property
    def circle_radius_m(self) -> float:
        return self.footprint_radius_m + CONTROLLER_MARGIN_M

    @classmethod
    def of(cls, description: RobotDescription) -> Robot:
        half_length, half_width = description.geometry.footprint_half_extents_m
        return cls(description.geometry.footprint_radius_m, 2 * half_width, 2 * half_length)


@dataclass
class Draw:
    """One layout in the making: its parameters, its random generator, the robot, and the
    scenario data being built (`obstacles` is a list of the schema's obstacle entries)."""

    params: Mapping[str, float]
    rng: np.random.Generator
    robot: Robot
    obstacles: list[dict[str, Any]] = field(default_factory=list)

    def __getitem__(self, name: str) -> float:
        return self.params[name]

    def uniform(self, low: float, high: float) -> float:
        return float(self.rng.uniform(low, high))

    def sign(self) -> float:
        """+1.0 or -1.0, evenly: which side, which way round."""
        return 1.0 if self.rng.uniform() < 0.5 else -1.0

    def static(self, x_m: float, y_m: float, radius_m: float) -> None:
        """A static cylinder."""
        self.obstacles.append({"x_m": _mm(x_m), "y_m": _mm(y_m), "radius_m": _mm(radius_m)})

    def walker(self, path: Sequence[tuple[float, float]], speed_mps: float, radius_m: float = 0.3) -> None:
        """A mover that walks the polyline `path` (its first point is where it starts) at
        speed_mps and stays at the last point."""
        (x0, y0), rest = path[0], path[1:]
        self.obstacles.append(
            {
                "x_m": _mm(x0),
                "y_m": _mm(y0),
                "radius_m": _mm(radius_m),
                "speed_mps": _mm(speed_mps),
                "waypoints": [[_mm(x), _mm(y)] for x, y in rest],
            }
        )

    def wall(
        self,
        a: tuple[float, float],
        b: tuple[float, float],
        post_radius_m: float = POST_RADIUS_M,
        gap_m: float = 0.1,
    ) -> None:
        """A wall of static posts from a to b (m): cylinders of post_radius_m whose surfaces are
        gap_m apart, too narrow for any robot, so the wall blocks as a solid one would."""
        ax, ay = a
        length = math.hypot(b[0] - ax, b[1] - ay)
        pitch = 2 * post_radius_m + gap_m
        count = max(int(math.floor(length / pitch)) + 1, 1)
        for i in range(count):
            f = 0.0 if count == 1 else i / (count - 1)
            self.static(ax + f * (b[0] - ax), ay + f * (b[1] - ay), post_radius_m)


def _mm(value: float) -> float:
    """A coordinate rounded to the millimetre: what a layout file holds (and reads back exactly)."""
    return round(float(value), 3)


def pose(x_m: float, y_m: float, yaw_rad: float = 0.0) -> dict[str, float]:
    return {"x_m": _mm(x_m), "y_m": _mm(y_m), "yaw_rad": round(float(yaw_rad), 4)}


def scenario_data(
    draw: Draw,
    start: dict[str, float],
    reference: dict[str, Any],
    duration_s: float,
    **extra: Any,
) -> dict[str, Any]:
    """Scenario data for a layout with the draw's obstacles, its start and its reference (a goal
    or a circle), lasting duration_s rounded up to a whole second (name and description are the
    generator's)."""
    return {
        "tau_s": 0.1,
        "duration_s": float(math.ceil(duration_s)),
        "robot": {"start": start, "radius_margin_m": CONTROLLER_MARGIN_M},
        "reference": reference,
        "obstacles": draw.obstacles,
        "controller": {"horizon": 12, "gamma": 0.2},
        **extra,
    }


def set_point_scenario(
    draw: Draw,
    start: dict[str, float],
    goal: dict[str, float],
    duration_s: float,
    **extra: Any,
) -> dict[str, Any]:
    """Scenario data for a set-point layout (scenario_data with the goal as its reference)."""
    return scenario_data(draw, start, {"goal": goal}, duration_s, **extra)


def travel_duration_s(distance_m: float) -> float:
    """A set-point run's duration for a way of distance_m: time at half the nominal speed plus
    20 s to settle, so a timeout means a robot that made no progress, not a slow one."""
    return 20.0 + distance_m / (0.5 * NOMINAL_SPEED_MPS)


@dataclass(frozen=True)
class Family:
    """A scenario family: its name, a one-line summary, its parameters (drawn in this order),
    what its layouts guarantee (beyond the generator's feasibility check), and `build`, which
    turns a Draw into scenario data."""

    name: str
    summary: str
    params: tuple[Param, ...]
    guarantees: str
    build: Callable[[Draw], dict[str, Any]]

    def param(self, name: str) -> Param:
        for p in self.params:
            if p.name == name:
                return p
        names = ", ".join(p.name for p in self.params)
        raise ValueError(f"--param {name}: family {self.name} has no such parameter ({names})")

    def draw_params(self, rng: np.random.Generator, fixed: Mapping[str, float]) -> dict[str, float]:
        """Every parameter: uniform in its range (one draw each, in order), or its fixed value."""
        for name in fixed:
            self.param(name)
        values = {}
        for p in self.params:
            drawn = p.from_unit(float(rng.uniform()))
            values[p.name] = p.check(fixed[p.name]) if p.name in fixed else drawn
        return values


def distance_to_polyline(point: tuple[float, float], path: Sequence[tuple[float, float]]) -> float:
    """Distance (m) from a point to a polyline."""
    p = np.asarray(point, dtype=float)
    best = math.inf
    for a, b in zip(path[:-1], path[1:], strict=True):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        ab = b - a
        denom = float(ab @ ab)
        f = 0.0 if denom == 0 else min(max(float((p - a) @ ab) / denom, 0.0), 1.0)
        best = min(best, float(np.linalg.norm(p - (a + f * ab))))
    return best


def heading(angle_rad: float) -> np.ndarray:
    """The unit vector at angle_rad."""
    return np.array([math.cos(angle_rad), math.sin(angle_rad)])


def turning_path(
    through: tuple[float, float],
    direction_rad: float,
    before_m: float,
    after_m: float,
    turn_rad: float,
) -> list[tuple[float, float]]:
    """A walker's polyline through the point `through`, heading direction_rad there: it comes
    from before_m back along a path that turns by turn_rad halfway, and goes on after_m, turning
    by turn_rad again (the same way) halfway; the walk is before_m + after_m long."""
    c = np.asarray(through, dtype=float)
    back = c - 0.5 * before_m * heading(direction_rad)
    start = back - 0.5 * before_m * heading(direction_rad - turn_rad)
    ahead = c + 0.5 * after_m * heading(direction_rad)
    end = ahead + 0.5 * after_m * heading(direction_rad + turn_rad)
    return [tuple(map(float, q)) for q in (start, back, c, ahead, end)]
