"""An episode's outcome, decided in one place and fed step by step: the thresholds (`Outcomes`)
and the monitor that applies them after every control step (`OutcomeMonitor`). The closed loop
(husky_sim.sim.rollout, for the PyBullet and the kinematic plant alike) and the gymnasium
environment (husky_sim.sim.environment) both use it, so a run and an environment episode end for
the same reasons."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from controllers import Reference, SetPoint
from controllers.model import wrap_angle


@dataclass(frozen=True)
class Outcomes:
    """Thresholds that name an episode's outcome."""

    goal_position_m: float = 0.1  # point stabilisation: position error bound
    goal_heading_rad: float = 0.1  # point stabilisation: heading error bound
    goal_hold_s: float = 1.0  # both bounds held this long -> reached
    tracking_settle_s: float = 10.0  # tracking RMSE counted after this time
    tracking_rmse_m: float = 0.3  # tracking converged when RMSE <= this (metrics.judge_tracking)
    # once an obstacle has left the reference, the error must be back below tracking_rmse_m within
    # this (s). 5 s: going round an obstacle on the reference leaves the Husky up to ~3 m behind (a
    # 0.45 m obstacle plus the 0.82 m robot circle either side is 2.5 m across), and at its 1 m/s
    # limit it gains >= 0.6 m/s on the shipped references (0.23 to 0.4 m/s): 3 m in 5 s. A robot
    # that needs longer once the way is clear is waiting or lagging, not tracking.
    rejoin_s: float = 5.0
    # the instants this long (s) before the reference becomes unreachable are not judged either: a
    # robot standing on it must be gone when the obstacle arrives. 2 s: to take its circle out of
    # a mover's way (the robot's plus the mover's radius, 1.1 to 1.3 m on the shipped scenarios)
    # the Husky drives that far sideways, which at its 1 m/s and 1 m/s^2 (ROS 2 limits) alone takes
    # 1.6 to 1.8 s, before any turn towards the side; a robot that leaves earlier is judged.
    leave_s: float = 2.0
    stuck_window_steps: int = 10  # mean |v| over this many control steps ...
    stuck_speed_mps: float = 0.05  # ... below this, away from the reference -> stuck
    # ... and mean |yaw rate| below this: a skid-steer robot turning in place is not stuck
    stuck_yaw_rate_radps: float = 0.05
    stuck_grace_s: float = 2.0  # no stuck verdict before this time
    stop_on_collision: bool = True
    stop_early: bool = True  # end the episode once reached or stuck (else run the full duration)


def is_idle(v: np.ndarray, omega: np.ndarray, outcomes: Outcomes) -> bool:
    """The stuck rule's motion test: a full window of `stuck_window_steps` whose mean |v| (m/s) and
    mean |omega| (rad/s) are both below their thresholds (turning in place is not idle)."""
    return (
        len(v) == outcomes.stuck_window_steps
        and float(np.mean(np.abs(v))) < outcomes.stuck_speed_mps
        and float(np.mean(np.abs(omega))) < outcomes.stuck_yaw_rate_radps
    )


def is_stuck_window(rows: Sequence[dict[str, object]], outcomes: Outcomes) -> bool:
    """The stuck rule over the last `stuck_window_steps` logged control steps: the robot is idle
    (measured body velocities, `is_idle`) and the controller is not trying to move it either (the
    commanded v and omega are idle by the same thresholds: a command the skid-steer cannot yet
    follow, such as a slow turn in place, is progress). A window that starts right after a solver
    fallback, or in which the controller resumed after one, is not judged: the drive is ramping up
    from the brake. A window of nothing but fallbacks (a solver that keeps failing and braking) is
    judged like any other: that robot is stuck."""
    n = outcomes.stuck_window_steps
    window = rows[-n:]
    if len(window) < n:
        return False
    recent = rows[-(n + 1) :]  # the step before the window too: "right after a fallback"
    resumed = any(
        a["fallback"] != "none" and b["fallback"] == "none" for a, b in zip(recent, recent[1:], strict=False)
    )
    if resumed:
        return False
    return is_idle(
        [r["v_body_mps"] for r in window], [r["omega_body_radps"] for r in window], outcomes
    ) and is_idle([r["v_cmd_mps"] for r in window], [r["omega_cmd_radps"] for r in window], outcomes)


