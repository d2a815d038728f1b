"""What every family of figures shares: reading a recorded run, the series derived from it,
saving a figure as PNG and SVG (cropped, reproducible), and the pieces an xy panel is drawn from.

A run directory, as `husky-sim run` writes it, holds `summary.json`, `log.csv` (one row per
control step) and `trace.npz` (obstacles at 60 Hz, the reference path, the goal). The xy panels
are framed on everything they draw (obstacles grown by the robot radius, start, goal or
reference, moving obstacles' marks, walls) with a small margin. Every figure is written as
`<name>.png` and `<name>.svg`, cropped to its drawn extent (no label cut); SVGs carry no date and
a fixed hash salt so the same input gives the same file. Units: m, s, rad, m/s, rad/s; B in m^2.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed; must precede the pyplot import

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from controllers import registry  # noqa: E402
from husky_sim.runs.run_folder import read_log, read_summary, read_trace  # noqa: E402
from husky_sim.sim.trace import EpisodeTrace  # noqa: E402

#: Raster resolution (dots per inch); a figure of w x h inches is w*DPI x h*DPI pixels.
DPI = 110

#: log.csv columns the figures read (the rest are ignored).
LOG_NEEDED = (
    "t_s",
    "x_m",
    "y_m",
    "v_cmd_mps",
    "omega_cmd_radps",
    "v_applied_mps",
    "omega_applied_radps",
    "v_body_mps",
    "omega_body_radps",
    "clearance_m",
    "s_h_min",
    "s_v_max",
    "solve_ms",
)

SUMMARY_NEEDED = ("scenario", "controller", "horizon", "tau_s")

#: Free border (m) of the xy panels around everything drawn, plus this fraction of the larger side.
SCENE_MARGIN_M = 0.3
SCENE_MARGIN_FRACTION = 0.04

MOVING_COLOUR = "tab:pink"  # the paper draws moving obstacles as pink dashed lines
LIMIT_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 0.9}

FigurePaths = tuple[Path, Path]  # (png, svg)
SceneBox = tuple[np.ndarray, np.ndarray]  # (lower-left, upper-right) corners (m)


def _entry_flag(controller: str, flag: str) -> bool:
    """A registered controller's flag (controllers.registry); True for a run of a controller this
    process does not know (its figures show what its log holds)."""
    try:
        return bool(getattr(registry.entry(controller), flag))
    except ValueError:
        return True


def _shows_gamma(controller: str) -> bool:
    """Whether gamma means something to the controller (BT has no decay rate)."""
    return _entry_flag(controller, "decay_rate")


def decay_slack_is_variable(controller: str) -> bool:
    """Whether s_h is one of the controller's decision variables (Relax-CBF's)."""
    return _entry_flag(controller, "decay_slack")


class PlotInputError(ValueError):
    """Runs that cannot be plotted together (none, or of different scenarios), or a scenario a
    results file does not have; files that cannot be read are husky_sim.runs.run_folder's
    RunFolderError."""


# ---------------------------------------------------------------------------------------------
# Reading runs
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunRecord:
    """One recorded run: its summary, its log as column arrays and its trace."""

    run_dir: Path
    summary: dict[str, object]
    log: dict[str, np.ndarray]  # numeric columns as float arrays, others as str arrays
    trace: EpisodeTrace

    @property
    def tau_s(self) -> float:
        """Control period (s)."""
        return float(self.summary["tau_s"])

    @property
    def robot_radius_m(self) -> float:
        """The controller's robot circle (m); the URDF footprint when the run has none."""
        for value in (self.trace.robot_radius_m, self.summary.get("robot_radius_m")):
            if value is not None and math.isfinite(float(value)):
                return float(value)
        return float(self.trace.footprint_radius_m)

    def label(self, with_seed: bool = False) -> str:
        """Legend text such as "bt N=5" or "relax-cbf N=5 γ=0.12"."""
        controller = str(self.summary["controller"])
        text = f"{controller} N={self.summary['horizon']}"
        if _shows_gamma(controller) and self.summary.get("gamma") is not None:
            text += f" γ={float(self.summary['gamma']):g}"
        if with_seed:
            text += f" seed={self.summary.get('seed')}"
        return text


