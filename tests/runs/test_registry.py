"""A controller is added through the registry alone: this test registers a small one of its own (a
proportional go-to-goal law that brakes short of obstacles, no NLP) and runs it through `run`,
the suite and `check`, with no other file changed; then the registry's own rules."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence

import numpy as np
import pytest

from controllers import ControlResult, NMPCConfig, Obstacle, Reference, registry
from controllers.obstacles import surface_distance
from controllers.registry import ControllerEntry, ControllerInputs, PlanProfile
from husky_sim.realcheck.check import CheckOptions, run_check
from husky_sim.runs.run import run_scenario, run_scenario_kinematic
from husky_sim.runs.scenario import load_scenario
from husky_sim.study.suite import matrix, run_suite

NAME = "go-to-goal"


@dataclasses.dataclass(frozen=True)
class GoToGoalConfig:
    """The law's gains, and the NMPC settings the scenario gave (their speed bounds, tau, N)."""

    nmpc: NMPCConfig
    robot_radius_m: float
    speed_gain: float = 0.8  # (1/s) on the distance to the goal
    turn_gain: float = 1.5  # (1/s) on the bearing error
    stop_clearance_m: float = 0.3  # brake when the nearest obstacle is closer than this


class GoToGoal:
    """Drive towards the reference's position, turn towards it, stop near an obstacle ahead."""

    def __init__(self, config: GoToGoalConfig) -> None:
        self.config = config

    def reset(self) -> None:
        pass

    def solve(
        self, state: np.ndarray, reference: Reference, obstacles: Sequence[Obstacle], t: float
    ) -> ControlResult:
        c, n = self.config, self.config.nmpc.horizon
        goal = reference.state_at(t)
        dx, dy = goal[0] - state[0], goal[1] - state[1]
        bearing = math.atan2(math.sin(math.atan2(dy, dx) - state[2]), math.cos(math.atan2(dy, dx) - state[2]))
        v = min(c.speed_gain * math.hypot(dx, dy), c.nmpc.v_max_mps) * max(math.cos(bearing), 0.0)
        omega = float(np.clip(c.turn_gain * bearing, -c.nmpc.omega_max_radps, c.nmpc.omega_max_radps))
        clearances = [surface_distance(state[:2], o) - c.robot_radius_m for o in obstacles]
        if clearances and min(clearances) < c.stop_clearance_m:
            return ControlResult.brake(n, len(obstacles), 0, 0.0, "an obstacle within the stop clearance")
        plan = np.tile(state, (n + 1, 1))
        return ControlResult(
            control=np.array([v, omega]),
            predicted_states=plan,
            predicted_controls=np.tile([v, omega], (n, 1)),
            clf_slack=np.zeros(n),
            decay_slack=np.ones(n),
            predicted_barrier=np.full((len(obstacles), n + 1), np.nan),
            safety_active=0,
            status="proportional law",
            success=True,
            fallback="none",
            iterations=-1,
            solve_time_s=0.0,
            obstacles_considered=len(obstacles),
            obstacles_ignored=0,
        )


def _configure(inputs: ControllerInputs) -> GoToGoalConfig:
    return GoToGoalConfig(inputs.nmpc, inputs.nmpc.robot_radius_m)


ENTRY = ControllerEntry(
    NAME,
    "a test's proportional go-to-goal law",
    configure=_configure,
    build=GoToGoal,
    profile=lambda config: PlanProfile(config.nmpc, config.nmpc.omega_max_radps),
    decay_rate=False,
)


@pytest.fixture
def go_to_goal() -> Iterator[ControllerEntry]:
    registry.register(ENTRY)
    yield ENTRY
    registry.unregister(NAME)


def test_a_controller_registered_alone_runs_through_run_suite_and_check(go_to_goal, tmp_path) -> None:
    """narrow_gap: the law drives at the gap and brakes before it; what matters here is that every
    tool takes it by name, and that its runs are its own (not another controller's)."""
    assert NAME in registry.names()
    summary = run_scenario("narrow_gap", NAME, out_dir=tmp_path / "run")
    assert summary.settings.controller == NAME and summary.metrics.steps > 0
    assert summary.metrics.solver_fallbacks == 0 and summary.settings.gamma is not None
    assert (tmp_path / "run" / "log.csv").is_file()

    cells = matrix(["narrow_gap"], [NAME], [5], gammas=(0.1, 0.3))
    assert len(cells) == 1  # no decay rate: one cell, not one per gamma
    rows = run_suite(cells, jobs=1, out_dir=tmp_path / "suite", progress=False)
    assert rows[0]["controller"] == NAME and rows[0]["outcome"] != "error", rows[0]

    report = run_check(
        load_scenario("narrow_gap"),
        CheckOptions(controller=NAME, samples=2, jobs=1, timing_solves=5),
        tmp_path / "check",
    )
    assert report.controller == NAME and len(report.results) == 2
    assert (tmp_path / "check" / "check.md").is_file()
    assert {f.check for f in report.findings} >= {"robot radius", "velocity limits", "timing"}


def test_the_kinematic_loop_and_the_cli_name_only_what_is_registered(go_to_goal) -> None:
    """The kinematic loop is the paper's unicycle setting: it runs the paper's controllers only,
    and says which; an unknown name is one line naming the registered ones."""
    with pytest.raises(ValueError, match=r"the kinematic loop runs the paper's \(none, bt, cbf, relax-cbf\)"):
        run_scenario_kinematic("narrow_gap", NAME)
    with pytest.raises(ValueError, match=rf"controller: must be one of .*{NAME}.*, got 'nope'"):
        registry.entry("nope")
    from husky_sim.cli import build_parser

    args = build_parser().parse_args(["run", "narrow_gap", "--controller", NAME])
    assert args.controller == NAME


def test_a_name_is_registered_once() -> None:
    with pytest.raises(ValueError, match="'cbf' is registered already"):
        registry.register(dataclasses.replace(ENTRY, name="cbf"))
    with pytest.raises(ValueError, match="a name of letters"):
        registry.register(dataclasses.replace(ENTRY, name="go to goal"))
    assert NAME not in registry.names()


def test_built_in_entries_say_what_the_tools_ask_of_them() -> None:
    """The paper's four and husky-cbf, with the flags the suite, the figures and the audit read."""
    assert registry.names() == ("none", "bt", "cbf", "relax-cbf", "husky-cbf")
    assert registry.paper_names(with_baseline=False) == ("bt", "cbf", "relax-cbf")
    assert [registry.entry(n).decay_rate for n in ("none", "bt", "cbf")] == [False, False, True]
    assert [n for n in registry.names() if registry.entry(n).decay_slack] == ["relax-cbf", "husky-cbf"]
    sc = load_scenario("head_on_moving_obstacle")
    paper, ours = sc.plan_profile("relax-cbf"), sc.plan_profile("husky-cbf")
    assert paper.body is None and paper.planned_accel is None
    assert ours.body is not None and ours.body.count >= 2 and ours.planned_accel is not None
