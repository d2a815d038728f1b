"""Yielding to movers: three behaviours on one judgement of a mover's course (SideStep).

A skid-steer needs a second or two to turn, so a short horizon that first sees a mover when its
constraint activates can only back away in front of it (and be chased). So each mover's track
relative to a point is extrapolated yielding.horizon_s ahead; a mover whose closest approach comes
within its radius plus the robot's inflation plus yielding.margin_m (or plus the NMPC's growth of
that mover and the planner's release margin, if that is more) is on a collision course, and the
step aside is the point that much to the side of the mover's relative line.

- StepAside: from the robot itself, judged at the velocity the robot means to have; on a moving
  reference, from the reference point at its velocity, once the drive's limits leave no later
  time (RobotLimits.leave_s), to the side behind the mover.
- WaitBeside: on the way back to a slow trajectory's point, with a mover on course to that point:
  where the robot would step aside to from the point, on the robot's own side of the mover's line.
- BraceAcross: at a slow trajectory's point, with a mover on course to it within a longer horizon:
  the robot turns its axis across the mover's track, so that its step aside is a drive along it.

The NMPC's obstacle constraints stay in force throughout: yielding only moves the target.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.husky_cbf.behaviours.approach import POINT_FAR_M
from controllers.husky_cbf.behaviours.base import ReferenceKind, Situation, Target, nearer_way
from controllers.husky_cbf.config import HuskyCBFConfig, YieldConfig
from controllers.husky_cbf.movers import MoverModel, is_static
from controllers.husky_cbf.planner import RELEASE_MARGIN_M
from controllers.obstacles import Obstacle

#: A mover passing within this (m) of dead ahead is stepped round on the left: a fixed side, so
#: that sensing noise cannot flip the side from step to step
DEAD_AHEAD_M = 0.02
#: Bracing judges movers over this much longer (s) than yielding.horizon_s: a quarter turn in
#: place takes a loaded skid-steer up to that, and must be done before the step aside starts
BRACE_LEAD_S = 4.0
#: Below this squared relative speed ((m/s)^2) a mover keeps its distance: no closest approach
STILL_RELATIVE_SPEED_SQ = 1e-9


@dataclass(frozen=True)
class Threat:
    """A mover on a collision course with a point: its closest approach relative to the point
    `closest_m` [x, y] (m), its velocity relative to the point `relative_mps` (m/s), the distance
    it must pass at (m), and the mover itself."""

    closest_m: np.ndarray
    relative_mps: np.ndarray
    needed_m: float
    mover: Obstacle

    @property
    def normal(self) -> np.ndarray:
        """The unit vector left of the relative track."""
        v = self.relative_mps
        return np.array([-v[1], v[0]]) / np.hypot(*v)

    def shift_m(self, side: float) -> float:
        """How far (m) the point must move to `side` (+1 left, -1 right) of the relative track to
        clear it by the distance needed."""
        return max(self.needed_m + side * float(self.closest_m @ self.normal), 0.0)

    def step_m(self, side: float) -> np.ndarray:
        """The step [x, y] (m) from the point to `side` of the relative track."""
        return side * self.normal * self.shift_m(side)

    def track_gap_m(self, xy: np.ndarray) -> float:
        """How far (m) `xy` is from the mover's track ahead of it (the ray from where it is along
        its velocity)."""
        ob = self.mover
        start, velocity = np.array([ob.x_m, ob.y_m]), np.array([ob.vx_mps, ob.vy_mps])
        along = max(float((xy - start) @ velocity) / float(velocity @ velocity), 0.0)
        return float(np.hypot(*(xy - start - along * velocity)))


class SideStep:
    """The judgement every yielding behaviour shares: the step aside from the soonest mover on a
    collision course with a point (module docstring). Remembers the side taken (kept until no
    mover is on course) and the threat's time to its closest approach (`soonest_s`)."""

    def __init__(self, config: YieldConfig, movers: MoverModel) -> None:
        self.config = config
        self.movers = movers
        self.side = 0.0  # the side taken (+1 left of the mover's relative track, -1 right)
        self.soonest_s = math.inf

    def reset(self) -> None:
        self.side = 0.0

    @property
    def active(self) -> bool:
        """Whether the last `step` found a mover on a collision course."""
        return bool(self.side)

    def step(
        self,
        point_xy: np.ndarray,
        heading_rad: float,
        velocity_mps: np.ndarray,
        obstacles: Sequence[Obstacle],
        side_of: np.ndarray | None = None,
        horizon_s: float | None = None,
        behind_mover: bool = False,
    ) -> Target | None:
        """The step aside from the soonest mover on a collision course with `point_xy` [x, y] (m)
        moving at `velocity_mps` [vx, vy] (m/s, world frame), or None; its heading is the step's
        direction or its opposite, whichever is nearer `heading_rad` (the heading at the point).
        The step goes to the side of the mover's line that the point `side_of` [x, y] (m) is on,
        if given; else, with `behind_mover`, to the side farther from the mover's own track ahead
        of it (where the NMPC and the planner sweep it); else away from the line (to the left when
        dead ahead). Movers are judged over `horizon_s` (s; default yielding.horizon_s)."""
        point_xy = np.asarray(point_xy, dtype=float)
        threat, soonest = self.threat(point_xy, velocity_mps, obstacles, horizon_s)
        self.soonest_s = soonest  # the threat's time to its closest approach (s); inf: none
        if threat is None:
            self.side = 0.0
            return None
        if not self.side and behind_mover and side_of is None:
            ahead = [threat.track_gap_m(point_xy + threat.step_m(side)) for side in (-1.0, 1.0)]
            self.side = -1.0 if ahead[0] > ahead[1] else 1.0
        elif not self.side:
            offset = float(threat.closest_m @ threat.normal)  # > 0: the mover passes left of the point
            if side_of is not None:  # ... left of `side_of`
                offset -= float((np.asarray(side_of, dtype=float) - point_xy) @ threat.normal)
            self.side = -1.0 if offset > DEAD_AHEAD_M else 1.0  # the other side (left if dead ahead)
        step = threat.step_m(self.side)
        target = point_xy + step
        heading = nearer_way(math.atan2(step[1], step[0]), heading_rad)  # reversing if that turns less
        return Target(float(target[0]), float(target[1]), heading, np.array([point_xy, target]))

    def threat(
        self,
        point_xy: np.ndarray,
        velocity_mps: np.ndarray,
        obstacles: Sequence[Obstacle],
        horizon_s: float | None = None,
    ) -> tuple[Threat | None, float]:
        """The soonest mover on a collision course with `point_xy` moving at `velocity_mps` within
        `horizon_s` (default yielding.horizon_s), and its time to closest approach (s); (None, inf)
        when there is none. Pure: the side taken is not touched."""
        cfg = self.config
        horizon_s = cfg.horizon_s if horizon_s is None else horizon_s
        point_xy = np.asarray(point_xy, dtype=float)
        velocity = np.asarray(velocity_mps, dtype=float)
        threat, soonest = None, math.inf
        for ob in obstacles:
            speed = math.hypot(ob.vx_mps, ob.vy_mps)
            if is_static(ob):
                continue
            rel_p = np.array([ob.x_m, ob.y_m]) - point_xy
            rel_v = np.array([ob.vx_mps, ob.vy_mps]) - velocity
            vv = float(rel_v @ rel_v)
            t_c = -float(rel_p @ rel_v) / vv if vv > STILL_RELATIVE_SPEED_SQ else 0.0
            if not 0.0 < t_c < horizon_s:
                continue
            closest = rel_p + t_c * rel_v
            # at least as wide as the NMPC sees the mover, with the planner's margin to spare
            swept = self.movers.growth_m(speed) + RELEASE_MARGIN_M
            needed = ob.radius_m + self.movers.inflation_m + max(cfg.margin_m, swept)
            if np.hypot(*closest) < needed and t_c < soonest:
                threat, soonest = Threat(closest, rel_v, needed, ob), t_c
        return threat, soonest


