"""Figures of recorded runs, after the paper's (PNG and SVG, matplotlib's Agg backend).

A run directory, as `husky-sim run` writes it, holds `summary.json`, `log.csv` (one row per
control step) and `trace.npz` (obstacles at 60 Hz, the reference path, the goal). From it:

* `plot_run`: the xy trajectory with obstacles to scale (paper Figs. 3 and 4), the control
  signals against their limits (Figs. 4 and 6), clearance and barrier value, the slacks s_h and
  s_v, and a histogram of solve times against the control period tau.
* `plot_comparison`: several runs of one scenario overlaid (xy, v, omega, clearance).
* `plot_tuning_maps`: from a suite's `results.csv`, gamma x N maps of outcome, minimum clearance
  and time to goal (tracking RMSE for tracking scenarios), per scenario and controller. Clearance
  colours are absolute and the same on every map: red at or below 0 m (contact), green from
  SAFE_CLEARANCE_M up. An empty panel says what is missing and why.

The xy panels are framed on everything they draw (obstacles grown by the robot radius, start,
goal or reference, moving obstacles' marks, walls) with a small margin. Every figure is written as
`<name>.png` and `<name>.svg`, cropped to its drawn extent (no label cut); SVGs carry no date and
a fixed hash salt so the same input gives the same file. Units: m, s, rad, m/s, rad/s; B in m^2.
"""

from __future__ import annotations

import math
import os
import re
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed; must precede the pyplot import

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.colors import Colormap, ListedColormap, Normalize, to_rgba  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.image import AxesImage  # noqa: E402
from matplotlib.patches import Circle, Patch, Rectangle  # noqa: E402

from husky_sim.runs.run_folder import read_log, read_results, read_summary, read_trace  # noqa: E402
from husky_sim.sim.trace import EpisodeTrace  # noqa: E402

#: Raster resolution (dots per inch); a figure of w x h inches is w*DPI x h*DPI pixels.
DPI = 110

#: Figures written by plot_run, by file stem.
RUN_FIGURES = ("xy", "controls", "safety", "slacks", "solve_time")

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

#: Outcome categories of the tuning maps: (name, colour), in legend order.
OUTCOME_CATEGORIES = (
    ("reached", "#2ca02c"),
    ("tracking converged", "#98df8a"),
    ("tracking, not converged", "#dbdb8d"),
    ("stuck", "#ff7f0e"),
    ("collided", "#d62728"),
    ("timeout", "#9467bd"),
    ("error", "#7f7f7f"),  # the run raised (suite rows)
    ("other", "#dddddd"),
)

RESULTS_NEEDED = ("scenario", "controller", "horizon", "gamma", "outcome")

#: Clearance (m) at and above which a tuning-map cell is fully green; at or below 0 m (contact,
#: a collision) it is fully red. One fixed scale for every map, so colours compare across maps.
SAFE_CLEARANCE_M = 0.5
CLEARANCE_CMAP = "RdYlGn"  # red - yellow - green

#: Free border (m) of the xy panels around everything drawn, plus this fraction of the larger side.
SCENE_MARGIN_M = 0.3
SCENE_MARGIN_FRACTION = 0.04

MOVING_COLOUR = "tab:pink"  # the paper draws moving obstacles as pink dashed lines
LIMIT_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 0.9}

FigurePaths = tuple[Path, Path]  # (png, svg)
SceneBox = tuple[np.ndarray, np.ndarray]  # (lower-left, upper-right) corners (m)


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
        if controller != "bt" and self.summary.get("gamma") is not None:
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


def _save(fig: Figure, out_dir: Path, stem: str) -> FigurePaths:
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


def _stem(text: str) -> str:
    """A file-name-safe version of text."""
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", text).strip("_") or "unnamed"


# ---------------------------------------------------------------------------------------------
# Drawing pieces
# ---------------------------------------------------------------------------------------------


def _time_label(t_s: float, t_end_s: float) -> str:
    return f"t={t_s:.0f} s" if t_end_s >= 10 else f"t={t_s:.1f} s"


def _draw_static_obstacles(ax: Axes, trace: EpisodeTrace, robot_radius_m: float) -> None:
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


def _draw_moving_obstacles(ax: Axes, trace: EpisodeTrace, marks_s: np.ndarray, t_end_s: float) -> None:
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
                _time_label(t, t_end_s),
                centres[k, j],
                fontsize=6,
                ha="center",
                va="center",
                color="black",
                clip_on=True,
                zorder=3,
            )


def _draw_reference(ax: Axes, trace: EpisodeTrace, start_xy: np.ndarray) -> None:
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


def _draw_arena(ax: Axes, trace: EpisodeTrace) -> None:
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


