"""Recovery from a stall, as Nav2 has it: a progress checker and recovery phases.

A CBF-constrained NMPC can settle where the gradient of its cost meets an obstacle's barrier (an
obstacle between the robot and its goal, a goal straight behind it with the opposite heading):
every plan it can see within its horizon costs more than standing still. The progress checker
notices (the robot neither came `progress_min_m` closer to its target nor moved that far within
`progress_window_s`, or it was commanded to stand still for `idle_s`, away from the target), and
recovery then hands the NMPC waypoints the short horizon cannot find by itself:

1. `turn`: to face the way (the bearing to a point DRIVE_M along a shortest path round the
   obstacles, planner.Planner.plan_path), if it faces more than AIM_RAD away; where it stands,
   or, if its body cannot swing round there (its corners would meet an obstacle), first `room`:
   along its axis, forwards or backwards (whichever is nearer), to the nearest point where it can,
   as Nav2's recoveries rotate only where there is room;
2. `drive`: to that point;
3. a robot told to stand still (pinned at an obstacle), or stalled again within MEMORY_RADIUS_M
   of an earlier stall, starts with `back_up` (BACK_UP_M straight back, where that is free); a
   repeated stall also marks the spot as a virtual obstacle of TABU_RADIUS_M for the next TABU_S,
   so that the path (and the planner afterwards) goes another way: the spot is a local minimum,
   and the way through it has failed twice.

The NMPC's obstacle constraints stay in force throughout: recovery only moves the target.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from controllers.husky_cbf.behaviours.base import Situation, Target
from controllers.husky_cbf.config import RecoveryConfig
from controllers.husky_cbf.planner import Planner, arc_lengths, segment_blocked
from controllers.model import wrap_angle

#: A command below both of these (m/s, rad/s) is idle: the robot is told to stand still
IDLE_SPEED_MPS = 0.05
IDLE_YAW_RATE_RADPS = 0.05
#: Within this of the target (m) the set-point approach (docking, pivot) owns the robot: no stall
NEAR_M = 0.3
#: A robot facing the way within this (rad) needs no turn first
AIM_RAD = 0.35
#: The way's point lies this far (m) along the path: past one obstacle
DRIVE_M = 1.0
#: A phase's point is reached within this (m), and `room` searches the axis in steps of it
ARRIVE_M = 0.15
#: A pinned robot backs up this far (m): room to turn
BACK_UP_M = 0.5
#: A phase ends after this long (s), reached or not
PHASE_TIMEOUT_S = 5.0
#: A stall within this (m) of an earlier one, within TABU_S, is a repeat
MEMORY_RADIUS_M = 0.6
#: A repeated stall's spot is a virtual obstacle of this radius (m) ...
TABU_RADIUS_M = 0.5
#: ... for this long (s)
TABU_S = 20.0

#: a path from the robot to the target (m), given extra circles [x, y, r] to avoid: Planner.plan_path
PathPlanner = Callable[[np.ndarray, np.ndarray, np.ndarray], "np.ndarray | None"]


class ProgressChecker:
    """Whether the robot is stalled short of its target: over the last `progress_window_s` it
    came less than `progress_min_m` closer to it and moved less than that (m), or its commands
    were idle for the last `idle_s`; never within NEAR_M of the target."""

    def __init__(self, config: RecoveryConfig, tau_s: float) -> None:
        self.config = config
        self._window = max(round(config.progress_window_s / tau_s), 1)
        self.idle_steps = max(round(config.idle_s / tau_s), 1)
        self._history: deque[tuple[np.ndarray, float, bool]] = deque(maxlen=self._window + 1)

    def reset(self) -> None:
        self._history.clear()

    def update(self, xy: np.ndarray, distance_m: float, idle: bool) -> str:
        """Add this step's position (m), distance to the target (m) and whether its command is
        idle; the stall: "idle" (told to stand still), "slow" (no progress), or "" (none)."""
        cfg = self.config
        self._history.append((np.asarray(xy, dtype=float).copy(), float(distance_m), bool(idle)))
        if distance_m <= NEAR_M:
            return ""
        recent = list(self._history)[-self.idle_steps :]
        if len(recent) == self.idle_steps and all(i for _, _, i in recent):
            return "idle"
        if len(self._history) <= self._window:
            return ""
        first_xy, first_distance, _ = self._history[0]
        closer = first_distance - distance_m
        moved = float(np.max(np.hypot(*(np.array([h[0] for h in self._history]) - first_xy).T)))
        return "slow" if closer < cfg.progress_min_m and moved < cfg.progress_min_m else ""


class Recovery:
    """The recovery phases after a stall (module docstring; a Behaviour): a queue of phases,
    each a waypoint held until it is reached, times out, or the robot stalls in it. `planner`
    gives the way round the obstacles (Planner.plan_path) for `propose`."""

    def __init__(
        self, config: RecoveryConfig, tau_s: float, swing_m: float = 0.0, planner: Planner | None = None
    ) -> None:
        self.config = config
        self.tau_s = tau_s
        self.planner = planner
        #: how much farther (m) the body's corners reach, turning in place, than the inflated
        #: obstacles already allow for (the circumscribed radius less the body disc's)
        self.swing_m = swing_m
        self.checker = ProgressChecker(config, tau_s)
        self.reset()

    def reset(self) -> None:
        self.checker.reset()
        self.phase = ""  # "", "back_up", "room", "turn" or "drive"
        self._queue: list[str] = []
        self._waypoint: Target | None = None
        self._phase_steps = 0
        self._stalls: list[tuple[np.ndarray, float]] = []  # where and when (s) stalls happened
        self._tabu: list[tuple[float, float, float, float]] = []  # x, y, r (m), until (s)
        self.started = 0  # recoveries started since reset

    @property
    def enabled(self) -> bool:
        """Whether a stalled robot recovers at all (RecoveryConfig.enabled)."""
        return self.config.enabled

    @property
    def reversing(self) -> bool:
        """Whether the robot is meant to move backwards now (backing up)."""
        return self.phase == "back_up"

    def pause(self) -> None:
        """Stop any recovery and forget the progress so far (the robot leaves its way on purpose);
        the stalls and tabu spots are kept."""
        self.checker.reset()
        self.phase, self._queue, self._waypoint, self._phase_steps = "", [], None, 0

    def tabu_circles(self, t: float) -> np.ndarray:
        """(M, 3) virtual obstacles [x, y, r] (m) at stall spots still remembered at t (s)."""
        self._tabu = [c for c in self._tabu if c[3] > t]
        return np.array([c[:3] for c in self._tabu]).reshape(-1, 3)

    def propose(self, situation: Situation) -> Target | None:
        """The recovery's target on the way to `situation.goal`, or None when not recovering."""
        planner, obstacles = self.planner, situation.obstacles
        if planner is None:
            raise ValueError("Recovery.propose needs a planner")

        def plan(xy: np.ndarray, goal_xy: np.ndarray, extra: np.ndarray) -> np.ndarray | None:
            return planner.plan_path(xy, goal_xy, obstacles, extra)

        return self.waypoint(
            situation.pose, situation.goal, situation.command, situation.circles, plan, situation.t
        )

    def waypoint(
        self,
        pose: np.ndarray,
        target: np.ndarray,
        command: np.ndarray,
        circles: np.ndarray,
        plan_path: PathPlanner,
        t: float,
    ) -> Target | None:
        """The recovery's waypoint this step, or None when not recovering. `target` (x, y,
        heading; m, m, rad) is where the robot is going, `command` the last command [v, omega]
        (m/s, rad/s), `circles` the inflated obstacles (MoverModel.body_circles), `plan_path`
        the shortest-path search."""
        pose = np.asarray(pose, dtype=float)
        distance = math.hypot(*(np.asarray(target[:2]) - pose[:2]))
        idle = abs(command[0]) < IDLE_SPEED_MPS and abs(command[1]) < IDLE_YAW_RATE_RADPS
        stalled = self.checker.update(pose[:2], distance, idle)
        if self.phase:
            self._phase_steps += 1
            if stalled == "idle":  # told to stand still while recovering: pinned, back up
                self._start(pose, target, circles, plan_path, t, repeat=True)
            elif self._phase_done(pose):
                self._next_phase(pose, target, circles, plan_path, t)
        elif stalled:
            self._start(pose, target, circles, plan_path, t, repeat=stalled == "idle")
        return self._waypoint if self.phase else None

    # -- phases -------------------------------------------------------------------------------
    def _start(
        self,
        pose: np.ndarray,
        target: np.ndarray,
        circles: np.ndarray,
        plan_path: PathPlanner,
        t: float,
        repeat: bool,
    ) -> None:
        """Start a recovery; `repeat`: the robot is pinned (told to stand still, or stalled while
        recovering), so back up first."""
        again = any(
            math.hypot(*(xy - pose[:2])) < MEMORY_RADIUS_M and t - when < TABU_S for xy, when in self._stalls
        )
        self._stalls.append((pose[:2].copy(), t))
        self._queue = ["room", "turn", "drive"]
        if repeat or again:
            self._queue.insert(0, "back_up")
        if again:  # the way through this spot failed before: the planner goes round it now
            self._tabu.append((float(pose[0]), float(pose[1]), TABU_RADIUS_M, t + TABU_S))
        self.started += 1
        self._next_phase(pose, target, circles, plan_path, t)

    def _next_phase(
        self, pose: np.ndarray, target: np.ndarray, circles: np.ndarray, plan_path: PathPlanner, t: float
    ) -> None:
        """Enter the next phase that has something to do; none left: the recovery ends."""
        self.phase, self._waypoint, self._phase_steps = "", None, 0
        while self._queue:
            phase = self._queue.pop(0)
            waypoint = self._phase_waypoint(phase, pose, target, circles, plan_path, t)
            if waypoint is not None:
                self.phase, self._waypoint = phase, waypoint
                break
        self.checker.reset()  # progress is judged afresh in each phase and after the recovery

    def _phase_waypoint(
        self,
        phase: str,
        pose: np.ndarray,
        target: np.ndarray,
        circles: np.ndarray,
        plan_path: PathPlanner,
        t: float,
    ) -> Target | None:
        xy, heading = pose[:2], float(pose[2])
        if phase == "back_up":
            behind = xy - BACK_UP_M * np.array([math.cos(heading), math.sin(heading)])
            if segment_blocked(xy, behind, circles):
                return None
            return Target(float(behind[0]), float(behind[1]), heading, np.array([xy, behind]))
        way = self._way_point(xy, target, plan_path, t)
        bearing = math.atan2(way[1] - xy[1], way[0] - xy[0])
        aimed = abs(float(wrap_angle(bearing - heading))) <= AIM_RAD  # no turn needed
        if phase == "room":
            if aimed:
                return None
            room = self._room_to_turn(xy, heading, circles)
            return (
                None
                if room is None
                else Target(float(room[0]), float(room[1]), heading, np.array([xy, room]))
            )
        if phase == "turn":
            if aimed:
                return None
            return Target(float(xy[0]), float(xy[1]), bearing, np.array([xy, xy]))
        return Target(float(way[0]), float(way[1]), bearing, np.array([xy, way]))

    def _room_to_turn(self, xy: np.ndarray, heading: float, circles: np.ndarray) -> np.ndarray | None:
        """A point (m) just past the nearest one along the robot's axis, forwards or backwards
        within DRIVE_M, in steps of ARRIVE_M, where its body can swing round, reached in a straight
        line; None where it can swing round already, or nowhere within reach."""
        if not segment_blocked(xy, xy, circles, self.swing_m):
            return None
        axis = np.array([math.cos(heading), math.sin(heading)])
        steps = int(DRIVE_M / ARRIVE_M)
        for along in ARRIVE_M * np.arange(1, steps + 1):
            for sign in (1.0, -1.0):
                # the waypoint lies ARRIVE_M past the first such point: reached, the robot is there
                point, beyond = (xy + sign * reach * axis for reach in (along, along + ARRIVE_M))
                swing_free = not any(segment_blocked(q, q, circles, self.swing_m) for q in (point, beyond))
                if swing_free and not segment_blocked(xy, beyond, circles):
                    return beyond
        return None

    def _way_point(self, xy: np.ndarray, target: np.ndarray, plan_path: PathPlanner, t: float) -> np.ndarray:
        """The point DRIVE_M along a shortest path to the target avoiding the tabu spots (m); the
        target itself, or the point DRIVE_M towards it, when there is no path."""
        goal = np.asarray(target[:2], dtype=float)
        path = plan_path(xy, goal, self.tabu_circles(t))
        if path is None or len(path) < 2:
            offset = goal - xy
            length = math.hypot(*offset)
            return goal if length <= DRIVE_M else xy + DRIVE_M * offset / length
        along = arc_lengths(path)
        index = int(np.searchsorted(along, DRIVE_M))
        return np.asarray(path[min(index, len(path) - 1)], dtype=float)

    def _phase_done(self, pose: np.ndarray) -> bool:
        waypoint = self._waypoint
        if waypoint is None or self._phase_steps * self.tau_s > PHASE_TIMEOUT_S:
            return True
        if self.phase == "turn":
            return abs(float(wrap_angle(waypoint.heading_rad - pose[2]))) <= 0.5 * AIM_RAD
        return math.hypot(waypoint.x_m - pose[0], waypoint.y_m - pose[1]) <= ARRIVE_M
