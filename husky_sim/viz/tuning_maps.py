"""Tuning maps from a suite's `results.csv` (`plot_tuning_maps`): gamma x N maps of outcome,
minimum clearance and time to goal (tracking RMSE for tracking scenarios), per scenario and
controller. Clearance colours are absolute and the same on every map: red at or below 0 m
(contact), green from SAFE_CLEARANCE_M up. An empty panel says what is missing and why."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
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
from matplotlib.patches import Patch  # noqa: E402

from husky_sim.runs.run_folder import read_results  # noqa: E402
from husky_sim.viz.figure_base import (  # noqa: E402
    FigurePaths,
    PlotInputError,
    file_stem,
    no_data,
    save_figure,
)

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
        no_data(ax, empty_text or "no values", fontsize=7)
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
            written[f"{name}/{controller}"] = save_figure(
                figure, out, file_stem(f"tuning_{name}_{controller}")
            )
    return written