def _scene_box(
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


def _scene_aspect(box: SceneBox) -> float:
    """Height over width of a scene box, clamped to [0.25, 3]."""
    lo, hi = box
    return float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.25, 3.0))


def _frame_xy(ax: Axes, box: SceneBox) -> None:
    """Limits to box, equal aspect, axis labels in m."""
    lo, hi = box
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, linewidth=0.3)


def _no_data(ax: Axes, text: str, fontsize: float | None = None) -> None:
    """text, grey, in the middle of an empty panel."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4", fontsize=fontsize)


def _title(run: RunRecord) -> str:
    return f"{run.summary['scenario']}: {run.label()} ({run.summary.get('outcome', '?')})"


# ---------------------------------------------------------------------------------------------
# One run
# ---------------------------------------------------------------------------------------------


def _draw_scene(ax: Axes, run: RunRecord, t_end_s: float) -> None:
    """Arena, obstacles (moving ones up to t_end_s), start and goal or reference of a run."""
    _draw_arena(ax, run.trace)
    _draw_static_obstacles(ax, run.trace, run.robot_radius_m)
    _draw_moving_obstacles(ax, run.trace, time_marks(t_end_s), t_end_s)
    _draw_reference(ax, run.trace, np.array([run.log["x_m"][0], run.log["y_m"][0]]))


def _draw_robot_marks(ax: Axes, run: RunRecord, marks_s: np.ndarray, t_end_s: float) -> None:
    """The robot's position at marks_s (s), labelled with t, to read against moving obstacles."""
    t, x, y = run.log["t_s"], run.log["x_m"], run.log["y_m"]
    at = np.column_stack([np.interp(marks_s, t, x), np.interp(marks_s, t, y)])
    ax.plot(at[:, 0], at[:, 1], "s", color="tab:blue", markersize=4, zorder=5)
    for time_s, p in zip(marks_s, at, strict=True):
        ax.annotate(
            _time_label(time_s, t_end_s),
            p,
            xytext=(4, 4),
            textcoords="offset points",
            fontsize=6,
            color="tab:blue",
            clip_on=True,
            zorder=5,
        )


def _xy_figure_size_in(
    box: SceneBox, max_width_in: float = 6.5, max_height_in: float = 9.0
) -> tuple[float, float]:
    """(width, height) in inches of the xy figure: the scene to scale in at most max_width_in x
    max_height_in, plus room for the axis labels, the title and the legend on the right."""
    width_m, height_m = np.maximum(box[1] - box[0], 1e-6)
    inches_per_m = min(max_width_in / width_m, max_height_in / height_m)
    return max(width_m * inches_per_m, 2.0) + 2.6, max(height_m * inches_per_m, 1.6) + 1.0


def xy_figure(run: RunRecord) -> Figure:
    """The run's path over its scene to scale, framed on everything drawn; constrained layout
    (and _save crops to the drawn extent), so no label is cut for tall or wide scenes."""
    xy = np.column_stack([run.log["x_m"], run.log["y_m"]])
    t_end = float(run.log["t_s"][-1])
    box = _scene_box(run.trace, [xy], run.robot_radius_m, t_end)
    fig, ax = plt.subplots(figsize=_xy_figure_size_in(box), layout="constrained")
    _draw_scene(ax, run, t_end)
    ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", linewidth=1.6, zorder=4, label="robot")
    if moving_obstacles(run.trace).any():
        _draw_robot_marks(ax, run, time_marks(t_end), t_end)
    _frame_xy(ax, box)
    ax.set_title(_title(run), fontsize=10)
    fig.legend(fontsize=7, loc="outside right upper")
    return fig


def _controls_figure(run: RunRecord) -> Figure:
    log, s, tau = run.log, run.summary, run.tau_s
    t = log["t_s"]
    fig, (ax_v, ax_w) = plt.subplots(2, 1, figsize=(8.0, 5.5), sharex=True, layout="constrained")
    panels = (
        (ax_v, "v", "v (m/s)", (s.get("v_min_mps"), s.get("v_max_mps"))),
        (ax_w, "omega", "ω (rad/s)", _symmetric(s.get("omega_max_radps"))),
    )
    for ax, key, ylabel, limits in panels:
        unit = "mps" if key == "v" else "radps"
        ax.step(t, log[f"{key}_cmd_{unit}"], where="post", color="tab:blue", label="commanded")
        ax.plot(
            t + tau,
            log[f"{key}_applied_{unit}"],
            color="tab:orange",
            linewidth=1.0,
            label="applied (drive-limited, end of step)",
        )
        ax.plot(t, log[f"{key}_body_{unit}"], color="0.5", linewidth=0.8, label="measured body")
        for n, lim in enumerate(v for v in limits if v is not None):
            ax.axhline(float(lim), **LIMIT_STYLE, label="limit" if n == 0 else None)
        ax.set_ylabel(ylabel)
        ax.grid(True, linewidth=0.3)
    ax_v.legend(fontsize=7, loc="best")
    ax_w.set_xlabel("t (s)")
    ax_v.set_title(f"control signals: {_title(run)}", fontsize=10)
    return fig


