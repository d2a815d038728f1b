"""Several runs of one scenario overlaid (`plot_comparison`: xy, v, omega, clearance), and
`plot_runs`, which draws each run and, for runs of one scenario, their comparison."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed; must precede the pyplot import

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from husky_sim.sim.trace import EpisodeTrace  # noqa: E402
from husky_sim.viz.figure_base import (  # noqa: E402
    LIMIT_STYLE,
    FigurePaths,
    PlotInputError,
    RunRecord,
    file_stem,
    frame_xy,
    load_run,
    no_data,
    save_figure,
    scene_aspect,
    scene_box,
)
from husky_sim.viz.run_figures import (  # noqa: E402
    draw_scene,
    plot_record,
    symmetric_limits,
)

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
        (ax_w, symmetric_limits(summary.get("omega_max_radps"))),
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
    return save_figure(comparison_figure(runs), stem.parent, stem.name)


def comparison_figure(runs: Sequence[RunRecord]) -> Figure:
    """Runs of one scenario overlaid: xy over the first run's scene (framed on everything drawn),
    and commanded v (m/s), omega (rad/s) and clearance (m) against t (s). The xy axes come first
    in fig.axes. Raises PlotInputError when the runs are of different scenarios."""
    scenario = _check_comparable(runs)
    with_seed = len({r.summary.get("seed") for r in runs}) > 1
    first = runs[0]
    t_end = max(float(r.log["t_s"][-1]) for r in runs)
    paths = [np.column_stack([r.log["x_m"], r.log["y_m"]]) for r in runs]
    box = scene_box(first.trace, paths, first.robot_radius_m, t_end)
    fig, ax_xy, ax_v, ax_w, ax_c = _comparison_axes(scene_aspect(box))
    draw_scene(ax_xy, first, t_end)
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
    frame_xy(ax_xy, box)
    fig.legend(fontsize=7, loc="outside right upper")
    _draw_limits(ax_v, ax_w, first.summary)
    if any(np.any(np.isfinite(r.log["clearance_m"])) for r in runs):
        ax_c.axhline(0.0, **LIMIT_STYLE)
    else:
        no_data(ax_c, "no obstacles or walls")
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
            target = out / file_stem(run.run_dir.resolve().name)
            while target in targets.values():
                target = target.with_name(target.name + "_")
        targets[run.run_dir] = target
        plot_record(run, target)
    comparison = None
    if len(runs) > 1:
        base = out if out is not None else Path(os.path.commonpath([r.run_dir.resolve() for r in runs]))
        comparison = _compare_records(runs, base / "comparison")
    return PlottedRuns(targets, comparison)
