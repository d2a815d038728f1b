"""The cameras of a rendered video: `top` (fixed, looking down, framed on the whole episode) and
`chase` (behind the robot, heading low-passed); view and projection matrices, and where the
ground lies in pixels (for the scale bar)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.trace import EpisodeTrace

if TYPE_CHECKING:
    from husky_sim.viz.rendering import RenderOptions

_NEAR_M = 0.1  # near clipping distance of the chase camera (m)
_TALLEST_M = 1.0  # the top camera's near plane stays this far above the robot and the walls (m)


# --------------------------------------------------------------------------------------------- cameras


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: PyBullet's column-major view and projection matrices, its image size (px)
    and the near plane distance (m) its projection was built with."""

    view: tuple[float, ...]
    projection: tuple[float, ...]
    width: int
    height: int
    near_m: float = _NEAR_M

    @property
    def matrix(self) -> np.ndarray:
        """Projection x view (4, 4), acting on column vectors of world points (m)."""
        proj = np.asarray(self.projection).reshape(4, 4).T
        return proj @ np.asarray(self.view).reshape(4, 4).T


def _camera(
    eye: np.ndarray,
    target: np.ndarray,
    up: tuple[float, float, float],
    fov_deg: float,
    far_m: float,
    width: int,
    height: int,
    near_m: float = _NEAR_M,
) -> Camera:
    view = p.computeViewMatrix(eye.tolist(), target.tolist(), list(up))
    proj = p.computeProjectionMatrixFOV(fov_deg, width / height, near_m, far_m)
    return Camera(tuple(view), tuple(proj), width, height, near_m)


def scene_bounds(trace: EpisodeTrace) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper (x, y) corners (m) of everything the top view must show."""
    points = [trace.base_position_m[:, :2], trace.reference_path[:, :2]]
    if trace.obstacle_xy_m.size:
        r = trace.obstacle_radius_m[None, :, None]
        points += [(trace.obstacle_xy_m - r).reshape(-1, 2), (trace.obstacle_xy_m + r).reshape(-1, 2)]
    if np.all(np.isfinite(trace.goal)):
        points.append(trace.goal[None, :2])
    if math.isfinite(trace.arena_half_size_m):
        half = trace.arena_half_size_m + 0.1
        points.append(np.array([[-half, -half], [half, half]]))
    xy = np.concatenate([q for q in points if q.size])
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    return xy.min(axis=0), xy.max(axis=0)


def top_camera(trace: EpisodeTrace, options: RenderOptions) -> Camera:
    """Fixed camera straight above the scene's centre, high enough to frame the whole episode.

    Its near plane sits just above the tallest thing in the scene, not at 0.1 m: the EGL depth
    buffer's resolution scales with near / distance^2, and with a 0.1 m near plane 20 m up the
    ground and the goal disc a few cm above it z-fight (the disc came out as grey stripes).
    """
    lo, hi = scene_bounds(trace)
    centre = 0.5 * (lo + hi)
    half_x, half_y = np.maximum(0.5 * (hi - lo) + options.margin_m, 1.5)
    tan_half = math.tan(math.radians(options.top_fov_deg) / 2)
    aspect = options.width / options.height
    tallest_m = max([_TALLEST_M, *trace.obstacle_height_m.tolist()])
    height_m = max(half_y / tan_half, half_x / (tan_half * aspect)) + tallest_m
    near_m = max(_NEAR_M, height_m - tallest_m - 1.0)
    eye = np.array([centre[0], centre[1], height_m])
    target = np.array([centre[0], centre[1], 0.0])
    return _camera(
        eye,
        target,
        (0.0, 1.0, 0.0),
        options.top_fov_deg,
        height_m + 1.0,
        options.width,
        options.height,
        near_m,
    )


def ground_pixels_per_m(camera: Camera, xy_m: np.ndarray) -> float:
    """Image scale (px per m) on the ground at xy_m (m), from the camera's projection: the pixel
    distance between xy_m and a point 1 m from it along x. Uniform over the top camera's view."""
    points = np.array([xy_m[:2], xy_m[:2] + np.array([1.0, 0.0])], dtype=float)
    pieces = project_polyline(camera, points, 0.0)
    if len(pieces) != 1 or len(pieces[0]) != 2:
        return math.nan
    (x0, y0), (x1, y1) = pieces[0]
    return math.hypot(x1 - x0, y1 - y0)


def camera_eye_m(camera: Camera) -> np.ndarray:
    """(3,) position (m) of the camera in the world, from its view matrix."""
    return np.linalg.inv(np.asarray(camera.view).reshape(4, 4).T)[:3, 3]


def chase_camera(xy_m: np.ndarray, heading_rad: float, options: RenderOptions) -> Camera:
    """Camera behind and above the robot at xy_m, looking along heading_rad (rad)."""
    forward = np.array([math.cos(heading_rad), math.sin(heading_rad)])
    eye = np.append(xy_m - options.chase_distance_m * forward, options.chase_height_m)
    target = np.append(xy_m + options.chase_lookahead_m * forward, 0.2)
    return _camera(eye, target, (0.0, 0.0, 1.0), options.chase_fov_deg, 80.0, options.width, options.height)


def chase_headings(trace: EpisodeTrace, times_s: np.ndarray, tau_s: float) -> np.ndarray:
    """Robot yaw (rad) at each frame time, low-passed with time constant tau_s (s)."""
    out = np.empty(len(times_s))
    smooth = None
    for i, t in enumerate(times_s):
        yaw = _yaw(trace.base_orientation_xyzw[trace.pose_index(float(t))])
        if smooth is None:
            smooth = yaw
        else:
            dt = float(t - times_s[i - 1])
            gain = 1.0 - math.exp(-dt / tau_s) if tau_s > 0 else 1.0
            smooth += gain * math.remainder(yaw - smooth, 2 * math.pi)
        out[i] = smooth
    return out


def _yaw(quat_xyzw: np.ndarray) -> float:
    x, y, z, w = (float(q) for q in quat_xyzw)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def project_polyline(camera: Camera, xy_m: np.ndarray, z_m: float) -> list[list[tuple[float, float]]]:
    """Pixel polylines of the ground polyline xy_m (P, 2) at height z_m, cut at the near plane."""
    if len(xy_m) == 0:
        return []
    world = np.column_stack([xy_m, np.full(len(xy_m), z_m), np.ones(len(xy_m))])
    clip = world @ camera.matrix.T
    front = clip[:, 3] >= camera.near_m
    if front.all():
        return [_to_pixels(camera, clip)]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], front.astype(np.int8), [0]])))
    pieces = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):  # runs [start, end) in front
        run = [clip[start:end]]
        if start > 0:
            run.insert(0, _near_cut(clip[start - 1], clip[start], camera.near_m))
        if end < len(clip):
            run.append(_near_cut(clip[end - 1], clip[end], camera.near_m))
        pieces.append(_to_pixels(camera, np.vstack(run)))
    return pieces


def _near_cut(a: np.ndarray, b: np.ndarray, near_m: float) -> np.ndarray:
    """The point (clip coordinates) where segment a-b crosses the near plane w = near_m."""
    s = (near_m - a[3]) / (b[3] - a[3])
    return (a + s * (b - a))[None, :]


def _to_pixels(camera: Camera, clip: np.ndarray) -> list[tuple[float, float]]:
    ndc = clip[:, :2] / clip[:, 3:4]
    px = (ndc[:, 0] + 1.0) * 0.5 * camera.width
    py = (1.0 - ndc[:, 1]) * 0.5 * camera.height
    return list(zip(px.tolist(), py.tolist(), strict=True))
