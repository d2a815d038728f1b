"""Approach behaviours: onto a set-point along the goal's line (pre-goal, docking, pivot), and at
the point of a trajectory too slow to come to the robot.

A unicycle beside its goal cannot close the gap within a short horizon (its cost falls only by
backing up and turning), and a skid-steer barely answers the small turns that would; so near a
set-point the robot is led onto the goal's line first (SetPointApproach). A point that barely
moves is reached by driving at it (PointApproach): lining up on its tangent would cost a docking
manoeuvre for a heading that tracking does not judge.
"""

from __future__ import annotations

import math

import numpy as np

from controllers.husky_cbf.behaviours.base import Situation, Target
from controllers.husky_cbf.config import ApproachConfig

#: A waypoint on the goal's line is this far (m) ahead of the robot's projection onto the line
LOOKAHEAD_M = 1.0
#: A robot more than this (m) off the goal's line is led onto it (and a settled pivot restarts)
ENTER_M = 0.07
#: ... and counts as on the line within this (m): a band, so that noise does not flip the decision
EXIT_M = 0.03
#: Docking ends aligned with the goal's heading within this (rad)
EXIT_RAD = 0.05
#: The pre-goal lies this many LOOKAHEAD_M before the goal on its line, so that the robot arrives
#: straight; docking backs up at least as far behind the goal
PRE_GOAL_LOOKAHEADS = 1.5
#: The pre-goal counts as reached within this (m): near it the robot is lined up well enough for
#: the run-in, which docking corrects
PRE_GOAL_REACHED_M = 0.3
#: Docking backs up this far behind the goal per metre of lateral error (m/m): a turn onto the
#: line and a straight run-in at a skid-steer's yaw response need about that
DOCKING_BACK_PER_LATERAL = 4.0
#: ... and at most approach.radius_m less this (m), so that it stays within the approach
DOCKING_RADIUS_MARGIN_M = 0.3
#: ... and drives in once it has backed up this fraction of the way: the last few per cent of a
#: back-up cost more time braking than the run-in gains
DOCKING_BACKED_UP = 0.93
#: A pivot turns until aimed within this (rad) before it drives, and judges the goal's heading
#: reached within it
PIVOT_AIM_RAD = 0.2
#: A pivot's drive ends within this (m) of the goal
PIVOT_ARRIVE_M = 0.05
#: A settled pivot restarts beyond this (m) from the goal, and a pivot is dropped this far beyond
#: the radius it started in
PIVOT_RESTART_M = 0.1
#: A slow trajectory's point: the NMPC tracks the reference itself within this (m) of it
POINT_NEAR_M = 0.1
#: ... and the robot drives at the point along the bearing beyond this (m), turning to the
#: reference's heading in between; within it the robot counts as at the point
POINT_FAR_M = 0.3


def room_behind(
    goal: np.ndarray, heading: np.ndarray, circles: np.ndarray, needed_m: float, step_m: float
) -> float:
    """How far (m, at most needed_m) the goal's line runs behind the goal (against its unit
    `heading`) before it enters an inflated obstacle (`circles`), in step_m."""
    if circles.size == 0:
        return needed_m
    s = np.arange(0.0, needed_m + step_m, step_m)
    points = np.asarray(goal[:2], dtype=float) - s[:, None] * heading
    distance = np.hypot(points[:, None, 0] - circles[:, 0], points[:, None, 1] - circles[:, 1])
    inside = np.any(distance < circles[:, 2], axis=1)
    return float(s[np.argmax(inside)]) if inside.any() else needed_m