def _symmetric(limit: object) -> tuple[float | None, float | None]:
    return (None, None) if limit is None else (-float(limit), float(limit))


def _safety_figure(run: RunRecord) -> Figure:
    t = run.log["t_s"]
    clearance = run.log["clearance_m"]
    barrier = barrier_series(run)
    fig, (ax_c, ax_b) = plt.subplots(2, 1, figsize=(8.0, 5.5), sharex=True, layout="constrained")
    if np.any(np.isfinite(clearance)):
        ax_c.plot(
            t,
            np.where(np.isfinite(clearance), clearance, np.nan),
            color="tab:green",
            label="clearance (physics, min over the step)",
        )
        ax_c.axhline(0.0, **LIMIT_STYLE, label="contact")
        ax_c.legend(fontsize=7, loc="best")
    else:
        _no_data(ax_c, "no obstacles or walls")
    ax_c.set_ylabel("clearance (m)")
    if np.any(np.isfinite(barrier)):
        ax_b.plot(
            t,
            barrier,
            color="tab:purple",
            label=f"B = min_j |p - c_j|² - (r + r_j)², r = {run.robot_radius_m:.3f} m",
        )
        ax_b.axhline(0.0, **LIMIT_STYLE, label="B = 0")
        ax_b.legend(fontsize=7, loc="best")
    else:
        _no_data(ax_b, "no obstacles")
    ax_b.set_ylabel("B (m²)")
    ax_b.set_xlabel("t (s)")
    for ax in (ax_c, ax_b):
        ax.grid(True, linewidth=0.3)
    ax_c.set_title(f"safety: {_title(run)}", fontsize=10)
    return fig


def _slacks_figure(run: RunRecord) -> Figure:
    t, controller = run.log["t_s"], str(run.summary["controller"])
    fig, (ax_h, ax_v) = plt.subplots(2, 1, figsize=(8.0, 5.0), sharex=True, layout="constrained")
    s_h = run.log["s_h_min"]
    ax_h.step(t, s_h, where="post", color="tab:brown", label="s_h (smallest over the horizon)")
    ax_h.axhline(1.0, color="0.4", linestyle=":", linewidth=0.9, label="s_h = 1 (no relaxation)")
    if controller != "relax-cbf":
        ax_h.text(
            0.01,
            0.05,
            f"s_h is not a variable for {controller}: fixed at 1",
            transform=ax_h.transAxes,
            fontsize=7,
            color="0.4",
        )
    ax_h.set_ylabel("s_h")
    ax_h.legend(fontsize=7, loc="best")
    ax_v.step(t, run.log["s_v_max"], where="post", color="tab:cyan", label="s_v (largest over the horizon)")
    ax_v.axhline(0.0, color="0.4", linestyle=":", linewidth=0.9)
    ax_v.set_ylabel("s_v")
    ax_v.set_xlabel("t (s)")
    ax_v.legend(fontsize=7, loc="best")
    for ax in (ax_h, ax_v):
        ax.grid(True, linewidth=0.3)
    ax_h.set_title(f"slacks: {_title(run)}", fontsize=10)
    return fig


def _solve_time_figure(run: RunRecord) -> Figure:
    solve = run.log["solve_ms"]
    solve = solve[np.isfinite(solve)]
    tau_ms = 1000.0 * run.tau_s
    fig, ax = plt.subplots(figsize=(7.0, 4.0), layout="constrained")
    if solve.size:
        positive = np.maximum(solve, 1e-3)
        lo, hi = positive.min() * 0.8, max(positive.max(), tau_ms) * 1.25
        ax.hist(positive, bins=np.geomspace(lo, hi, 40), color="tab:blue", alpha=0.8)
        ax.axvline(
            float(np.median(solve)),
            color="black",
            linestyle="-.",
            linewidth=1.0,
            label=f"median {np.median(solve):.2f} ms",
        )
        ax.set_xscale("log")
    else:
        _no_data(ax, "no solve times logged")
    ax.axvline(tau_ms, **LIMIT_STYLE, label=f"τ = {tau_ms:g} ms")
    ax.set_xlabel("solve time (ms, log scale)")
    ax.set_ylabel("control steps")
    ax.legend(fontsize=8)
    over = int(np.sum(solve > tau_ms))
    ax.set_title(f"solve times ({solve.size} steps, {over} over τ): {_title(run)}", fontsize=9)
    return fig


