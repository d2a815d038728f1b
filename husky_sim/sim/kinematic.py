"""Kinematic closed loop: the controller drives its own unicycle model (RK4 over tau), no physics.

This is the paper's MATLAB-style simulation, kept as a reference point next to the PyBullet runs:
it isolates the controller's behaviour from wheel slip, actuator limits and body geometry.
Obstacles move at constant velocity; clearance is measured on the circle model every step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from controllers import Controller, Obstacle, Reference, SetPoint
from controllers.model import step, wrap_angle
from husky_sim.sim.metrics import count_reversals
from husky_sim.sim.outcomes import Outcomes


@dataclass
class KinematicEpisode:
    """Per-step record of a kinematic closed-loop run and its headline figures."""

    times_s: np.ndarray  # (K+1,)
    states: np.ndarray  # (K+1, 3)
    controls: np.ndarray  # (K, 2)
    clearance_m: np.ndarray  # (K+1,) min over obstacles of centre distance - radii sum
    min_decay_slack: np.ndarray  # (K,) smallest s_h of each solved plan
    safety_active: np.ndarray  # (K,) active obstacle constraints per step
    solve_time_s: np.ndarray  # (K,)
    fallbacks: int
    reached: bool
    time_to_goal_s: float | None
    statuses: list[str] = field(default_factory=list)

    @property
    def min_clearance_m(self) -> float:
        return float(np.min(self.clearance_m))

    @property
    def collided(self) -> bool:
        return self.min_clearance_m < 0.0

    @property
    def reversals(self) -> int:
        """Times the command switched into reverse (see husky_sim.sim.metrics.count_reversals)."""
        return count_reversals(self.controls[:, 0])[0]

    @property
    def reverse_steps(self) -> int:
        """Control steps commanding reverse."""
        return count_reversals(self.controls[:, 0])[1]

    @property
    def safety_active_steps(self) -> int:
        return int(np.sum(self.safety_active > 0))

    def final_errors(self, reference: Reference) -> tuple[float, float]:
        """Final position (m) and wrapped heading (rad) errors against the reference."""
        ref = reference.state_at(float(self.times_s[-1]))
        pos = float(np.hypot(*(self.states[-1, :2] - ref[:2])))
        return pos, abs(float(wrap_angle(self.states[-1, 2] - ref[2])))


def obstacles_at(obstacles: Sequence[Obstacle], t_s: float) -> list[Obstacle]:
    """Constant-velocity obstacles as seen at time t_s (position advanced, velocity kept)."""
    out = []
    for o in obstacles:
        x, y = o.position_after(t_s)
        out.append(Obstacle(float(x), float(y), o.radius_m, o.vx_mps, o.vy_mps))
    return out


def clearance(position_xy: np.ndarray, obstacles: Sequence[Obstacle], robot_radius_m: float) -> float:
    """Smallest centre distance minus radii sum (m); +inf without obstacles."""
    if not obstacles:
        return float("inf")
    return min(
        float(np.hypot(position_xy[0] - o.x_m, position_xy[1] - o.y_m)) - o.radius_m - robot_radius_m
        for o in obstacles
    )


def run_kinematic(
    controller: Controller,
    start: Sequence[float],
    reference: Reference,
    obstacles: Sequence[Obstacle],
    tau_s: float,
    duration_s: float,
    robot_radius_m: float,
    outcomes: Outcomes | None = None,
) -> KinematicEpisode:
    """Run the closed loop for duration_s (s); a set-point run stops once the goal is held within
    the goal tolerances of `outcomes` (position m, heading rad, for goal_hold_s)."""
    outcomes = outcomes or Outcomes()
    controller.reset()
    steps = int(round(duration_s / tau_s))
    hold_steps = max(int(round(outcomes.goal_hold_s / tau_s)), 1)
    state = np.asarray(start, dtype=float)
    states, controls, clear, sh, active, solve_t, statuses = [state], [], [], [], [], [], []
    clear.append(clearance(state, obstacles_at(obstacles, 0.0), robot_radius_m))
    fallbacks, in_tol, reached_at = 0, 0, None
    for k in range(steps):
        t = k * tau_s
        result = controller.solve(state, reference, obstacles_at(obstacles, t), t)
        state = step(state, result.control, tau_s)
        states.append(state)
        controls.append(result.control)
        sh.append(float(np.min(result.decay_slack)))
        active.append(result.safety_active)
        solve_t.append(result.solve_time_s)
        statuses.append(result.status)
        fallbacks += result.is_fallback
        clear.append(clearance(state, obstacles_at(obstacles, t + tau_s), robot_radius_m))
        if isinstance(reference, SetPoint):
            goal = reference.state_at(t + tau_s)
            ok = (
                np.hypot(*(state[:2] - goal[:2])) <= outcomes.goal_position_m
                and abs(wrap_angle(state[2] - goal[2])) <= outcomes.goal_heading_rad
            )
            in_tol = in_tol + 1 if ok else 0
            if in_tol == 1:
                reached_at = t + tau_s
            if in_tol >= hold_steps:
                break
    reached = in_tol >= hold_steps
    return KinematicEpisode(
        times_s=tau_s * np.arange(len(states)),
        states=np.array(states),
        controls=np.array(controls).reshape(-1, 2),
        clearance_m=np.array(clear),
        min_decay_slack=np.array(sh),
        safety_active=np.array(active),
        solve_time_s=np.array(solve_t),
        fallbacks=fallbacks,
        reached=reached,
        time_to_goal_s=reached_at if reached else None,
        statuses=statuses,
    )
