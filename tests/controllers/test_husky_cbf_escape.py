"""husky-cbf's deadlock escape (controllers/husky_cbf/escape.py) and the set-point approach's
room check, on their own: the progress checker's verdicts, the escape's phases and waypoints, and
docking that gives way to a pivot where an obstacle takes the room behind the goal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers import Obstacle
from controllers.husky_cbf.config import EscapeConfig, GuidanceConfig
from controllers.husky_cbf.escape import Escape, ProgressChecker
from controllers.husky_cbf.guidance import Guidance, LineApproach

TAU = 0.1
INFLATION = 0.48
MOVING = np.array([0.5, 0.0])  # a command that is not idle (m/s, rad/s)
IDLE = np.zeros(2)


def _no_path(xy: np.ndarray, goal: np.ndarray, extra: np.ndarray) -> None:
    return None


def test_the_progress_checker_names_idle_and_slow_stalls_and_leaves_progress_alone() -> None:
    config = EscapeConfig()
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
    near = [checker.update(np.array([1.0, 0.0]), 0.5 * config.near_m, idle=True) for _ in range(40)]
    assert set(near) == {""}  # at the target the set-point approach owns the robot


def test_a_slow_stall_turns_to_the_way_then_drives_along_it() -> None:
    escape = Escape(EscapeConfig(), TAU)
    target = np.array([-3.0, 0.0, math.pi])  # behind the robot
    pose = np.array([0.0, 0.0, 0.0])
    none = np.zeros((0, 3))
    waypoints = [escape.waypoint(pose, target, MOVING, none, _no_path, 0.1 * k) for k in range(31)]
    assert waypoints[:-1] == [None] * 30 and escape.phase == "turn" and escape.started == 1
    turn = waypoints[-1]
    assert (turn.x_m, turn.y_m) == (0.0, 0.0) and abs(turn.heading_rad) == pytest.approx(math.pi)
    drive = escape.waypoint(np.array([0.0, 0.0, math.pi]), target, MOVING, none, _no_path, 3.1)
    assert escape.phase == "drive"
    assert (drive.x_m, drive.y_m) == pytest.approx((-EscapeConfig().drive_m, 0.0))
    assert escape.waypoint(np.array([-0.95, 0.0, math.pi]), target, MOVING, none, _no_path, 5.0) is None
    assert escape.phase == "" and not escape.reversing


def test_a_robot_that_cannot_swing_round_where_it_stalled_first_moves_along_its_axis_to_room() -> None:
    """Beside an obstacle its corners would meet turning in place, the escape first drives along
    the robot's axis, the nearer way (here backwards), to just past where the body swings free;
    then it turns there. With nothing in the way, or a body that swings within its discs, it turns
    where it stands."""
    config, swing = EscapeConfig(), 0.2
    target, pose = np.array([-3.0, 0.0, math.pi]), np.array([0.0, 0.0, 0.0])  # behind the robot
    beside = np.array([[0.2, 0.8, 0.65]])  # clear of the discs (0.8 m > 0.65 m), not of the swing

    def stall(escape: Escape, circles: np.ndarray) -> object:
        for k in range(round(config.progress_window_s / TAU) + 1):
            waypoint = escape.waypoint(pose, target, MOVING, circles, _no_path, 0.1 * k)
        return waypoint

    escape = Escape(config, TAU, swing)
    room = stall(escape, beside)
    assert escape.phase == "room" and not escape.reversing
    assert (room.x_m, room.y_m, room.heading_rad) == pytest.approx((-2 * config.arrive_m, 0.0, 0.0))
    turn = escape.waypoint(np.array([room.x_m, 0.0, 0.0]), target, MOVING, beside, _no_path, 3.2)
    assert escape.phase == "turn" and (turn.x_m, turn.y_m) == pytest.approx((room.x_m, 0.0))
    assert abs(turn.heading_rad) == pytest.approx(math.pi)
    for circles, swing_m in ((np.zeros((0, 3)), swing), (beside, 0.0)):
        free = Escape(config, TAU, swing_m)
        stall(free, circles)
        assert free.phase == "turn"


def test_a_robot_told_to_stand_still_backs_up_first_where_there_is_room() -> None:
    config = EscapeConfig()
    target = np.array([4.0, 0.0, 0.0])
    pose = np.array([0.0, 0.0, 0.0])
    escape = Escape(config, TAU)
    for k in range(escape.checker.idle_steps):
        waypoint = escape.waypoint(pose, target, IDLE, np.zeros((0, 3)), _no_path, 0.1 * k)
    assert escape.phase == "back_up" and escape.reversing
    assert (waypoint.x_m, waypoint.y_m) == pytest.approx((-config.back_up_m, 0.0))
    walled = Escape(config, TAU)  # an obstacle right behind: no back-up
    behind = np.array([[-0.6, 0.0, 0.3]])
    for k in range(walled.checker.idle_steps):
        walled.waypoint(pose, target, IDLE, behind, _no_path, 0.1 * k)
    assert walled.phase == "drive"  # facing the target already: no turn either


def test_a_second_stall_at_the_same_spot_marks_it_and_the_path_goes_round_it() -> None:
    config = EscapeConfig()
    guidance = Guidance(GuidanceConfig(), INFLATION)
    escape = Escape(config, TAU)
    pose, target = np.array([0.0, 0.0, 0.0]), np.array([4.0, 0.0, 0.0])

    def plan(xy: np.ndarray, goal: np.ndarray, extra: np.ndarray) -> np.ndarray | None:
        return guidance.plan_path(xy, goal, [], extra)

    t = 0.0
    for stall in range(2):
        escape.pause()  # as if the last escape had ended where it began
        for _ in range(escape.checker.idle_steps):
            t += TAU
            escape.waypoint(pose, target, IDLE, np.zeros((0, 3)), plan, t)
        assert escape.phase == "back_up"
        assert len(escape.tabu_circles(t)) == stall  # the first stall marks nothing
    tabu = escape.tabu_circles(t)
    path = guidance.plan_path(np.array([-1.0, 0.0]), target[:2], [], tabu)
    spot = np.hypot(path[:, 0], path[:, 1])
    assert np.min(spot) >= config.tabu_radius_m - 0.1  # round the spot, within the grid's 0.1 m
    assert len(escape.tabu_circles(t + config.tabu_s)) == 0  # forgotten after tabu_s


def test_docking_gives_way_to_a_pivot_where_an_obstacle_takes_the_room_behind_the_goal() -> None:
    """Beside a goal and past it, the approach backs up along the goal's line to drive in; with an
    obstacle on that line behind the goal it pivots instead (it settled beside the obstacle)."""
    config = GuidanceConfig()
    goal = np.array([0.0, 0.0, 0.0])
    pose = np.array([0.3, 1.5, 0.0])  # beyond pivot_radius_m, past the goal: docking
    free = LineApproach(config)
    free.pre_goal_done = True
    free.waypoint(pose, goal, np.zeros((0, 3)))
    assert free.docking and free.pivot == ""
    blocked = LineApproach(config)
    blocked.pre_goal_done = True
    circles = Guidance(config, INFLATION).circles(pose[:2], [Obstacle(-1.5, 0.0, 0.4)])
    blocked.waypoint(pose, goal, circles)
    assert not blocked.docking and blocked.pivot == "turn"


def test_a_robot_that_slides_off_the_line_while_settling_pivots_again() -> None:
    """Turning in place to the goal's heading, a skid-steer scrubs sideways: 8 cm off the line
    (beyond approach_enter_m, within pivot_restart_m of the goal) it pivots again, 5 cm it settles."""
    config = GuidanceConfig()
    goal, none = np.array([9.0, 0.0, 0.0]), np.zeros((0, 3))
    for lateral, phase in ((0.05, "settle"), (0.08, "turn")):
        approach = LineApproach(config)
        approach.pre_goal_done, approach.pivot = True, "settle"
        approach.waypoint(np.array([9.02, lateral, -0.14]), goal, none)
        assert approach.pivot == phase


def test_a_settle_still_turning_to_the_goal_heading_is_not_restarted_by_its_own_scrub() -> None:
    """Mid-turn, 8 cm off the line is the turn's own slip (scrub and the NMPC's shuffle): the
    settle goes on (restarted there, the pivot's turns each way slipped as much again, cycling 7
    to 9 cm from the goal); drifted beyond pivot_restart_m it pivots again whatever its heading."""
    config = GuidanceConfig()
    goal, none = np.array([9.0, 0.0, 0.0]), np.zeros((0, 3))
    for pose, phase in (
        ((9.02, 0.08, -1.0), "settle"),
        ((9.02, 0.08, -0.14), "turn"),
        ((9.0, 0.12, -1.0), "turn"),
    ):
        approach = LineApproach(config)
        approach.pre_goal_done, approach.pivot = True, "settle"
        approach.waypoint(np.array(pose), goal, none)
        assert approach.pivot == phase, pose
