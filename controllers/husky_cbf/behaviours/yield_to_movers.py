"""Yielding to movers: three behaviours on one judgement of a mover's course (SideStep).

A skid-steer needs a second or two to turn, so a short horizon that first sees a mover when its
constraint activates can only back away in front of it (and be chased). So each mover's track
relative to a point is extrapolated yielding.horizon_s ahead; a mover whose closest approach comes
within its radius plus the robot's inflation plus yielding.margin_m (or plus the NMPC's growth of
that mover and the planner's release margin, if that is more) is on a collision course, and the
step aside is the point that much to the side of the mover's relative line.

- StepAside: from the robot itself, judged at the velocity the robot means to have.
- WaitBeside: on the way back to a slow trajectory's point, with a mover on course to that point:
  where the robot would step aside to from the point, on the robot's own side of the mover's line.
- BraceAcross: at a slow trajectory's point, with a mover on course to it within a longer horizon:
  the robot turns its axis across the mover's track, so that its step aside is a drive along it.

The NMPC's obstacle constraints stay in force throughout: yielding only moves the target.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from controllers.husky_cbf.behaviours.approach import POINT_FAR_M
from controllers.husky_cbf.behaviours.base import ReferenceKind, Situation, Target, nearer_way
from controllers.husky_cbf.config import YieldConfig
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
    ) -> Target | None:
        """The step aside from the soonest mover on a collision course with `point_xy` [x, y] (m)
        moving at `velocity_mps` [vx, vy] (m/s, world frame), or None; its heading is the step's
        direction or its opposite, whichever is nearer `heading_rad` (the heading at the point).
        The step goes to the side of the mover's line that the point `side_of` [x, y] (m) is on,
        if given (else away from the line; to the left when dead ahead); movers are judged over
        `horizon_s` (s; default yielding.horizon_s)."""
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
                threat, soonest = (closest, rel_v, needed), t_c
        self.soonest_s = soonest  # the threat's time to its closest approach (s); inf: none
        if threat is None:
            self.side = 0.0
            return None
        closest, rel_v, needed = threat
        normal = np.array([-rel_v[1], rel_v[0]]) / np.hypot(*rel_v)  # left of the relative track
        if not self.side:
            offset = float(closest @ normal)  # > 0: the mover passes left of the point
            if side_of is not None:  # ... left of `side_of`
                offset -= float((np.asarray(side_of, dtype=float) - point_xy) @ normal)
            # step to the other side (left if dead ahead)
            self.side = -1.0 if offset > DEAD_AHEAD_M else 1.0
        shift = needed + self.side * float(closest @ normal)  # to `needed` beyond the mover's line
        step = self.side * normal * max(shift, 0.0)
        target = point_xy + step
        heading = nearer_way(math.atan2(step[1], step[0]), heading_rad)  # reversing if that turns less
        return Target(float(target[0]), float(target[1]), heading, np.array([point_xy, target]))


class StepAside:
    """Steps the robot aside from a mover on a collision course with it (a Behaviour)."""

    def __init__(self, config: YieldConfig, movers: MoverModel) -> None:
        self.judge = SideStep(config, movers)

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
        pose = situation.pose
        return self.judge.step(pose[:2], pose[2], self.meant_velocity(situation), situation.obstacles)


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
