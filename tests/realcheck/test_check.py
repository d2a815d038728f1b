"""`husky-sim check`: configuration audit, seeded robustness sweep (local processes and Dask),
reproducible failing samples, verdict and exit codes. Real PyBullet and real IPOPT throughout;
durations are shortened so the file runs in about a minute."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controllers import Obstacle
from husky_sim.cli import main
from husky_sim.realcheck.audit import (
    AuditThresholds,
    audit,
    check_robot_radius,
    check_timing,
    measure_solve_times,
)
from husky_sim.realcheck.check import CheckOptions, sweep_stats, verdict
from husky_sim.realcheck.steerability import CAN_PIVOT_RADPS, failure_class, steerability
from husky_sim.realcheck.sweep import (
    WALL_CLOCK_KEYS,
    PerturbationRanges,
    SampleTask,
    apply_perturbation,
    nominal_current_a,
    run_tasks,
    sample_perturbations,
)
from husky_sim.runs.run import run_scenario
from husky_sim.runs.scenario import Scenario, load_scenario
from husky_sim.sim.geometry import load_geometry
from husky_sim.sim.ground import load_ground
from husky_sim.sim.robot_description import load_robot
from husky_sim.sim.sensing import SensingConfig, Sensor
from husky_sim.sim.tyre import stiffness_ratio_for_yaw_ratio

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)


def _modified(scenario: Scenario, **changes: Any) -> Scenario:
    """A validated copy with nested fields changed: _modified(sc, robot={"radius_m": 0.25})."""
    data = scenario.model_dump()
    for key, value in changes.items():
        if isinstance(value, dict):
            data[key].update(value)
        else:
            data[key] = value
    return Scenario.model_validate(data)


def _without_wall_clock(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in r.items() if k not in WALL_CLOCK_KEYS} for r in results]


#: The check's default ranges with the payload decided for the Husky (0 to its 20 kg all-terrain
#: payload).
HUSKY_RANGES = PerturbationRanges().for_robot(load_robot())


def _short_moving_scenario(duration_s: float = 2.5) -> Scenario:
    """The shipped head-on scenario (a moving obstacle, so every perturbation acts), shortened."""
    return load_scenario("head_on_moving_obstacle").model_copy(update={"duration_s": duration_s})


# -- audit ------------------------------------------------------------------------------------
def test_audit_fails_the_papers_radius_and_passes_a_sane_one() -> None:
    shipped = load_scenario("paper_point_stabilisation")
    footprint = load_geometry().footprint_radius_m
    assert footprint == pytest.approx(0.570, abs=1e-3)
    t = AuditThresholds()

    paper = _modified(shipped, robot={"radius_m": 0.25, "radius_margin_m": None})
    finding = check_robot_radius(paper, t)
    assert finding.status == "fail"
    assert finding.values["robot_radius_m"] == 0.25
    assert finding.values["margin_m"] == pytest.approx(0.25 - footprint)

    sane = _modified(shipped, robot={"radius_m": None, "radius_margin_m": 0.1})
    assert check_robot_radius(sane, t).status == "pass"
    # the margin must also cover the sensing noise: 3 sigma of 5 cm pose + 5 cm obstacle noise > 0.1 m
    noisy = _modified(sane, sensing={"pose_xy_std_m": 0.05, "obstacle_xy_std_m": 0.05})
    assert check_robot_radius(noisy, t).status == "warn"

    # the whole audit of the sane set-up (solve times well inside tau) has no failure; the
    # paper's radius fails it, and the verdict names the reason
    fast = [0.004] * 100
    assert all(f.status != "fail" for f in audit(sane, fast))
    findings = audit(paper, fast)
    assert [f.check for f in findings if f.status == "fail"] == ["robot radius"]
    nominal = {"passed": True, "outcome": "reached"}
    one_pass = {
        "index": 0,
        "passed": True,
        "collided": False,
        "outcome": "reached",
        "min_clearance_m": 0.4,
        "steerability": {"turn_in_place_radps": 1.0, "current_headroom_a": 15.0},  # an unloaded robot
    }
    stats, samples = sweep_stats([one_pass]), sample_perturbations(HUSKY_RANGES, 1, 0)
    decision, reason = verdict(findings, nominal, stats, samples, 0.9)
    assert decision == "FAIL" and "robot radius" in reason
    assert verdict(audit(sane, fast), nominal, stats, samples, 0.9)[0] == "PASS"
    # a colliding sample fails the verdict even at a 0 % required pass rate
    collided = sweep_stats([{**one_pass, "passed": False, "collided": True, "outcome": "collided"}])
    assert verdict(audit(sane, fast), nominal, collided, samples, 0.0)[0] == "FAIL"


def test_audit_flags_velocity_bounds_beyond_the_husky() -> None:
    sc = _modified(load_scenario("paper_point_stabilisation"), controller={"v_max_mps": 2.0})
    by_check = {f.check: f for f in audit(sc, [0.004] * 10)}
    assert by_check["velocity limits"].status == "fail"
    assert by_check["acceleration"].values["implied_linear_accel_mps2"] == pytest.approx(3.0 / sc.tau_s)


def test_audit_judges_husky_cbf_by_its_own_body_and_model() -> None:
    """husky-cbf has no robot circle and plans its accelerations and braking: the audit checks its
    discs, its bounds against the drive's, and only the latency and dead time beyond its plan."""
    sc = load_scenario("husky_point_stabilisation")
    fast = [0.004] * 10
    by_check = {f.check: f for f in audit(sc, fast, controller="husky-cbf")}
    paper = {f.check: f for f in audit(sc, fast)}
    assert (
        paper["acceleration"].status == "warn"
        and "no acceleration constraint" in paper["acceleration"].detail
    )
    assert by_check["acceleration"].status == "pass"
    assert (
        by_check["acceleration"].values["planned_linear_accel_mps2"]
        == sc.drive.config().max_linear_accel_mps2
    )
    body = by_check["robot radius"]
    assert body.status == "pass" and body.values["discs"] == 3 and "discs" in body.detail
    # husky-cbf commands up to the drive's 2 rad/s: more than Clearpath's ROS 2 driver allows
    assert by_check["velocity limits"].values["omega_max_radps"] == 2.0
    assert by_check["velocity limits"].status == "warn" and "ROS 2" in by_check["velocity limits"].detail
    assert by_check["stopping distance"].status == "pass"
    # told of a latency, it plans over it: 1 m/s x 0.2 s is within its plan, not beyond it
    late = _modified(sc, sensing={"latency_steps": 1})
    stopping = {f.check: f for f in audit(late, fast, controller="husky-cbf")}["stopping distance"]
    assert stopping.status == "pass" and stopping.values["unplanned_overrun_m"] == pytest.approx(0.0)
    assert stopping.values["planned_latency_m"] == pytest.approx(0.2)
    # the paper's controllers are not told: the same 0.2 m counts against their margin
    paper_late = {f.check: f for f in audit(late, fast)}["stopping distance"]
    assert paper_late.values["latency_m"] == pytest.approx(0.2)
    assert paper_late.values["unplanned_overrun_m"] > stopping.values["unplanned_overrun_m"] + 0.2 - 1e-9
    noisy = _modified(sc, sensing={"pose_xy_std_m": 0.05, "obstacle_xy_std_m": 0.05})
    assert {f.check: f for f in audit(noisy, fast, controller="husky-cbf")}["robot radius"].status == "warn"
    # told no dead time on a ground whose drive has 0.343 s: 0.343 m beyond its plan at 1 m/s
    untold = _modified(sc, robot={"yaw_response": {"gain": 0.85, "time_constant_s": 0.11}})
    stopping = {f.check: f for f in audit(untold, fast, controller="husky-cbf")}["stopping distance"]
    assert stopping.status == "warn" and stopping.values["unplanned_overrun_m"] == pytest.approx(0.343)


