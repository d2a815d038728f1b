"""The one small interface between a simulator and a controller.

A simulator calls `reset()` at the start of an episode and `solve(state, reference, obstacles, t)`
once per control step; it applies `ControlResult.control` until the next step. Nothing else of
the controller is needed by the simulator, and `controllers` never imports the simulator.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from controllers.obstacles import Obstacle
from controllers.references import Reference

FallbackKind = Literal["none", "previous-plan", "brake"]


@dataclass
class ControlResult:
    """One control step's decision and everything worth logging about it."""

    control: np.ndarray  # [v (m/s), omega (rad/s)] to apply now
    predicted_states: np.ndarray  # (N+1, 3) planned [x, y, theta], step k at plan_start_s + k tau
    predicted_controls: np.ndarray  # (N, 2) planned [v, omega]
    clf_slack: np.ndarray  # s_v (N,)
    decay_slack: np.ndarray  # s_h (N,); ones where s_h is not a variable
    predicted_barrier: np.ndarray  # (obstacles considered, N+1) B = d^2 - (r_rb + r_ob)^2 (m^2)
    safety_active: int  # obstacle constraints at their bound (residual <= ACTIVE_TOL)
    status: str  # the solver's return status, or the reason of a fallback
    success: bool  # the solver converged to a (possibly acceptable) optimum
    fallback: FallbackKind  # what was applied instead of a solved plan
    iterations: int  # solver iterations (-1 when no solve ran or the solver does not report it)
    solve_time_s: float  # wall time of the whole `solve` call (s)
    obstacles_considered: int  # obstacles in the NLP this step (<= obstacle slots)
    obstacles_ignored: int  # obstacles dropped because more than the slots were given
    recovered_by: str = ""  # the retry guess that solved after a failed solve (controllers.recovery)
    soft_constraint: bool = False  # solved only with the obstacle constraint's exact-penalty slack
    guided: bool = False  # tracked a waypoint instead of the reference (a behaviour's, a planner's)
    solver: str = ""  # the NLP solver whose answer this is (fatrop, ipopt, opti)
    solver_fallback: str = ""  # why the structured solver's answer was not used (IPOPT solved)
    # no solver ran: every problem of the step had been solved before, this step or the last, bit
    # for bit, and its answer was reused (controllers.backends.repeats)
    repeated: bool = False
    #: when the plan starts after the measurement it was solved from (s): 0 for a plan from the
    #: measured pose; husky-cbf's starts where the drive acts on its first command (its dead time)
    plan_start_s: float = 0.0
    #: the deadlock recovery's phase this step ("" when none; husky-cbf's behaviours/recovery.py):
    #: the controller found itself making no progress and follows a recovery waypoint
    escape: str = ""
    #: a safety filter sent another command than the plan's first (husky-cbf's safety_filter.py):
    #: the committed trajectory, a braking or evasive backup, or an evasion went instead
    filtered: bool = False
    #: the behaviour whose target the plan tracked ("" where a controller has none): husky-cbf's
    #: arbiter mode (track, detour, yield, approach, recover; arbiter.py)
    mode: str = ""

    @property
    def is_fallback(self) -> bool:
        return self.fallback != "none"

    @classmethod
    def brake(
        cls,
        horizon: int,
        considered: int,
        ignored: int,
        solve_time_s: float,
        status: str,
        guided: bool = False,
        mode: str = "",
    ) -> ControlResult:
        """A braking command (v = 0, omega = 0) with no plan: what a controller applies when no
        solve gave one."""
        n = horizon
        return cls(
            control=np.zeros(2),
            predicted_states=np.full((n + 1, 3), np.nan),
            predicted_controls=np.zeros((n, 2)),
            clf_slack=np.zeros(n),
            decay_slack=np.ones(n),
            predicted_barrier=np.full((considered, n + 1), np.nan),
            safety_active=0,
            status=status,
            success=False,
            fallback="brake",
            iterations=-1,
            solve_time_s=solve_time_s,
            obstacles_considered=considered,
            obstacles_ignored=ignored,
            guided=guided,
            mode=mode,
        )


class Controller(Protocol):
    """What a simulator needs from a controller."""

    def reset(self) -> None:
        """Forget the previous plan (new episode)."""

    def solve(
        self, state: np.ndarray, reference: Reference, obstacles: Sequence[Obstacle], t: float
    ) -> ControlResult:
        """Control for measured state [x, y, theta] (m, m, rad) at time t (s); never raises for a
        solver failure."""
