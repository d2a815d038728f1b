"""Figures from real recorded runs: every PNG/SVG written and readable, the barrier series checked
by hand, the CLI without a display, tuning maps from a results.csv built from real summaries, and
bad input as one line with exit code 2. No mocks: the runs are short PyBullet episodes."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib.image
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from matplotlib.patches import Circle

from husky_sim.cli import main
from husky_sim.runs.run import run_scenario
from husky_sim.runs.run_folder import read_results
from husky_sim.runs.scenario import load_scenario
from husky_sim.sim.trace import EpisodeTrace
from husky_sim.viz.comparison_figures import comparison_figure, plot_comparison
from husky_sim.viz.figure_base import (
    DPI,
    PlotInputError,
    barrier_series,
    barrier_values,
    load_run,
    moving_obstacles,
    obstacle_centres_at,
)
from husky_sim.viz.run_figures import RUN_FIGURES, plot_run, xy_figure
from husky_sim.viz.tuning_maps import (
    NO_RUNS_TEXT,
    OUTCOME_CATEGORIES,
    SAFE_CLEARANCE_M,
    clearance_colour,
    clearance_missing_reason,
    plot_tuning_maps,
    third_missing_reason,
    tuning_figure,
    tuning_grid,
)

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)

SCENARIO = "husky_point_stabilisation"


def _record(root: Path, name: str, controller: str, duration_s: float, **kwargs: object) -> Path:
    sc = load_scenario(name).model_copy(update={"duration_s": duration_s})
    out = root / f"{name}__{controller}__{kwargs.get('horizon', 'file')}"
    run_scenario(sc, controller, out_dir=out, **kwargs)
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Short real runs: point stabilisation with cbf (file's N) and bt N=7, a moving obstacle, and
    the paper's point stabilisation (goal 10 m straight ahead along y: a tall scene)."""
    root = tmp_path_factory.mktemp("runs")
    return {
        "cbf": _record(root, SCENARIO, "cbf", 3.0),
        "bt": _record(root, SCENARIO, "bt", 3.0, horizon=7),
        "moving": _record(root, "head_on_moving_obstacle", "relax-cbf", 2.0, horizon=5),
        "tall": _record(root, "paper_point_stabilisation", "cbf", 2.0),
    }


def _assert_png(path: Path, min_px: tuple[int, int] = (300, 200)) -> np.ndarray:
    image = matplotlib.image.imread(path)
    height, width = image.shape[:2]
    assert width >= min_px[0] and height >= min_px[1], (path, image.shape)
    assert width <= 30 * DPI and height <= 30 * DPI, (path, image.shape)
    assert float(np.std(image[..., :3])) > 0.01, f"{path} is blank"
    return image


def _assert_svg(path: Path) -> None:
    root = ET.parse(path).getroot()
    assert root.tag.endswith("svg")
    assert len(list(root.iter("{http://www.w3.org/2000/svg}path"))) > 20, f"{path} has almost no drawing"


def test_plot_run_writes_every_figure(runs: dict[str, Path], tmp_path: Path) -> None:
    """The moving-obstacle run, so the xy figure also draws obstacle paths and time marks."""
    written = plot_run(runs["moving"], tmp_path / "plots")
    assert tuple(written) == RUN_FIGURES
    for name, (png, svg) in written.items():
        assert png == tmp_path / "plots" / f"{name}.png" and svg.suffix == ".svg"
        _assert_png(png)
        _assert_svg(svg)
    # the scene (start at x=0, goal at x=8, obstacle near y=0) is wide and drawn to scale
    height, width = _assert_png(written["xy"][0]).shape[:2]
    assert width > 1.5 * height


def test_barrier_equals_hand_computation_static(runs: dict[str, Path]) -> None:
    run = load_run(runs["cbf"])
    summary = json.loads((runs["cbf"] / "summary.json").read_text())
    obstacle = load_scenario(SCENARIO).obstacles[0]
    barrier = barrier_series(run)
    assert barrier.shape == (summary["steps"],)
    k = summary["steps"] // 2
    with (runs["cbf"] / "log.csv").open() as f:
        row = list(csv.DictReader(f))[k]
    x, y = float(row["x_m"]), float(row["y_m"])
    by_hand = (
        (x - obstacle.x_m) ** 2
        + (y - obstacle.y_m) ** 2
        - (summary["robot_radius_m"] + obstacle.radius_m) ** 2
    )
    assert barrier[k] == pytest.approx(by_hand, rel=1e-6, abs=1e-9)


