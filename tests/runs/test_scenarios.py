"""Scenario files: every shipped file validates and builds; bad input is one line naming the field;
the command line writes the documented summary."""

import json
import math
from pathlib import Path

import pytest
import yaml

from controllers import NMPCConfig
from controllers.husky_cbf.config import MoverConfig, PlannerConfig, RecoveryConfig
from husky_sim.cli import main
from husky_sim.runs.scenario import ScenarioError, load_scenario, scenario_from_data, shipped_scenarios
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.ground import DEFAULT_GROUND, load_ground
from husky_sim.sim.outcomes import Outcomes
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.world import WorldConfig

SUMMARY_KEYS = {
    "scenario",
    "controller",
    "horizon",
    "gamma",
    "outcome",
    "collided",
    "min_clearance_m",
    "converged",
    "final_position_error_m",
    "tracking_rmse_m",
    "time_to_goal_s",
    "solve_ms_median",
    "solve_ms_p95",
    "solve_ms_max",
    "fallbacks",
    "deadline_misses",
    "safety_active_steps",
    "sim_time_s",
    "wall_time_s",
}


def test_required_scenarios_are_shipped() -> None:
    names = {p.stem for p in shipped_scenarios()}
    assert {
        "paper_point_stabilisation",
        "paper_dynamic_tracking",
        "paper_dynamic_tracking_crossing",
        "husky_point_stabilisation",
        "husky_circle_tracking",
        "head_on_moving_obstacle",
        "narrow_gap",
        "dense_random_field",
    } <= names


@pytest.mark.parametrize("path", shipped_scenarios(), ids=lambda p: p.stem)
def test_shipped_scenarios_build(path: Path) -> None:
    sc = load_scenario(str(path))
    assert sc.name == path.stem
    cfg = sc.controller_config("relax-cbf")
    episode = sc.episode_config()
    assert cfg.tau_s == episode.tau_s and cfg.robot_radius_m > 0.57  # footprint-based circle
    assert len(episode.world.obstacles) == cfg.obstacle_slots


def test_paper_parameters_are_as_printed() -> None:
    ps = load_scenario("paper_point_stabilisation")
    assert (ps.robot.start.x_m, ps.robot.start.y_m) == (0.0, 0.0)
    assert math.isclose(ps.robot.start.yaw_rad, math.pi / 2, abs_tol=1e-6)
    assert (ps.reference.goal.x_m, ps.reference.goal.y_m) == (0.0, 10.0)
    assert (ps.obstacles[0].x_m, ps.obstacles[0].y_m, ps.obstacles[0].radius_m) == (0.1, 4.7, 0.6)
    tracking = load_scenario("paper_dynamic_tracking")
    walker = tracking.obstacle_specs()[3]  # (-8, 10, -0.78, 0.63, 0.25)
    assert (walker.vx_mps, walker.vy_mps) == pytest.approx((0.63 * math.cos(-0.78), 0.63 * math.sin(-0.78)))
    husky = load_scenario("husky_point_stabilisation").controller_config("cbf")
    assert (husky.tau_s, husky.horizon, husky.alpha, husky.clf_slack_weight) == (0.2, 5, 0.2, 100.0)
    assert load_scenario("husky_circle_tracking").controller.horizon == 7


def test_random_field_is_seeded() -> None:
    a = load_scenario("dense_random_field").obstacle_specs()
    b = load_scenario("dense_random_field").obstacle_specs()
    assert a == b and len(a) == 12


def _write(tmp_path: Path, data: dict) -> str:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


BASE = {
    "name": "t",
    "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_margin_m": 0.1},
    "reference": {"goal": {"x_m": 5.0, "y_m": 0.0}},
}


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"tau_s": -0.1}, "tau_s"),
        ({"colour": "red"}, "colour"),
        ({"controller": {"horizon": 0}}, "controller.horizon"),
        ({"controller": {"gamma": 1.5}}, "controller.gamma"),
        ({"obstacles": [{"x_m": 1.0, "y_m": 1.0, "radius_m": -0.3}]}, "obstacles.0.radius_m"),
        ({"obstacles": [{"x_m": 5.2, "y_m": 0.0, "radius_m": 0.3}]}, "reference.goal"),
        ({"obstacles": [{"x_m": 0.3, "y_m": 0.0, "radius_m": 0.3}]}, "robot.start"),
        ({"reference": {}}, "reference"),
        ({"sensing": {"latency_steps": -1}}, "sensing.latency_steps"),
        (
            {"robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_margin_m": 0.1, "payload_kg": 90}},
            "payload_kg",
        ),
    ],
)
def test_bad_scenarios_give_one_line_naming_the_field(tmp_path: Path, change: dict, field: str) -> None:
    with pytest.raises(ScenarioError) as exc:
        load_scenario(_write(tmp_path, {**BASE, **change}))
    message = str(exc.value)
    assert "\n" not in message and field in message