def test_the_stopping_distance_counts_the_grounds_drive_dead_time() -> None:
    """The calibrated default ground's drive acts 0.343 s after a command (the real Husky's): at
    1 m/s the paper's controllers, which plan an instant stop, overrun it by that much more than
    braking (1 / (2 x 3) m) and latency; on the uncalibrated ground, which answers at once, not."""
    fast = [0.004] * 10
    sc = load_scenario("paper_point_stabilisation")
    stopping = {f.check: f for f in audit(sc, fast)}["stopping distance"]
    assert stopping.values["dead_time_m"] == pytest.approx(0.343)
    assert stopping.values["unplanned_overrun_m"] == pytest.approx(0.343 + 1.0 / 6.0)
    assert stopping.status == "warn" and "dead time" in stopping.detail
    instant = _modified(sc, ground="pybullet_coulomb")
    stopping = {f.check: f for f in audit(instant, fast)}["stopping distance"]
    assert stopping.values["dead_time_m"] == 0.0 and stopping.status == "pass"


def test_timing_fails_when_tau_is_shorter_than_the_measured_solves() -> None:
    # a runnable scenario (2000 Hz physics, one physics step per control step) whose tau of 0.5 ms
    # is shorter than any IPOPT solve: the real measured p99 must exceed it
    shipped = load_scenario("paper_point_stabilisation")
    tight = _modified(shipped, tau_s=0.0005, physics_hz=2000.0, duration_s=5.0)
    tight.episode_config()  # the scenario itself is valid and could run
    times = measure_solve_times(tight, "cbf", solves=20)
    assert times.shape == (20,) and np.all(times > 0)
    finding = check_timing(tight.tau_s, times, AuditThresholds())
    assert finding.status == "fail", finding.detail
    assert finding.values["solve_p99_ms"] > finding.values["tau_ms"] == pytest.approx(0.5)

    # the rule itself, on the same measured times: tau far above them passes, tau just above warns
    p99 = float(np.percentile(times, 99))
    assert check_timing(10.0 * p99 + 1e-3, times, AuditThresholds()).status == "pass"
    assert check_timing(1.5 * p99, times, AuditThresholds()).status == "warn"


