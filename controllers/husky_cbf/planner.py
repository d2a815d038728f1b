"""The global planner of husky-cbf: a shortest path round the static layer and the swept movers.

A short-horizon NMPC whose straight path is blocked (an obstacle on the line, a gap, a wall of
obstacles, a mover coming head-on) stops at the obstacle: its cost only falls by going straight.
The planner detects that case and hands the NMPC a nearer waypoint instead of the goal:

- obstacles are inflated by the robot's disc radius plus margin; a mover is swept along its track
  from where the NMPC's first circle of it is (movers.MoverModel.swept_circles), so a path is not
  planned through where it will be, nor kept from where it was;
- blocked: the segment from the robot to the goal crosses an inflated obstacle (a robot already
  detouring needs RELEASE_MARGIN_M more to stop, so it does not flicker in and out);
- then a shortest path on a cost grid (cells near obstacles cost more, so the path keeps its
  distance) by scipy.sparse.csgraph.dijkstra, and the waypoint is the farthest path point within
  `lookahead_m` that the robot can see. When nothing blocks, there is no waypoint and the NMPC
  follows the reference unchanged;
- where movers block the way round the static obstacles alone, that way is still taken if the
  movers will have cleared it by the time the robot gets there (after a wait shorter than the
  detour): the robot follows a mover through a gap instead of turning back.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from controllers.husky_cbf.behaviours.base import Target
from controllers.husky_cbf.config import PlannerConfig
from controllers.husky_cbf.movers import ROBOT_EXCLUSION_M, MoverModel, is_static
from controllers.obstacles import Obstacle

#: The grid extends this far (m) beyond the box round robot and goal: room for a way round
GRID_PADDING_M = 3.0
#: A waypoint's heading points along the path this many cells further on: one cell would give
#: only the grid's eight directions
PATH_HEADING_CELLS = 3
#: A detouring robot returns to the straight way only with this much (m) to spare round every
#: inflated obstacle, so that it does not flicker in and out of the detour
RELEASE_MARGIN_M = 0.1
#: Among static obstacles, cells near the last path cost this fraction less, so that the way round
#: does not change sides on centimetres of sensing noise (not among movers: there the way round
#: changes for real)
PATH_HYSTERESIS = 0.2
#: ... within this distance (m) of the last path
PATH_HYSTERESIS_WIDTH_M = 0.2
#: A way round movers longer than the way round the static obstacles alone is taken only if the
#: movers clear the shorter way no sooner than its extra length takes at this speed (m/s): a
#: cruise speed with its turns
DETOUR_SPEED_MPS = 0.6
#: A path ending within this (m) of the goal ends at it: its last waypoint takes the goal's heading
AT_GOAL_M = 1e-6


def arc_lengths(path: np.ndarray) -> np.ndarray:
    """The distance (m) along a polyline (K, 2) from its first point to each of its points."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])


def segment_blocked(a: np.ndarray, b: np.ndarray, circles: np.ndarray, extra_m: float = 0.0) -> bool:
    """Whether the segment a-b (m) passes within r + extra_m of any circle's centre."""
    if circles.size == 0:
        return False
    d = np.asarray(b, dtype=float) - np.asarray(a, dtype=float)
    length_sq = float(d @ d)
    rel = circles[:, :2] - a
    s = np.clip(rel @ d / length_sq, 0.0, 1.0) if length_sq > 0 else np.zeros(len(circles))
    closest = a + s[:, None] * d
    return bool(np.any(np.hypot(*(circles[:, :2] - closest).T) < circles[:, 2] + extra_m))


def _meets(path: np.ndarray, times_s: np.ndarray, sweep: np.ndarray, mover: Obstacle) -> bool:
    """Whether a robot at path[i] (m) at times_s[i] (s) is inside a mover's swept circles `sweep`
    ((S, 3), inflated_circles of that mover now, from its first circle), carried along its track
    to each time, at any i."""
    offsets = sweep[:, :2] - sweep[:1, :2]  # the sweep's samples, from the first
    radius = float(sweep[0, 2])
    velocity = np.array([mover.vx_mps, mover.vy_mps])
    centres = sweep[0, :2] + times_s[:, None, None] * velocity + offsets[None, :, :]
    gaps = np.hypot(*(path[:, None, :] - centres).transpose(2, 0, 1))
    return bool(np.any(gaps < radius))