@pytest.mark.physics
def test_run_writes_summary_and_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code = main(
        ["run", "head_on_moving_obstacle", "--controller", "cbf", "--horizon", "7", "--out", str(out)]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary.keys() >= SUMMARY_KEYS
    assert summary["controller"] == "cbf" and summary["horizon"] == 7 and summary["gamma"] == 0.2
    assert (out / "log.csv").read_text().count("\n") == summary["steps"] + 1
    assert "head_on_moving_obstacle cbf N=7" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "no_such_scenario"],
        ["run", "narrow_gap", "--horizon", "0"],
        ["run", "narrow_gap", "--gamma", "2"],
    ],
)
def test_run_bad_input_exits_2_with_one_line(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and "error" in err[-1]


def test_scenarios_lists_every_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(shipped_scenarios())


def test_an_omitted_setting_takes_the_run_time_default() -> None:
    """Each default exists once, in the run-time dataclass: a scenario that gives only what it must
    resolves to exactly the defaults of NMPCConfig, EpisodeConfig, SensingConfig and Outcomes."""
    data = {
        "name": "minimal",
        "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_m": 0.6},
        "reference": {"goal": {"x_m": 5.0, "y_m": 0.0}},
    }
    sc = scenario_from_data(data, "test")
    assert sc.controller_config("cbf") == NMPCConfig(safety="cbf", robot_radius_m=0.6, obstacle_slots=1)
    episode = sc.episode_config()
    assert (episode.tau_s, episode.duration_s) == (EpisodeConfig.tau_s, EpisodeConfig.duration_s)
    assert episode.sensing == SensingConfig() and episode.outcomes == Outcomes()
    assert episode.ground == load_ground(DEFAULT_GROUND)
    assert (episode.world.physics_hz, episode.world.ground_friction) == (
        WorldConfig.physics_hz,
        episode.ground.tyre.friction,
    )


def test_a_scenario_sets_husky_cbfs_own_settings_within_their_ranges() -> None:
    """`controller.husky_cbf` reaches husky-cbf's config (nested planner and recovery included);
    what it omits keeps the config's default; a value outside the config's range, or a name the
    config lacks, is one line naming it."""
    data = {
        "name": "settings",
        "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_m": 0.6},
        "reference": {"goal": {"x_m": 5.0, "y_m": 0.0}},
        "obstacles": [{"x_m": 2.5, "y_m": 2.0, "radius_m": 0.3}],
        "controller": {
            "husky_cbf": {
                "margin_m": 0.2,
                "terminal_weight": [1.0, 2.0, 3.0],
                "planner": {"lookahead_m": 2.0},
                "recovery": {"enabled": False, "idle_s": 1.0},
            }
        },
    }
    config = scenario_from_data(data, "test").controller_config("husky-cbf")
    assert (config.margin_m, config.terminal_weight) == (0.2, (1.0, 2.0, 3.0))
    assert config.planner.lookahead_m == 2.0 and config.planner == PlannerConfig(lookahead_m=2.0)
    assert config.recovery == RecoveryConfig(enabled=False, idle_s=1.0)
    assert config.movers == MoverConfig()  # omitted: the defaults
    for settings, needle in (
        ({"margin_m": 3.0}, "controller.husky_cbf.margin_m: must be a finite number in [0, 2] m"),
        ({"slots": 0}, "controller.husky_cbf.slots: must be an integer in [1, 64]"),
        ({"planner": {"lookahead": 2.0}}, "controller.husky_cbf.planner.lookahead"),
        ({"recovery": {"enabled": 1}}, "controller.husky_cbf.recovery.enabled"),
        ({"guidance": {"lookahead_m": 2.0}}, "controller.husky_cbf.guidance"),
    ):
        data["controller"]["husky_cbf"] = settings
        with pytest.raises(ScenarioError) as exc:
            scenario_from_data(data, "test")
        assert needle in str(exc.value) and "\n" not in str(exc.value)
