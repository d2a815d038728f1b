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

from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.runs.run_folder import read_summary, read_trace, summary_or_empty, write_summary
from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.robot_description import load_robot
from husky_sim.sim.trace import EpisodeTrace
from husky_sim.viz.video_annotations import (
    GOAL_ARROW_LENGTH_M,
    GOAL_ARROW_RGBA,
    GOAL_DISC_RADIUS_M,
    GOAL_DISC_THICKNESS_M,
    GOAL_RGBA,
    MOVING_OBSTACLE_RGBA,
    PREDICTION_RGB,
    REFERENCE_RGB,
    SAFETY_RGB,
    STATIC_OBSTACLE_RGBA,
    TRAIL_RGB,
    WALL_RGBA,
    GroundPath,
    annotate_frame,
    circle_points_m,
    draw_overlays,
    draw_scale_bar,
    drawn_reference,
    frame_caption,
    frame_font,
    legend_entries,
    legend_image,
    moving_obstacle_mask,
    safety_radius_m,
)
from husky_sim.viz.video_cameras import (
    Camera,
    chase_camera,
    chase_headings,
    top_camera,
)

CAMERAS = ("top", "chase", "both")
RENDERERS = ("auto", "egl", "tiny")


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

    def __init__(self, trace: EpisodeTrace, renderer: str, urdf: Path | None = None) -> None:
        self.urdf = urdf if urdf is not None else load_robot().urdf  # the robot the run drove
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
        self.robot = p.loadURDF(str(self.urdf), flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=cid)
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
    urdf: Path | None = None,
) -> RenderResult:
    """Render a trace to an H.264 MP4 at out_file (written whole, then moved into place); the robot
    drawn is `urdf`'s (default: the default robot's).

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
    font, small_font = frame_font(options.height), frame_font(options.height, lines_per_frame=45)
    legend = legend_image(legend_entries(trace), small_font, int(0.6 * options.width))  # within one view
    start = time.perf_counter()
    scene = Scene(trace, options.renderer, urdf)
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
    urdf = load_robot(str(summary.get("robot", DEFAULT_ROBOT))).urdf
    return render_trace(
        trace, out, options, caption=run_caption(summary), outcome=run_outcome(summary), urdf=urdf
    )


def record_in_summary(run_dir: Path, result: RenderResult) -> None:
    """Add the render's facts under the key `video` of RUN_DIR/summary.json."""
    summary = read_summary(run_dir)
    summary["video"] = result.as_dict()
    write_summary(Path(run_dir), summary)