class SetPointApproach:
    """Brings a robot onto its set-point along the goal's line (a Behaviour).

    First a pre-goal waypoint PRE_GOAL_LOOKAHEADS lookaheads before the goal on its line (unless an
    obstacle covers it), so that the robot arrives straight; within radius_m of the goal a robot
    off the line is led onto it by a waypoint on the line ahead of it, or, beside or past the goal,
    behind it (docking: it backs up onto the line, then drives in along it).

    Within pivot_radius_m of the goal and off its line, the robot pivots instead of docking: it
    turns where it stands to face the goal (or to back onto it, whichever needs less turning in
    all), drives to it, and turns to the goal's heading there; a skid-steer answers small turns
    weakly, and a pivot turns only where it stands. It also pivots, from anywhere within radius_m,
    where an obstacle takes the room the docking needs behind the goal (`room_step_m`: the step in
    which that room is measured, the planner's grid resolution)."""

    def __init__(self, config: ApproachConfig, room_step_m: float) -> None:
        self.config = config
        self.room_step_m = room_step_m
        self.reset()

    def reset(self) -> None:
        self.docking = False
        self.pre_goal_done = False
        self.back_to = 0.0  # how far behind the goal (m) the current docking backs up
        self.pivot = ""  # the pivot's phase: "", "turn", "drive" or "settle"
        self.pivot_from = np.zeros(2)  # where the pivot's first turn is made (m)
        self.pivot_heading = 0.0  # the heading (rad) in which the pivot drives to the goal
        self.pivot_reverse = False  # whether it backs onto the goal
        self.pivot_radius_m = self.config.pivot_radius_m  # the pivot is dropped beyond this (m)

    @property
    def reversing(self) -> bool:
        """Whether the robot is meant to move backwards: docking, or a pivot backing onto the goal."""
        return self.docking or (self.pivot in ("turn", "drive") and self.pivot_reverse)

    @property
    def settling(self) -> bool:
        """Whether the pivot has brought the robot to the goal and it turns to the goal's heading."""
        return self.pivot == "settle"

    def propose(self, situation: Situation) -> Target | None:
        """The approach's target for the set-point `situation.goal`, judged on the filtered pose."""
        return self.waypoint(situation.estimate, situation.goal, situation.circles)

    def waypoint(self, pose: np.ndarray, goal: np.ndarray, circles: np.ndarray) -> Target | None:
        """The approach waypoint, or None to go for the goal itself; `circles` are the inflated
        obstacles (movers.MoverModel.body_circles)."""
        cfg = self.config
        h = np.array([math.cos(goal[2]), math.sin(goal[2])])
        d = np.asarray(pose[:2], dtype=float) - goal[:2]
        along, lateral = float(d @ h), float(h[0] * d[1] - h[1] * d[0])
        back = PRE_GOAL_LOOKAHEADS * LOOKAHEAD_M
        if not self.pre_goal_done:
            pre_goal = goal[:2] - back * h
            blocked = circles.size and np.any(np.hypot(*(circles[:, :2] - pre_goal).T) < circles[:, 2])
            if math.hypot(*(pose[:2] - pre_goal)) < PRE_GOAL_REACHED_M or along > -back:
                self.pre_goal_done = True
            elif not blocked:  # (an obstacle over it, perhaps only passing: the goal for now)
                return Target(
                    float(pre_goal[0]), float(pre_goal[1]), float(goal[2]), np.array([pose[:2], pre_goal])
                )
        pivot = self._pivot(pose, goal, lateral)
        if pivot is not None or self.pivot:
            return pivot
        aligned = abs(math.remainder(float(pose[2]) - float(goal[2]), 2 * math.pi)) <= EXIT_RAD
        on_line = abs(lateral) <= EXIT_M and (aligned or not self.docking)
        backed_up = along <= -DOCKING_BACKED_UP * self.back_to  # far enough back: drive in now
        if on_line or backed_up or math.hypot(*d) > cfg.radius_m:
            self.docking = False
        if on_line or math.hypot(*d) > cfg.radius_m:
            return None
        if not self.docking and along > -0.5 * LOOKAHEAD_M and abs(lateral) > ENTER_M:
            # back up far enough to turn onto the line and reach it
            back_to = min(
                max(back, DOCKING_BACK_PER_LATERAL * abs(lateral)),
                cfg.radius_m - DOCKING_RADIUS_MARGIN_M,
            )
            if room_behind(goal, h, circles, back_to, self.room_step_m) < back_to:
                return self._pivot(pose, goal, lateral, radius_m=cfg.radius_m)
            self.docking, self.back_to = True, back_to
        target = max(along - LOOKAHEAD_M, -self.back_to) if self.docking else min(along + LOOKAHEAD_M, 0.0)
        point = goal[:2] + target * h
        return Target(float(point[0]), float(point[1]), float(goal[2]), np.array([pose[:2], point]))

    def _pivot(
        self, pose: np.ndarray, goal: np.ndarray, lateral: float, radius_m: float | None = None
    ) -> Target | None:
        """The pivot's waypoint (None while it settles on the goal, or when not pivoting); a new
        pivot starts within `radius_m` of the goal (m; default pivot_radius_m)."""
        cfg = self.config
        offset = np.asarray(goal[:2], dtype=float) - np.asarray(pose[:2], dtype=float)
        distance = math.hypot(*offset)
        turned = abs(math.remainder(float(pose[2]) - float(goal[2]), 2 * math.pi)) <= PIVOT_AIM_RAD
        slid = turned and abs(lateral) > ENTER_M
        if self.pivot == "settle" and (distance > PIVOT_RESTART_M or slid):
            # drifted away, or found off the line once turned to the goal's heading (a skid-steer
            # turning in place scrubs sideways); not judged mid-turn, where the turn's own scrub
            # would restart the pivot over and over
            self.pivot = ""
        if self.pivot and distance > self.pivot_radius_m + PIVOT_RESTART_M:
            self.pivot = ""  # taken away (out of a mover's way): judged afresh when back
        if not self.pivot and not self.docking:
            radius = cfg.pivot_radius_m if radius_m is None else radius_m
            if distance > radius or abs(lateral) <= ENTER_M:
                return None
            self.pivot_radius_m = radius
            bearing = math.atan2(offset[1], offset[0])
            theta, heading = float(pose[2]), float(goal[2])

            def turning(travel: float) -> float:
                return abs(math.remainder(travel - theta, 2 * math.pi)) + abs(
                    math.remainder(heading - travel, 2 * math.pi)
                )

            reverse = turning(bearing + math.pi) < turning(bearing)
            self.pivot, self.pivot_from = "turn", np.asarray(pose[:2], dtype=float).copy()
            self.pivot_heading = math.remainder(bearing + (math.pi if reverse else 0.0), 2 * math.pi)
            self.pivot_reverse = reverse
        if self.pivot == "turn":
            if abs(math.remainder(float(pose[2]) - self.pivot_heading, 2 * math.pi)) <= PIVOT_AIM_RAD:
                self.pivot = "drive"
            else:
                x, y = self.pivot_from
                return Target(float(x), float(y), self.pivot_heading, np.array([pose[:2], self.pivot_from]))
        if self.pivot == "drive":
            travel = np.array([math.cos(self.pivot_heading), math.sin(self.pivot_heading)])
            ahead = float(offset @ travel) * (-1.0 if self.pivot_reverse else 1.0)
            if distance > PIVOT_ARRIVE_M and ahead > 0.0:
                return Target(
                    float(goal[0]), float(goal[1]), self.pivot_heading, np.array([pose[:2], goal[:2]])
                )
            self.pivot = "settle"
        return None