class Planner:
    """The global planner (module docstring). Remembers whether the last step detoured (for the
    release margin) and the path it took (which the next search favours: PATH_HYSTERESIS)."""

    def __init__(self, config: PlannerConfig, movers: MoverModel) -> None:
        self.config = config
        self.movers = movers
        self.reset()

    def reset(self) -> None:
        self.guided = False  # whether the last waypoint call detoured
        self.path: np.ndarray | None = None  # the last path taken ((K, 2), m)

    def circles(
        self,
        robot_xy: np.ndarray,
        obstacles: Sequence[Obstacle],
        extra: np.ndarray | None = None,
    ) -> np.ndarray:
        """(M, 3) circles [x, y, r] (m) that the planner avoids: the obstacles inflated and swept
        (MoverModel.swept_circles) and `extra` ones (recovery's tabu spots), neither over the
        robot."""
        circles = self.movers.swept_circles(obstacles, robot_xy)
        if extra is not None and len(extra):
            extra = np.array(extra, dtype=float).reshape(-1, 3)
            dist = np.hypot(extra[:, 0] - robot_xy[0], extra[:, 1] - robot_xy[1])
            extra[:, 2] = np.minimum(extra[:, 2], np.maximum(dist - ROBOT_EXCLUSION_M, 0.0))
            circles = np.vstack([circles, extra])
        return circles

    def plan_path(
        self,
        robot_xy: np.ndarray,
        goal_xy: np.ndarray,
        obstacles: Sequence[Obstacle],
        extra: np.ndarray | None = None,
    ) -> np.ndarray | None:
        """A shortest path ((K, 2), m) from the robot to goal_xy round the obstacles and `extra`
        circles, blocked or not; None when the robot cannot move on the grid."""
        robot_xy = np.asarray(robot_xy, dtype=float)
        circles = self.circles(robot_xy, obstacles, extra)
        return self._shortest_path(robot_xy, np.asarray(goal_xy, dtype=float)[:2], circles, False)

    def waypoint(
        self,
        robot_xy: np.ndarray,
        goal: np.ndarray,
        obstacles: Sequence[Obstacle],
        extra: np.ndarray | None = None,
        may_wait: bool = True,
    ) -> Target | None:
        """A waypoint toward goal [x, y, heading] (m, m, rad) if the straight way is blocked by
        the obstacles or the `extra` circles [x, y, r] (m); `may_wait`: whether the robot may wait
        for movers to clear a shorter way (_wait_for_movers)."""
        robot_xy = np.asarray(robot_xy, dtype=float)
        circles = self.circles(robot_xy, obstacles, extra)
        margin = RELEASE_MARGIN_M if self.guided else 0.0
        if not segment_blocked(robot_xy, goal[:2], circles, margin):
            self.guided, self.path = False, None
            return None
        # among movers the way round changes for real from step to step: no hysteresis
        static = all(is_static(o) for o in obstacles)
        path = self._shortest_path(robot_xy, np.asarray(goal[:2], dtype=float), circles, static)
        if path is None or len(path) < 2:  # no way round (yet): wait behind the obstacle
            self.guided, self.path = False, None
            return None
        shorter = (
            self._wait_for_movers(robot_xy, goal, obstacles, extra, path) if may_wait and not static else None
        )
        path = path if shorter is None else shorter
        self.guided, self.path = True, path
        return self._carrot(robot_xy, path, circles, goal)

    def _wait_for_movers(
        self,
        robot_xy: np.ndarray,
        goal: np.ndarray,
        obstacles: Sequence[Obstacle],
        extra: np.ndarray | None,
        path: np.ndarray,
    ) -> np.ndarray | None:
        """The shortest way round the static obstacles alone ((K, 2), m) instead of `path`, the way
        round the movers too, if a robot driving it at DETOUR_SPEED_MPS, now or after a wait
        shorter than `path`'s extra length takes at that speed, meets no mover (swept as the
        planner sweeps it, where it will be when the robot gets there); else None."""
        moving = [not is_static(o) for o in obstacles]
        statics = [o for o, m in zip(obstacles, moving, strict=True) if not m]
        movers = [o for o, m in zip(obstacles, moving, strict=True) if m]
        static_path = self._shortest_path(
            robot_xy, np.asarray(goal[:2], dtype=float), self.circles(robot_xy, statics, extra), False
        )
        if static_path is None or len(static_path) < 2:
            return None
        along = arc_lengths(static_path)
        detour_s = (arc_lengths(path)[-1] - along[-1]) / DETOUR_SPEED_MPS
        arrival_s = along / DETOUR_SPEED_MPS
        # each mover's sweep as the planner draws it this step (from the mover model's lead on; a
        # circle that holds the robot shrunk to exclude it), carried along its track to each
        # arrival below
        sweeps = [(self.movers.swept_circles([m], robot_xy), m) for m in movers]
        # a mover's circles cover planner_sweep_s of its track: waits that far apart overlap halfway
        for wait_s in np.arange(0.0, detour_s, 0.5 * self.movers.planner_sweep_s):
            times_s = wait_s + arrival_s
            if not any(_meets(static_path, times_s, circles, mover) for circles, mover in sweeps):
                return static_path
        return None

    def _shortest_path(
        self, start: np.ndarray, goal: np.ndarray, circles: np.ndarray, sticky: bool
    ) -> np.ndarray | None:
        """Cheapest grid path start -> goal (m) round the `circles`; `sticky`: favouring the last
        path (PATH_HYSTERESIS)."""
        cfg = self.config
        lo = np.minimum(start, goal) - GRID_PADDING_M
        hi = np.maximum(start, goal) + GRID_PADDING_M
        res = max(cfg.grid_resolution_m, math.sqrt(float(np.prod(hi - lo)) / cfg.max_grid_cells))
        nx, ny = (np.ceil((hi - lo) / res).astype(int) + 1).tolist()
        xs, ys = lo[0] + res * np.arange(nx), lo[1] + res * np.arange(ny)
        occupied = np.zeros((ny, nx), dtype=bool)
        # each circle's rows and columns of the grid; one that covers none (off the grid) is skipped
        cx, cy, r = np.asarray(circles, dtype=float).reshape(-1, 3).T
        rows_from, rows_to = np.searchsorted(ys, cy - r), np.searchsorted(ys, cy + r)
        cols_from, cols_to = np.searchsorted(xs, cx - r), np.searchsorted(xs, cx + r)
        on_grid = np.flatnonzero((rows_to > rows_from) & (cols_to > cols_from))
        for k in on_grid.tolist():
            (i0, i1), (j0, j1) = (rows_from[k], rows_to[k]), (cols_from[k], cols_to[k])
            dx2, dy2 = (xs[j0:j1] - cx[k]) ** 2, (ys[i0:i1, None] - cy[k]) ** 2
            occupied[i0:i1, j0:j1] |= dx2 + dy2 < r[k] * r[k]

        def cells(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """(rows, columns) of the grid cells nearest to points (..., 2) (m), within the grid."""
            rows = np.clip(np.round((points[..., 1] - lo[1]) / res).astype(int), 0, ny - 1)
            return rows, np.clip(np.round((points[..., 0] - lo[0]) / res).astype(int), 0, nx - 1)

        si, sj = cells(start)
        occupied[si, sj] = False
        clearance = ndimage.distance_transform_edt(~occupied) * res
        cost = 1.0 + cfg.clearance_cost_gain * np.clip(1.0 - clearance / cfg.clearance_cost_m, 0.0, 1.0)
        if sticky and self.path is not None and PATH_HYSTERESIS > 0:
            # cells along the last path cost less, so the way round does not change sides on a
            # few cm of sensing noise
            near = np.zeros_like(occupied)
            near[cells(self.path)] = True
            width = int(round(PATH_HYSTERESIS_WIDTH_M / res))
            if width > 0:
                near = ndimage.binary_dilation(near, iterations=width)
            cost = np.where(near, (1.0 - PATH_HYSTERESIS) * cost, cost)
        index = np.arange(nx * ny).reshape(ny, nx)
        rows, cols, weights = [], [], []
        for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a = index[max(0, -di) : ny - max(0, di), max(0, -dj) : nx - max(0, dj)]
            b = index[max(0, di) : ny + min(0, di) or None, max(0, dj) : nx + min(0, dj) or None]
            a, b = a.ravel(), b.ravel()
            free = ~occupied.ravel()[a] & ~occupied.ravel()[b]
            a, b = a[free], b[free]
            rows.append(a)
            cols.append(b)
            weights.append(res * math.hypot(di, dj) * 0.5 * (cost.ravel()[a] + cost.ravel()[b]))
        graph = coo_matrix(
            (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(nx * ny, nx * ny)
        ).tocsr()
        source = int(index[si, sj])
        distance, predecessors = dijkstra(graph, directed=False, indices=source, return_predecessors=True)
        target = int(index[cells(goal)])
        if not np.isfinite(distance[target]):
            reachable = np.flatnonzero(np.isfinite(distance))
            if reachable.size <= 1:
                return None
            px, py = xs[reachable % nx], ys[reachable // nx]
            target = int(reachable[np.argmin(np.hypot(px - goal[0], py - goal[1]))])
        nodes = [target]
        while nodes[-1] != source:
            nodes.append(int(predecessors[nodes[-1]]))
        nodes.reverse()
        nodes_arr = np.array(nodes)
        path = np.column_stack([xs[nodes_arr % nx], ys[nodes_arr // nx]])
        path[0] = start
        return path

    def _carrot(
        self, robot_xy: np.ndarray, path: np.ndarray, circles: np.ndarray, goal: np.ndarray
    ) -> Target:
        """The farthest path point within lookahead_m that the robot can see, headed along the path."""
        cfg = self.config
        along = arc_lengths(path)
        chosen = 1
        for i in range(1, len(path)):
            if along[i] > cfg.lookahead_m:
                break
            if not segment_blocked(robot_xy, path[i], circles):
                chosen = i
        ahead = path[min(chosen + PATH_HEADING_CELLS, len(path) - 1)]
        if chosen == len(path) - 1 or np.allclose(ahead, path[chosen]):
            heading = (
                float(goal[2])
                if np.hypot(*(path[-1] - goal[:2])) < AT_GOAL_M
                else float(math.atan2(path[chosen][1] - robot_xy[1], path[chosen][0] - robot_xy[0]))
            )
        else:
            heading = math.atan2(ahead[1] - path[chosen][1], ahead[0] - path[chosen][0])
        return Target(float(path[chosen][0]), float(path[chosen][1]), float(heading), path)