class StepAside:
    """Steps the robot aside from a mover on a collision course with it (a Behaviour).

    On a trajectory the robot is judged, and steps aside, from the reference point moving at the
    reference's velocity: the step is across the mover's track relative to the reference, so the
    target moves on with the reference and the robot keeps its progress along it. It starts only
    when the robot must leave to be clear in time (`leave_s`): until then it tracks, since every
    second off the reference is tracking error. On a set-point it steps aside as soon as a mover
    is on course (yielding.horizon_s), from where the robot is."""

    def __init__(self, config: YieldConfig, movers: MoverModel, robot: RobotLimits) -> None:
        self.judge = SideStep(config, movers)
        self.robot = robot

    @property
    def active(self) -> bool:
        """Whether the robot is stepping aside this step."""
        return self.judge.active

    def reset(self) -> None:
        self.judge.reset()

    @staticmethod
    def meant_velocity(situation: Situation) -> np.ndarray:
        """The velocity [vx, vy] (m/s) the robot is judged at: where it means to go, not where its
        own stepping aside takes it (judged at its own flight, a robot backing away ahead of a
        mover sees no closing track). On a set-point, its commanded speed along its heading; on a
        slow trajectory, 0 (it means to stay); on a trajectory, the reference's velocity now (so
        that the verdict does not switch as the robot stops and starts)."""
        if situation.kind is ReferenceKind.SLOW_TRAJECTORY:
            return np.zeros(2)
        if situation.kind is ReferenceKind.SET_POINT:
            course, speed = situation.pose[2], situation.speed_mps
        else:
            course, speed = situation.reference_state[2], situation.reference_speed_mps
        return float(speed) * np.array([math.cos(course), math.sin(course)])

    def propose(self, situation: Situation) -> Target | None:
        s, velocity = situation, self.meant_velocity(situation)
        if s.kind is not ReferenceKind.TRAJECTORY:
            return self.judge.step(s.pose[:2], s.pose[2], velocity, s.obstacles)
        point = s.reference_state[:2]
        if not self.active:
            threat, soonest = self.judge.threat(point, velocity, s.obstacles)
            if threat is None:
                return None
            shift = max(threat.shift_m(side) for side in (-1.0, 1.0))  # either side it takes
            if soonest > self.robot.leave_s(shift):
                return None  # it tracks on: there is time to leave later
        return self.judge.step(point, s.pose[2], velocity, s.obstacles, behind_mover=True)