def point_approach(pose: np.ndarray, goal: np.ndarray, near_m: float, far_m: float) -> Target | None:
    """The approach to a slow trajectory's `goal` (x m, y m, heading rad): None (track the
    reference) within near_m of it; else the goal point, approached along the bearing from the
    robot beyond far_m, with the heading turned from that bearing to the reference's own in
    between."""
    offset = np.asarray(goal[:2], dtype=float) - np.asarray(pose[:2], dtype=float)
    distance = math.hypot(*offset)
    if distance <= near_m:
        return None
    bearing = math.atan2(offset[1], offset[0])
    blend = min((distance - near_m) / (far_m - near_m), 1.0) if far_m > near_m else 1.0
    heading = float(goal[2]) + blend * math.remainder(bearing - float(goal[2]), 2 * math.pi)
    return Target(float(goal[0]), float(goal[1]), heading, np.array([pose[:2], goal[:2]]))


class PointApproach:
    """Drives at the point of a trajectory too slow to come to the robot (a Behaviour; no state):
    point_approach between POINT_NEAR_M and POINT_FAR_M."""

    def propose(self, situation: Situation) -> Target | None:
        return point_approach(situation.pose, situation.goal, POINT_NEAR_M, POINT_FAR_M)

    def reset(self) -> None:
        pass
