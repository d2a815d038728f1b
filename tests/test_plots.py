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
import numpy as np
import pytest

from husky_sim.cli import main
from husky_sim.plots import (
    DPI,
    OUTCOME_CATEGORIES,
    RUN_FIGURES,
    PlotInputError,
    barrier_series,
    barrier_values,
    load_run,
    obstacle_centres_at,
    plot_comparison,
    plot_run,
    plot_tuning_maps,
    read_results,
    tuning_grid,
)
from husky_sim.run import run_scenario
from husky_sim.scenario import load_scenario
from husky_sim.trace import EpisodeTrace

SCENARIO = "husky_point_stabilisation"


def _record(root: Path, name: str, controller: str, duration_s: float, **kwargs: object) -> Path:
    sc = load_scenario(name).model_copy(update={"duration_s": duration_s})
    out = root / f"{name}__{controller}__{kwargs.get('horizon', 'file')}"
    run_scenario(sc, controller, out_dir=out, **kwargs)
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Short real runs: point stabilisation with cbf (file's N) and bt N=7, and a moving obstacle."""
    root = tmp_path_factory.mktemp("runs")
    return {
        "cbf": _record(root, SCENARIO, "cbf", 3.0),
        "bt": _record(root, SCENARIO, "bt", 3.0, horizon=7),
        "moving": _record(root, "head_on_moving_obstacle", "relax-cbf", 2.0, horizon=5),
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