def plot_run(run_dir: Path | str, out_dir: Path | str) -> dict[str, FigurePaths]:
    """Plot one run; write out_dir/<name>.png and .svg for each name in RUN_FIGURES.

    xy: trajectory, obstacles to scale, reference or goal. controls: v and omega, commanded,
    applied and measured, with the limits. safety: physics clearance (m) and barrier B (m^2).
    slacks: s_h and s_v. solve_time: histogram of solve times (ms) with tau marked.
    Returns {name: (png path, svg path)}.
    """
    return _plot_record(load_run(run_dir), Path(out_dir))


def _plot_record(run: RunRecord, out: Path) -> dict[str, FigurePaths]:
    builders = {
        "xy": xy_figure,
        "controls": _controls_figure,
        "safety": _safety_figure,
        "slacks": _slacks_figure,
        "solve_time": _solve_time_figure,
    }
    return {name: _save(builders[name](run), out, name) for name in RUN_FIGURES}


# ---------------------------------------------------------------------------------------------
# Several runs of one scenario
# ---------------------------------------------------------------------------------------------


def _same_obstacles(a: EpisodeTrace, b: EpisodeTrace) -> bool:
    return a.obstacle_radius_m.shape == b.obstacle_radius_m.shape and bool(
        np.allclose(a.obstacle_radius_m, b.obstacle_radius_m)
        and np.allclose(a.obstacle_xy_m[0], b.obstacle_xy_m[0])
    )


def _comparison_axes(aspect: float) -> tuple[Figure, Axes, Axes, Axes, Axes]:
    """Figure and axes (xy, v, omega, clearance): xy on top of the three time panels for a wide
    scene (height/width `aspect` < 0.6), else on their left."""
    if aspect < 0.6:
        fig = plt.figure(figsize=(13.0, 13.0 * aspect + 4.5), layout="constrained")
        grid = fig.add_gridspec(2, 3, height_ratios=(max(13.0 * aspect, 2.5), 3.2))
        ax_xy = fig.add_subplot(grid[0, :])
        slots = (grid[1, 0], grid[1, 1], grid[1, 2])
    else:
        fig = plt.figure(figsize=(13.0, 7.5), layout="constrained")
        grid = fig.add_gridspec(3, 2, width_ratios=(1.15, 1.0))
        ax_xy = fig.add_subplot(grid[:, 0])
        slots = (grid[0, 1], grid[1, 1], grid[2, 1])
    ax_v = fig.add_subplot(slots[0])
    ax_w = fig.add_subplot(slots[1], sharex=ax_v)
    ax_c = fig.add_subplot(slots[2], sharex=ax_v)
    return fig, ax_xy, ax_v, ax_w, ax_c


def _draw_limits(ax_v: Axes, ax_w: Axes, summary: dict[str, object]) -> None:
    """The controller's v limits (m/s) and omega limits (rad/s) as horizontal lines."""
    for ax, limits in (
        (ax_v, (summary.get("v_min_mps"), summary.get("v_max_mps"))),
        (ax_w, _symmetric(summary.get("omega_max_radps"))),
    ):
        for lim in limits:
            if lim is not None:
                ax.axhline(float(lim), **LIMIT_STYLE)


def plot_comparison(run_dirs: Sequence[Path | str], out_path_stem: Path | str) -> FigurePaths:
    """Overlay runs of one scenario: xy, and commanded v (m/s), omega (rad/s) and clearance (m).

    Writes <out_path_stem>.png and .svg and returns the two paths. Legend entries read like
    "bt N=5 (stuck)". The obstacles drawn are the first run's (the title says so when the others'
    differ, e.g. other seeds of a random field). Raises PlotInputError when the runs are of
    different scenarios.
    """
    return _compare_records([load_run(d) for d in run_dirs], Path(out_path_stem))


def _check_comparable(runs: Sequence[RunRecord]) -> str:
    """The runs' common scenario; PlotInputError when there are none or several."""
    if not runs:
        raise PlotInputError("no run directories to compare")
    scenarios = sorted({str(r.summary["scenario"]) for r in runs})
    if len(scenarios) > 1:
        raise PlotInputError(f"cannot compare runs of different scenarios ({', '.join(scenarios)})")
    return scenarios[0]


def _compare_records(runs: Sequence[RunRecord], stem: Path) -> FigurePaths:
    """comparison_figure of runs, saved as stem.png and stem.svg."""
    return _save(comparison_figure(runs), stem.parent, stem.name)


