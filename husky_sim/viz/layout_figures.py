"""Pictures of scenario layouts: a gallery of panels, each a layout's static obstacles (grey),
movers (pink, with the way they walk and their start), the robot's start pose and circle, the
goal or the reference circle, and optionally the path the robot drove (blue, with a red cross at
a collision). The family pages of the docs and the campaign's failure galleries are drawn here."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import Circle, FancyArrow

from husky_sim.runs.scenario import Scenario
from husky_sim.viz.figure_base import MOVING_COLOUR, FigurePaths, plt, save_figure


@dataclass(frozen=True)
class LayoutPanel:
    """One panel: a layout, its title, and the robot's driven path (m, shape (n, 2)) if any."""

    scenario: Scenario
    title: str
    path_xy_m: np.ndarray | None = None
    collided_at_xy_m: tuple[float, float] | None = None
    collided_at_t_s: float | None = None  # movers are also drawn where they were then (outlined)


def draw_layout(ax: Axes, panel: LayoutPanel) -> None:
    sc = panel.scenario
    for o in sc.obstacle_specs():
        if o.moving:
            points = np.array([[o.x_m, o.y_m], *o.waypoints]) if o.waypoints else None
            if points is None:
                end = (o.x_m + 20 * o.vx_mps, o.y_m + 20 * o.vy_mps)
                points = np.array([[o.x_m, o.y_m], end])
            ax.plot(points[:, 0], points[:, 1], ls="--", lw=0.8, color=MOVING_COLOUR)
            ax.add_patch(Circle((o.x_m, o.y_m), o.radius_m, fc=MOVING_COLOUR, ec="none", alpha=0.8))
            if panel.collided_at_t_s is not None:
                x, y, _, _ = o.motion_at(panel.collided_at_t_s)
                ax.add_patch(Circle((x, y), o.radius_m, fc="none", ec=MOVING_COLOUR, lw=1.2))
        else:
            ax.add_patch(Circle((o.x_m, o.y_m), o.radius_m, fc="0.35", ec="none"))
    start = sc.robot.start
    ax.add_patch(Circle((start.x_m, start.y_m), sc.robot.radius(), fc="none", ec="tab:blue", lw=0.8))
    ax.add_patch(
        FancyArrow(
            start.x_m,
            start.y_m,
            0.6 * math.cos(start.yaw_rad),
            0.6 * math.sin(start.yaw_rad),
            width=0.06,
            color="tab:blue",
        )
    )
    if sc.reference.goal is not None:
        g = sc.reference.goal
        ax.plot([g.x_m], [g.y_m], marker="*", ms=10, color="tab:green")
        ax.plot(
            [g.x_m, g.x_m + 0.5 * math.cos(g.yaw_rad)],
            [g.y_m, g.y_m + 0.5 * math.sin(g.yaw_rad)],
            color="tab:green",
        )
    else:
        c = sc.reference.circle
        ax.add_patch(Circle((c.center_x_m, c.center_y_m), c.radius_m, fc="none", ec="tab:green", ls=":"))
    if panel.path_xy_m is not None and len(panel.path_xy_m):
        ax.plot(panel.path_xy_m[:, 0], panel.path_xy_m[:, 1], color="tab:blue", lw=1.2)
    if panel.collided_at_xy_m is not None:
        ax.plot(*panel.collided_at_xy_m, marker="x", ms=10, mew=2.5, color="tab:red")
    xs, ys = _extent(sc, panel.path_xy_m)
    ax.set_xlim(*xs)
    ax.set_ylim(*ys)
    ax.set_aspect("equal")
    ax.set_title(panel.title, fontsize=7)
    ax.tick_params(labelsize=6)


def _extent(sc: Scenario, path: np.ndarray | None) -> tuple[tuple[float, float], tuple[float, float]]:
    """The panel's frame: the start, goal or reference circle, the path, and the obstacles near
    them (a mover's far way out is left outside)."""
    pts = [(sc.robot.start.x_m, sc.robot.start.y_m)]
    if sc.reference.goal is not None:
        pts.append((sc.reference.goal.x_m, sc.reference.goal.y_m))
    else:
        c = sc.reference.circle
        pts += [
            (c.center_x_m - c.radius_m, c.center_y_m - c.radius_m),
            (c.center_x_m + c.radius_m, c.center_y_m + c.radius_m),
        ]
    if path is not None and len(path):
        pts += [tuple(path.min(axis=0)), tuple(path.max(axis=0))]
    core = np.array(pts)
    lo, hi = core.min(axis=0) - 3.0, core.max(axis=0) + 3.0
    near = [
        (o.x_m, o.y_m) for o in sc.obstacle_specs() if lo[0] <= o.x_m <= hi[0] and lo[1] <= o.y_m <= hi[1]
    ]
    allp = np.vstack([core, np.array(near).reshape(-1, 2)])
    lo, hi = allp.min(axis=0) - 1.0, allp.max(axis=0) + 1.0
    short = int(np.argmin(hi - lo))  # no panel flatter than 1:2
    grow = max(0.5 * float(np.max(hi - lo)) - float((hi - lo)[short]), 0.0)
    lo[short], hi[short] = lo[short] - 0.5 * grow, hi[short] + 0.5 * grow
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def layout_gallery(
    panels: Sequence[LayoutPanel], out_dir: Path, stem: str, title: str, columns: int = 4
) -> FigurePaths:
    """The panels on a grid of `columns`, written as out_dir/stem.png and .svg."""
    columns = max(min(columns, len(panels)), 1)
    rows = max(math.ceil(len(panels) / columns), 1)
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.8 * rows), squeeze=False)
    for ax in axes.flat[len(panels) :]:
        ax.set_axis_off()
    for ax, panel in zip(axes.flat, panels, strict=False):
        draw_layout(ax, panel)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, out_dir, stem)
