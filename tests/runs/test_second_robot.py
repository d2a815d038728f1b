"""The robot is data: a second robot folder (assets/jackal_j100/, a Clearpath Jackal J100 from its
published description) runs through `run` and the suite with `robot.model: jackal_j100` in a
scenario, on its own URDF, drive limits, ground and identified yaw response, with no code of its
own; and a scenario cannot mix one robot's ground or payload with another."""

from __future__ import annotations

from pathlib import Path

import pytest

from husky_sim.runs.run import run_scenario
from husky_sim.runs.run_folder import read_summary, read_trace
from husky_sim.runs.scenario import ScenarioError, load_scenario, scenario_from_data
from husky_sim.scenario_file import scenario_yaml
from husky_sim.sim.robot_description import load_robot, robot_names
from husky_sim.study.suite import Cell, run_suite

JACKAL = "jackal_j100"


def _jackal_scenario_data() -> dict:
    """narrow_gap for the Jackal: its own model and ground, the rest of the file unchanged."""
    data = load_scenario("narrow_gap").model_dump(mode="json", exclude_none=True)
    data["robot"]["model"] = JACKAL
    return data


def test_robot_folders_are_what_the_scenarios_may_name() -> None:
    assert {"husky_a200", JACKAL} <= set(robot_names())
    husky, jackal = load_robot("husky_a200"), load_robot(JACKAL)
    assert jackal.geometry.track_width_m < husky.geometry.track_width_m  # a smaller robot
    assert jackal.specs.spec_sheet.mass_kg < husky.specs.spec_sheet.mass_kg
    sc = scenario_from_data(_jackal_scenario_data(), "test")
    drive = sc.drive_config()
    published = jackal.specs.ros1_diff_drive
    assert drive.max_linear_mps == published.linear_max_velocity_mps
    assert drive.wheel_separation_multiplier == published.wheel_separation_multiplier
    assert sc.ground_config().name == jackal.default_ground
    assert sc.robot.radius() == pytest.approx(jackal.geometry.footprint_radius_m + sc.robot.radius_margin_m)


def test_a_scenario_cannot_give_a_robot_another_robots_ground_or_payload() -> None:
    data = _jackal_scenario_data()
    with pytest.raises(ScenarioError, match=r"unknown ground 'wet_grass' \(shipped: "):
        scenario_from_data({**data, "ground": "wet_grass"}, "test")  # the Husky's ground
    heavy = {**data, "robot": {**data["robot"], "payload_kg": 50.0}}
    with pytest.raises(ScenarioError, match=r"robot: payload_kg: at most \d+ kg on a Clearpath Jackal"):
        scenario_from_data(heavy, "test")
    with pytest.raises(ScenarioError, match=r"robot.model: must name a robot folder under assets/"):
        scenario_from_data({**data, "robot": {**data["robot"], "model": "nope"}}, "test")


@pytest.mark.physics
def test_the_second_robot_runs_through_run_and_the_suite(tmp_path: Path) -> None:
    """Its run drives its own body (the trace's footprint is its URDF's), and the suite takes the
    same file as any scenario."""
    path = tmp_path / "narrow_gap_jackal.yaml"
    path.write_text(scenario_yaml(_jackal_scenario_data()))
    summary = run_scenario(str(path), "husky-cbf", out_dir=tmp_path / "run")
    assert summary.settings.robot == JACKAL and summary.metrics.steps > 0
    assert read_summary(tmp_path / "run")["robot"] == JACKAL
    footprint = read_trace(tmp_path / "run").footprint_radius_m
    assert footprint == pytest.approx(load_robot(JACKAL).geometry.footprint_radius_m)
    assert footprint < load_robot("husky_a200").geometry.footprint_radius_m

    (row,) = run_suite([Cell(str(path), "relax-cbf", 5, None)], jobs=1, out_dir=tmp_path / "suite")
    assert row["robot"] == JACKAL and row["outcome"] != "error", row
