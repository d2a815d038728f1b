"""Is a layout feasible for the robot's body? A grid planner on the static obstacles.

The robot is its footprint's circumscribed circle (`footprint_radius_m`): a path on which that
circle touches nothing can be driven in any orientation, so a way found here is a way for the
body itself, whatever turns it takes (sufficient, and conservative by the circle's corners). The
static obstacles are rasterised on a square grid of `RESOLUTION_M`; a cell is free when its
centre is farther than the circle's radius plus half a cell's diagonal from every obstacle
surface (so a free cell is free all over), and the shortest 4-connected path from the start's cell
to the goal's (Dijkstra, scipy.sparse.csgraph) is the way. A tracking layout has no goal: its
free reference points must all be reachable from the start, and at most `MAX_BLOCKED_FRACTION`
of the reference may lie where the body cannot be.

Movers are not obstacles of the plan (they pass); the start must be clear of every mover's
first `MOVER_CLEAR_S` seconds for the controller's circle, so no layout begins in a collision the
robot could not avoid. No mover may pass through a static obstacle while the run lasts (its disc
may touch one, never overlap it by more than `OVERLAP_TOLERANCE_M`): a person walks round a
pillar, a parked cart or a wall, and a mover that walks through one is no layout a robot meets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from husky_sim.runs.scenario import Scenario
from husky_sim.sim.world import ObstacleSpec

#: Grid cell (m): a tenth of a Husky's width.
RESOLUTION_M = 0.05
#: Free space kept around the layout's extent (m), so a way round its outside is found.
BORDER_M = 3.0
#: Most of a tracking reference (fraction of its points) that may be blocked by static obstacles.
MAX_BLOCKED_FRACTION = 0.2
#: The start is clear of every mover for this long (s).
MOVER_CLEAR_S = 1.0
#: A mover's disc may overlap a static one by this much (m): the millimetre rounding of a file.
OVERLAP_TOLERANCE_M = 0.005
#: A mover's path is checked against the static obstacles at this spacing (m) along it.
MOVER_CHECK_SPACING_M = 0.02


@dataclass(frozen=True)
class Feasibility:
    """The check's verdict: whether the layout is feasible, why not if it is not, and the planned
    way's length (m; None without a way)."""

    feasible: bool
    reason: str
    path_length_m: float | None = None


class StaticGrid:
    """The static obstacles, inflated by a body circle, on a grid around given points."""

    def __init__(
        self,
        centres_m: np.ndarray,
        radii_m: np.ndarray,
        body_radius_m: float,
        extent_points_m: np.ndarray,
    ) -> None:
        points = np.vstack([extent_points_m.reshape(-1, 2), centres_m.reshape(-1, 2)])
        self.origin = points.min(axis=0) - BORDER_M
        top = points.max(axis=0) + BORDER_M
        self.shape = tuple(int(n) for n in np.ceil((top - self.origin) / RESOLUTION_M).astype(int) + 1)
        nx, ny = self.shape
        free = np.ones((nx, ny), dtype=bool)
        reach = body_radius_m + RESOLUTION_M / math.sqrt(2)
        for (cx, cy), r in zip(centres_m.reshape(-1, 2), radii_m, strict=True):
            outer = r + reach
            i0, j0 = self.cell((cx - outer, cy - outer))
            i1, j1 = self.cell((cx + outer, cy + outer))
            i0, j0, i1, j1 = max(i0, 0), max(j0, 0), min(i1 + 1, nx), min(j1 + 1, ny)
            if i0 >= i1 or j0 >= j1:
                continue
            xs = self.origin[0] + RESOLUTION_M * np.arange(i0, i1)
            ys = self.origin[1] + RESOLUTION_M * np.arange(j0, j1)
            inside = (xs[:, None] - cx) ** 2 + (ys[None, :] - cy) ** 2 <= outer**2
            free[i0:i1, j0:j1] &= ~inside
        self.free = free

    def cell(self, xy: tuple[float, float] | np.ndarray) -> tuple[int, int]:
        i, j = np.round((np.asarray(xy, dtype=float) - self.origin) / RESOLUTION_M).astype(int)
        return int(i), int(j)

    def is_free(self, xy: tuple[float, float] | np.ndarray) -> bool:
        i, j = self.cell(xy)
        return 0 <= i < self.shape[0] and 0 <= j < self.shape[1] and bool(self.free[i, j])

    def distances_from(self, xy: tuple[float, float] | np.ndarray) -> np.ndarray:
        """Shortest 4-connected path length (m) from xy's cell to every cell (inf: no way)."""
        nx, ny = self.shape
        index = np.arange(nx * ny).reshape(nx, ny)
        rows, cols = [], []
        for a, b in (
            (self.free[:-1, :] & self.free[1:, :], (index[:-1, :], index[1:, :])),
            (self.free[:, :-1] & self.free[:, 1:], (index[:, :-1], index[:, 1:])),
        ):
            rows.append(b[0][a])
            cols.append(b[1][a])
        r, c = np.concatenate(rows), np.concatenate(cols)
        graph = coo_matrix((np.full(len(r), RESOLUTION_M), (r, c)), shape=(nx * ny, nx * ny)).tocsr()
        i, j = self.cell(xy)
        return dijkstra(graph, directed=False, indices=int(index[i, j])).reshape(nx, ny)