def comparison_figure(runs: Sequence[RunRecord]) -> Figure:
    """Runs of one scenario overlaid: xy over the first run's scene (framed on everything drawn),
    and commanded v (m/s), omega (rad/s) and clearance (m) against t (s). The xy axes come first
    in fig.axes. Raises PlotInputError when the runs are of different scenarios."""
    scenario = _check_comparable(runs)
    with_seed = len({r.summary.get("seed") for r in runs}) > 1
    first = runs[0]
    t_end = max(float(r.log["t_s"][-1]) for r in runs)
    paths = [np.column_stack([r.log["x_m"], r.log["y_m"]]) for r in runs]
    box = _scene_box(first.trace, paths, first.robot_radius_m, t_end)
    fig, ax_xy, ax_v, ax_w, ax_c = _comparison_axes(_scene_aspect(box))
    _draw_scene(ax_xy, first, t_end)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, run in enumerate(runs):
        colour = colours[i % len(colours)]
        label = f"{run.label(with_seed)} ({run.summary.get('outcome', '?')})"
        log, t = run.log, run.log["t_s"]
        ax_xy.plot(log["x_m"], log["y_m"], color=colour, linewidth=1.5, zorder=4, label=label)
        ax_xy.plot(log["x_m"][-1], log["y_m"][-1], "o", color=colour, markersize=4, zorder=5)
        ax_v.step(t, log["v_cmd_mps"], where="post", color=colour, linewidth=1.0)
        ax_w.step(t, log["omega_cmd_radps"], where="post", color=colour, linewidth=1.0)
        clearance = log["clearance_m"]
        ax_c.plot(t, np.where(np.isfinite(clearance), clearance, np.nan), color=colour, linewidth=1.0)
    _frame_xy(ax_xy, box)
    fig.legend(fontsize=7, loc="outside right upper")
    _draw_limits(ax_v, ax_w, first.summary)
    if any(np.any(np.isfinite(r.log["clearance_m"])) for r in runs):
        ax_c.axhline(0.0, **LIMIT_STYLE)
    else:
        _no_data(ax_c, "no obstacles or walls")
    for ax, ylabel in ((ax_v, "v cmd (m/s)"), (ax_w, "ω cmd (rad/s)"), (ax_c, "clearance (m)")):
        ax.set_ylabel(ylabel)
        ax.set_xlabel("t (s)")
        ax.grid(True, linewidth=0.3)
    title = f"{scenario}: {len(runs)} run{'' if len(runs) == 1 else 's'}"
    if not all(_same_obstacles(first.trace, r.trace) for r in runs[1:]):
        title += f" (obstacles drawn: {first.label(with_seed)}'s)"
    fig.suptitle(title, fontsize=11)
    return fig


@dataclass(frozen=True)
class PlottedRuns:
    """Where plot_runs put its figures."""

    runs: dict[Path, Path]  # run directory -> folder holding its RUN_FIGURES
    comparison: FigurePaths | None  # (png, svg) when several runs were given


def plot_runs(run_dirs: Sequence[Path | str], out_dir: Path | str | None = None) -> PlottedRuns:
    """plot_run for each run directory and, for several, plot_comparison of them all.

    Every directory is read (and the runs checked to share a scenario) before anything is
    written. With out_dir: one run's figures go straight into it; several go to
    out_dir/<run directory name>/ and the comparison to out_dir/comparison.png/.svg. Without:
    each run's go to <run dir>/plots/ and the comparison to <common parent>/comparison.png/.svg.
    """
    runs = [load_run(d) for d in run_dirs]
    if len(runs) > 1:
        _check_comparable(runs)
    out = None if out_dir is None else Path(out_dir)
    targets: dict[Path, Path] = {}
    for run in runs:
        if out is None:
            target = run.run_dir / "plots"
        elif len(runs) == 1:
            target = out
        else:
            target = out / _stem(run.run_dir.resolve().name)
            while target in targets.values():
                target = target.with_name(target.name + "_")
        targets[run.run_dir] = target
        _plot_record(run, target)
    comparison = None
    if len(runs) > 1:
        base = out if out is not None else Path(os.path.commonpath([r.run_dir.resolve() for r in runs]))
        comparison = _compare_records(runs, base / "comparison")
    return PlottedRuns(targets, comparison)


# ---------------------------------------------------------------------------------------------
# Tuning maps from a suite's results.csv
# ---------------------------------------------------------------------------------------------


def _number(text: object) -> float:
    """A CSV cell as a float; NaN for empty, None, null or unparsable cells."""
    try:
        return float(str(text).strip())
    except ValueError:
        return math.nan


def _truthy(text: object) -> bool:
    return str(text).strip().lower() in {"true", "1", "yes"}


def outcome_category(outcome: str, converged: bool) -> str:
    """Category of the outcome maps: a name in OUTCOME_CATEGORIES."""
    if outcome == "tracking":
        return "tracking converged" if converged else "tracking, not converged"
    names = {name for name, _ in OUTCOME_CATEGORIES}
    return outcome if outcome in names else "other"


