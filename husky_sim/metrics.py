"""Per-episode metrics and the outcome name, computed from the per-step log rows."""

from __future__ import annotations

import signal
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from controllers import Reference
from controllers.model import wrap_angle

if TYPE_CHECKING:
    from husky_sim.episode import Outcomes

#: What each outcome word means, for people reading results (results.md, README).
OUTCOME_MEANINGS = {
    "reached": "the Husky held the goal (position and heading tolerances) for goal_hold_s: success",
    "tracking": "a tracking run that ran its full duration without collision; `converged` says whether "
    "its RMSE after tracking_settle_s met the scenario's bound",
    "stuck": "a deadlock: over the last stuck_window_steps control steps the Husky neither moved nor "
    "turned and the controller commanded neither (or its solver kept failing and braking), away from "
    "the goal or reference",
    "collided": "the Husky's body touched an obstacle or a wall in the physics engine (clearance <= 0)",
    "timeout": "a point-stabilisation run that ended without reaching the goal, colliding or deadlocking",
    "interrupted": "Ctrl-C or SIGTERM ended the run early: not a result (the steps completed are kept)",
    "error": "the run crashed; the error is in the row (results.csv) and nothing was measured",
}
#: The outcomes an episode can have ("error" is a suite row's, not an episode's).
OUTCOMES = tuple(o for o in OUTCOME_MEANINGS if o != "error")


#: A command below this (m/s) counts as driving backwards.
REVERSE_SPEED_MPS = -0.01


def count_reversals(v_cmd_mps: np.ndarray) -> tuple[int, int]:
    """(times the command switched into reverse, control steps commanding reverse)."""
    backwards = np.asarray(v_cmd_mps) < REVERSE_SPEED_MPS
    if backwards.size == 0:
        return 0, 0
    return int(np.sum(backwards[1:] & ~backwards[:-1]) + int(backwards[0])), int(np.sum(backwards))


def tracking_rmse(errors_m: np.ndarray, t_s: np.ndarray, settle_s: float) -> float | None:
    """RMS of the position errors (m) from settle_s (s) on; None if the run ended before it."""
    settled = np.asarray(t_s) >= settle_s
    return float(np.sqrt(np.mean(np.asarray(errors_m)[settled] ** 2))) if np.any(settled) else None


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


