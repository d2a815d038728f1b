"""Figures of one recorded run, after the paper's (`plot_run`): the xy trajectory with obstacles
to scale (paper Figs. 3 and 4), the control signals against their limits (Figs. 4 and 6),
clearance and barrier value, the slacks s_h and s_v, and a histogram of solve times against the
control period tau."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed; must precede the pyplot import

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from husky_sim.viz.figure_base import (  # noqa: E402
    LIMIT_STYLE,
    FigurePaths,
    RunRecord,
    SceneBox,
    barrier_series,
    decay_slack_is_variable,
    draw_arena,
    draw_moving_obstacles,
    draw_reference,
    draw_static_obstacles,
    frame_xy,
    load_run,
    moving_obstacles,
    no_data,
    run_title,
    save_figure,
    scene_box,
    time_label,
    time_marks,
)

#: Figures written by plot_run, by file stem.
RUN_FIGURES = ("xy", "controls", "safety", "slacks", "solve_time")

# ---------------------------------------------------------------------------------------------
# One run
# ---------------------------------------------------------------------------------------------


def draw_scene(ax: Axes, run: RunRecord, t_end_s: float) -> None:
    """Arena, obstacles (moving ones up to t_end_s), start and goal or reference of a run."""
    draw_arena(ax, run.trace)
    draw_static_obstacles(ax, run.trace, run.robot_radius_m)
    draw_moving_obstacles(ax, run.trace, time_marks(t_end_s), t_end_s)
    draw_reference(ax, run.trace, np.array([run.log["x_m"][0], run.log["y_m"][0]]))


def _draw_robot_marks(ax: Axes, run: RunRecord, marks_s: np.ndarray, t_end_s: float) -> None:
    """The robot's position at marks_s (s), labelled with t, to read against moving obstacles."""
    t, x, y = run.log["t_s"], run.log["x_m"], run.log["y_m"]
    at = np.column_stack([np.interp(marks_s, t, x), np.interp(marks_s, t, y)])
    ax.plot(at[:, 0], at[:, 1], "s", color="tab:blue", markersize=4, zorder=5)
    for time_s, p in zip(marks_s, at, strict=True):
        ax.annotate(
            time_label(time_s, t_end_s),
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
    (and save_figure crops to the drawn extent), so no label is cut for tall or wide scenes."""
    xy = np.column_stack([run.log["x_m"], run.log["y_m"]])
    t_end = float(run.log["t_s"][-1])
    box = scene_box(run.trace, [xy], run.robot_radius_m, t_end)
    fig, ax = plt.subplots(figsize=_xy_figure_size_in(box), layout="constrained")
    draw_scene(ax, run, t_end)
    ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", linewidth=1.6, zorder=4, label="robot")
    if moving_obstacles(run.trace).any():
        _draw_robot_marks(ax, run, time_marks(t_end), t_end)
    frame_xy(ax, box)
    ax.set_title(run_title(run), fontsize=10)
    fig.legend(fontsize=7, loc="outside right upper")
    return fig


def _controls_figure(run: RunRecord) -> Figure:
    log, s, tau = run.log, run.summary, run.tau_s
    t = log["t_s"]
    fig, (ax_v, ax_w) = plt.subplots(2, 1, figsize=(8.0, 5.5), sharex=True, layout="constrained")
    panels = (
        (ax_v, "v", "v (m/s)", (s.get("v_min_mps"), s.get("v_max_mps"))),
        (ax_w, "omega", "ω (rad/s)", symmetric_limits(s.get("omega_max_radps"))),
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
    ax_v.set_title(f"control signals: {run_title(run)}", fontsize=10)
    return fig


def symmetric_limits(limit: object) -> tuple[float | None, float | None]:
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
        no_data(ax_c, "no obstacles or walls")
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
        no_data(ax_b, "no obstacles")
    ax_b.set_ylabel("B (m²)")
    ax_b.set_xlabel("t (s)")
    for ax in (ax_c, ax_b):
        ax.grid(True, linewidth=0.3)
    ax_c.set_title(f"safety: {run_title(run)}", fontsize=10)
    return fig


def _slacks_figure(run: RunRecord) -> Figure:
    t, controller = run.log["t_s"], str(run.summary["controller"])
    fig, (ax_h, ax_v) = plt.subplots(2, 1, figsize=(8.0, 5.0), sharex=True, layout="constrained")
    s_h = run.log["s_h_min"]
    ax_h.step(t, s_h, where="post", color="tab:brown", label="s_h (smallest over the horizon)")
    ax_h.axhline(1.0, color="0.4", linestyle=":", linewidth=0.9, label="s_h = 1 (no relaxation)")
    if not decay_slack_is_variable(controller):
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
    ax_h.set_title(f"slacks: {run_title(run)}", fontsize=10)
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
        no_data(ax, "no solve times logged")
    ax.axvline(tau_ms, **LIMIT_STYLE, label=f"τ = {tau_ms:g} ms")
    ax.set_xlabel("solve time (ms, log scale)")
    ax.set_ylabel("control steps")
    ax.legend(fontsize=8)
    over = int(np.sum(solve > tau_ms))
    ax.set_title(f"solve times ({solve.size} steps, {over} over τ): {run_title(run)}", fontsize=9)
    return fig


def plot_run(run_dir: Path | str, out_dir: Path | str) -> dict[str, FigurePaths]:
    """Plot one run; write out_dir/<name>.png and .svg for each name in RUN_FIGURES.

    xy: trajectory, obstacles to scale, reference or goal. controls: v and omega, commanded,
    applied and measured, with the limits. safety: physics clearance (m) and barrier B (m^2).
    slacks: s_h and s_v. solve_time: histogram of solve times (ms) with tau marked.
    Returns {name: (png path, svg path)}.
    """
    return plot_record(load_run(run_dir), Path(out_dir))


def plot_record(run: RunRecord, out: Path) -> dict[str, FigurePaths]:
    builders = {
        "xy": xy_figure,
        "controls": _controls_figure,
        "safety": _safety_figure,
        "slacks": _slacks_figure,
        "solve_time": _solve_time_figure,
    }
    return {name: save_figure(builders[name](run), out, name) for name in RUN_FIGURES}
