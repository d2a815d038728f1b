"""husky_sim.calibration.recordings on the real Husky A200 recordings (assets/husky_a200/drive_recordings):
the figures their README states, and the reader's definitions on synthetic files. Fast: no PyBullet."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from husky_sim.calibration.recordings import (
    COMMAND_CLASSES,
    RECORDING_BASELINE_M,
    RECORDING_WHEEL_RADIUS_M,
    DriveRecording,
    RecordingError,
    SteadyStep,
    command_class,
    load_drive_recording,
)

DATA = Path(__file__).resolve().parents[2] / "assets" / "husky_a200" / "drive_recordings"
TURNING = ("in_place", "tight_arc", "wide_arc")


@pytest.fixture(scope="module")
def grass() -> DriveRecording:
    return load_drive_recording(DATA / "wet_grass_raw.csv")


@pytest.fixture(scope="module")
def tile() -> DriveRecording:
    return load_drive_recording(DATA / "tile_deflated_windows.csv")


def _median(values) -> float:
    return float(np.median(list(values)))


# --- the README's figures ----------------------------------------------------------------------------


def test_the_licence_stays_with_the_recordings() -> None:
    assert "BSD" in (DATA / "LICENSE").read_text() or "Redistribution" in (DATA / "LICENSE").read_text()
    assert "husky_sim/calibration/recordings.py" in (DATA / "README.md").read_text()


def test_wet_grass_yaw_ratio_is_0_52_in_place_and_on_arcs(grass: DriveRecording) -> None:
    assert grass.name == "wet_grass"
    # 40 steps: 5 interrupted by the operator are dropped, 3 of the other 35 drive straight.
    assert len(grass.steps) == 35
    assert len(grass.yaw_ratios()) == 32
    assert grass.median_yaw_ratio() == pytest.approx(0.52, abs=0.02)
    for name in TURNING:
        assert grass.median_yaw_ratio(name) == pytest.approx(0.52, abs=0.02), name
    q25, q75 = np.percentile(grass.yaw_ratios(), [25, 75])
    assert q25 >= 0.48 and q75 <= 0.55


def test_wet_grass_forward_ratio_is_0_95(grass: DriveRecording) -> None:
    assert grass.median_forward_ratio() == pytest.approx(0.95, abs=0.03)


def test_wet_grass_currents_in_place_and_on_arcs(grass: DriveRecording) -> None:
    assert all(s.current_a is not None for s in grass.steps)
    in_place = [s.current_a for s in grass.steps if s.command_class == "in_place"]
    arcs = [s.current_a for s in grass.steps if s.command_class in ("tight_arc", "wide_arc")]
    assert 10.0 <= _median(in_place) <= 14.0
    assert 4.0 <= _median(arcs) <= 6.0


def test_wet_grass_wheel_step_response(grass: DriveRecording) -> None:
    """README: median of 59 wheel steps, 63 % at 0.45 s and 95 % at 0.65 s from the command change."""
    assert len(grass.wheel_step_times) == 59
    times = grass.median_step_times("wheel")
    assert times.t63_s == pytest.approx(0.45, abs=0.05)
    assert times.t95_s == pytest.approx(0.65, abs=0.05)
    assert grass.yaw_step_times == ()
    with pytest.raises(RecordingError, match="no yaw step responses"):
        grass.median_step_times("yaw")


def test_tile_yaw_ratio_is_0_54_and_0_53_in_place(tile: DriveRecording) -> None:
    assert tile.name == "tile"
    assert len(tile.steps) == 400  # steady windows
    assert all(s.window >= 0 and s.current_a is None for s in tile.steps)
    assert tile.median_yaw_ratio() == pytest.approx(0.54, abs=0.02)
    assert tile.median_yaw_ratio("in_place") == pytest.approx(0.53, abs=0.02)
    # The README's 284 windows are those turning at least 0.3 rad/s by their wheels.
    strong = [s.yaw_ratio for s in tile.steps if abs(s.w_wheels_radps) >= 0.3]
    assert len(strong) == 284
    assert _median(strong) == pytest.approx(0.54, abs=0.02)


def test_tile_gyro_agrees_with_icp(tile: DriveRecording) -> None:
    turning = [s for s in tile.steps if s.yaw_ratio is not None and s.command_class != "straight"]
    gyro = _median(s.gyro_w_radps / s.w_wheels_radps for s in turning)
    assert gyro == pytest.approx(tile.median_yaw_ratio(), abs=0.03)


def test_tile_forward_ratio(tile: DriveRecording) -> None:
    """Measured 0.965, not the README's 1.17: every definition of the forward speed from these windows
    (chord, path, least squares, the authors' own step_frame_vx gain 0.96) reads 0.96-1.00."""
    assert tile.median_forward_ratio() == pytest.approx(0.965, abs=0.03)


def test_tile_step_times_are_the_authors_fits(tile: DriveRecording) -> None:
    assert len(tile.yaw_step_times) == 200
    assert len(tile.wheel_step_times) == 400  # one per side per step
    yaw = tile.median_step_times("yaw")
    assert yaw.t63_s == pytest.approx(0.62, abs=0.05)
    assert yaw.t95_s == pytest.approx(1.26, abs=0.05)
    # README: wheel delay 0.34 s + time constant 0.21 s, i.e. 63 % at 0.55 s.
    assert tile.median_step_times("wheel").t63_s == pytest.approx(0.34 + 0.21, abs=0.05)


# --- definitions -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("v", "w", "expected"),
    [
        (0.0, 1.0, "in_place"),
        (0.24, 1.0, "in_place"),
        (0.25, -1.0, "tight_arc"),
        (-0.99, 1.0, "tight_arc"),
        (1.0, 1.0, "wide_arc"),
        (0.39, 0.1, "wide_arc"),
        (0.4, 0.1, "straight"),
        (0.0, 0.04, "straight"),
        (0.0, 0.0, "straight"),
    ],
)
def test_command_class(v: float, w: float, expected: str) -> None:
    assert command_class(v, w) == expected
    assert expected in COMMAND_CLASSES


