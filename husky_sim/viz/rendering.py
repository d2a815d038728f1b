"""Headless MP4 video of a recorded episode, redrawn from its `trace.npz` (never re-solved).

A fresh PyBullet DIRECT client (never a GUI, no X) holds visual-only copies of the scene: the
Husky URDF posed from the recorded base (centre-of-mass) pose, the obstacles at their true radius
and recorded centres, the goal marker and the arena walls. It is rendered with the EGL plugin
(`ER_BULLET_HARDWARE_OPENGL`; on a machine without a GPU it runs on Mesa llvmpipe) or with the
CPU TinyRenderer: `--renderer auto` tries EGL and falls back to tiny (saying why), `egl` fails
with one line when the plugin does not load, `tiny` never tries EGL. PyBullet's debug lines are not
drawn by `getCameraImage`, so the ground-level overlays are projected with the camera's matrices
and drawn with Pillow: the reference path and the trail driven so far are kept only where the
rendered surface under them is the ground (depth test), so the robot and obstacles hide them; the
NMPC's predicted states at the current control step and the controller's robot circle (the
trace's `robot_radius_m`, dashed, around the robot) are drawn over everything (a short plan lies
mostly under the robot's own body). The goal is a flat green disc with a dark green arrow along the
goal yaw (visual shapes with rgbaColor). Each frame then gets a caption (sim time, the run's outcome
from its summary.json, scenario, controller, N), a legend, and in the top view a scale bar whose
length in px comes from the camera's projection. The EGL plugin's banners ("EGL device choice"
on stderr, GL vendor lines on stdout) are sent to /dev/null at the file-descriptor level; whether
it loaded is read from loadPlugin's return value.

Frames: frame i shows sim time t_i = i / fps for i = 0, 1, ... while t_i <= t_end (the last
trace sample), so a run of T s at F frames/s gives floor(T * F) + 1 frames, played back in real
time (the MP4's rate is F). Cameras: `top` (fixed, looking down, framed on the whole episode),
`chase` (behind the robot, heading low-passed) or `both`, written as one side-by-side video
(top left, chase right) of 2 x width by height pixels. Encoding: H.264 (libx264, yuv420p) through
imageio-ffmpeg's ffmpeg, which runs in its own process beside the renderer.

Speed: every render prints "rendered F frames in S s (X frames/s) via egl|tiny"; measure with e.g.
`husky-sim render RUN_DIR --width 640 --height 360 --renderer egl`.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import math
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pybullet_data
from PIL import Image, ImageDraw, ImageFont

from husky_sim.runs.run_folder import read_summary, read_trace, summary_or_empty, write_summary
from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.geometry import DEFAULT_URDF
from husky_sim.sim.trace import EpisodeTrace

CAMERAS = ("top", "chase", "both")
RENDERERS = ("auto", "egl", "tiny")

#: RGB colours of the drawn items (the Husky's own yellow, 0.95 0.75 0.05, is used by nothing else
#: in the scene; only the legend's robot swatch repeats it).
HUSKY_RGB = (242, 191, 13)
REFERENCE_RGB = (0, 150, 60)
TRAIL_RGB = (20, 40, 170)
PREDICTION_RGB = (215, 0, 200)
SAFETY_RGB = (225, 20, 40)  # the controller's robot circle, dashed
GOAL_RGBA = (0.0, 0.8, 0.2, 1.0)
GOAL_ARROW_RGBA = (0.0, 0.4, 0.1, 1.0)
STATIC_OBSTACLE_RGBA = (0.25, 0.25, 0.25, 1.0)  # as husky_sim.sim.world
MOVING_OBSTACLE_RGBA = (0.8, 0.3, 0.2, 1.0)
WALL_RGBA = (0.55, 0.55, 0.6, 1.0)

#: The goal marker: a flat disc (radius, thickness in m) and an arrow along the goal yaw (length m).
GOAL_DISC_RADIUS_M = 0.3
GOAL_DISC_THICKNESS_M = 0.03
GOAL_ARROW_LENGTH_M = 0.7

_OVERLAY_Z_M = 0.02  # height of the drawn paths above the ground (m)
_GROUND_Z_M = 0.06  # a pixel whose surface is below this height (m) counts as ground for overlays
_NEAR_M = 0.1  # near clipping distance of the chase camera (m)
_TALLEST_M = 1.0  # the top camera's near plane stays this far above the robot and the walls (m)
_SAFETY_CIRCLE_POINTS = 64  # polyline points of the drawn safety circle (every other gap is a dash)


class RenderError(ValueError):
    """A trace that cannot be rendered, or a renderer that cannot be had (a run folder that cannot
    be read is husky_sim.runs.run_folder's RunFolderError)."""


@dataclass(frozen=True)
class RenderOptions:
    """What to render: size (px) of one camera view, frame rate (frames per s of sim time),
    camera (`top`, `chase`, or `both` side by side) and renderer (`auto`: EGL, else TinyRenderer)."""

    width: int = 1280
    height: int = 720
    fps: float = 30.0
    camera: str = "top"
    renderer: str = "auto"
    top_fov_deg: float = 30.0  # vertical field of view of the top camera
    chase_fov_deg: float = 60.0
    chase_distance_m: float = 3.5  # camera behind the robot
    chase_height_m: float = 2.0  # camera above the ground
    chase_lookahead_m: float = 1.0  # the camera looks at this point ahead of the robot
    chase_heading_tau_s: float = 0.5  # time constant of the chase camera's heading low-pass
    margin_m: float = 1.0  # free border of the top view around everything drawn

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if value < 16 or value > 4096 or value % 2:
                raise ValueError(f"{name}: must be an even number of pixels in [16, 4096], got {value}")
        if not (math.isfinite(self.fps) and 0 < self.fps <= 240):
            raise ValueError(f"fps: must be in (0, 240] frames per s, got {self.fps}")
        if self.camera not in CAMERAS:
            raise ValueError(f"camera: must be one of {', '.join(CAMERAS)}, got {self.camera!r}")
        if self.renderer not in RENDERERS:
            raise ValueError(f"renderer: must be one of {', '.join(RENDERERS)}, got {self.renderer!r}")

    @property
    def frame_size(self) -> tuple[int, int]:
        """(width, height) in px of a video frame: two views side by side with `both`."""
        return (2 * self.width if self.camera == "both" else self.width), self.height


@dataclass(frozen=True)
class RenderResult:
    """What a render wrote and how fast (wall-clock s, frames per wall-clock s)."""

    file: str
    renderer: str  # the path used: "egl" or "tiny"
    camera: str
    frames: int
    width: int  # frame size (px)
    height: int
    fps: float  # frames per s of sim time (the MP4's rate)
    wall_s: float
    note: str = ""  # why `auto` fell back to the TinyRenderer, if it did

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.wall_s if self.wall_s > 0 else float("inf")

    def as_dict(self) -> dict[str, object]:
        return {**asdict(self), "frames_per_s": round(self.frames_per_s, 2), "wall_s": round(self.wall_s, 3)}

    def report(self) -> str:
        text = (
            f"rendered {self.frames} frames in {self.wall_s:.1f} s ({self.frames_per_s:.1f} frames/s) "
            f"via {self.renderer}, {self.width}x{self.height} at {self.fps:g} fps -> {self.file}"
        )
        return f"{text} ({self.note})" if self.note else text


def frame_times(t_end_s: float, fps: float) -> np.ndarray:
    """Sim times (s) of the frames: i / fps for i = 0 .. floor(t_end_s * fps)."""
    return np.arange(int(math.floor(max(t_end_s, 0.0) * fps + 1e-6)) + 1) / fps


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


# ------------------------------------------------------------------------------------- what is drawn


def moving_obstacle_mask(trace: EpisodeTrace) -> np.ndarray:
    """(M,) bool: obstacles whose recorded centre moves at all."""
    xy = trace.obstacle_xy_m
    if xy.shape[0] == 0 or xy.shape[1] == 0:
        return np.zeros(xy.shape[1], dtype=bool)
    return np.ptp(xy, axis=0).max(axis=1) > 1e-9


def drawn_reference(trace: EpisodeTrace) -> np.ndarray | None:
    """(P, 2) reference path (m) drawn on the ground, or None for a set point (a single point)."""
    ref = trace.reference_path[:, :2]
    if len(ref) > 1 and np.ptp(ref, axis=0).max() > 0.01:
        return ref
    return None


def safety_radius_m(trace: EpisodeTrace) -> float:
    """The controller's robot circle (m) drawn around the robot; the URDF footprint if unrecorded."""
    radius = float(trace.robot_radius_m)
    return radius if math.isfinite(radius) and radius > 0 else float(trace.footprint_radius_m)


def circle_points_m(
    centre_xy_m: np.ndarray, radius_m: float, count: int = _SAFETY_CIRCLE_POINTS
) -> np.ndarray:
    """(count + 1, 2) closed polyline (m) of the circle of radius_m around centre_xy_m."""
    angle = np.linspace(0.0, 2.0 * math.pi, count + 1)
    return centre_xy_m[:2] + radius_m * np.column_stack([np.cos(angle), np.sin(angle)])


# -------------------------------------------------------------------------------------------- overlays


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


def ground_mask(camera: Camera, depth: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """True where the rendered surface at pixel (row, col) lies below _GROUND_Z_M (or is empty),
    from the depth buffer (OpenGL depth in [0, 1]) unprojected through the camera."""
    d = depth[rows, cols].astype(float)
    ndc = np.column_stack(
        [
            (cols + 0.5) / camera.width * 2.0 - 1.0,
            1.0 - (rows + 0.5) / camera.height * 2.0,
            2.0 * d - 1.0,
            np.ones(len(d)),
        ]
    )
    world = ndc @ np.linalg.inv(camera.matrix).T
    z = world[:, 2] / world[:, 3]
    return (z < _GROUND_Z_M) | (d >= 1.0 - 1e-6)


@dataclass(frozen=True)
class GroundPath:
    """A polyline on the ground to draw: points (P, 2) in m, colour, line width (px), a dot at each
    point, and whether it is drawn over everything (else hidden where the scene covers the ground)."""

    xy_m: np.ndarray
    rgb: tuple[int, int, int]
    width_px: int
    dots: bool = False
    on_top: bool = False
    dashed: bool = False  # draw every other segment only


def _draw_paths(draw: ImageDraw.ImageDraw, camera: Camera, paths: list[GroundPath]) -> None:
    for path in paths:
        fill = (*path.rgb, 255)
        for line in project_polyline(camera, path.xy_m, _OVERLAY_Z_M):
            if len(line) > 1 and path.dashed:
                for a, b in zip(line[:-1:2], line[1::2], strict=False):
                    draw.line([a, b], fill=fill, width=path.width_px)
            elif len(line) > 1:
                joint = "curve" if len(line) <= 64 else None  # round joints cost ~6 us each in Pillow
                draw.line(line, fill=fill, width=path.width_px, joint=joint)
            if path.dots:
                r = path.width_px + 1
                for x, y in line:
                    draw.ellipse((x - r, y - r, x + r, y + r), fill=fill)


def draw_overlays(rgb: np.ndarray, depth: np.ndarray, camera: Camera, paths: list[GroundPath]) -> np.ndarray:
    """rgb (H, W, 3) with the paths drawn: first those hidden where the depth buffer says the
    surface under a pixel is above the ground, then those drawn on top."""
    hidden = [q for q in paths if not q.on_top]
    if hidden:
        layer = Image.new("RGBA", (camera.width, camera.height), (0, 0, 0, 0))
        _draw_paths(ImageDraw.Draw(layer), camera, hidden)
        pixels = np.asarray(layer)
        rows, cols = np.nonzero(pixels[:, :, 3])
        keep = ground_mask(camera, depth, rows, cols)
        rgb[rows[keep], cols[keep]] = pixels[rows[keep], cols[keep], :3]
    on_top = [q for q in paths if q.on_top]
    if not on_top:
        return rgb
    image = Image.fromarray(rgb)
    _draw_paths(ImageDraw.Draw(image), camera, on_top)
    return np.asarray(image)


Font = ImageFont.ImageFont | ImageFont.FreeTypeFont


def _font(height_px: int, lines_per_frame: int = 30) -> Font:
    """Pillow's default font, about height_px / lines_per_frame px high (at least 10 px)."""
    try:
        return ImageFont.load_default(size=max(10, height_px // lines_per_frame))
    except (TypeError, OSError):  # a Pillow without FreeType
        return ImageFont.load_default()


def frame_caption(t_s: float, run_text: str = "", outcome: str = "") -> str:
    """Caption of the frame at sim time t_s (s): "t =  1.20 s   run outcome: stuck", then the run
    (scenario, controller, N) on a second line; parts left empty are left out."""
    text = f"t = {t_s:5.2f} s"
    if outcome:
        text += f"   run outcome: {outcome}"
    return f"{text}\n{run_text}" if run_text else text


def draw_caption(frame: np.ndarray, text: str, font: Font) -> np.ndarray:
    """The frame (H, W, 3) with `text` (one or more lines) in a dark box at its top left corner;
    the frame as it is for empty text."""
    if not text:
        return frame
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    box = draw.multiline_textbbox((8, 6), text, font=font)
    draw.rectangle((box[0] - 4, box[1] - 3, box[2] + 4, box[3] + 3), fill=(0, 0, 0))
    draw.multiline_text((8, 6), text, fill=(255, 255, 255), font=font)
    return np.asarray(image)


@dataclass(frozen=True)
class LegendEntry:
    """One legend item: its text, its colour and its symbol: "box", "disc", "line", "dots" or "ring"."""

    label: str
    rgb: tuple[int, int, int]
    symbol: str


def _rgb(rgba: tuple[float, ...]) -> tuple[int, int, int]:
    """0..255 RGB of a 0..1 RGBA colour."""
    r, g, b = (round(255 * c) for c in rgba[:3])
    return r, g, b


def legend_entries(trace: EpisodeTrace) -> list[LegendEntry]:
    """What the frames of this trace show, in legend order."""
    entries = [
        LegendEntry("robot", HUSKY_RGB, "box"),
        LegendEntry("obstacle", _rgb(STATIC_OBSTACLE_RGBA), "disc"),
    ]
    if moving_obstacle_mask(trace).any():
        entries.append(LegendEntry("moving obstacle", _rgb(MOVING_OBSTACLE_RGBA), "disc"))
    if np.all(np.isfinite(trace.goal)):
        entries.append(LegendEntry("goal", _rgb(GOAL_RGBA), "disc"))
    if drawn_reference(trace) is not None:
        entries.append(LegendEntry("reference", REFERENCE_RGB, "line"))
    entries += [
        LegendEntry("plan (NMPC)", PREDICTION_RGB, "dots"),
        LegendEntry("trail", TRAIL_RGB, "line"),
        LegendEntry(f"safety circle r={safety_radius_m(trace):.2f} m", SAFETY_RGB, "ring"),
    ]
    return entries


def _draw_symbol(draw: ImageDraw.ImageDraw, box: tuple[int, int, int, int], entry: LegendEntry) -> None:
    """entry's symbol inside the square box (x0, y0, x1, y1) px."""
    x0, y0, x1, y1 = box
    mid = (y0 + y1) / 2
    width_px = max(2, (y1 - y0) // 5)
    if entry.symbol == "box":
        draw.rectangle((x0, y0 + 2, x1, y1 - 2), fill=entry.rgb, outline=(40, 40, 40))
    elif entry.symbol == "disc":
        draw.ellipse(box, fill=entry.rgb)
    elif entry.symbol == "ring":
        draw.ellipse(box, outline=entry.rgb, width=width_px)
    else:  # a line, with dots at its ends and middle for "dots"
        draw.line((x0, mid, x1, mid), fill=entry.rgb, width=width_px)
        if entry.symbol == "dots":
            r = width_px + 1
            for x in (x0 + r, (x0 + x1) / 2, x1 - r):
                draw.ellipse((x - r, mid - r, x + r, mid + r), fill=entry.rgb)


def legend_image(entries: list[LegendEntry], font: Font, max_width_px: int) -> Image.Image:
    """An RGBA legend (symbol, then text, per entry) on a translucent white box, entries flowing
    left to right in rows no wider than max_width_px."""
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    line_px = int(probe.textbbox((0, 0), "Ag", font=font)[3]) + 2
    pad, gap = 4, line_px // 2
    widths = [line_px + gap // 2 + int(probe.textlength(e.label, font=font)) for e in entries]
    rows: list[list[int]] = [[]]
    for n, width in enumerate(widths):
        used = sum(widths[i] + gap for i in rows[-1])
        if rows[-1] and used + width > max_width_px - 2 * pad:
            rows.append([])
        rows[-1].append(n)
    width_px = 2 * pad + max(sum(widths[i] + gap for i in row) - gap for row in rows)
    image = Image.new("RGBA", (width_px, 2 * pad + len(rows) * line_px), (255, 255, 255, 210))
    draw = ImageDraw.Draw(image)
    size = line_px - 4  # of a symbol's square
    for r, row in enumerate(rows):
        x, y = pad, pad + r * line_px
        for n in row:
            _draw_symbol(draw, (x, y + 2, x + size, y + 2 + size), entries[n])
            draw.text((x + line_px + gap // 2 - 2, y), entries[n].label, fill=(0, 0, 0), font=font)
            x += widths[n] + gap
    return image


def paste_legend(frame: np.ndarray, legend: Image.Image, border_px: int = 6) -> np.ndarray:
    """frame (H, W, 3) with the RGBA legend blended into its bottom right corner."""
    image = Image.fromarray(frame)
    corner = (frame.shape[1] - legend.width - border_px, frame.shape[0] - legend.height - border_px)
    image.paste(legend, corner, legend)
    return np.asarray(image)


#: Scale bar lengths (m) to choose from.
SCALE_BAR_LENGTHS_M = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)


def scale_bar_length_m(pixels_per_m: float, max_px: float) -> float:
    """The longest of SCALE_BAR_LENGTHS_M that spans at most max_px px (the shortest if none does)."""
    fitting = [length for length in SCALE_BAR_LENGTHS_M if length * pixels_per_m <= max_px]
    return fitting[-1] if fitting else SCALE_BAR_LENGTHS_M[0]


def draw_scale_bar(frame: np.ndarray, camera: Camera, font: Font, border_px: int = 6) -> np.ndarray:
    """frame (H, W, 3) of the top camera with a scale bar at its bottom left corner: a length in m
    drawn at the ground scale (px per m) the camera's projection gives under its eye."""
    pixels_per_m = ground_pixels_per_m(camera, camera_eye_m(camera)[:2])
    if not math.isfinite(pixels_per_m) or pixels_per_m <= 0:
        return frame
    length_m = scale_bar_length_m(pixels_per_m, 0.2 * camera.width)
    length_px = round(length_m * pixels_per_m)
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image, "RGBA")
    label = f"{length_m:g} m"
    left, top, right, bottom = (int(v) for v in draw.textbbox((0, 0), label, font=font))
    bar_px, pad = max(3, camera.height // 120), 5
    box_w = max(length_px, right - left) + 2 * pad
    box_h = pad + (bottom - top) + 2 + 2 * bar_px + pad  # label, gap, ticks above the bar, bar
    x0, y0 = border_px, frame.shape[0] - border_px - box_h
    draw.rectangle((x0, y0, x0 + box_w, y0 + box_h), fill=(255, 255, 255, 210))
    bar_x0, bar_y0 = x0 + pad, y0 + box_h - pad - bar_px
    draw.rectangle((bar_x0, bar_y0, bar_x0 + length_px, bar_y0 + bar_px), fill=(0, 0, 0))
    for x in (bar_x0, bar_x0 + length_px):  # end ticks, up from the bar
        draw.rectangle((x - 1, bar_y0 - bar_px, x + 1, bar_y0 + bar_px), fill=(0, 0, 0))
    text_x = bar_x0 + max(0, (length_px - (right - left)) // 2) - left
    draw.text((text_x, y0 + pad - top), label, fill=(0, 0, 0), font=font)
    return np.asarray(image)


def annotate_frame(frame: np.ndarray, caption: str, font: Font, legend: Image.Image | None) -> np.ndarray:
    """A video frame with its caption (top left) and the legend (bottom right)."""
    frame = draw_caption(frame, caption, font)
    return frame if legend is None else paste_legend(frame, legend)


# ----------------------------------------------------------------------------------------------- scene


@contextlib.contextmanager
def _quiet_fds(*fds: int) -> Iterator[None]:
    """Send what C code writes on the file descriptors fds (1: stdout, 2: stderr) to /dev/null,
    and restore them afterwards. The EGL plugin prints its GL banners on 1 and "EGL device
    choice: ..." on 2; whether it loaded comes back as loadPlugin's return value, not as text."""
    sys.stdout.flush()
    sys.stderr.flush()
    _flush_c_stdio()
    saved: list[tuple[int, int]] = []
    try:
        with open(os.devnull, "wb") as null:
            for fd in fds:
                saved.append((fd, os.dup(fd)))
                os.dup2(null.fileno(), fd)
        yield
    finally:
        _flush_c_stdio()  # C stdio buffers a pipe's output: flush it while it still goes to /dev/null
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


def _flush_c_stdio() -> None:
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)


class Scene:
    """The recorded scene in a fresh, headless PyBullet client, posed per frame from the trace."""

    def __init__(self, trace: EpisodeTrace, renderer: str) -> None:
        self.trace = trace
        self.client = p.connect(p.DIRECT)
        self._egl_plugin = -1
        self.note = ""
        try:
            self.renderer = self._pick_renderer(renderer)
            self._build()
        except BaseException:
            self.close()
            raise
        self._noisy_images = 2  # the EGL plugin prints its GL vendor on stdout at the first two renders

    def _pick_renderer(self, choice: str) -> str:
        """Load the EGL plugin for `egl` / `auto`; `auto` falls back to the TinyRenderer."""
        if choice == "tiny":
            return "tiny"
        spec = importlib.util.find_spec("eglRenderer")
        if spec is None or spec.origin is None:
            reason = "the eglRenderer module is not installed with pybullet"
        else:
            with _quiet_fds(1, 2):
                self._egl_plugin = p.loadPlugin(
                    spec.origin, "_eglRendererPlugin", physicsClientId=self.client
                )
            reason = "" if self._egl_plugin >= 0 else "the EGL renderer plugin failed to load"
        if not reason:
            return "egl"
        if choice == "egl":
            raise RenderError(f"renderer egl: {reason}; use --renderer tiny or auto")
        self.note = f"{reason}; fell back to tiny"
        return "tiny"

    def _build(self) -> None:
        cid, trace = self.client, self.trace
        ground = os.path.join(pybullet_data.getDataPath(), "plane100.urdf")  # 1 m checker, 200 m wide
        if not os.path.exists(ground):
            ground = os.path.join(pybullet_data.getDataPath(), "plane.urdf")
        p.loadURDF(ground, physicsClientId=cid)
        self.robot = p.loadURDF(str(DEFAULT_URDF), flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=cid)
        xy = trace.obstacle_xy_m
        moving = moving_obstacle_mask(trace)
        self.obstacles: list[tuple[int, float, bool]] = []
        for j, (radius, height) in enumerate(
            zip(trace.obstacle_radius_m, trace.obstacle_height_m, strict=True)
        ):
            rgba = MOVING_OBSTACLE_RGBA if moving[j] else STATIC_OBSTACLE_RGBA
            body = self._visual(
                p.GEOM_CYLINDER,
                rgba,
                [xy[0, j, 0], xy[0, j, 1], 0.5 * height],
                radius=float(radius),
                length=float(height),
            )
            self.obstacles.append((body, float(height), bool(moving[j])))
        if np.all(np.isfinite(trace.goal)):
            self._goal_marker(trace.goal)
        if math.isfinite(trace.arena_half_size_m):
            self._walls(trace.arena_half_size_m)

    def _visual(
        self,
        shape: int,
        rgba: tuple[float, ...],
        position: list[float],
        orientation: tuple[float, ...] = (0, 0, 0, 1),
        **size: object,
    ) -> int:
        """A body with a visual shape only (no collision shape, no mass)."""
        visual = p.createVisualShape(shape, rgbaColor=list(rgba), physicsClientId=self.client, **size)
        return p.createMultiBody(
            0,
            -1,
            visual,
            basePosition=position,
            baseOrientation=list(orientation),
            physicsClientId=self.client,
        )

    def _goal_marker(self, goal: np.ndarray) -> None:
        """A flat green disc at the goal and a darker green arrow along the goal yaw, all visual
        shapes coloured through rgbaColor (getCameraImage draws no debug lines)."""
        x, y, yaw = (float(v) for v in goal)
        thick = GOAL_DISC_THICKNESS_M
        self._visual(p.GEOM_CYLINDER, GOAL_RGBA, [x, y, thick / 2], radius=GOAL_DISC_RADIUS_M, length=thick)
        centre, z = np.array([x, y]), thick + 0.01  # the arrow lies on the disc
        tip = centre + GOAL_ARROW_LENGTH_M * np.array([math.cos(yaw), math.sin(yaw)])
        self._bar(centre, yaw, GOAL_ARROW_LENGTH_M, z)
        for side in (1.0, -1.0):  # the head: two strokes back from the tip
            self._bar(tip, yaw + side * 0.8 * math.pi, 0.35 * GOAL_ARROW_LENGTH_M, z)

    def _bar(self, start_xy_m: np.ndarray, angle_rad: float, length_m: float, z_m: float) -> None:
        """A flat bar of the goal arrow from start_xy_m, length_m long along angle_rad."""
        direction = np.array([math.cos(angle_rad), math.sin(angle_rad)])
        middle = start_xy_m + 0.5 * length_m * direction
        quat = p.getQuaternionFromEuler([0, 0, angle_rad])
        width_m = 0.1 * GOAL_ARROW_LENGTH_M
        extents = [0.5 * length_m + 0.5 * width_m, 0.5 * width_m, 0.01]
        self._visual(p.GEOM_BOX, GOAL_ARROW_RGBA, [*middle, z_m], quat, halfExtents=extents)

    def _walls(self, half: float) -> None:
        """The arena's four walls, placed as husky_sim.sim.world places them (0.1 m thick, 0.5 m high)."""
        thick, height = 0.1, 0.5
        for nx, ny in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            extents = [thick, half + thick, height / 2] if nx else [half + thick, thick, height / 2]
            self._visual(p.GEOM_BOX, WALL_RGBA, [nx * half, ny * half, height / 2], halfExtents=extents)

    def pose(self, sample: int) -> None:
        """Put the robot and the moving obstacles where they were at trace sample `sample`."""
        cid = self.client
        pos, orn = self.trace.base_position_m[sample], self.trace.base_orientation_xyzw[sample]
        p.resetBasePositionAndOrientation(self.robot, pos.tolist(), orn.tolist(), physicsClientId=cid)
        for j, (body, height, moving) in enumerate(self.obstacles):
            if moving:
                x, y = self.trace.obstacle_xy_m[sample, j]
                p.resetBasePositionAndOrientation(
                    body, [x, y, 0.5 * height], [0, 0, 0, 1], physicsClientId=cid
                )

    def image(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """RGB (H, W, 3) uint8 and depth buffer (H, W) float32 of the scene as posed."""
        flag = p.ER_BULLET_HARDWARE_OPENGL if self.renderer == "egl" else p.ER_TINY_RENDERER
        quiet = _quiet_fds(1) if self._noisy_images > 0 else contextlib.nullcontext()
        with quiet:
            _, _, rgba, depth, _ = p.getCameraImage(
                camera.width,
                camera.height,
                list(camera.view),
                list(camera.projection),
                shadow=0,
                renderer=flag,
                flags=p.ER_NO_SEGMENTATION_MASK,
                physicsClientId=self.client,
            )
        self._noisy_images -= 1
        rgba = np.asarray(rgba, dtype=np.uint8).reshape(camera.height, camera.width, 4)
        depth = np.asarray(depth, dtype=np.float32).reshape(camera.height, camera.width)
        return np.ascontiguousarray(rgba[:, :, :3]), depth

    def close(self) -> None:
        if not p.isConnected(self.client):
            return
        with _quiet_fds(1):  # "Destroy EGL OpenGL window."
            if self._egl_plugin >= 0:
                p.unloadPlugin(self._egl_plugin, physicsClientId=self.client)
            p.disconnect(self.client)


# ---------------------------------------------------------------------------------------------- render


def camera_view(scene: Scene, camera: Camera, t_s: float, width_px: int) -> np.ndarray:
    """One camera view (H, W, 3) at sim time t_s: the scene plus reference, trail, prediction and
    the controller's robot circle (dashed) around the robot, in lines width_px px wide."""
    trace = scene.trace
    rgb, depth = scene.image(camera)
    sample = trace.pose_index(t_s)
    paths: list[GroundPath] = []
    ref = drawn_reference(trace)
    if ref is not None:
        paths.append(GroundPath(ref, REFERENCE_RGB, width_px))
    paths.append(GroundPath(trace.base_position_m[: sample + 1, :2], TRAIL_RGB, width_px))
    if len(trace.control_t_s) and trace.control_t_s[0] <= t_s + 1e-9:
        plan = trace.predicted_states[trace.control_index(t_s)][:, :2]
        plan = plan[np.all(np.isfinite(plan), axis=1)]
        paths.append(GroundPath(plan, PREDICTION_RGB, max(1, width_px - 1), dots=True, on_top=True))
    circle = circle_points_m(trace.base_position_m[sample, :2], safety_radius_m(trace))
    paths.append(GroundPath(circle, SAFETY_RGB, max(2, width_px - 1), on_top=True, dashed=True))
    return draw_overlays(rgb, depth, camera, paths)


def render_trace(
    trace: EpisodeTrace,
    out_file: Path,
    options: RenderOptions | None = None,
    caption: str = "",
    outcome: str = "",
) -> RenderResult:
    """Render a trace to an H.264 MP4 at out_file (written whole, then moved into place).

    Every frame carries the sim time, the run's outcome (when given) and caption at its top left,
    a legend at its bottom right and, in the top view, a scale bar in m at its bottom left.
    """
    options = options or RenderOptions()
    _check_trace(trace)
    out_file = Path(out_file)
    if out_file.suffix.lower() != ".mp4":
        raise RenderError(f"{out_file}: the video file name must end in .mp4")
    out_file.parent.mkdir(parents=True, exist_ok=True)
    partial = out_file.with_name(out_file.stem + ".partial.mp4")
    times = frame_times(float(trace.sample_t_s[-1]), options.fps)
    width_px = max(2, round(options.height / 150))
    font, small_font = _font(options.height), _font(options.height, lines_per_frame=45)
    legend = legend_image(legend_entries(trace), small_font, int(0.6 * options.width))  # within one view
    start = time.perf_counter()
    scene = Scene(trace, options.renderer)
    try:
        top = top_camera(trace, options) if options.camera in ("top", "both") else None
        headings = (
            chase_headings(trace, times, options.chase_heading_tau_s) if options.camera != "top" else None
        )
        writer = imageio_ffmpeg.write_frames(
            str(partial),
            options.frame_size,
            fps=options.fps,
            codec="libx264",
            quality=7,
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            macro_block_size=2,
            ffmpeg_log_level="error",
            output_params=["-preset", "veryfast"],
        )
        writer.send(None)
        try:
            for i, t in enumerate(times):
                t = float(t)
                scene.pose(trace.pose_index(t))
                views = []
                if top is not None:
                    views.append(draw_scale_bar(camera_view(scene, top, t, width_px), top, small_font))
                if headings is not None:
                    xy = trace.base_position_m[trace.pose_index(t), :2]
                    views.append(
                        camera_view(scene, chase_camera(xy, float(headings[i]), options), t, width_px)
                    )
                frame = views[0] if len(views) == 1 else np.concatenate(views, axis=1)
                writer.send(annotate_frame(frame, frame_caption(t, caption, outcome), font, legend))
        finally:
            writer.close()
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    finally:
        scene.close()
    partial.replace(out_file)
    width, height = options.frame_size
    return RenderResult(
        str(out_file),
        scene.renderer,
        options.camera,
        len(times),
        width,
        height,
        options.fps,
        time.perf_counter() - start,
        scene.note,
    )


def _check_trace(trace: EpisodeTrace) -> None:
    """Raise RenderError when the trace's arrays do not fit together."""
    s = len(trace.sample_t_s)
    k = len(trace.control_t_s)
    problems = []
    if s == 0:
        problems.append("no pose samples")
    if trace.base_position_m.shape != (s, 3) or trace.base_orientation_xyzw.shape != (s, 4):
        problems.append("base pose arrays do not match sample_t_s")
    m = len(trace.obstacle_radius_m)
    if trace.obstacle_xy_m.shape != (s, m, 2) or trace.obstacle_height_m.shape != (m,):
        problems.append("obstacle arrays do not match")
    if trace.predicted_states.ndim != 3 or (k and trace.predicted_states.shape[0] != k):
        problems.append("predicted_states does not match control_t_s")
    if trace.reference_path.ndim != 2 or trace.reference_path.shape[1:] != (3,):
        problems.append("reference_path is not (P, 3)")
    if s and not np.all(np.isfinite(trace.base_position_m)):
        problems.append("non-finite base positions")
    if problems:
        raise RenderError(f"trace cannot be rendered: {'; '.join(problems)}")


def load_run_trace(run_dir: Path) -> EpisodeTrace:
    """The trace of a run directory, checked for what rendering needs; one-line error otherwise."""
    trace = read_trace(run_dir)
    _check_trace(trace)
    return trace


def run_caption(summary: dict[str, object]) -> str:
    """'scenario controller N=..' from a run's summary, or '' if it does not say."""
    try:
        return f"{summary['scenario']}  {summary['controller']}  N={summary['horizon']}"
    except KeyError:
        return ""


def run_outcome(summary: dict[str, object]) -> str:
    """The run's outcome ("reached", "stuck", ...) from its summary, or '' if unknown."""
    outcome = summary.get("outcome")
    return str(outcome) if outcome else ""


def default_video_file(run_dir: Path, camera: str) -> Path:
    return Path(run_dir) / f"video_{camera}.mp4"


def render_run(
    run_dir: Path, options: RenderOptions | None = None, out_file: Path | None = None
) -> RenderResult:
    """Re-render a recorded run directory (its trace.npz) to out_file (default RUN_DIR/video_CAMERA.mp4)."""
    options = options or RenderOptions()
    trace = load_run_trace(run_dir)
    out = Path(out_file) if out_file is not None else default_video_file(run_dir, options.camera)
    summary = summary_or_empty(run_dir)  # read once, for the caption and the outcome
    return render_trace(trace, out, options, caption=run_caption(summary), outcome=run_outcome(summary))


def record_in_summary(run_dir: Path, result: RenderResult) -> None:
    """Add the render's facts under the key `video` of RUN_DIR/summary.json."""
    summary = read_summary(run_dir)
    summary["video"] = result.as_dict()
    write_summary(Path(run_dir), summary)