def test_barrier_equals_hand_computation_moving(runs: dict[str, Path]) -> None:
    run = load_run(runs["moving"])
    summary = json.loads((runs["moving"] / "summary.json").read_text())
    obstacle = load_scenario("head_on_moving_obstacle").obstacles[0]
    k = len(run.log["t_s"]) - 3
    t, x, y = run.log["t_s"][k], run.log["x_m"][k], run.log["y_m"][k]
    assert t > 1.0  # the obstacle has moved 0.4 m/s x t by now
    cx, cy = obstacle.x_m + obstacle.vx_mps * t, obstacle.y_m + obstacle.vy_mps * t
    by_hand = (x - cx) ** 2 + (y - cy) ** 2 - (summary["robot_radius_m"] + obstacle.radius_m) ** 2
    assert barrier_series(run)[k] == pytest.approx(by_hand, rel=1e-5, abs=1e-6)


def test_obstacle_centres_interpolate_between_samples() -> None:
    """Control times fall between the 60 Hz samples: the centre is linearly interpolated."""
    t = np.arange(0.0, 1.0 + 1e-9, 1 / 60)
    xy = np.stack([np.column_stack([2.0 * t, 1.0 - t]), np.column_stack([t * 0 + 5.0, t * 0])], axis=1)
    trace = EpisodeTrace(
        sample_t_s=t,
        base_position_m=np.zeros((t.size, 3)),
        base_orientation_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (t.size, 1)),
        obstacle_xy_m=xy,
        obstacle_radius_m=np.array([0.3, 0.5]),
        obstacle_height_m=np.ones(2),
        control_t_s=np.array([0.0]),
        predicted_states=np.zeros((1, 2, 3)),
        reference_path=np.zeros((1, 3)),
        goal=np.zeros(3),
        robot_radius_m=0.2,
        footprint_radius_m=0.2,
    )
    at = obstacle_centres_at(trace, np.array([0.125, 2.0]))
    assert at[0, 0] == pytest.approx([0.25, 0.875])
    assert at[1, 0] == pytest.approx([2.0, 0.0])  # after the last sample: held
    b = barrier_values(np.array([0.25]), np.array([0.0]), np.array([0.125]), trace, 0.2)
    assert b[0] == pytest.approx([0.875**2 - 0.5**2, 4.75**2 - 0.7**2])


def test_comparison_overlays_runs_of_one_scenario(runs: dict[str, Path], tmp_path: Path) -> None:
    png, svg = plot_comparison([runs["cbf"], runs["bt"]], tmp_path / "cmp" / "point_stab")
    assert png == tmp_path / "cmp" / "point_stab.png" and svg.name == "point_stab.svg"
    _assert_png(png, (800, 500))
    _assert_svg(svg)
    again = plot_comparison([runs["cbf"], runs["bt"]], tmp_path / "again")[1]
    assert again.read_bytes() == svg.read_bytes()  # SVGs are reproducible (no date, fixed salt)
    assert load_run(runs["bt"]).label() == "bt N=7"
    assert load_run(runs["cbf"]).label().startswith("cbf N=5 γ=")
    with pytest.raises(PlotInputError, match="different scenarios"):
        plot_comparison([runs["cbf"], runs["moving"]], tmp_path / "mixed")