def test_ratios_are_undefined_for_small_wheel_speeds() -> None:
    step = SteadyStep(0, -1, 1.0, 1.3, 0.18, 0.09, 0.17, 0.05, None)
    assert step.yaw_ratio is None
    assert step.forward_ratio == pytest.approx(0.17 / 0.18)
    assert step.command_class == "wide_arc"


def _arc(t: np.ndarray, v: float, w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    yaw = w * t
    return v / w * np.sin(yaw), v / w * (1.0 - np.cos(yaw)), yaw


def _write(path: Path, header: list[str], rows: list[list[object]]) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


TILE_HEADER = [
    "window",
    "step",
    "sample",
    "t_s",
    "steady",
    "cmd_left",
    "cmd_right",
    "left_wheel_vel",
    "right_wheel_vel",
    "imu_yaw",
    "icp_x",
    "icp_y",
    "icp_yaw",
]


@pytest.mark.parametrize("w", [0.8, -1.4, 2.5])  # 1.6, 2.8 and 5 rad turned in the 2 s window
def test_an_arc_reads_its_speed_along_the_arc(tmp_path: Path, w: float) -> None:
    t = np.arange(40) * 0.05
    v, ratio = 0.6, 0.5
    x, y, yaw = _arc(t, v, ratio * w)
    r, b = RECORDING_WHEEL_RADIUS_M, RECORDING_BASELINE_M
    left, right = (v - w * b / 2) / r, (v + w * b / 2) / r
    rows = [
        [
            0,
            3,
            i,
            t[i],
            "True",
            left,
            right,
            left,
            right,
            ratio * w,
            x[i],
            y[i],
            math.remainder(yaw[i], math.tau),
        ]
        for i in range(len(t))
    ]
    rec = load_drive_recording(_write(tmp_path / "arc_windows.csv", TILE_HEADER, rows))
    (step,) = rec.steps
    assert (step.step, step.window) == (3, 0)
    assert step.w_wheels_radps == pytest.approx(w)
    assert step.yaw_ratio == pytest.approx(ratio)
    assert step.forward_ratio == pytest.approx(1.0, abs=0.01)
    assert rec.wheel_step_times == rec.yaw_step_times == ()  # no arc_authors_fits.csv beside it
    with pytest.raises(RecordingError, match="no wheel step responses"):
        rec.median_step_times("wheel")


WET_HEADER = [
    "t_s",
    "calib_state",
    "calib_step",
    "meas_left_vel",
    "meas_right_vel",
    "icp_pos_x",
    "icp_pos_y",
    "icp_yaw",
    "left_wheel_current",
    "right_wheel_current",
]


def test_wet_grass_steps_interruptions_and_wheel_rise_times(tmp_path: Path) -> None:
    """Three 6 s steps; the wheels answer each after 0.3 s (all at once); step 2 is interrupted by
    idle rows. Steps 1 and 3 are steady steps; the wheel responses at steps 2 and 3 rise in 0.3 s."""
    dt, r, b, ratio = 0.05, RECORDING_WHEEL_RADIUS_M, RECORDING_BASELINE_M, 0.5
    wheels = {1: (2.0, 4.0), 2: (-3.0, 3.0), 3: (4.0, 0.0)}
    rows, t, pose = [], 0.0, np.zeros(3)
    for step, (left, right) in wheels.items():
        previous = wheels.get(step - 1, (0.0, 0.0))
        for i in range(120):
            if step == 2 and i == 60:  # the operator takes over for 5 s
                for _ in range(100):
                    rows.append([t, "idle", step, 0.0, 0.0, *pose, 0.0, 0.0])
                    t += dt
            wl, wr = (left, right) if i >= 6 else previous
            v, w = r * (wr + wl) / 2, ratio * r * (wr - wl) / b
            rows.append([t, "calib", step, wl, wr, *pose, 10.0, -12.0])
            heading = pose[2]
            pose = pose + (v * math.cos(heading) * dt, v * math.sin(heading) * dt, w * dt)
            t += dt
    rec = load_drive_recording(_write(tmp_path / "grass.csv", WET_HEADER, rows))
    assert [s.step for s in rec.steps] == [1, 3]
    assert all(s.window == -1 and s.current_a == pytest.approx(11.0) for s in rec.steps)
    assert rec.steps[0].yaw_ratio == pytest.approx(ratio, rel=1e-3)
    assert rec.steps[0].forward_ratio == pytest.approx(1.0, rel=0.01)
    # Step 1 follows nothing; step 2: both sides change by 5 and 1 rad/s (1 is too small); step 3: 7 and 3.
    assert len(rec.wheel_step_times) == 3
    assert all(s.t63_s == pytest.approx(0.3) and s.t95_s == pytest.approx(0.3) for s in rec.wheel_step_times)


# --- bad input ---------------------------------------------------------------------------------------


def _one_line_error(path: Path) -> str:
    with pytest.raises(RecordingError) as err:
        load_drive_recording(path)
    message = str(err.value)
    assert "\n" not in message and path.name in message
    return message


def test_a_missing_file(tmp_path: Path) -> None:
    assert "no such file" in _one_line_error(tmp_path / "absent.csv")


def test_an_unknown_header(tmp_path: Path) -> None:
    message = _one_line_error(_write(tmp_path / "other.csv", ["time", "speed"], [[0.0, 1.0]]))
    assert "unknown header" in message and "calib_state" in message and "window" in message


@pytest.mark.parametrize(
    ("header", "column"),
    [
        ([c for c in WET_HEADER if c != "icp_yaw"], "icp_yaw"),
        ([c for c in WET_HEADER if c != "right_wheel_current"], "right_wheel_current"),
        ([c for c in TILE_HEADER if c != "left_wheel_vel"], "left_wheel_vel"),
    ],
)
def test_a_missing_column(tmp_path: Path, header: list[str], column: str) -> None:
    message = _one_line_error(_write(tmp_path / "short.csv", header, []))
    assert f"column {column}" in message


def test_a_non_numeric_cell(tmp_path: Path) -> None:
    rows = [[0.05 * i, "calib", 1, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0, 1.0] for i in range(5)]
    rows[3][4] = "fast"
    message = _one_line_error(_write(tmp_path / "bad.csv", WET_HEADER, rows))
    assert "meas_right_vel" in message and "line 5" in message and "'fast'" in message


def test_a_row_of_the_wrong_length(tmp_path: Path) -> None:
    path = _write(tmp_path / "ragged.csv", TILE_HEADER, [[0] * len(TILE_HEADER), [0] * 3])
    assert "line 3" in _one_line_error(path)