def load_run(run_dir: Path | str) -> RunRecord:
    """Read a run directory; raises RunFolderError (one line, naming the file) if it is unusable."""
    summary = read_summary(run_dir, SUMMARY_NEEDED)
    return RunRecord(Path(run_dir), summary, read_log(run_dir, LOG_NEEDED), read_trace(run_dir))


# ---------------------------------------------------------------------------------------------
# Derived series
# ---------------------------------------------------------------------------------------------


def obstacle_centres_at(trace: EpisodeTrace, t_s: np.ndarray) -> np.ndarray:
    """(K, M, 2) obstacle centres (m) at times t_s (s), linearly interpolated from the trace.

    The trace samples the true centres at 60 Hz of sim time; times outside the samples take the
    first or last sample.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    xy = trace.obstacle_xy_m
    out = np.empty((t.size, xy.shape[1], 2))
    for j in range(xy.shape[1]):
        for c in range(2):
            out[:, j, c] = np.interp(t, trace.sample_t_s, xy[:, j, c])
    return out


def barrier_values(
    x_m: np.ndarray, y_m: np.ndarray, t_s: np.ndarray, trace: EpisodeTrace, robot_radius_m: float
) -> np.ndarray:
    """(K, M) barrier per obstacle, B_j = |p - c_j|^2 - (r + r_j)^2 (m^2).

    p = (x_m, y_m) is the robot position at the control times t_s (s), c_j the obstacle centre
    interpolated at the same times, r the robot radius and r_j the obstacle radius (m). B_j >= 0
    means the robot circle is outside obstacle j: the paper's h(x) for one obstacle.
    """
    centres = obstacle_centres_at(trace, t_s)
    pos = np.column_stack([np.asarray(x_m, float), np.asarray(y_m, float)])[:, None, :]
    sq_dist = np.sum((pos - centres) ** 2, axis=2)
    return sq_dist - (robot_radius_m + trace.obstacle_radius_m[None, :]) ** 2


def barrier_series(run: RunRecord) -> np.ndarray:
    """(K,) barrier B (m^2) of a run at each control step: the smallest B_j over the obstacles.

    The smallest B_j is the most binding obstacle constraint; it is the obstacle with the
    nearest centre whenever the radii are equal. NaN when the run has no obstacles.
    """
    values = barrier_values(run.log["x_m"], run.log["y_m"], run.log["t_s"], run.trace, run.robot_radius_m)
    if values.shape[1] == 0:
        return np.full(values.shape[0], np.nan)
    return values.min(axis=1)


def moving_obstacles(trace: EpisodeTrace, tolerance_m: float = 1e-3) -> np.ndarray:
    """(M,) bool: obstacles whose centre moves more than tolerance_m (m) over the trace."""
    xy = trace.obstacle_xy_m
    if xy.shape[0] == 0 or xy.shape[1] == 0:
        return np.zeros(xy.shape[1], dtype=bool)
    return np.ptp(xy, axis=0).max(axis=1) > tolerance_m


def time_marks(t_end_s: float, count: int = 4) -> np.ndarray:
    """`count` evenly spaced times (s) from 0 to t_end_s, where moving obstacles are drawn."""
    return np.linspace(0.0, max(t_end_s, 0.0), count)


# ---------------------------------------------------------------------------------------------
# Saving
# ---------------------------------------------------------------------------------------------


def save_figure(fig: Figure, out_dir: Path, stem: str) -> FigurePaths:
    """Write fig as out_dir/stem.png and .svg, close it, and return the two paths."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        png, svg = out_dir / f"{stem}.png", out_dir / f"{stem}.svg"
        fig.savefig(png, dpi=DPI, bbox_inches="tight", pad_inches=0.1)  # no label cut at the edges
        # the SVG keeps the layout the PNG was drawn with rather than working it out again (at
        # 72 dpi): both files show the same figure, and a figure's layout pass is 15 % of its CPU
        fig.set_layout_engine("none")
        with plt.rc_context({"svg.hashsalt": "husky-sim"}):
            fig.savefig(svg, metadata={"Date": None}, bbox_inches="tight", pad_inches=0.1)
    finally:
        plt.close(fig)
    return png, svg