def test_cli_without_display_plots_runs_and_comparison(runs: dict[str, Path], tmp_path: Path) -> None:
    """`env -u DISPLAY husky-sim plot A B --out OUT`, with an interactive backend asked for in
    MPLBACKEND, writes each run's figures to OUT/<run dir name>/ and the comparison to
    OUT/comparison.*."""
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    env["MPLBACKEND"] = "TkAgg"
    exe = Path(sys.executable).parent / "husky-sim"
    out = tmp_path / "figs"
    argv = [str(exe), "plot", str(runs["cbf"]), str(runs["bt"]), "--out", str(out)]
    done = subprocess.run(
        ["env", "-u", "DISPLAY", *argv], env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    for run_dir in (runs["cbf"], runs["bt"]):
        assert f"-> {out / run_dir.name}" in done.stdout
        for name in RUN_FIGURES:
            _assert_png(out / run_dir.name / f"{name}.png")
            _assert_svg(out / run_dir.name / f"{name}.svg")
    _assert_png(out / "comparison.png", (800, 500))
    _assert_svg(out / "comparison.svg")


def _results_csv(runs: dict[str, Path], path: Path) -> Path:
    """A suite-like results.csv from the real summaries: cbf on a 2 x 2 gamma x N grid with one
    cell missing and one cell run twice, bt at a single N and gamma, and an error row."""
    cbf = json.loads((runs["cbf"] / "summary.json").read_text())
    bt = json.loads((runs["bt"] / "summary.json").read_text())
    rows = [
        {**cbf, "gamma": 0.1, "horizon": 5, "run_dir": str(runs["cbf"])},
        {**cbf, "gamma": 0.2, "horizon": 5, "run_dir": str(runs["cbf"])},
        {**cbf, "gamma": 0.2, "horizon": 7, "min_clearance_m": 0.5, "run_dir": str(runs["cbf"])},
        {
            **cbf,
            "gamma": 0.2,
            "horizon": 7,
            "outcome": "reached",
            "converged": True,
            "time_to_goal_s": 9.5,
            "min_clearance_m": 0.3,
        },
        {**bt, "run_dir": str(runs["bt"])},
        {"scenario": SCENARIO, "controller": "cbf", "horizon": None, "gamma": None, "outcome": "error"},
    ]
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    return path


def test_tuning_maps(runs: dict[str, Path], tmp_path: Path) -> None:
    results = _results_csv(runs, tmp_path / "results.csv")
    written = plot_tuning_maps(results, tmp_path / "maps")
    assert set(written) == {f"{SCENARIO}/bt", f"{SCENARIO}/cbf"}
    for png, svg in written.values():
        _assert_png(png)
        _assert_svg(svg)
    assert written[f"{SCENARIO}/bt"][0].name == f"tuning_{SCENARIO}_bt.png"

    cbf_summary = json.loads((runs["cbf"] / "summary.json").read_text())
    rows = [r for r in read_results(results) if r["controller"] == "cbf" and r["horizon"]]
    grid = tuning_grid(rows)
    names = [name for name, _ in OUTCOME_CATEGORIES]
    assert grid.gammas == [0.1, 0.2] and grid.horizons == [5, 7]
    assert grid.category[1, 0] == names.index(cbf_summary["outcome"])
    assert grid.category[0, 1] == -1  # gamma 0.1, N 7: not run, blank
    assert np.isnan(grid.min_clearance_m[0, 1]) and np.isnan(grid.third[0, 1])
    assert grid.min_clearance_m[1, 1] == pytest.approx(0.3)  # worst of the cell's two runs
    assert grid.third[1, 1] == pytest.approx(9.5) and grid.third_name == "time to goal (s)"
    assert grid.category_text[1][1].endswith("1/2")
    assert grid.min_clearance_m[1, 0] == pytest.approx(cbf_summary["min_clearance_m"])


def test_tuning_maps_cli_and_scenario_filter(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    results = _results_csv(runs, tmp_path / "results.csv")
    out = tmp_path / "maps"
    assert main(["plot", "--results", str(results), "--out", str(out), "--scenario", SCENARIO]) == 0
    assert "2 tuning maps" in capsys.readouterr().out
    assert len(list(out.glob("*.png"))) == 2 and len(list(out.glob("*.svg"))) == 2
    with pytest.raises(PlotInputError, match="no runs of scenario"):
        plot_tuning_maps(results, out, scenario="narrow_gap")


def _bad_run(tmp_path: Path, runs: dict[str, Path], broken: str, text: str) -> Path:
    bad = tmp_path / "bad_run"
    bad.mkdir()
    for f in runs["bt"].iterdir():
        if f.is_file():
            (bad / f.name).write_bytes(f.read_bytes())
    (bad / broken).write_text(text)
    return bad


@pytest.mark.parametrize(
    ("case", "words"),
    [
        ("missing_dir", "not a run directory"),
        ("corrupt_summary", "summary.json"),
        ("empty_log", "no control steps"),
        ("corrupt_trace", "trace.npz"),
        ("missing_results", "results.csv: missing"),
        ("not_results", "missing columns"),
        ("nothing", "give one or more run directories"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(
    case: str, words: str, runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = {
        "missing_dir": lambda: ["plot", str(tmp_path / "nope")],
        "corrupt_summary": lambda: ["plot", str(_bad_run(tmp_path, runs, "summary.json", "{not json"))],
        "empty_log": lambda: ["plot", str(_bad_run(tmp_path, runs, "log.csv", "step,t_s\n"))],
        "corrupt_trace": lambda: ["plot", str(_bad_run(tmp_path, runs, "trace.npz", "garbage"))],
        "missing_results": lambda: ["plot", "--results", str(tmp_path / "results.csv")],
        "not_results": lambda: ["plot", "--results", str(runs["bt"] / "log.csv")],
        "nothing": lambda: ["plot"],
    }[case]()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("husky-sim: error:") and words in err[0], err


# ---------------------------------------------------------------------------------------------
# Framing, layout and colour scales
# ---------------------------------------------------------------------------------------------


def _assert_xy_holds_everything(fig: Figure, runs: list[Path]) -> None:
    """Every circle on the xy axes (obstacles, their robot-radius-grown circles, moving marks),
    the start and the goal lie inside the axis limits, with some margin."""
    ax = fig.axes[0]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    circles = [patch for patch in ax.patches if isinstance(patch, Circle)]
    assert circles
    for circle in circles:
        (cx, cy), r = circle.center, circle.radius
        assert x0 < cx - r and cx + r < x1 and y0 < cy - r and cy + r < y1, (
            circle,
            ax.get_xlim(),
            ax.get_ylim(),
        )
    run = load_run(runs[0])
    for j in np.flatnonzero(~moving_obstacles(run.trace)):  # static ones get the grown circle
        grown_r = float(run.trace.obstacle_radius_m[j]) + run.robot_radius_m
        assert any(c.radius == pytest.approx(grown_r) for c in circles), "obstacle + robot radius circle"
    for path in runs:
        log = load_run(path).log
        for x, y in ((log["x_m"][0], log["y_m"][0]), (log["x_m"][-1], log["y_m"][-1])):
            assert x0 < x < x1 and y0 < y < y1
    gx, gy = run.trace.goal[:2]
    assert x0 + 0.2 < gx < x1 - 0.2 and y0 + 0.2 < gy < y1 - 0.2


def test_comparison_axes_hold_every_drawn_circle(runs: dict[str, Path]) -> None:
    """The grown circle (0.45 m + the 0.82 m robot circle around y = 0) reaches y = -1.27 m,
    below anything the runs drove through: it must still be inside the limits."""
    pair = [runs["cbf"], runs["bt"]]
    fig = comparison_figure([load_run(d) for d in pair])
    try:
        _assert_xy_holds_everything(fig, pair)
    finally:
        plt.close(fig)


@pytest.mark.parametrize("case", ["tall", "moving", "cbf"])
def test_xy_figure_holds_scene_and_labels(case: str, runs: dict[str, Path], tmp_path: Path) -> None:
    """Tall (paper point stabilisation), wide (moving obstacle) and plain scenes: everything drawn is
    inside the limits, and the axis labels and title lie inside the figure and its tight bbox,
    which is what the PNG is cropped to."""
    fig = xy_figure(load_run(runs[case]))
    try:
        _assert_xy_holds_everything(fig, [runs[case]])
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        ax = fig.axes[0]
        tight_px = fig.get_tightbbox(renderer).transformed(fig.dpi_scale_trans)
        for text in (ax.yaxis.label, ax.xaxis.label, ax.title):
            box = text.get_window_extent(renderer)
            assert box.width > 0 and box.height > 0
            assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1, (text.get_text(), box, fig.bbox)
            assert fig.bbox.y0 <= box.y0 and box.y1 <= fig.bbox.y1, (text.get_text(), box, fig.bbox)
            assert tight_px.x0 <= box.x0 + 1 and box.x1 <= tight_px.x1 + 1
        expected_px = (
            tight_px.width / fig.dpi * DPI + 0.2 * DPI,
            tight_px.height / fig.dpi * DPI + 0.2 * DPI,
        )
    finally:
        plt.close(fig)
    png = plot_run(runs[case], tmp_path)["xy"][0]
    height, width = matplotlib.image.imread(png).shape[:2]
    assert (width, height) == pytest.approx(expected_px, abs=3)  # cropped to the tight bbox + 0.1 in
    if case == "tall":
        assert height > 1.5 * width


def test_clearance_colours_are_absolute() -> None:
    """0 m (contact) and below are red, 0.36 m is not red (it is past yellow, toward green),
    SAFE_CLEARANCE_M and above are green; the scale does not depend on the other cells."""
    red, past = clearance_colour(0.0), clearance_colour(0.36)
    assert red[0] > 0.5 and red[1] < 0.2 and red[2] < 0.3
    assert clearance_colour(-0.3) == red
    assert past[1] > past[0] and past[1] > 0.6
    green = clearance_colour(SAFE_CLEARANCE_M)
    assert green[1] > 0.3 and green[1] > 2 * green[0]
    assert clearance_colour(2.0) == green
    assert clearance_colour(float("nan")) == (1.0, 1.0, 1.0, 1.0)


def _grid_rows(clearances_m: list[float], outcome: str = "stuck", **extra: object) -> list[dict[str, str]]:
    return [
        {
            "scenario": SCENARIO,
            "controller": "cbf",
            "horizon": str(5 + 2 * n),
            "gamma": "0.1",
            "outcome": outcome,
            "min_clearance_m": str(c),
            **{k: str(v) for k, v in extra.items()},
        }
        for n, c in enumerate(clearances_m)
    ]


def _clearance_image(fig: Figure) -> AxesImage:
    (image,) = fig.axes[1].get_images()
    return image


def test_tuning_maps_share_one_clearance_scale() -> None:
    """Two maps with different clearance ranges colour a cell alike; the colour bar says the scale
    is fixed and in metres."""
    figures = [
        tuning_figure(SCENARIO, "cbf", tuning_grid(_grid_rows([0.36, 0.4]))),
        tuning_figure(SCENARIO, "cbf", tuning_grid(_grid_rows([0.36, 1.5, -0.01]))),
    ]
    try:
        images = [_clearance_image(fig) for fig in figures]
        for image in images:
            assert (image.norm.vmin, image.norm.vmax) == (0.0, SAFE_CLEARANCE_M)
            assert image.cmap(image.norm(0.36)) == pytest.approx(clearance_colour(0.36))
        labels = [ax.get_ylabel() for fig in figures for ax in fig.axes if "clearance (m)" in ax.get_ylabel()]
        assert len(labels) == 2 and all("fixed scale" in t and "≤ 0 m" in t for t in labels), labels
    finally:
        for fig in figures:
            plt.close(fig)


def test_empty_tuning_panels_say_what_is_missing() -> None:
    """No run reached the goal: the time panel says so (with the outcomes); no clearance column:
    the clearance panel names it; no runs at all: the panel says so."""
    rows = [{k: v for k, v in row.items() if k != "min_clearance_m"} for row in _grid_rows([0.3, 0.3])]
    grid = tuning_grid(rows)
    assert "no run reached the goal" in grid.third_missing and "time to goal undefined" in grid.third_missing
    assert "stuck 2" in grid.third_missing
    assert "no min_clearance_m column" in grid.min_clearance_missing
    fig = tuning_figure(SCENARIO, "cbf", grid)
    try:
        texts = [[t.get_text() for t in ax.texts] for ax in fig.axes[1:3]]
        assert texts == [[grid.min_clearance_missing], [grid.third_missing]]
    finally:
        plt.close(fig)
    reached = _grid_rows([0.3], outcome="reached", time_to_goal_s="")
    assert "for the 1 run that reached the goal" in third_missing_reason(reached)
    assert "value in results.csv\nfor 1 run" in clearance_missing_reason(_grid_rows([float("nan")]))
    assert clearance_missing_reason([]) == third_missing_reason([]) == NO_RUNS_TEXT