@dataclass(frozen=True)
class EpisodeMetrics:
    """Headline figures of one episode (units in the names)."""

    outcome: str
    collided: bool
    converged: bool
    min_clearance_m: float | None
    final_position_error_m: float
    final_heading_error_rad: float
    tracking_rmse_m: float | None
    time_to_goal_s: float | None
    path_length_m: float
    reversals: int  # times the command went from forward/standing to backward (v < -0.01 m/s)
    reverse_steps: int  # control steps commanding v < -0.01 m/s
    max_abs_v_mps: float  # applied (after the drive's limits)
    max_abs_omega_radps: float
    max_abs_linear_accel_mps2: float
    max_abs_angular_accel_radps2: float
    solve_ms_median: float | None  # None only when no control step completed
    solve_ms_p95: float | None
    solve_ms_p99: float | None
    solve_ms_max: float | None
    solve_budget_ms: float  # tau: a solve slower than this delivers its command late on a robot
    solves_over_budget: int  # solves that took longer than tau (wall clock)
    fallbacks: int
    deadline_misses: int
    safety_active_steps: int
    steps: int
    sim_time_s: float
    wall_time_s: float
    robot_radius_m: float | None
    footprint_radius_m: float
    robot_radius_below_footprint: bool  # the controller's circle is smaller than the real body
    interrupted_by: str | None = None  # "SIGINT" / "SIGTERM" when outcome is "interrupted"

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def summarise(
    rows: Sequence[dict[str, object]],
    applied: np.ndarray,
    physics_dt_s: float,
    reference: Reference,
    is_setpoint: bool,
    outcome: str | None,
    reached_at: float | None,
    outcomes: Outcomes,
    tau_s: float,
    wall_time_s: float,
    *,
    robot_radius_m: float | None,
    footprint_radius_m: float,
    final_pose: np.ndarray,
    sim_time_s: float,
    interrupted_by: int | None = None,
) -> EpisodeMetrics:
    """Metrics of an episode whose rows were logged by husky_sim.episode (possibly none, when a
    signal ended it before the first control step)."""
    col: dict[str, np.ndarray] = (
        {key: np.array([r[key] for r in rows]) for key in rows[0]}
        if rows
        else defaultdict(lambda: np.zeros(0))
    )
    poses = np.vstack([np.column_stack([col["x_m"], col["y_m"], col["yaw_rad"]]), final_pose])
    t_end = len(rows) * tau_s
    ref_end = reference.state_at(t_end)
    final_pos = float(np.hypot(*(final_pose[:2] - ref_end[:2])))
    final_head = abs(float(wrap_angle(final_pose[2] - ref_end[2])))
    clearance = col["clearance_m"].astype(float)
    min_clear = float(np.min(clearance)) if np.any(np.isfinite(clearance)) else None  # None: no obstacles
    collided = min_clear is not None and min_clear <= 0.0
    rmse = None
    if not is_setpoint:
        errs = np.hypot(col["x_m"] - col["ref_x_m"], col["y_m"] - col["ref_y_m"])
        rmse = tracking_rmse(errs, col["t_s"], outcomes.tracking_settle_s)
    if interrupted_by is not None:
        outcome = "interrupted"  # never judged as a result, whatever happened before the signal
    elif outcome is None:
        outcome = "collided" if collided else ("timeout" if is_setpoint else "tracking")
    converged = (
        (outcome == "reached")
        if is_setpoint
        else (outcome == "tracking" and rmse is not None and rmse <= outcomes.tracking_rmse_m)
    )
    reversals, reverse_steps = count_reversals(col["v_cmd_mps"])
    accel = np.abs(np.diff(applied, axis=0)) / physics_dt_s if len(applied) > 1 else np.zeros((1, 2))
    solve = col["solve_ms"].astype(float)

    def solve_stat(percentile: float) -> float | None:  # None: no solve happened (interrupted at once)
        return float(np.percentile(solve, percentile)) if solve.size else None

    return EpisodeMetrics(
        outcome=outcome,
        collided=collided,
        converged=bool(converged),
        min_clearance_m=min_clear,
        final_position_error_m=final_pos,
        final_heading_error_rad=final_head,
        tracking_rmse_m=rmse,
        time_to_goal_s=reached_at if outcome == "reached" else None,
        path_length_m=float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T))),
        reversals=reversals,
        reverse_steps=reverse_steps,
        max_abs_v_mps=float(np.max(np.abs(applied[:, 0]))),
        max_abs_omega_radps=float(np.max(np.abs(applied[:, 1]))),
        max_abs_linear_accel_mps2=float(np.max(accel[:, 0])),
        max_abs_angular_accel_radps2=float(np.max(accel[:, 1])),
        solve_ms_median=solve_stat(50),
        solve_ms_p95=solve_stat(95),
        solve_ms_p99=solve_stat(99),
        solve_ms_max=solve_stat(100),
        solve_budget_ms=1000.0 * tau_s,
        solves_over_budget=int(np.sum(solve > 1000.0 * tau_s)),
        fallbacks=int(np.sum(col["fallback"] != "none")),
        deadline_misses=int(np.sum(col["deadline_miss"])),
        safety_active_steps=int(np.sum(col["safety_active"] > 0)),
        steps=len(rows),
        sim_time_s=sim_time_s,
        wall_time_s=wall_time_s,
        robot_radius_m=robot_radius_m,
        footprint_radius_m=footprint_radius_m,
        robot_radius_below_footprint=robot_radius_m is not None and robot_radius_m < footprint_radius_m,
        interrupted_by=None if interrupted_by is None else signal.Signals(interrupted_by).name,
    )
