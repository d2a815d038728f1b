"""husky-cbf's recovery from a stall (controllers/husky_cbf/behaviours/recovery.py) on its own:
the progress checker's verdicts, the recovery's phases and waypoints, and the tabu spots the
planner goes round."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.husky_cbf.behaviours import recovery as rec
from controllers.husky_cbf.behaviours.recovery import ProgressChecker, Recovery
from controllers.husky_cbf.config import PlannerConfig, RecoveryConfig
from controllers.husky_cbf.movers import MoverModel
from controllers.husky_cbf.planner import Planner

TAU = 0.1
INFLATION = 0.48
MOVING = np.array([0.5, 0.0])  # a command that is not idle (m/s, rad/s)
IDLE = np.zeros(2)


def _no_path(xy: np.ndarray, goal: np.ndarray, extra: np.ndarray) -> None:
    return None


def test_the_progress_checker_names_idle_and_slow_stalls_and_leaves_progress_alone() -> None:
    config = RecoveryConfig()
    checker = ProgressChecker(config, TAU)
    for k in range(60):  # 6 s driving at the target at 0.5 m/s: progress
        assert checker.update(np.array([0.05 * k, 0.0]), 5.0 - 0.05 * k, idle=False) == ""
    checker.reset()
    verdicts = [checker.update(np.array([1.0, 0.0]), 2.0, idle=False) for _ in range(40)]
    window = round(config.progress_window_s / TAU)
    assert verdicts[:window] == [""] * window  # a full window first
    assert verdicts[window] == "slow"  # turning on the spot 3 s with nothing gained
    checker.reset()
    verdicts = [checker.update(np.array([1.0, 0.0]), 2.0, idle=True) for _ in range(6)]
    assert verdicts.index("idle") == checker.idle_steps - 1  # told to stand still for idle_s
    checker.reset()
    near = [checker.update(np.array([1.0, 0.0]), 0.5 * rec.NEAR_M, idle=True) for _ in range(40)]
    assert set(near) == {""}  # at the target the set-point approach owns the robot


def test_a_slow_stall_turns_to_the_way_then_drives_along_it() -> None:
    recovery = Recovery(RecoveryConfig(), TAU)
    target = np.array([-3.0, 0.0, math.pi])  # behind the robot
    pose = np.array([0.0, 0.0, 0.0])
    none = np.zeros((0, 3))
    waypoints = [recovery.waypoint(pose, target, MOVING, none, _no_path, 0.1 * k) for k in range(31)]
    assert waypoints[:-1] == [None] * 30 and recovery.phase == "turn" and recovery.started == 1
    turn = waypoints[-1]
    assert (turn.x_m, turn.y_m) == (0.0, 0.0) and abs(turn.heading_rad) == pytest.approx(math.pi)
    drive = recovery.waypoint(np.array([0.0, 0.0, math.pi]), target, MOVING, none, _no_path, 3.1)
    assert recovery.phase == "drive"
    assert (drive.x_m, drive.y_m) == pytest.approx((-rec.DRIVE_M, 0.0))
    assert recovery.waypoint(np.array([-0.95, 0.0, math.pi]), target, MOVING, none, _no_path, 5.0) is None
    assert recovery.phase == "" and not recovery.reversing


def test_a_robot_that_cannot_swing_round_where_it_stalled_first_moves_along_its_axis_to_room() -> None:
    """Beside an obstacle its corners would meet turning in place, recovery first drives along
    the robot's axis, the nearer way (here backwards), to just past where the body swings free;
    then it turns there. With nothing in the way, or a body that swings within its discs, it turns
    where it stands."""
    config, swing = RecoveryConfig(), 0.2
    target, pose = np.array([-3.0, 0.0, math.pi]), np.array([0.0, 0.0, 0.0])  # behind the robot
    beside = np.array([[0.2, 0.8, 0.65]])  # clear of the discs (0.8 m > 0.65 m), not of the swing

    def stall(recovery: Recovery, circles: np.ndarray) -> object:
        for k in range(round(config.progress_window_s / TAU) + 1):
            waypoint = recovery.waypoint(pose, target, MOVING, circles, _no_path, 0.1 * k)
        return waypoint

    recovery = Recovery(config, TAU, swing)
    room = stall(recovery, beside)
    assert recovery.phase == "room" and not recovery.reversing
    assert (room.x_m, room.y_m, room.heading_rad) == pytest.approx((-2 * rec.ARRIVE_M, 0.0, 0.0))
    turn = recovery.waypoint(np.array([room.x_m, 0.0, 0.0]), target, MOVING, beside, _no_path, 3.2)
    assert recovery.phase == "turn" and (turn.x_m, turn.y_m) == pytest.approx((room.x_m, 0.0))
    assert abs(turn.heading_rad) == pytest.approx(math.pi)
    for circles, swing_m in ((np.zeros((0, 3)), swing), (beside, 0.0)):
        free = Recovery(config, TAU, swing_m)
        stall(free, circles)
        assert free.phase == "turn"


def test_a_robot_told_to_stand_still_backs_up_first_where_there_is_room() -> None:
    config = RecoveryConfig()
    target = np.array([4.0, 0.0, 0.0])
    pose = np.array([0.0, 0.0, 0.0])
    recovery = Recovery(config, TAU)
    for k in range(recovery.checker.idle_steps):
        waypoint = recovery.waypoint(pose, target, IDLE, np.zeros((0, 3)), _no_path, 0.1 * k)
    assert recovery.phase == "back_up" and recovery.reversing
    assert (waypoint.x_m, waypoint.y_m) == pytest.approx((-rec.BACK_UP_M, 0.0))
    walled = Recovery(config, TAU)  # an obstacle right behind: no back-up
    behind = np.array([[-0.6, 0.0, 0.3]])
    for k in range(walled.checker.idle_steps):
        walled.waypoint(pose, target, IDLE, behind, _no_path, 0.1 * k)
    assert walled.phase == "drive"  # facing the target already: no turn either


def test_a_second_stall_at_the_same_spot_marks_it_and_the_path_goes_round_it() -> None:
    config = RecoveryConfig()
    planner = Planner(PlannerConfig(), MoverModel(1.5, inflation_m=INFLATION))
    recovery = Recovery(config, TAU)
    pose, target = np.array([0.0, 0.0, 0.0]), np.array([4.0, 0.0, 0.0])

    def plan(xy: np.ndarray, goal: np.ndarray, extra: np.ndarray) -> np.ndarray | None:
        return planner.plan_path(xy, goal, [], extra)

    t = 0.0
    for stall in range(2):
        recovery.pause()  # as if the last recovery had ended where it began
        for _ in range(recovery.checker.idle_steps):
            t += TAU
            recovery.waypoint(pose, target, IDLE, np.zeros((0, 3)), plan, t)
        assert recovery.phase == "back_up"
        assert len(recovery.tabu_circles(t)) == stall  # the first stall marks nothing
    tabu = recovery.tabu_circles(t)
    path = planner.plan_path(np.array([-1.0, 0.0]), target[:2], [], tabu)
    spot = np.hypot(path[:, 0], path[:, 1])
    assert np.min(spot) >= rec.TABU_RADIUS_M - 0.1  # round the spot, within the grid's 0.1 m
    assert len(recovery.tabu_circles(t + rec.TABU_S)) == 0  # forgotten after tabu_s
