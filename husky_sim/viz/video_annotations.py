"""What a rendered video frame shows besides the 3-D scene: what is drawn in the world (colours,
the reference, moving obstacles, the controller's robot circle), the ground-level overlays
projected with the camera's matrices and depth-tested, the caption, the legend and the scale bar
(drawn with Pillow: PyBullet's debug lines are not drawn by getCameraImage)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from husky_sim.sim.trace import EpisodeTrace
from husky_sim.viz.video_cameras import (
    Camera,
    camera_eye_m,
    ground_pixels_per_m,
    project_polyline,
)

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
_SAFETY_CIRCLE_POINTS = 64  # polyline points of the drawn safety circle (every other gap is a dash)


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


def frame_font(height_px: int, lines_per_frame: int = 30) -> Font:
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