# -- sampling and perturbations ----------------------------------------------------------------
def test_sampling_is_deterministic_and_within_the_ranges() -> None:
    ranges = HUSKY_RANGES
    a, b = sample_perturbations(ranges, 20, 42), sample_perturbations(ranges, 20, 42)
    assert a == b
    assert sample_perturbations(ranges, 5, 42) == a[:5]  # K is a prefix: more samples extend the list
    assert sample_perturbations(ranges, 20, 43) != a
    assert len({p.episode_seed for p in a}) == 20
    for p in a:
        assert ranges.ground_friction[0] <= p.ground_friction <= ranges.ground_friction[1]
        assert 0.0 <= p.payload_kg <= load_robot().specs.spec_sheet.all_terrain_payload_kg
        assert 0.7 <= p.torque_scale <= 1.0 and 0.8 <= p.obstacle_velocity_scale <= 1.2
    assert {p.latency_steps for p in a} == {0, 1, 2}
    with pytest.raises(ValueError, match="samples"):
        sample_perturbations(ranges, 0, 42)
    with pytest.raises(ValueError, match="payload"):  # the payload is a robot's, decided first
        sample_perturbations(PerturbationRanges(), 1, 42)


@pytest.mark.parametrize("robot", ["husky_a200", "jackal_j100"])
def test_the_payload_range_is_the_robots(robot: str) -> None:
    """0 to the robot's all-terrain payload by default; a declared range above its maximum payload
    is refused in one line naming the flag and the robot's figure."""
    description = load_robot(robot)
    sheet = description.specs.spec_sheet
    assert PerturbationRanges().for_robot(description).payload_kg == (0.0, sheet.all_terrain_payload_kg)
    declared = PerturbationRanges(payload_kg=(0.0, sheet.max_payload_kg))
    assert declared.for_robot(description).payload_kg == (0.0, sheet.max_payload_kg)
    with pytest.raises(ValueError, match=rf"--payload-kg: at most {sheet.max_payload_kg:g} kg on a"):
        PerturbationRanges(payload_kg=(0.0, sheet.max_payload_kg + 1.0)).for_robot(description)