def _placeable(row: dict[str, str]) -> bool:
    """Whether a results row has a numeric N and gamma (error rows of default cells may not)."""
    return math.isfinite(_number(row["horizon"])) and math.isfinite(_number(row["gamma"]))


@dataclass(frozen=True)
class TuningGrid:
    """Cells of one scenario and controller: rows are gammas, columns horizons N."""

    gammas: list[float]  # row values
    horizons: list[int]  # column values
    category: np.ndarray  # (G, H) int index into OUTCOME_CATEGORIES, -1 for no run
    category_text: list[list[str]]  # per cell, e.g. "stuck" or "reached 2/3"
    min_clearance_m: np.ndarray  # (G, H) smallest over the cell's runs (worst case), NaN: none
    third: np.ndarray  # (G, H) mean time to goal (s) or tracking RMSE (m), NaN: none
    third_name: str  # "time to goal (s)" or "tracking RMSE (m)"
    min_clearance_missing: str = ""  # why no cell has a clearance (shown on an empty panel)
    third_missing: str = ""  # why no cell has a time to goal or RMSE


#: What an empty tuning-map panel says when the scenario and controller have no runs at all.
NO_RUNS_TEXT = "no runs with this scenario/controller\nin results.csv"


def _runs_text(count: int) -> str:
    """ "1 run" or "N runs"."""
    return f"{count} run{'' if count == 1 else 's'}"


def _column_missing(rows: Sequence[dict[str, str]], column: str) -> bool:
    """Whether results.csv has no such column (DictReader rows then lack the key)."""
    return not any(column in row for row in rows)


def _outcome_counts(rows: Sequence[dict[str, str]]) -> str:
    """The rows' outcomes, most frequent first, e.g. "stuck 3, timeout 1"."""
    counts = Counter(row["outcome"].strip() or "?" for row in rows)
    return ", ".join(f"{name} {count}" for name, count in counts.most_common())


def clearance_missing_reason(rows: Sequence[dict[str, str]]) -> str:
    """Why none of rows (one scenario and controller) has a min clearance, for an empty panel."""
    if not rows:
        return NO_RUNS_TEXT
    if _column_missing(rows, "min_clearance_m"):
        return "no min_clearance_m column\nin results.csv"
    return (
        f"no min_clearance_m value in results.csv\nfor {_runs_text(len(rows))} "
        "(none is recorded\nwithout obstacles or walls)"
    )


def third_missing_reason(rows: Sequence[dict[str, str]]) -> str:
    """Why none of rows has a time to goal (or tracking RMSE), for an empty panel."""
    if not rows:
        return NO_RUNS_TEXT
    outcomes = [row["outcome"].strip() for row in rows]
    tracking = outcomes.count("tracking")
    reached = outcomes.count("reached")
    if tracking:
        return f"no tracking_rmse_m value in results.csv\nfor {_runs_text(len(rows))} ({tracking} tracking)"
    if reached == 0:
        return f"no run reached the goal\n({_outcome_counts(rows)}):\ntime to goal undefined"
    if _column_missing(rows, "time_to_goal_s"):
        return "no time_to_goal_s column\nin results.csv"
    return f"time_to_goal_s empty in results.csv\nfor the {_runs_text(reached)} that reached the goal"


def tuning_grid(rows: Sequence[dict[str, str]]) -> TuningGrid:
    """Aggregate the runs of one scenario and controller (rows with numeric N and gamma) into a
    gamma x N grid.

    Several runs in one cell (seeds) give the most frequent outcome, the worst (smallest)
    clearance and the mean time to goal or tracking RMSE over the runs that have one.
    """
    gammas = sorted({_number(r["gamma"]) for r in rows})
    horizons = sorted({int(_number(r["horizon"])) for r in rows})
    times = [_number(r.get("time_to_goal_s")) for r in rows]
    rmses = [_number(r.get("tracking_rmse_m")) for r in rows]
    use_rmse = not any(math.isfinite(v) for v in times) and any(math.isfinite(v) for v in rmses)
    third_values = rmses if use_rmse else times
    shape = (len(gammas), len(horizons))
    category = np.full(shape, -1, dtype=int)
    text = [["" for _ in horizons] for _ in gammas]
    clearance = np.full(shape, np.nan)
    third = np.full(shape, np.nan)
    names = [name for name, _ in OUTCOME_CATEGORIES]
    cells: dict[tuple[int, int], list[int]] = {}
    for n, row in enumerate(rows):
        key = (gammas.index(_number(row["gamma"])), horizons.index(int(_number(row["horizon"]))))
        cells.setdefault(key, []).append(n)
    for (gi, hi), members in cells.items():
        cats = Counter(
            outcome_category(rows[n]["outcome"].strip(), _truthy(rows[n].get("converged", "")))
            for n in members
        )
        top, count = cats.most_common(1)[0]
        category[gi, hi] = names.index(top)
        text[gi][hi] = top if count == len(members) else f"{top} {count}/{len(members)}"
        clear = [_number(rows[n].get("min_clearance_m")) for n in members]
        clear = [c for c in clear if math.isfinite(c)]
        clearance[gi, hi] = min(clear) if clear else np.nan
        vals = [third_values[n] for n in members if math.isfinite(third_values[n])]
        third[gi, hi] = float(np.mean(vals)) if vals else np.nan
    third_name = "tracking RMSE (m)" if use_rmse else "time to goal (s)"
    return TuningGrid(
        gammas,
        horizons,
        category,
        text,
        clearance,
        third,
        third_name,
        min_clearance_missing=clearance_missing_reason(rows),
        third_missing=third_missing_reason(rows),
    )


