"""What the controller is told: the Husky's pose and the obstacle circles, from the simulator,
with optional seeded Gaussian noise, a latency of k control steps, a scale error on the
obstacles' velocities (an estimator that over- or under-reads how fast they move), and a 2-D
lidar's visibility model (range, field of view, occlusion by static obstacles: `visible_mask`).

By default every obstacle is visible (unlimited range, 360 deg, no occlusion): the controller is
told every circle, as without the model.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from controllers import Obstacle


@dataclass(frozen=True)
class SensingConfig:
    """Noise standard deviations, latency (control steps), the factor (dimensionless) by which
    the reported obstacle velocities differ from the true ones (1: exact, 0: reported static),
    and the lidar's visibility model: its range (m; inf, or None as the scenario schema spells
    it: unlimited), its field of view (deg, in (0, 360], centred on the robot's heading) and
    whether static obstacles hide what lies behind them (see `visible_mask`)."""

    pose_xy_std_m: float = 0.0
    pose_yaw_std_rad: float = 0.0
    obstacle_xy_std_m: float = 0.0
    latency_steps: int = 0
    obstacle_velocity_scale: float = 1.0
    range_m: float = math.inf
    fov_deg: float = 360.0
    occlusion: bool = False

    def __post_init__(self) -> None:
        for name in ("pose_xy_std_m", "pose_yaw_std_rad", "obstacle_xy_std_m", "obstacle_velocity_scale"):
            value = getattr(self, name)
            if not (value >= 0 and math.isfinite(value)):
                raise ValueError(f"sensing.{name}: must be >= 0, got {value}")
        if self.latency_steps < 0:
            raise ValueError(f"sensing.latency_steps: must be >= 0, got {self.latency_steps}")
        if self.range_m is None:  # the scenario schema's "unlimited"
            object.__setattr__(self, "range_m", math.inf)
        if not self.range_m > 0:
            raise ValueError(f"sensing.range_m: must be > 0 m (inf: unlimited), got {self.range_m}")
        if not 0 < self.fov_deg <= 360:
            raise ValueError(f"sensing.fov_deg: must be in (0, 360] deg, got {self.fov_deg}")
        if not isinstance(self.occlusion, bool):
            raise ValueError(f"sensing.occlusion: must be true or false, got {self.occlusion!r}")

    @property
    def sees_everything(self) -> bool:
        """Whether the visibility model is off (unlimited range, 360 deg, no occlusion)."""
        return self.range_m == math.inf and self.fov_deg >= 360 and not self.occlusion


@dataclass(frozen=True)
class Measurement:
    """What the controller is told at one control step: the pose, the circles of the obstacles
    the sensor saw and their indices in the plant's obstacle order (ascending; `obstacles[k]` is
    obstacle `visible[k]`). With latency both are those of the measurement latency_steps ago."""

    pose: np.ndarray  # [x, y, yaw] (m, m, rad)
    obstacles: list[Obstacle]
    visible: tuple[int, ...]


def _wrap(angle_rad: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2 * math.pi) - math.pi


def _entry_m(distance_m: np.ndarray, radius_m: np.ndarray, offset_rad: np.ndarray) -> np.ndarray:
    """Where (m from the sensor) a ray offset_rad off a circle's centre bearing enters it (the
    ray must meet the circle; rounding just outside it is read as a graze)."""
    across = distance_m * np.sin(offset_rad)
    return distance_m * np.cos(offset_rad) - np.sqrt(np.maximum(radius_m**2 - across**2, 0.0))


#: Added to each obstacle row's angles in the occlusion sweep, so that one cumulative maximum runs
#: over every row at once (a row's angles lie within [-pi/2, pi/2]: rows never mix).
_ROW_OFFSET_RAD = 10.0
#: Gaps between occluders narrower than this (rad; 1e-7 m at 100 m) are closed: below what the
#: sweep's rounding can decide.
GAP_TOL_RAD = 1e-9


#: Upper bounds (rad) of the classes of occluder half-widths in which `_overlapping` searches: a
#: few wide occluders (near ones) do not widen the search of the many narrow ones.
_EXTENT_CLASSES_RAD = tuple(math.pi / 2 / 4**k for k in range(8))


def _overlapping(
    target_bearing: np.ndarray, target_half: np.ndarray, bearing: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every (target, occluder) index pair whose angular intervals (bearing +- half-width, rad,
    half-widths at most pi/2) may overlap, found by binary search over the occluders sorted by
    bearing, one class of half-widths at a time (never a dense targets x occluders array); a
    pair may come twice, and some come that do not overlap (the caller clips)."""
    all_rows, all_cols = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
    bounds = (*_EXTENT_CLASSES_RAD[1:], -1.0)
    for upper, lower in zip(_EXTENT_CLASSES_RAD, bounds, strict=True):
        members = np.flatnonzero((half <= upper) & (half > lower))
        if len(members) == 0:
            continue
        members = members[np.argsort(bearing[members], kind="stable")]
        circle = np.concatenate(
            [bearing[members] - 2 * math.pi, bearing[members], bearing[members] + 2 * math.pi]
        )
        reach = target_half + upper
        start = np.searchsorted(circle, target_bearing - reach, side="left")
        stop = np.searchsorted(circle, target_bearing + reach, side="right")
        counts = stop - start
        rows = np.repeat(np.arange(len(target_bearing)), counts)
        offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        all_rows.append(rows)
        all_cols.append(members[(np.repeat(start, counts) + offsets) % len(members)])
    return np.concatenate(all_rows), np.concatenate(all_cols)