def file_stem(text: str) -> str:
    """A file-name-safe version of text."""
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", text).strip("_") or "unnamed"


# ---------------------------------------------------------------------------------------------
# Drawing pieces
# ---------------------------------------------------------------------------------------------


def time_label(t_s: float, t_end_s: float) -> str:
    return f"t={t_s:.0f} s" if t_end_s >= 10 else f"t={t_s:.1f} s"


def draw_static_obstacles(ax: Axes, trace: EpisodeTrace, robot_radius_m: float) -> None:
    """Static obstacles to scale (filled), with the circle the robot centre must stay out of."""
    moving = moving_obstacles(trace)
    first = True
    for j in np.flatnonzero(~moving):
        centre = trace.obstacle_xy_m[0, j]
        radius = float(trace.obstacle_radius_m[j])
        ax.add_patch(
            Circle(
                centre,
                radius,
                facecolor="0.55",
                edgecolor="black",
                zorder=2,
                label="obstacle" if first else None,
            )
        )
        ax.add_patch(
            Circle(
                centre,
                radius + robot_radius_m,
                fill=False,
                edgecolor="0.4",
                linestyle=":",
                linewidth=0.8,
                zorder=2,
                label="obstacle + robot radius" if first else None,
            )
        )
        first = False


def draw_moving_obstacles(ax: Axes, trace: EpisodeTrace, marks_s: np.ndarray, t_end_s: float) -> None:
    """Moving obstacles: dashed centre paths up to t_end_s, circles at marks_s labelled with t."""
    moving = np.flatnonzero(moving_obstacles(trace))
    if moving.size == 0:
        return
    shown = trace.sample_t_s <= t_end_s + 1e-9
    centres = obstacle_centres_at(trace, marks_s)
    for n, j in enumerate(moving):
        path = trace.obstacle_xy_m[shown, j]
        ax.plot(
            path[:, 0],
            path[:, 1],
            "--",
            color=MOVING_COLOUR,
            linewidth=1.0,
            zorder=1,
            label="moving obstacle path" if n == 0 else None,
        )
        radius = float(trace.obstacle_radius_m[j])
        for k, t in enumerate(marks_s):
            alpha = 0.15 + 0.5 * k / max(len(marks_s) - 1, 1)
            ax.add_patch(
                Circle(
                    centres[k, j],
                    radius,
                    facecolor=MOVING_COLOUR,
                    alpha=alpha,
                    edgecolor=MOVING_COLOUR,
                    zorder=2,
                )
            )
            ax.annotate(
                time_label(t, t_end_s),
                centres[k, j],
                fontsize=6,
                ha="center",
                va="center",
                color="black",
                clip_on=True,
                zorder=3,
            )


def draw_reference(ax: Axes, trace: EpisodeTrace, start_xy: np.ndarray) -> None:
    """The start, and the goal (point stabilisation) or the reference path (tracking)."""
    ax.plot(*start_xy, "o", color="black", markersize=6, zorder=5, label="start")
    if np.all(np.isfinite(trace.goal)):
        ax.plot(
            trace.goal[0],
            trace.goal[1],
            "*",
            color="gold",
            markeredgecolor="black",
            markersize=14,
            zorder=5,
            label="goal",
        )
    elif len(trace.reference_path):
        ref = trace.reference_path
        ax.plot(ref[:, 0], ref[:, 1], "--", color="0.3", linewidth=1.0, zorder=1, label="reference")