def _grid_axes(ax: Axes, grid: TuningGrid) -> None:
    ax.set_xticks(range(len(grid.horizons)), [str(h) for h in grid.horizons])
    ax.set_yticks(range(len(grid.gammas)), [f"{g:g}" for g in grid.gammas])
    ax.set_xlabel("horizon N")
    ax.set_ylabel("γ", rotation=0, labelpad=8)


def _text_colour(rgba: Sequence[float]) -> str:
    """Black or white, whichever reads better on a cell of colour rgba."""
    luminance = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2]
    return "black" if luminance > 0.5 else "white"


def _outcome_map(ax: Axes, grid: TuningGrid) -> None:
    colours = ListedColormap([c for _, c in OUTCOME_CATEGORIES]).with_extremes(bad="white")
    data = np.ma.masked_less(grid.category, 0)
    ax.imshow(
        data, cmap=colours, vmin=-0.5, vmax=len(OUTCOME_CATEGORIES) - 0.5, origin="lower", aspect="auto"
    )
    for (gi, hi), code in np.ndenumerate(grid.category):
        if code >= 0:
            text = grid.category_text[gi][hi].replace(", ", ",\n").replace(" converged", "\nconverged")
            colour = _text_colour(to_rgba(OUTCOME_CATEGORIES[code][1]))
            ax.text(hi, gi, text, ha="center", va="center", fontsize=7, color=colour)
    present = sorted({int(c) for c in grid.category.ravel() if c >= 0})
    handles = [Patch(color=OUTCOME_CATEGORIES[c][1], label=OUTCOME_CATEGORIES[c][0]) for c in present]
    ax.legend(handles=handles, fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
    ax.set_title("outcome", fontsize=9)
    _grid_axes(ax, grid)


def clearance_norm() -> Normalize:
    """The fixed clearance scale of every tuning map: 0 m (contact) .. SAFE_CLEARANCE_M, clipped."""
    return Normalize(vmin=0.0, vmax=SAFE_CLEARANCE_M, clip=True)


def clearance_colour(clearance_m: float) -> tuple[float, float, float, float]:
    """RGBA of a min clearance (m) on the tuning maps: red at or below 0 m (a collision), yellow
    halfway, green at or above SAFE_CLEARANCE_M; NaN (no value) is white."""
    if not math.isfinite(clearance_m):
        return (1.0, 1.0, 1.0, 1.0)
    rgba = matplotlib.colormaps[CLEARANCE_CMAP](float(clearance_norm()(clearance_m)))
    return tuple(float(c) for c in rgba)


def _relative_norm(values: np.ndarray) -> Normalize:
    """A scale from the smallest to the largest finite value; one value is centred in it."""
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    if hi - lo < 1e-12:
        pad = max(0.1 * abs(lo), 1e-3)
        lo, hi = lo - pad, hi + pad
    return Normalize(vmin=lo, vmax=hi)


def _value_map(
    ax: Axes,
    values: np.ndarray,
    title: str,
    fmt: str,
    empty_text: str,
    cmap: Colormap,
    norm: Normalize | None = None,
) -> AxesImage | None:
    """Heatmap of values (NaN cells blank), each cell annotated with format(value, fmt).

    norm None: a scale from the map's own smallest to largest value. Returns the image (for a
    colour bar), or None, with empty_text written on the panel, when no cell has a value.
    """
    ax.set_title(title, fontsize=9)
    ax.set_xlim(-0.5, values.shape[1] - 0.5)
    ax.set_ylim(-0.5, values.shape[0] - 0.5)
    if not np.any(np.isfinite(values)):
        _no_data(ax, empty_text or "no values", fontsize=7)
        return None
    image = ax.imshow(
        np.ma.masked_invalid(values),
        cmap=cmap.with_extremes(bad="white"),
        norm=norm or _relative_norm(values),
        origin="lower",
        aspect="auto",
    )
    for (gi, hi), value in np.ndenumerate(values):
        if math.isfinite(value):
            colour = _text_colour(image.cmap(image.norm(value)))
            ax.text(hi, gi, format(value, fmt), ha="center", va="center", fontsize=7, color=colour)
    return image


def _clearance_map(ax: Axes, grid: TuningGrid) -> None:
    """Min clearance (m) on the fixed scale of clearance_norm, with its colour bar."""
    image = _value_map(
        ax,
        grid.min_clearance_m,
        "min clearance (m)",
        ".3f",
        grid.min_clearance_missing,
        matplotlib.colormaps[CLEARANCE_CMAP],
        clearance_norm(),
    )
    if image is None:
        return
    bar = ax.figure.colorbar(image, ax=ax, shrink=0.8)
    ticks = np.linspace(0.0, SAFE_CLEARANCE_M, 6)
    bar.set_ticks(ticks, labels=["≤ 0", *(f"{t:g}" for t in ticks[1:-1]), f"≥ {SAFE_CLEARANCE_M:g}"])
    safe = f"≥ {SAFE_CLEARANCE_M:g} m safe (green)"
    bar.set_label(f"clearance (m), fixed scale on every map:\n≤ 0 m collision (red), {safe}", fontsize=7)


def _third_map(ax: Axes, grid: TuningGrid) -> None:
    """Time to goal (s) or tracking RMSE (m), on the map's own scale, with its colour bar."""
    rmse = "RMSE" in grid.third_name
    image = _value_map(
        ax,
        grid.third,
        grid.third_name,
        ".2f" if rmse else ".1f",
        grid.third_missing,
        matplotlib.colormaps["viridis_r"],
    )
    if image is not None:
        bar = ax.figure.colorbar(image, ax=ax, shrink=0.8)
        bar.set_label(f"{grid.third_name}, this map's range", fontsize=7)


def tuning_figure(scenario: str, controller: str, grid: TuningGrid, unplaced: int = 0) -> Figure:
    """Outcome, min clearance (fixed scale) and time to goal or RMSE maps of one grid, side by side;
    unplaced runs (no N or gamma) are counted in the title."""
    panel_width_in = 1.8 + 0.75 * len(grid.horizons)
    height_in = 2.9 + 0.4 * len(grid.gammas)
    fig, axes = plt.subplots(1, 3, figsize=(3 * panel_width_in + 1.5, height_in), layout="constrained")
    fig.get_layout_engine().set(wspace=0.06)
    _outcome_map(axes[0], grid)
    _clearance_map(axes[1], grid)
    _third_map(axes[2], grid)
    for ax in axes[1:]:
        _grid_axes(ax, grid)
    title = f"{scenario}: {controller}"
    if unplaced:
        title += f" ({unplaced} run{'' if unplaced == 1 else 's'} without N or γ not shown)"
    fig.suptitle(title, fontsize=11)
    return fig


def plot_tuning_maps(
    results_csv: Path | str, out_dir: Path | str, scenario: str | None = None
) -> dict[str, FigurePaths]:
    """Gamma x N maps of outcome, min clearance (m) and time to goal (s) per scenario and controller.

    Reads a suite's results.csv (one row per run with at least scenario, controller, horizon,
    gamma and outcome; converged, min_clearance_m, time_to_goal_s and tracking_rmse_m when
    present). Tracking scenarios, which have no time to goal, show the tracking RMSE (m) instead.
    Cells without a run or a value are blank; a single gamma or N gives a 1 x n map; rows without
    a numeric N or gamma (suite error rows) are counted in the title, and a controller with no
    other rows gets no figure. Writes out_dir/tuning_<scenario>_<controller>.png and .svg;
    returns {"<scenario>/<controller>": (png, svg)}. `scenario` limits it to one scenario.
    """
    rows = read_results(results_csv, RESULTS_NEEDED)
    if scenario is not None:
        rows = [r for r in rows if r["scenario"] == scenario]
        if not rows:
            raise PlotInputError(f"{results_csv}: no runs of scenario {scenario!r}")
    out = Path(out_dir)
    written: dict[str, FigurePaths] = {}
    for name in sorted({r["scenario"] for r in rows}):
        of_scenario = [r for r in rows if r["scenario"] == name]
        for controller in sorted({r["controller"] for r in of_scenario}):
            runs = [r for r in of_scenario if r["controller"] == controller]
            placed = [r for r in runs if _placeable(r)]
            if not placed:
                continue
            figure = tuning_figure(name, controller, tuning_grid(placed), len(runs) - len(placed))
            written[f"{name}/{controller}"] = _save(figure, out, _stem(f"tuning_{name}_{controller}"))
    return written