@dataclass(frozen=True)
class RobotLimits:
    """The drive's limits that bound how soon a robot on its way can be out of a mover's track:
    speed (m/s), acceleration (m/s^2), body yaw rate (rad/s) and yaw acceleration (rad/s^2), and
    the dead time plus yaw lag (s) before a command acts."""

    v_max_mps: float
    accel_mps2: float
    yaw_rate_radps: float
    yaw_accel_radps2: float
    delay_s: float

    @classmethod
    def of(cls, config: HuskyCBFConfig) -> RobotLimits:
        """husky-cbf's robot: its drive's limits, its commanded yaw-rate bound through the yaw
        gain, and its measurement-to-action delay plus the yaw lag."""
        r = config.response
        return cls(
            v_max_mps=min(config.nmpc.v_max_mps, r.max_linear_mps),
            accel_mps2=r.max_linear_accel_mps2,
            yaw_rate_radps=r.yaw_gain * config.omega_cmd_max_radps,
            yaw_accel_radps2=r.max_angular_accel_radps2,
            delay_s=config.measurement_delay_s + r.yaw_time_constant_s,
        )

    def leave_s(self, distance_m: float) -> float:
        """A bound (s) on the time to move `distance_m` (m) across the robot's course: the delay,
        a quarter turn from rest at the yaw limits, then the distance from rest at the speed and
        acceleration limits (turn and drive in sequence, so the bound is on the safe side)."""
        quarter_turn_s = 0.5 * math.pi / self.yaw_rate_radps + self.yaw_rate_radps / self.yaw_accel_radps2
        drive_s = distance_m / self.v_max_mps + self.v_max_mps / self.accel_mps2
        return self.delay_s + quarter_turn_s + drive_s


class WaitBeside:
    """On the way back to a slow trajectory's point (`situation.goal`), with a mover on course to
    that point: waits where it would step aside to from the point, on the robot's own side of the
    mover's line (a Behaviour). None when no mover reaches the point before the robot would (at
    `approach_speed_mps`), or the robot is at the point (within POINT_FAR_M)."""

    def __init__(self, config: YieldConfig, movers: MoverModel, approach_speed_mps: float) -> None:
        self.judge = SideStep(config, movers)
        self.approach_speed_mps = approach_speed_mps

    def reset(self) -> None:
        self.judge.reset()

    def propose(self, situation: Situation) -> Target | None:
        """The waiting spot, with the robot's heading now, or None."""
        pose, point = situation.pose, situation.goal
        distance = math.hypot(point[0] - pose[0], point[1] - pose[1])
        if distance <= POINT_FAR_M:
            self.reset()
            return None
        point = np.asarray(point, dtype=float)
        spot = self.judge.step(point[:2], point[2], np.zeros(2), situation.obstacles, side_of=pose[:2])
        if spot is None:
            return None
        if self.judge.soonest_s < distance / self.approach_speed_mps:
            self.reset()  # the mover passes the point before the robot gets there
            return None
        xy = np.array([spot.x_m, spot.y_m])
        return Target(spot.x_m, spot.y_m, float(pose[2]), np.array([pose[:2], xy]))


class BraceAcross:
    """At a slow trajectory's point (`situation.goal`, within POINT_FAR_M), with a mover on course
    to it within yielding.horizon_s + BRACE_LEAD_S: turns the robot's axis across the mover's track,
    whichever way turns it less, so that its step aside is a drive along its axis (a Behaviour)."""

    def __init__(self, config: YieldConfig, movers: MoverModel) -> None:
        self.judge = SideStep(config, movers)
        self.horizon_s = config.horizon_s + BRACE_LEAD_S

    def reset(self) -> None:
        self.judge.reset()

    def propose(self, situation: Situation) -> Target | None:
        """The point, with the heading across the mover's track; or None."""
        pose, point = situation.pose, situation.goal
        if math.hypot(point[0] - pose[0], point[1] - pose[1]) > POINT_FAR_M:
            self.reset()
            return None
        point = np.asarray(point, dtype=float)
        step = self.judge.step(
            point[:2], point[2], np.zeros(2), situation.obstacles, horizon_s=self.horizon_s
        )
        if step is None:
            return None
        across = nearer_way(step.heading_rad, pose[2])
        return Target(float(point[0]), float(point[1]), across, np.array([pose[:2], point[:2]]))