def final_outcome(
    decided: str | None, *, collided: bool, is_setpoint: bool, interrupted: bool = False
) -> str:
    """The episode's outcome word: `interrupted` whatever happened before the signal, else what
    the step-by-step rules decided, else `collided` if the clearance ever reached 0, else
    `timeout` (a set-point not reached) or `tracking` (a tracking run that ran its time)."""
    if interrupted:
        return "interrupted"
    if decided is not None:
        return decided
    return "collided" if collided else ("timeout" if is_setpoint else "tracking")


def reference_error(pose: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """Position error (m) and absolute heading error (rad) of a pose against a reference state."""
    return float(np.hypot(*(pose[:2] - ref[:2]))), abs(float(wrap_angle(pose[2] - ref[2])))


def reference_reachable(
    ref_xy_m: np.ndarray, obstacle_xy_m: np.ndarray, obstacle_radius_m: np.ndarray, robot_radius_m: float
) -> np.ndarray:
    """Whether the reference point (m; shape (..., 2)) lies outside every obstacle circle (centres
    (..., M, 2) m, radii (M,) m) inflated by the robot's radius (m): distance > r_obs + r_robot.
    Tracking is judged only where it holds (husky_sim.sim.metrics.judge_tracking)."""
    ref = np.asarray(ref_xy_m, dtype=float)[..., None, :]
    distance = np.hypot(*np.moveaxis(ref - np.asarray(obstacle_xy_m, dtype=float), -1, 0))
    return np.all(distance > np.asarray(obstacle_radius_m, dtype=float) + robot_radius_m, axis=-1)


def mover_within_reach(
    robot_xy_m: np.ndarray,
    obstacle_centres: Callable[[float], np.ndarray],
    obstacle_radius_m: np.ndarray,
    robot_radius_m: float,
    t_s: float,
    tau_s: float,
    ahead_s: float,
) -> bool:
    """Whether a mover could reach the robot's circle at robot_xy_m (m) within ahead_s (s) at its
    true speed at t_s (s), in whatever direction: gap <= speed * ahead_s, the gap between its
    circle and the robot's (m), its speed from its true motion over the next tau_s (s). Static
    obstacles never count. A robot that stands this close to a mover is giving way to it, not
    deadlocked (OutcomeMonitor.update's `waiting`)."""
    now, then = obstacle_centres(t_s), obstacle_centres(t_s + tau_s)
    if len(now) == 0:
        return False
    speed = np.hypot(*(then - now).T) / tau_s
    gap = np.hypot(*(now - np.asarray(robot_xy_m, dtype=float)[:2]).T) - obstacle_radius_m - robot_radius_m
    return bool(np.any((speed > 0.0) & (gap <= speed * ahead_s)))


class ReferenceBlockage:
    """The latest control instant (s) at which the reference point is unreachable
    (reference_reachable), looked ahead_s (s) into the obstacles' true motion, which is the
    simulator's to know. Each instant k tau is judged once, as the look-ahead reaches it."""

    def __init__(
        self,
        reference: Reference,
        obstacle_centres: Callable[[float], np.ndarray],
        obstacle_radius_m: np.ndarray,
        robot_radius_m: float,
        tau_s: float,
        ahead_s: float,
    ) -> None:
        self._reference, self._centres = reference, obstacle_centres
        self._radii, self._robot_radius_m = obstacle_radius_m, robot_radius_m
        self._tau_s, self._ahead_steps = tau_s, round(ahead_s / tau_s)
        self._next_step = 0  # the first instant not yet judged, in steps of tau
        self._latest_s = -math.inf

    def waiting(self, step: int) -> bool:
        """Whether the reference is unreachable at control step `step` or at any instant up to
        ahead_s after the next one (the window OutcomeMonitor.update's `waiting` means)."""
        last = step + 1 + self._ahead_steps
        while self._next_step <= last:
            t = self._next_step * self._tau_s
            ref = self._reference.state_at(t)[:2]
            if not reference_reachable(ref, self._centres(t), self._radii, self._robot_radius_m):
                self._latest_s = t
            self._next_step += 1
        return self._latest_s >= step * self._tau_s - 1e-9


class OutcomeMonitor:
    """Names the outcome after each control step: `collided` when the clearance reaches
    -contact_tolerance_m (whatever happens after it), `reached` when a set-point is held within its
    tolerance for `goal_hold_s`, `stuck` when the robot idles away from the reference
    (is_stuck_window) and was not waiting for its reference to come free, or for a mover to pass,
    in the last stuck_grace_s (`update`'s `waiting`); `update` says whether the episode ends there
    (Outcomes.stop_on_collision, stop_early; a held goal ends it even after a collision, which
    still names it).

    `contact_tolerance_m`: 0 for the physics engine's clearance; the kinematic loop's exact circle
    model meets a constraint boundary to the solver's tolerance, which is contact, not collision.
    `stuck_at_end`: judge the stuck rule once, on the last window of commands (`finish`), instead
    of after every step: the paper's kinematic loop runs its full time, and its robots stop in
    front of an obstacle for seconds before going round it."""

    def __init__(
        self,
        reference: Reference,
        outcomes: Outcomes,
        tau_s: float,
        *,
        contact_tolerance_m: float = 0.0,
        stuck_at_end: bool = False,
    ) -> None:
        self.reference, self.outcomes = reference, outcomes
        self.is_setpoint = isinstance(reference, SetPoint)
        self._hold_steps = max(round(outcomes.goal_hold_s / tau_s), 1)
        self._contact_tolerance_m = contact_tolerance_m
        self._stuck_at_end = stuck_at_end
        self._in_tolerance = 0
        self._entered_at: float | None = None
        self._position_error_m = math.nan  # at the last step judged
        self.outcome: str | None = None
        self.goal_held = False  # the set-point was held for goal_hold_s (even after a collision)
        self.reached_at: float | None = None  # s: entry into the tolerance band that was then held
        self._waited_at = -math.inf  # s: the last step at which the robot was waiting (update)

    def update(
        self,
        t_next: float,
        pose: np.ndarray,
        clearance: float,
        rows: Sequence[dict[str, object]],
        waiting: bool = False,
    ) -> bool:
        """Judge the step that ended at t_next (s) with the robot at `pose` (x m, y m, yaw rad) and
        the smallest clearance (m) over its physics steps; `rows` are the control steps so far
        (the stuck rule reads their velocities, commands and fallbacks). `waiting`: the reference
        is unreachable now or within leave_s (ReferenceBlockage), or a mover could reach the robot
        within leave_s (mover_within_reach). A robot that waits for a mover to pass its reference
        or its way is not deadlocked, so the stuck rule is not judged until stuck_grace_s after
        that; a robot that never moves on still fails, as a timeout or as tracking not converged.
        True: stop here."""
        outcomes = self.outcomes
        if waiting:
            self._waited_at = t_next
        if clearance <= -self._contact_tolerance_m:
            self.outcome = "collided"  # a collision names the episode whatever happens after it
            if outcomes.stop_on_collision:
                return True
        pos_err, head_err = reference_error(pose, self.reference.state_at(t_next))
        self._position_error_m = pos_err
        if self.is_setpoint and not self.goal_held:
            ok = pos_err <= outcomes.goal_position_m and head_err <= outcomes.goal_heading_rad
            self._in_tolerance = self._in_tolerance + 1 if ok else 0
            if self._in_tolerance == 1:
                self._entered_at = t_next
            if self._in_tolerance >= self._hold_steps:
                self.goal_held, self.reached_at = True, self._entered_at
                if self.outcome is None:
                    self.outcome = "reached"
                if outcomes.stop_early:
                    return True
        if (
            not self._stuck_at_end
            and self._away(pos_err)
            and t_next >= outcomes.stuck_grace_s
            and t_next - self._waited_at >= outcomes.stuck_grace_s
            and is_stuck_window(rows, outcomes)
            and self.outcome is None
        ):
            self.outcome = "stuck"
            if outcomes.stop_early:
                return True
        return False

    def finish(self, rows: Sequence[dict[str, object]]) -> None:
        """After the last step: with `stuck_at_end`, an undecided episode whose last
        `stuck_window_steps` commands were idle (is_idle), away from the reference, is `stuck`."""
        if not self._stuck_at_end or self.outcome is not None:
            return
        window = rows[-self.outcomes.stuck_window_steps :]
        v, omega = [r["v_cmd_mps"] for r in window], [r["omega_cmd_radps"] for r in window]
        if is_idle(v, omega, self.outcomes) and self._away(self._position_error_m):
            self.outcome = "stuck"

    def _away(self, position_error_m: float) -> bool:
        outcomes = self.outcomes
        return position_error_m > (outcomes.goal_position_m if self.is_setpoint else outcomes.tracking_rmse_m)