def visible_mask(
    sensor_pose: np.ndarray,
    centres_xy_m: np.ndarray,
    radii_m: np.ndarray,
    occluders: np.ndarray,
    range_m: float = math.inf,
    fov_deg: float = 360.0,
    occlusion: bool = False,
) -> np.ndarray:
    """Which circles a planar lidar at `sensor_pose` [x m, y m, yaw rad] sees: a bool per circle
    (centres (n, 2) m, radii (n,) m). The lidar is mounted at the pose given (the caller passes
    the robot's base pose: a mount offset of 0) and sees in the plane.

    A circle is visible when some part of it lies within `range_m` of the sensor, within the field
    of view (`fov_deg`, centred on the heading: a circle counts when the angular extent of its part
    in range overlaps it) and, with `occlusion`, is not wholly hidden: a circle is hidden when every
    ray that reaches it in range and in view first meets an `occluders` circle (the caller's
    static obstacles; an obstacle that is not an occluder, a mover, hides nothing, a stated
    simplification: a real person does hide what is behind them). Partial visibility is
    visibility: a gap between occluders, or beside the edge of the view, shows it (a gap narrower
    than GAP_TOL_RAD is closed).
    Which of two circles is in front along shared rays is decided on one shared ray, which is
    exact for circles that do not overlap. A circle that contains the sensor is visible and hides
    nothing. Vectorised: circles beyond range are dropped first, and only pairs whose angular
    intervals may overlap are swept (_overlapping).
    """
    centres = np.asarray(centres_xy_m, dtype=float).reshape(-1, 2)
    radii = np.asarray(radii_m, dtype=float).reshape(-1)
    n = len(radii)
    rel = centres - np.asarray(sensor_pose[:2], dtype=float)
    distance = np.hypot(rel[:, 0], rel[:, 1])
    seen = distance - radii <= range_m  # the nearest surface point in range (inside: always)
    full_view = fov_deg >= 360.0
    if n == 0 or (full_view and not occlusion):
        return seen
    inside = distance <= radii
    bearing = _wrap(np.arctan2(rel[:, 1], rel[:, 0]) - float(sensor_pose[2]))  # from the heading
    outside = ~inside
    extent = np.full(n, math.pi)  # half-width (rad) of each circle's angular interval
    extent[outside] = np.arcsin(np.clip(radii[outside] / distance[outside], 0.0, 1.0))
    in_range = extent.copy()  # ... of its part within range_m
    clipped = outside & seen & (distance**2 - radii**2 > range_m**2)  # tangent points beyond range
    d, r = distance[clipped], radii[clipped]
    in_range[clipped] = np.arccos(np.clip((d**2 + range_m**2 - r**2) / (2 * d * range_m), -1.0, 1.0))
    half_fov = math.radians(fov_deg) / 2
    if not full_view:
        seen &= np.abs(bearing) <= half_fov + in_range
    if not occlusion:
        return seen
    targets = np.flatnonzero(seen & outside)
    blockers = np.flatnonzero(np.asarray(occluders, dtype=bool) & (distance - radii <= range_m) & outside)
    if len(targets) == 0 or (len(blockers) == 0 and full_view):
        return seen
    window = in_range[targets]  # each target's interval is [-window, window] about its bearing
    rows, cols = _overlapping(bearing[targets], window, bearing[blockers], extent[blockers])
    t, b = targets[rows], blockers[cols]
    keep = (t != b) & (distance[b] - radii[b] < distance[t] + radii[t])  # b may be in front of t
    rows, t, b = rows[keep], t[keep], b[keep]
    # the occluder's interval about the target's bearing, clipped to the target's window
    centre = _wrap(bearing[b] - bearing[t])
    lo = np.maximum(centre - extent[b], -window[rows])
    hi = np.minimum(centre + extent[b], window[rows])
    ray = 0.5 * (lo + hi)  # a ray both circles meet: which is in front along it
    front = (lo < hi) & (_entry_m(distance[b], radii[b], ray - centre) < _entry_m(distance[t], radii[t], ray))
    rows, lo, hi = rows[front], lo[front], hi[front]
    if not full_view:  # the blind arc behind the lidar hides like an occluder in front
        blind = _wrap(math.pi - bearing[targets])
        for turn in (-2 * math.pi, 0.0, 2 * math.pi):
            b_lo = np.maximum(blind + turn - (math.pi - half_fov), -window)
            b_hi = np.minimum(blind + turn + (math.pi - half_fov), window)
            some = np.flatnonzero(b_lo < b_hi)
            rows, lo, hi = np.r_[rows, some], np.r_[lo, b_lo[some]], np.r_[hi, b_hi[some]]
    if len(rows) == 0:
        return seen
    order = np.lexsort((lo, rows))
    rows, lo, hi = rows[order], lo[order], hi[order]
    reach = np.maximum.accumulate(hi + _ROW_OFFSET_RAD * rows) - _ROW_OFFSET_RAD * rows
    first = np.r_[True, rows[1:] != rows[:-1]]
    before = np.where(first, -window[rows], np.r_[-math.inf, reach[:-1]])  # covered up to here
    gapped = np.zeros(len(targets), dtype=bool)
    gapped[rows[lo > before + GAP_TOL_RAD]] = True
    last = np.r_[rows[1:] != rows[:-1], True]
    covered = np.zeros(len(targets), dtype=bool)
    covered[rows[last]] = reach[last] >= window[rows[last]] - GAP_TOL_RAD
    seen[targets[covered & ~gapped]] = False
    return seen