def check_layout(scenario: Scenario) -> Feasibility:
    """The layout's feasibility for its robot (see the module docstring)."""
    body = scenario.robot.description().geometry.footprint_radius_m
    circle = scenario.robot.radius()
    specs = scenario.obstacle_specs()
    start = np.array([scenario.robot.start.x_m, scenario.robot.start.y_m])
    for i, o in enumerate(specs):
        if not o.moving:
            continue
        for t in np.linspace(0.0, MOVER_CLEAR_S, 11):
            x, y, _, _ = o.motion_at(float(t))
            if math.hypot(x - start[0], y - start[1]) <= o.radius_m + circle:
                return Feasibility(False, f"mover {i} reaches the start's circle within {MOVER_CLEAR_S:g} s")
    static = [o for o in specs if not o.moving]
    centres = np.array([[o.x_m, o.y_m] for o in static]).reshape(-1, 2)
    radii = np.array([o.radius_m for o in static])
    for i, o in enumerate(specs):
        if o.moving and (through := _walks_through(o, centres, radii, scenario.duration_s)) is not None:
            return Feasibility(False, f"mover {i} walks through a static obstacle at {through:.1f} s")
    goal = scenario.reference.goal
    if goal is not None:
        targets = np.array([[goal.x_m, goal.y_m]])
    else:
        c = scenario.reference.circle
        angles = np.linspace(0.0, 2 * math.pi, 72, endpoint=False)
        targets = np.stack(
            [c.center_x_m + c.radius_m * np.cos(angles), c.center_y_m + c.radius_m * np.sin(angles)], 1
        )
    grid = StaticGrid(centres, radii, body, np.vstack([start[None], targets]))
    if not grid.is_free(start):
        return Feasibility(False, "the start is too close to a static obstacle for the body")
    free_targets = [t for t in targets if grid.is_free(t)]
    if goal is not None and not free_targets:
        return Feasibility(False, "the goal is too close to a static obstacle for the body")
    if goal is None and len(free_targets) < (1 - MAX_BLOCKED_FRACTION) * len(targets):
        return Feasibility(
            False, f"static obstacles block more than {MAX_BLOCKED_FRACTION:.0%} of the reference"
        )
    distances = grid.distances_from(start)
    lengths = [float(distances[grid.cell(t)]) for t in free_targets]
    if not all(math.isfinite(d) for d in lengths):
        what = "the goal" if goal is not None else "some of the reference"
        return Feasibility(False, f"no way for the body from the start to {what} among the static obstacles")
    return Feasibility(True, "a way exists", max(lengths))


def _walks_through(
    mover: ObstacleSpec, centres_m: np.ndarray, radii_m: np.ndarray, duration_s: float
) -> float | None:
    """The first time (s) within `duration_s` at which `mover`'s disc overlaps a static disc
    (centres_m (S, 2), radii_m (S,)) by more than OVERLAP_TOLERANCE_M, sampled every
    MOVER_CHECK_SPACING_M of its travel; None if it never does."""
    if len(radii_m) == 0:
        return None
    speed = mover.speed_mps if mover.waypoints else math.hypot(mover.vx_mps, mover.vy_mps)
    times = np.arange(0.0, duration_s, MOVER_CHECK_SPACING_M / speed)
    centres = np.array([mover.motion_at(float(t))[:2] for t in times])  # (T, 2)
    gaps = np.linalg.norm(centres[:, None, :] - centres_m[None, :, :], axis=2) - radii_m[None, :]
    overlapping = np.flatnonzero(np.min(gaps, axis=1) < mover.radius_m - OVERLAP_TOLERANCE_M)
    return float(times[overlapping[0]]) if len(overlapping) else None
