"""The yaw-rate lag (husky_sim.sim.yaw_response): exact discretisation, recovery of known parameters,
identification in real PyBullet physics (no mocks), the scenario schema's `robot.yaw_response`,
and `husky-sim replay` reporting the recording's lag."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from husky_sim.cli import main
from husky_sim.realcheck.replay import (
    SUMMARY_NAME,
    SimParams,
    applied_yaw_rate,
    fit_recording_yaw,
    make_recording,
)
from husky_sim.runs import scenario as scenario_module
from husky_sim.runs.scenario import (
    ScenarioError,
    YawResponseSpec,
    load_scenario,
    scenario_from_data,
    shipped_scenarios,
)
from husky_sim.scenario_file import read_scenario_data
from husky_sim.sim.ground import load_ground
from husky_sim.sim.open_loop import simulate_commands
from husky_sim.sim.robot_description import RobotDescription, load_robot
from husky_sim.sim.yaw_response import (
    DEFAULT_FILE,
    PAYLOAD_FRACTIONS,
    YawResponse,
    fit_segments,
    fit_yaw_response,
    simulate_lag,
)
from tests.realcheck.test_replay import ODOM_EVERY_STEPS, SEGMENTS, START, TRUE, _commands

#: The synthetic signal: K = 0.55, T = 0.8 s, steps every 2 s, 0.1 s samples, noise 0.02 rad/s.
#: Measured recovery error (seed 0): gain +0.001, time constant +0.016 s; tolerances 0.02 and 0.05 s.
TRUE_LAG = YawResponse(gain=0.55, time_constant_s=0.8)
NOISE_RADPS = 0.02
GAIN_TOL, TIME_CONSTANT_TOL_S = 0.02, 0.05
#: `husky-sim identify` measured here on the calibrated default ground: gain 0.852, time constant
#: 0.111 s behind the ground's 0.343 s dead time, rms 0.131 rad/s over the 12 steps (the 1.2 rad/s
#: steps at 0.5 m/s saturate the tyres; a lag without the dead time took 0.877, 0.500 s and 0.152;
#: 0.485, 0.364 s and 0.2035 on the uncalibrated plant).
#: Bounds with some headroom;
#: a broken identification (sign error, wrong sampling, fit stuck at a bound) exceeds them.
IDENTIFIED_RMS_MAX_RADPS = 0.25
IDENTIFIED_STEP_RMS_MAX_RADPS = 0.35


def _synthetic(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 30.0, 0.1)
    levels = rng.choice([-1.2, -0.8, -0.4, 0.0, 0.4, 0.8, 1.2], size=15)
    applied = np.repeat(levels, 20)[: len(t)]
    clean = simulate_lag(t, applied, TRUE_LAG.gain, TRUE_LAG.time_constant_s)
    return t, applied, clean + rng.normal(0.0, NOISE_RADPS, len(t))


def test_simulate_lag_is_exact_on_any_grid() -> None:
    """A step from omega0: the analytic K u + (omega0 - K u) exp(-t / T), on an irregular grid."""
    t = np.cumsum(np.r_[0.0, np.random.default_rng(1).uniform(0.01, 0.5, 40)])
    out = simulate_lag(t, np.full(len(t), 0.9), 0.6, 0.7, omega0=-0.2)
    assert out == pytest.approx(0.54 + (-0.2 - 0.54) * np.exp(-t / 0.7), abs=1e-12)


def test_fit_recovers_a_known_lag_from_noisy_samples() -> None:
    t, applied, measured = _synthetic()
    response, rms_error = fit_yaw_response(t, applied, measured)
    assert response.gain == pytest.approx(TRUE_LAG.gain, abs=GAIN_TOL)
    assert response.time_constant_s == pytest.approx(TRUE_LAG.time_constant_s, abs=TIME_CONSTANT_TOL_S)
    assert rms_error == pytest.approx(NOISE_RADPS, rel=0.2)  # the noise, nothing more


def test_fit_of_several_segments_and_bad_input() -> None:
    segments = [_synthetic(seed) for seed in (2, 3)]
    response, _ = fit_segments(segments)
    assert response.gain == pytest.approx(TRUE_LAG.gain, abs=GAIN_TOL)
    t = np.arange(10) * 0.1
    with pytest.raises(ValueError, match="nothing to identify"):
        fit_yaw_response(t, np.zeros(10), np.zeros(10))
    with pytest.raises(ValueError, match="strictly increasing"):
        fit_yaw_response(t[::-1], np.ones(10), np.ones(10))


@pytest.fixture(scope="module")
def identified(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """`husky-sim identify --out FILE` once (12 PyBullet steps of 4 s, about 3 s)."""
    path = tmp_path_factory.mktemp("identify") / "yaw.yaml"
    assert main(["identify", "--out", str(path)]) == 0
    assert path.read_text().startswith("# Produced by `husky-sim identify --out ")
    return read_scenario_data(path)


@pytest.mark.physics
def test_identification_in_pybullet(identified: dict[str, object]) -> None:
    # calibrated default ground: 0.52 of the wheel-implied yaw rate x the 1.875 multiplier = 0.98 of
    # the command where the tyres do not saturate (0.85 identified, the 1.2 rad/s steps saturate);
    # behind the ground's dead time, the lag is about the drive's own (0.10 s) plus the tyres'
    assert 0.75 <= identified["gain"] <= 1.05
    assert 0.05 <= identified["time_constant_s"] <= 1.5
    assert identified["delay_s"] == load_ground().drive.command_delay_s > 0.3
    assert identified["rms_error_radps"] < IDENTIFIED_RMS_MAX_RADPS
    steps = identified["steps"]
    commanded = {(s["linear_mps"], s["yaw_rate_radps"]) for s in steps}
    assert commanded == {(v, w) for v in (0.0, 0.5) for w in (0.4, 0.8, 1.2, -0.4, -0.8, -1.2)}
    assert all(s["rms_error_radps"] < IDENTIFIED_STEP_RMS_MAX_RADPS for s in steps)
    assert all(0.2 < s["late_ratio"] < 1.0 for s in steps)  # turns the commanded way, partially


def test_shipped_default_is_the_current_identification(identified: dict[str, object]) -> None:
    """Deterministic physics: a fresh identification reproduces the shipped file (else re-run
    `husky-sim identify`), and scenarios without robot.yaw_response get exactly that."""
    shipped = read_scenario_data(DEFAULT_FILE)
    assert shipped["gain"] == pytest.approx(identified["gain"], abs=1e-3)
    assert shipped["time_constant_s"] == pytest.approx(identified["time_constant_s"], abs=1e-3)
    assert shipped["delay_s"] == identified["delay_s"] == load_ground().drive.command_delay_s
    lag = YawResponse(shipped["gain"], shipped["time_constant_s"], shipped["delay_s"])
    for path in shipped_scenarios():
        robot = load_scenario(str(path)).robot
        assert robot.yaw_response is None
        assert robot.yaw_response_params() == lag


def test_shipped_lag_by_payload_is_the_current_identification(identified: dict[str, object]) -> None:
    """The file holds the lag at each identified payload (0 to the Husky's 75 kg), the fresh
    identification reproduces it, the loaded robot turns less or later than the empty one, and a
    scenario's default lag is the one for its payload (linear between the identified ones)."""
    shipped = read_scenario_data(DEFAULT_FILE)["by_payload"]
    fresh = identified["by_payload"]
    most = load_robot().specs.spec_sheet.max_payload_kg
    assert [row["payload_kg"] for row in shipped] == [most * f for f in PAYLOAD_FRACTIONS]
    for old, new in zip(shipped, fresh, strict=True):
        assert old["payload_kg"] == new["payload_kg"]
        assert old["gain"] == pytest.approx(new["gain"], abs=1e-3), old["payload_kg"]
        assert old["time_constant_s"] == pytest.approx(new["time_constant_s"], abs=1e-3), old["payload_kg"]
    empty, full = shipped[0], shipped[-1]
    headline = read_scenario_data(DEFAULT_FILE)
    assert (empty["gain"], empty["time_constant_s"]) == (headline["gain"], headline["time_constant_s"])
    assert full["gain"] < empty["gain"] or full["time_constant_s"] > empty["time_constant_s"]
    base = load_scenario("husky_point_stabilisation")
    for row in shipped:
        loaded = base.model_copy(
            update={"robot": base.robot.model_copy(update={"payload_kg": row["payload_kg"]})}
        )
        lag = loaded.robot.yaw_response_params()
        assert (lag.gain, lag.time_constant_s) == (row["gain"], row["time_constant_s"])
        assert loaded.controller_config("husky-cbf").response.yaw_gain == row["gain"]
    a, b = shipped[1], shipped[2]
    between = base.model_copy(
        update={
            "robot": base.robot.model_copy(update={"payload_kg": 0.5 * (a["payload_kg"] + b["payload_kg"])})
        }
    )
    assert between.robot.yaw_response_params().gain == pytest.approx(0.5 * (a["gain"] + b["gain"]))


def _scenario_data(yaw_response: object) -> dict:
    data = load_scenario("husky_point_stabilisation").model_dump(mode="json")
    data["robot"]["yaw_response"] = yaw_response
    return data


def test_scenario_yaw_response_given() -> None:
    sc = scenario_from_data(_scenario_data({"gain": 0.7, "time_constant_s": 0.25}))
    assert sc.robot.yaw_response_params() == YawResponse(0.7, 0.25, 0.0)  # no dead time declared
    sc = scenario_from_data(_scenario_data({"gain": 0.7, "time_constant_s": 0.25, "delay_s": 0.3}))
    assert sc.robot.yaw_response_params() == YawResponse(0.7, 0.25, 0.3)
    assert sc.controller_config("husky-cbf").response.command_delay_s == 0.3


@pytest.mark.parametrize(
    ("value", "field", "message"),
    [
        ({"gain": 2.5, "time_constant_s": 0.5}, "gain", "[0.05, 2]"),
        ({"gain": 0.0, "time_constant_s": 0.5}, "gain", "[0.05, 2]"),
        ({"gain": 0.5, "time_constant_s": 0.0}, "time_constant_s", "[0.01, 10] s"),
        ({"gain": 0.5, "time_constant_s": 11}, "time_constant_s", "[0.01, 10] s"),
        ({"gain": "0.5", "time_constant_s": 0.5}, "gain", "finite number"),
        ({"gain": 0.5}, "time_constant_s", "Field required"),
        ({"gain": 0.5, "time_constant_s": 0.5, "delay_s": 2.5}, "delay_s", "[0, 2] s"),
        ({"gain": 0.5, "time_constant_s": 0.5, "dead_time_s": 0.1}, "dead_time_s", "Extra inputs"),
    ],
)
def test_scenario_rejects_bad_yaw_response(value: dict, field: str, message: str) -> None:
    with pytest.raises(ScenarioError) as error:
        scenario_from_data(_scenario_data(value), "bad.yaml")
    text = str(error.value)
    assert text.startswith(f"bad.yaml: robot.yaw_response.{field}: ") and message in text
    assert "\n" not in text


@pytest.mark.parametrize(
    ("content", "message"),
    [(None, "no such file"), ("gain: 0.5\ntime_constant_s: fast\n", "time_constant_s: must be a finite")],
)
def test_missing_or_malformed_default_is_one_line(
    content: str | None, message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "yaw_response.yaml"
    if content is not None:
        path.write_text(content)
    monkeypatch.setattr(RobotDescription, "yaw_response_file", property(lambda _: path))
    scenario_module.identified_yaw_responses.cache_clear()
    try:
        robot = load_scenario("husky_point_stabilisation").robot
        with pytest.raises(ScenarioError) as error:
            robot.yaw_response_params()
    finally:
        scenario_module.identified_yaw_responses.cache_clear()
    assert str(path) in str(error.value) and message in str(error.value)
    assert "\n" not in str(error.value)


def test_recording_fit_recovers_a_known_lag_from_odometry_twist() -> None:
    """The replay's pipeline (held commands through the drive limits, interval means) on a
    recording whose twist yaw rate is an exact lag of those applied commands."""
    cmd_t = np.arange(0.0, 12.0, 0.1) + 0.003
    commands = np.column_stack([np.full(len(cmd_t), 0.4), np.repeat([0.0, 0.8, -0.5, 1.0], 30)])
    pose_t = np.arange(0.0, 12.0, 0.05)
    dummy = make_recording("synthetic", "csv", cmd_t, commands, pose_t, np.zeros((len(pose_t), 3)))
    applied = applied_yaw_rate(dummy, pose_t, SimParams())
    yaw_rates = simulate_lag(pose_t, applied, TRUE_LAG.gain, TRUE_LAG.time_constant_s)
    recording = make_recording("synthetic", "ros1", cmd_t, commands, pose_t, dummy.poses, yaw_rates)
    fitted = fit_recording_yaw(recording)
    assert fitted.source == "odometry twist" and fitted.samples == len(pose_t)
    assert fitted.response.gain == pytest.approx(TRUE_LAG.gain, abs=1e-3)
    assert fitted.response.time_constant_s == pytest.approx(TRUE_LAG.time_constant_s, abs=1e-3)
    assert fitted.rms_error_radps < 1e-6


@pytest.fixture(scope="module")
def drive_csv(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    """tests/realcheck/test_replay.py's S-curve, simulated (multiplier 1.6, ground friction 0.6) and written
    as its CSV; with the simulated body yaw rates at the pose times."""
    cmd_t, commands = _commands()
    duration_s = sum(segment[0] for segment in SEGMENTS)
    track = simulate_commands(
        cmd_t, commands, duration_s, START, world=TRUE.world(), drive=TRUE.drive(), ground=TRUE.ground()
    )
    idx = np.arange(0, len(track.t_s), ODOM_EVERY_STEPS)
    rows = [(float(t), float(v), float(w), "", "", "") for t, (v, w) in zip(cmd_t, commands, strict=True)]
    rows += [
        (float(t), "", "", float(x), float(y), float(th))
        for t, (x, y, th) in zip(track.t_s[idx], track.poses[idx], strict=True)
    ]
    path = tmp_path_factory.mktemp("yaw_csv") / "drive.csv"
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["t", "v", "omega", "x", "y", "theta"])
        writer.writerows(sorted(rows, key=lambda r: r[0]))
    return path, track.body_velocity[idx, 1]


@pytest.mark.physics
def test_replay_reports_the_yaw_response(
    drive_csv: tuple[Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`replay` on a CSV (yaw rate from the differentiated yaw): the lag is printed, in the
    summary, and in the scenario snippet, whose robot.yaw_response the schema accepts."""
    path, _ = drive_csv
    out = tmp_path / "out"
    assert main(["replay", str(path), "--ground-friction", "0.6", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "yaw-rate lag of the recording (161 samples, yaw rate from the differentiated yaw)" in printed
    yaw = json.loads((out / SUMMARY_NAME).read_text())["yaw_response"]
    assert yaw["source"] == "differentiated yaw" and yaw["samples"] == 161
    # measured on the calibrated default ground: gain 1.001, T 0.513 s (the drive's 0.34 s dead time
    # is in it), rms 0.053 rad/s
    assert 0.7 < yaw["gain"] < 1.3 and 0.3 < yaw["time_constant_s"] < 0.8 and yaw["rms_error_radps"] < 0.1
    snippet = yaml.safe_load(
        printed[printed.index("scenario parameters:") :].split("\n", 1)[1].split("wrote")[0]
    )
    spec = YawResponseSpec(**snippet["robot"]["yaw_response"])
    assert spec.gain == pytest.approx(yaw["gain"], rel=1e-3)
    assert spec.time_constant_s == pytest.approx(yaw["time_constant_s"], rel=1e-3)
    assert snippet["friction"] == {"ground": 0.6}


def test_twist_and_differentiated_yaw_agree(drive_csv: tuple[Path, np.ndarray]) -> None:
    """The same simulated drive with its body yaw rate recorded as odometry twist: the fit uses the
    twist, and finds what the differentiated yaw found."""
    from husky_sim.realcheck.replay import load_recording

    path, yaw_rates = drive_csv
    from_yaw = load_recording(path)
    with_twist = make_recording(
        "twist", "ros1", from_yaw.cmd_t_s, from_yaw.commands, from_yaw.pose_t_s, from_yaw.poses, yaw_rates
    )
    a, b = fit_recording_yaw(from_yaw), fit_recording_yaw(with_twist)
    assert (a.source, b.source) == ("differentiated yaw", "odometry twist")
    assert b.response.gain == pytest.approx(a.response.gain, abs=0.05)
    assert math.isclose(b.response.time_constant_s, a.response.time_constant_s, abs_tol=0.05)