class Sensor:
    """Seeded noisy, delayed measurements of the obstacles the lidar sees; the same seed gives the
    same noise sequence. `static[i]` says whether obstacle i is static (it occludes, with
    occlusion on); None: judged at each measurement from its reported velocity (zero: static)."""

    def __init__(self, config: SensingConfig, seed: int, static: Sequence[bool] | None = None) -> None:
        self.config = config
        self._rng = np.random.default_rng(seed)
        self._queue: deque[Measurement] = deque()
        self._static = None if static is None else np.array(static, dtype=bool)

    def visible(self, pose: np.ndarray, obstacles: Sequence[Obstacle]) -> tuple[int, ...]:
        """The indices of the obstacles (true circles) that the lidar at `pose` (the true base
        pose) sees now (visible_mask; every index with the model off)."""
        cfg = self.config
        if cfg.sees_everything or not obstacles:
            return tuple(range(len(obstacles)))
        table = np.array([[o.x_m, o.y_m, o.radius_m, o.vx_mps, o.vy_mps] for o in obstacles])
        static = self._static if self._static is not None else (table[:, 3] == 0) & (table[:, 4] == 0)
        mask = visible_mask(pose, table[:, :2], table[:, 2], static, cfg.range_m, cfg.fov_deg, cfg.occlusion)
        return tuple(int(i) for i in np.flatnonzero(mask))

    def measure(self, pose: np.ndarray, obstacles: Sequence[Obstacle]) -> Measurement:
        """Record the true state now; return the (noisy) measurement taken latency_steps ago.
        Visibility is judged on the true pose and circles; the noise is drawn for every obstacle,
        seen or not, so the noise sequence does not depend on what was seen."""
        cfg = self.config
        noisy_pose = pose + self._rng.normal(0.0, 1.0, 3) * [
            cfg.pose_xy_std_m,
            cfg.pose_xy_std_m,
            cfg.pose_yaw_std_rad,
        ]
        offsets = self._rng.normal(0.0, cfg.obstacle_xy_std_m, (len(obstacles), 2)) if obstacles else []
        scale = cfg.obstacle_velocity_scale
        visible = self.visible(pose, obstacles)
        noisy_obstacles = [
            replace(
                obstacles[i],
                x_m=obstacles[i].x_m + float(offsets[i][0]),
                y_m=obstacles[i].y_m + float(offsets[i][1]),
                vx_mps=obstacles[i].vx_mps * scale,
                vy_mps=obstacles[i].vy_mps * scale,
            )
            for i in visible
        ]
        self._queue.append(Measurement(noisy_pose, noisy_obstacles, visible))
        while len(self._queue) > cfg.latency_steps + 1:
            self._queue.popleft()
        return self._queue[0]
