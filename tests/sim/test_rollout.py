"""The one closed loop (husky_sim.sim.rollout) on the kinematic plant with a scripted controller:
the rows it logs, deadline mode, the monitor's stop, and an interrupt mid-run. No physics and no
solver, so these are pure tests; the NMPC in both plants is covered by the episode and kinematic
tests."""

from __future__ import annotations

import math
import signal

import numpy as np
import pytest

from controllers import ControlResult, Obstacle, SetPoint
from husky_sim.interrupts import RunInterrupted
from husky_sim.sim.kinematic import KinematicEnvironment, run_kinematic
from husky_sim.sim.outcomes import OutcomeMonitor, Outcomes
from husky_sim.sim.rollout import control_steps, rollout
from husky_sim.sim.step_log import LOG_COLUMNS, StepLog

TAU_S = 0.1


class Scripted:
    """A controller that plays a list of commands (then stops), each with a stated solve time; it
    raises `raise_at` (an exception) at that step instead, as a signal handler would."""

    def __init__(self, commands: list[tuple[float, float]], solve_s: list[float] | None = None) -> None:
        self.commands, self.solve_s = commands, solve_s or [0.001] * len(commands)
        self.raise_at: tuple[int, BaseException] | None = None
        self.k = 0

    def reset(self) -> None:
        self.k = 0

    def solve(self, state, reference, obstacles, t) -> ControlResult:  # noqa: ANN001
        if self.raise_at is not None and self.k == self.raise_at[0]:
            raise self.raise_at[1]
        k = min(self.k, len(self.commands) - 1)
        self.k += 1
        result = ControlResult.brake(3, len(obstacles), 0, self.solve_s[k], "scripted")
        result.control, result.fallback = np.array(self.commands[k], dtype=float), "none"
        return result


def test_a_rollout_logs_every_column_and_holds_a_late_command_in_deadline_mode() -> None:
    plant = KinematicEnvironment((0.0, 0.0, 0.0), [Obstacle(3.0, 0.0, 0.5)], TAU_S, robot_radius_m=0.3)
    controller = Scripted([(1.0, 0.0), (0.5, 0.2), (0.0, 0.0)], solve_s=[0.01, 0.5, 0.01])
    monitor = OutcomeMonitor(SetPoint(5.0, 0.0, 0.0), Outcomes(), TAU_S)
    record = rollout(plant, controller, SetPoint(5.0, 0.0, 0.0), monitor, 3, TAU_S, deadline_mode=True)
    assert [set(r) for r in record.rows] == [set(LOG_COLUMNS)] * 3
    assert [r["v_cmd_mps"] for r in record.rows] == [1.0, 1.0, 0.0]  # step 1's solve took > tau
    assert [r["deadline_miss"] for r in record.rows] == [0, 1, 0]
    assert record.rows[1]["x_m"] == pytest.approx(0.1)  # the unicycle followed 1 m/s for 0.1 s
    assert record.rows[0]["clearance_m"] == pytest.approx(3.0 - 0.1 - 0.5 - 0.3)
    assert record.final_pose[0] == pytest.approx(0.2) and record.interrupted_by is None


def test_the_log_on_disk_has_the_rows_of_the_rollout(tmp_path) -> None:  # noqa: ANN001
    import csv

    log = StepLog(tmp_path / "log.csv")
    plant = KinematicEnvironment((0.0, 0.0, 0.0), [], TAU_S, robot_radius_m=0.3)
    goal = SetPoint(5.0, 0.0, 0.0)
    record = rollout(
        plant, Scripted([(0.4, 0.1)]), goal, OutcomeMonitor(goal, Outcomes(), TAU_S), 4, TAU_S, log=log
    )
    log.close()
    with (tmp_path / "log.csv").open() as f:
        logged = list(csv.DictReader(f))
    assert [float(r["x_m"]) for r in logged] == pytest.approx([r["x_m"] for r in record.rows], abs=1e-9)
    assert logged[0]["wheel_l1_radps"] == "nan"  # the unicycle has no wheels


def test_the_monitor_ends_the_loop_once_the_goal_is_held() -> None:
    goal = SetPoint(0.0, 0.0, 0.0)
    plant = KinematicEnvironment((0.05, 0.0, 0.0), [], TAU_S, robot_radius_m=0.3)
    monitor = OutcomeMonitor(goal, Outcomes(goal_hold_s=0.3), TAU_S)
    record = rollout(plant, Scripted([(0.0, 0.0)]), goal, monitor, 50, TAU_S)
    assert len(record.rows) == 3 and monitor.outcome == "reached" and monitor.reached_at == pytest.approx(0.1)


@pytest.mark.parametrize("error", [RunInterrupted(signal.SIGTERM), KeyboardInterrupt()])
def test_an_interrupt_keeps_the_steps_so_far_and_names_the_outcome(error: BaseException) -> None:
    goal = SetPoint(5.0, 0.0, 0.0)
    controller = Scripted([(1.0, 0.0)])
    controller.raise_at = (4, error)
    plant = KinematicEnvironment((0.0, 0.0, 0.0), [], TAU_S, robot_radius_m=0.3)
    monitor = OutcomeMonitor(goal, Outcomes(), TAU_S)
    record = rollout(plant, controller, goal, monitor, 10, TAU_S)
    assert len(record.rows) == 4 and monitor.outcome == "interrupted"
    assert record.interrupted_by == (signal.SIGTERM if isinstance(error, RunInterrupted) else signal.SIGINT)
    controller.raise_at = (2, error)
    with pytest.raises(RunInterrupted):  # a kinematic run has no folder: the signal goes on up
        run_kinematic(controller, (0.0, 0.0, 0.0), goal, [], TAU_S, 1.0, 0.3)


def test_the_kinematic_loop_runs_on_after_a_collision_and_calls_touching_contact() -> None:
    wall = [Obstacle(0.5, 0.0, 0.1)]
    through = run_kinematic(
        Scripted([(1.0, 0.0)]), (0.0, 0.0, 0.0), SetPoint(2.0, 0.0, 0.0), wall, TAU_S, 1.0, 0.2
    )
    assert through.outcome == "collided" and len(through.controls) == control_steps(1.0, TAU_S)
    # stopping 1e-7 m inside the circle model's boundary is contact at the solver's tolerance
    stop_x = 0.5 - 0.1 - 0.2 + 1e-7
    touch = run_kinematic(
        Scripted([(stop_x / TAU_S, 0.0), (0.0, 0.0)]),
        (0.0, 0.0, 0.0),
        SetPoint(2.0, 0.0, 0.0),
        wall,
        TAU_S,
        3.0,
        0.2,
    )
    assert touch.min_clearance_m < 0.0 and touch.outcome == "stuck"  # idle at the end, away from the goal


def test_control_steps_counts_the_steps_that_start_before_the_end() -> None:
    assert control_steps(20.0, 0.1) == 200 and control_steps(1.05, 0.1) == 11 and control_steps(0.1, 0.2) == 1
    assert math.isclose(control_steps(30.0, 0.2) * 0.2, 30.0)