def test_a_perturbation_changes_only_its_fields() -> None:
    base = _short_moving_scenario()
    p = sample_perturbations(HUSKY_RANGES, 1, 3)[0]
    sc = apply_perturbation(base, p)
    assert sc.seed == p.episode_seed
    assert sc.friction.ground == p.ground_friction and sc.robot.payload_kg == p.payload_kg
    assert sc.drive.current_limit_a == pytest.approx(nominal_current_a(base) * p.torque_scale)
    assert sc.friction.lateral_stiffness_ratio == pytest.approx(
        stiffness_ratio_for_yaw_ratio(
            p.yaw_ratio, load_geometry(), load_ground(base.ground).tyre.rolling_radius_scale
        )
    )
    assert sc.sensing.latency_steps == p.latency_steps
    assert sc.sensing.obstacle_velocity_scale == p.obstacle_velocity_scale
    changed = {"name", "description", "seed", "friction", "robot", "drive", "sensing"}
    before, after = base.model_dump(), sc.model_dump()
    assert {k: v for k, v in before.items() if k not in changed} == {
        k: v for k, v in after.items() if k not in changed
    }
    assert after["robot"]["start"] == before["robot"]["start"]


def test_sensor_scales_the_reported_obstacle_velocity() -> None:
    obstacles = [Obstacle(1.0, 2.0, 0.3, 0.4, -0.2)]
    pose = np.zeros(3)
    exact = Sensor(SensingConfig(), 0).measure(pose, obstacles).obstacles[0]
    assert exact == obstacles[0]
    slow = Sensor(SensingConfig(obstacle_velocity_scale=0.5), 0).measure(pose, obstacles).obstacles[0]
    assert (slow.x_m, slow.y_m, slow.vx_mps, slow.vy_mps) == (1.0, 2.0, 0.2, -0.1)


# -- sweep backends and reproduction -------------------------------------------------------------
def test_sweep_gives_identical_results_on_local_processes_and_dask() -> None:
    pytest.importorskip("distributed")
    base = _short_moving_scenario()
    perturbations = sample_perturbations(HUSKY_RANGES, 3, 11)
    tasks = [
        SampleTask(p.index, apply_perturbation(base, p).model_dump(mode="json"), "relax-cbf")
        for p in perturbations
    ]
    local = run_tasks(tasks, "local", jobs=2)
    dask = run_tasks(tasks, "dask", jobs=2)
    assert [r["index"] for r in local] == [0, 1, 2]
    assert _without_wall_clock(local) == _without_wall_clock(dask)
    # the samples really differ, so the comparison is not between three copies of one run
    assert len({r["min_clearance_m"] for r in local}) == 3