def draw_arena(ax: Axes, trace: EpisodeTrace) -> None:
    half = trace.arena_half_size_m
    if math.isfinite(half):
        ax.add_patch(
            Rectangle(
                (-half, -half), 2 * half, 2 * half, fill=False, edgecolor="black", linewidth=1.5, zorder=1
            )
        )


def _points_box(xy_m: np.ndarray, radius_m: float | np.ndarray = 0.0) -> np.ndarray:
    """(2, 2) [lower-left, upper-right] (m) of points xy_m (P, 2) grown by radius_m (scalar or (P,))."""
    r = np.broadcast_to(np.asarray(radius_m, dtype=float), xy_m.shape[:1])[:, None]
    return np.vstack([(xy_m - r).min(axis=0), (xy_m + r).max(axis=0)])


def scene_extent_boxes(
    trace: EpisodeTrace, trajectories: Iterable[np.ndarray], robot_radius_m: float, t_end_s: float
) -> list[np.ndarray]:
    """(2, 2) boxes (m) of everything the xy panels draw for a scene shown up to t_end_s (s).

    The trajectories (whose first points are the starts), the goal or the reference path, each
    static obstacle's circle grown by robot_radius_m (the dotted circle, which holds the obstacle
    when robot_radius_m >= 0), each moving obstacle's dashed path and its circles at the time
    marks, and the arena walls.
    """
    boxes = [_points_box(np.asarray(p, dtype=float)[:, :2]) for p in trajectories if len(p)]
    if np.all(np.isfinite(trace.goal)):
        boxes.append(_points_box(trace.goal[None, :2]))
    elif len(trace.reference_path):
        boxes.append(_points_box(trace.reference_path[:, :2]))
    moving = moving_obstacles(trace)
    static = np.flatnonzero(~moving)
    if static.size:
        radii = trace.obstacle_radius_m[static]
        boxes.append(_points_box(trace.obstacle_xy_m[0, static], radii + max(robot_radius_m, 0.0)))
    shown = trace.sample_t_s <= t_end_s + 1e-9
    marks = obstacle_centres_at(trace, time_marks(t_end_s))
    for j in np.flatnonzero(moving):
        boxes.append(_points_box(marks[:, j], trace.obstacle_radius_m[j]))
        if shown.any():
            boxes.append(_points_box(trace.obstacle_xy_m[shown, j]))
    half = trace.arena_half_size_m
    if math.isfinite(half):
        boxes.append(np.array([[-half, -half], [half, half]]))
    return boxes


def scene_box(
    trace: EpisodeTrace, trajectories: Iterable[np.ndarray], robot_radius_m: float, t_end_s: float
) -> SceneBox:
    """(lower-left, upper-right) corners (m) holding everything scene_extent_boxes lists, with a
    free border of SCENE_MARGIN_M plus SCENE_MARGIN_FRACTION of the larger side."""
    boxes = [
        b for b in scene_extent_boxes(trace, trajectories, robot_radius_m, t_end_s) if np.all(np.isfinite(b))
    ]
    if not boxes:
        boxes = [np.zeros((2, 2))]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    margin_m = SCENE_MARGIN_M + SCENE_MARGIN_FRACTION * float(np.max(hi - lo))
    return lo - margin_m, hi + margin_m


def scene_aspect(box: SceneBox) -> float:
    """Height over width of a scene box, clamped to [0.25, 3]."""
    lo, hi = box
    return float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.25, 3.0))


def frame_xy(ax: Axes, box: SceneBox) -> None:
    """Limits to box, equal aspect, axis labels in m."""
    lo, hi = box
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, linewidth=0.3)


def no_data(ax: Axes, text: str, fontsize: float | None = None) -> None:
    """text, grey, in the middle of an empty panel."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4", fontsize=fontsize)


def run_title(run: RunRecord) -> str:
    return f"{run.summary['scenario']}: {run.label()} ({run.summary.get('outcome', '?')})"
