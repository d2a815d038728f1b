"""The arbiter: which target the NMPC tracks this step, chosen among the behaviours' proposals by
one explicit, ordered policy (`Arbiter.decide`).

The policy, in order:

1. YIELD, step aside: a mover on a collision course with the robot (StepAside) is always judged
   first. Stepping aside, or any kind of reference but a slow trajectory, ends waiting beside the
   point (WaitBeside is reset).
2. RECOVER: recovery's target wins outright when it has one. Never on a slow trajectory (the robot
   waits for movers there on purpose); paused (stalls forgotten) while stepping aside. A detour is
   no exception: a robot that makes no progress along the planner's way round is stalled too.
3. The behaviour's target, unless stepping aside:
   - a slow trajectory: YIELD, wait beside the point for a mover on course to it (the point
     approach then leads to the waiting spot); else APPROACH the point (PointApproach), and, at
     the point, YIELD by bracing across a mover's track (BraceAcross), which overrides the
     approach (waiting beside the point comes first);
   - a set-point: APPROACH along the goal's line (SetPointApproach);
   - a trajectory: none.
4. DETOUR: the planner's waypoint towards that target (or the goal), when the straight way is
   blocked; stepping aside, the waypoint's heading is taken backwards if that turns the robot less.
5. The target of step 1 or 3 as it is (YIELD or APPROACH), else TRACK: the reference itself.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from controllers.husky_cbf.behaviours.approach import PointApproach, SetPointApproach
from controllers.husky_cbf.behaviours.base import ReferenceKind, Situation, Target, nearer_way
from controllers.husky_cbf.behaviours.recovery import Recovery
from controllers.husky_cbf.behaviours.yield_to_movers import BraceAcross, RobotLimits, StepAside, WaitBeside
from controllers.husky_cbf.config import HuskyCBFConfig
from controllers.husky_cbf.movers import MoverModel
from controllers.husky_cbf.planner import Planner


class Mode(Enum):
    """What the target the NMPC tracks comes from (the module docstring gives the policy's order)."""

    YIELD = "yield"  # out of a mover's way (behaviours.yield_to_movers)
    RECOVER = "recover"  # recovery from a stall (behaviours.recovery)
    APPROACH = "approach"  # onto a set-point's line, or at a slow trajectory's point
    DETOUR = "detour"  # the planner's waypoint round a blocked straight way
    TRACK = "track"  # the reference itself


@dataclass(frozen=True)
class Decision:
    """The arbiter's choice: its mode and target (None: track the reference), and what the NMPC's
    set-up reads from the behaviours this step: whether the robot steps aside from a mover (no
    approach speed cap), is meant to reverse (the terminal lookahead behind it), and is settling
    on a set-point's heading (no terminal lookahead)."""

    mode: Mode
    target: Target | None
    stepping_aside: bool
    reversing: bool
    settling: bool

    @property
    def guided(self) -> bool:
        """Whether the NMPC tracks a behaviour's or the planner's target, not the reference."""
        return self.target is not None


class Arbiter:
    """Holds the planner and the behaviours, and decides each step (module docstring)."""

    def __init__(
        self,
        planner: Planner,
        step_aside: StepAside,
        wait_beside: WaitBeside,
        brace_across: BraceAcross,
        set_point_approach: SetPointApproach,
        point_approach: PointApproach,
        recovery: Recovery,
    ) -> None:
        self.planner = planner
        self.step_aside = step_aside
        self.wait_beside = wait_beside
        self.brace_across = brace_across
        self.set_point_approach = set_point_approach
        self.point_approach = point_approach
        self.recovery = recovery

    @classmethod
    def build(cls, config: HuskyCBFConfig, movers: MoverModel, tau_s: float, swing_m: float) -> Arbiter:
        """husky-cbf's arbiter: its planner and behaviours configured from `config`, reading the
        mover model `movers`; `swing_m` is how much farther the body's corners reach turning in
        place than its discs (recovery's room to turn)."""
        planner = Planner(config.planner, movers)
        return cls(
            planner,
            StepAside(config.yielding, movers, RobotLimits.of(config)),
            WaitBeside(config.yielding, movers, config.approach.speed_mps),
            BraceAcross(config.yielding, movers),
            SetPointApproach(config.approach, config.planner.grid_resolution_m),
            PointApproach(),
            Recovery(config.recovery, tau_s, swing_m, planner),
        )

    def reset(self) -> None:
        self.planner.reset()
        self.set_point_approach.reset()
        self.step_aside.reset()
        self.wait_beside.reset()
        self.brace_across.reset()
        self.point_approach.reset()
        self.recovery.reset()

    def decide(self, situation: Situation) -> Decision:
        """This step's target for the NMPC (the policy in the module docstring)."""
        s = situation
        slow = s.kind is ReferenceKind.SLOW_TRAJECTORY
        # 1. YIELD: step aside from a mover on course to the robot
        target = self.step_aside.propose(s)
        mode = Mode.YIELD
        if target is not None or not slow:
            self.wait_beside.reset()
        # 2. RECOVER
        recovering = self._recovery(s, stepping_aside=target is not None)
        if recovering is not None:
            return self._decision(Mode.RECOVER, recovering)
        # 3. the behaviour's target for this kind of reference
        if target is None and slow:
            target, mode = self._at_slow_point(s)
        elif target is None and s.kind is ReferenceKind.SET_POINT:
            target, mode = self.set_point_approach.propose(s), Mode.APPROACH
        # 4. DETOUR towards that target, or the goal
        goal = s.goal if target is None else target.state
        detour = self.planner.waypoint(
            s.pose[:2], goal, s.obstacles, self.recovery.tabu_circles(s.t), may_wait=not slow
        )
        if detour is not None:
            if self.step_aside.active:
                detour = replace(detour, heading_rad=nearer_way(detour.heading_rad, s.pose[2]))
            return self._decision(Mode.DETOUR, detour)
        # 5. the target as it is, or the reference
        return self._decision(mode, target) if target is not None else self._decision(Mode.TRACK, None)

    def _recovery(self, s: Situation, stepping_aside: bool) -> Target | None:
        """Recovery's target where the policy lets it act (step 2), else None."""
        if not self.recovery.enabled or s.kind is ReferenceKind.SLOW_TRAJECTORY:
            return None
        if stepping_aside:
            self.recovery.pause()
            return None
        return self.recovery.propose(s)

    def _at_slow_point(self, s: Situation) -> tuple[Target | None, Mode]:
        """Step 3 on a slow trajectory: wait beside its point, approach it, or brace across."""
        spot = self.wait_beside.propose(s)
        if spot is None:
            target, mode = self.point_approach.propose(s), Mode.APPROACH
        else:  # to the waiting spot as to the point, facing as the robot does once there
            at_spot = replace(s, goal=np.array([spot.x_m, spot.y_m, s.goal[2]]))
            target, mode = self.point_approach.propose(at_spot) or spot, Mode.YIELD
        across = None if spot is not None else self.brace_across.propose(s)
        if across is not None:
            target, mode = across, Mode.YIELD
        return target, mode

    def _decision(self, mode: Mode, target: Target | None) -> Decision:
        return Decision(
            mode,
            target,
            stepping_aside=self.step_aside.active,
            reversing=self.set_point_approach.reversing or self.recovery.reversing,
            settling=self.set_point_approach.settling,
        )