def test_check_cli_writes_reports_and_a_failing_sample_reproduces(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 2.5 s is too short to reach the goal, so every sample fails (timeout) and is saved
    scenario_file = tmp_path / "short.yaml"
    import yaml

    scenario_file.write_text(yaml.safe_dump(_short_moving_scenario().model_dump(mode="json")))
    out = tmp_path / "check"
    argv = ["check", str(scenario_file), "--samples", "2", "--jobs", "1", "--timing-solves", "10"]
    rc = main([*argv, "--seed", "5", "--payload-kg", "10", "20", "--out", str(out)])
    printed = capsys.readouterr().out
    assert rc == 1
    assert "FAIL: the unperturbed scenario already fails (timeout)" in printed
    report = json.loads((out / "check.json").read_text())
    assert report["verdict"] == "FAIL" and report["stats"]["passed"] == 0
    assert [p["index"] for p in report["perturbations"]] == [0, 1]
    ranges = PerturbationRanges(payload_kg=(10.0, 20.0))  # the payload the robot will carry
    assert report["perturbations"] == [p.as_dict() for p in sample_perturbations(ranges, 2, 5)]
    assert report["ranges"]["payload_kg"] == [10.0, 20.0]
    assert all(10.0 <= p["payload_kg"] <= 20.0 for p in report["perturbations"])
    for name in ("check.md", "clearance_hist.png", "sensitivity.png", "pass_rate_by_payload.png"):
        assert (out / name).stat().st_size > 0
    text = (out / "check.md").read_text()
    assert "## Configuration audit" in text and "turn in place (rad/s)" in text
    # each sample's robot was probed: 10 to 20 kg turns in place (about 1 rad/s of 1 unloaded)
    for result in report["results"]:
        assert result["steerability"]["turn_in_place_radps"] > CAN_PIVOT_RADPS
        assert result["steerability"]["current_headroom_a"] > 0.0
    assert report["stats"]["failures_by_class"] == {"controller": 2}  # robots that could pivot

    # the saved sample reloads and `husky-sim run` gives the same result, to the last bit
    sample = report["results"][1]
    saved = out / "failures" / "sample_1.yaml"
    assert report["failure_files"]["1"] == str(saved)
    assert load_scenario(str(saved)).seed == report["perturbations"][1]["episode_seed"]
    assert main(["run", str(saved), "--controller", "relax-cbf", "--out", str(tmp_path / "rerun")]) == 0
    summary = json.loads((tmp_path / "rerun" / "summary.json").read_text())
    for key in ("outcome", "collided", "converged", "min_clearance_m", "final_position_error_m", "steps"):
        assert summary[key] == sample[key], key


def test_check_table_is_one_check_per_scenario_and_seed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`check-table` runs `check` for each seed (the same samples as `check --seed K`) and writes
    one row per scenario; a failed sample is shown with how it ended and whose failure it was."""
    import yaml

    scenario_file = tmp_path / "short.yaml"
    scenario_file.write_text(yaml.safe_dump(_short_moving_scenario().model_dump(mode="json")))
    out = tmp_path / "table"
    argv = ["check-table", str(scenario_file), "--samples", "1", "--seeds", "4", "5", "--jobs", "1"]
    assert main([*argv, "--timing-solves", "10", "--out", str(out)]) == 1  # 2.5 s: every sample times out
    table = json.loads((out / "check_table.json").read_text())
    assert [(c["scenario"], c["seed"]) for c in table["cells"]] == [(_short_moving_scenario().name, 4)] + [
        (_short_moving_scenario().name, 5)
    ]
    for cell in table["cells"]:
        report = json.loads((Path(cell["folder"]) / "check.json").read_text())
        assert report["seed"] == cell["seed"] and report["verdict"] == cell["verdict"] == "FAIL"
        assert cell["failures"] == {"timeout": 1} and cell["passed"] == 0
    text = (out / "check_table.md").read_text()
    assert "| seed 4 | seed 5 |" in text and text.count("FAIL 0/1 (1 timeout; controller 1)") == 2
    assert "0 of 2 checks PASS" in capsys.readouterr().out


def test_run_sample_matches_run_scenario_in_process() -> None:
    # the worker's result is what run_scenario gives for the perturbed scenario (no hidden state)
    base = _short_moving_scenario(1.5)
    p = sample_perturbations(HUSKY_RANGES, 1, 8)[0]
    sc = apply_perturbation(base, p)
    [result] = run_tasks([SampleTask(0, sc.model_dump(mode="json"), "bt")], "local", jobs=1)
    direct = run_scenario(sc, "bt").metrics
    assert result["min_clearance_m"] == direct.min_clearance_m
    assert result["outcome"] == direct.outcome


# -- bad input ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["check", "no_such_scenario"], "no_such_scenario"),
        (["check", "narrow_gap", "--samples", "0"], "samples"),
        (["check", "narrow_gap", "--jobs", "0"], "jobs"),
        (["check", "narrow_gap", "--scheduler", "tcp://127.0.0.1:8786"], "scheduler"),
        (["check", "narrow_gap", "--payload-kg", "0", "80"], "payload-kg"),  # above the Husky's 75 kg
        (["check", "narrow_gap", "--payload-kg", "30", "10"], "payload_kg"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(
    argv: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in captured.err
    assert captured.out == ""


def test_check_options_validate() -> None:
    with pytest.raises(ValueError, match="min_pass_rate"):
        CheckOptions(min_pass_rate=1.5)
    with pytest.raises(ValueError, match="backend"):
        CheckOptions(backend="ray")  # type: ignore[arg-type]


def test_a_failure_is_the_plants_when_its_robot_cannot_pivot() -> None:
    """The probe of a robot that turns in place is fine; 75 kg at a third of the current limit
    barely turns and has no current to spare: its failures are the plant's."""
    base = load_scenario("head_on_moving_obstacle")
    light = steerability(base)
    assert light["turn_in_place_radps"] > 0.8 and light["current_headroom_a"] > 5.0
    assert failure_class(light) == "controller"
    heavy = base.model_copy(
        update={
            "robot": base.robot.model_copy(update={"payload_kg": 75.0}),
            "drive": base.drive.model_copy(update={"current_limit_a": 9.0}),
        }
    )
    probe = steerability(heavy)
    assert probe["turn_in_place_radps"] < CAN_PIVOT_RADPS or probe["current_headroom_a"] <= 0.0
    assert failure_class(probe) == "plant"
