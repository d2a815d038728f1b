"""Per-episode metrics and the outcome name, computed from the rollout's per-step rows."""

from __future__ import annotations

import signal
from collections import defaultdict
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from controllers.model import wrap_angle
from husky_sim.sim.outcomes import Outcomes, final_outcome

if TYPE_CHECKING:
    from husky_sim.sim.rollout import Rollout

#: What each outcome word means, for people reading results (results.md, docs/index.md).
OUTCOME_MEANINGS = {
    "reached": "the Husky held the goal (position and heading tolerances) for goal_hold_s: success",
    "tracking": "a tracking run that ran its full duration without collision; `converged` says whether "
    "it tracked wherever tracking was possible: after tracking_settle_s, its RMSE over the instants when "
    "the reference point was reachable (outside every obstacle's circle inflated by the robot's) met the "
    "scenario's bound, and each time an obstacle had left the reference the robot came back within that "
    "bound in at most rejoin_s (instants while it was rejoining are judged by that rule, not the RMSE)",
    "stuck": "a deadlock: over the last stuck_window_steps control steps the Husky neither moved nor "
    "turned and the controller commanded neither (or its solver kept failing and braking), away from "
    "the goal or reference, while that was reachable (not while waiting for it to come free or for a "
    "mover within leave_s of the robot at its speed to pass, nor for stuck_grace_s after)",
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


def solver_times(solve_times: np.ndarray, repeated: np.ndarray) -> np.ndarray:
    """The solve times (in their unit) of the control steps that ran a solver: a `repeated` step's
    answers were all looked up (controllers.backends.repeats), and its time would make a deadlock's
    figures look fast."""
    return np.asarray(solve_times, dtype=float)[~np.asarray(repeated, dtype=bool)]


def tracking_rmse(errors_m: np.ndarray, t_s: np.ndarray, settle_s: float) -> float | None:
    """RMS of the position errors (m) from settle_s (s) on; None if the run ended before it."""
    settled = np.asarray(t_s) >= settle_s
    return float(np.sqrt(np.mean(np.asarray(errors_m)[settled] ** 2))) if np.any(settled) else None


@dataclass(frozen=True)
class TrackingJudgement:
    """A tracking run judged where tracking was possible (see `judge_tracking`)."""

    rmse_reachable_m: float | None  # RMSE over the judged instants after settle; None: none judged
    blocked_s: float  # time the reference point was unreachable (whole run)
    rejoin_times_s: tuple[float, ...]  # every measured rejoin, in order
    converged: bool

    def fields(self) -> dict[str, float | None]:
        """The summary's figures of this judgement (units in the names)."""
        return {
            "tracking_rmse_reachable_m": self.rmse_reachable_m,
            "reference_blocked_s": self.blocked_s,
            "rejoin_time_max_s": max(self.rejoin_times_s) if self.rejoin_times_s else None,
        }


#: The same figures for a set-point run, which has no reference to track.
NO_TRACKING_FIELDS: dict[str, float | None] = dict.fromkeys(
    ("tracking_rmse_reachable_m", "reference_blocked_s", "rejoin_time_max_s")
)


def judge_tracking(
    outcome: str,
    t_s: np.ndarray,
    errors_m: np.ndarray,
    ref_reachable: np.ndarray,
    tau_s: float,
    outcomes: Outcomes,
) -> TrackingJudgement:
    """The one definition of tracking success among obstacles, from per-step times t_s (s),
    position errors (m) and whether the reference point was reachable (`reference_reachable`).

    An instant is *blocked* while the reference point is unreachable: no safe robot can be there,
    so its error is not judged; nor is it in the `leave_s` before a blockage, when a robot must
    already be stepping out of the way. When the reference becomes reachable again a *rejoin
    window* opens; it closes at the first instant whose error is below `tracking_rmse_m`, and its
    length is that instant's time minus the window's start (the clock starts no earlier than
    `tracking_settle_s`: nothing before settling is judged). Instants in a window are judged by
    the rejoin rule, not the RMSE. A window cut short (by the end of the run or by a new blockage)
    is not judged unless it already lasted longer than `rejoin_s`: then it is a failed rejoin,
    with its length so far. The run converged when its outcome is `tracking`, the RMSE over the
    remaining instants from `tracking_settle_s` on is <= `tracking_rmse_m` (there must be at least
    one), and every measured rejoin took <= `rejoin_s`. With the reference always reachable this
    is the plain RMSE rule (`tracking_rmse`).
    """
    t = np.asarray(t_s, dtype=float)
    err = np.asarray(errors_m, dtype=float)
    reference_reachable = np.asarray(ref_reachable, dtype=bool)
    reachable = _clear_ahead(reference_reachable, round(outcomes.leave_s / tau_s))
    settle, bound, rejoin_s = outcomes.tracking_settle_s, outcomes.tracking_rmse_m, outcomes.rejoin_s
    judged = reachable.copy()
    rejoins: list[float] = []
    start: float | None = None  # the open window's start (s)
    for i in range(len(t)):
        if not reachable[i]:
            if start is not None and t[i] - max(start, settle) > rejoin_s:
                rejoins.append(float(t[i] - max(start, settle)))  # cut short, already overdue
            start = None
            continue
        if start is None and i > 0 and not reachable[i - 1]:
            start = float(t[i])
        if start is not None:
            if err[i] < bound:
                if t[i] >= settle:
                    rejoins.append(float(t[i] - max(start, settle)))
                start = None
            else:
                judged[i] = False
    if start is not None and len(t) and t[-1] + tau_s - max(start, settle) > rejoin_s:
        rejoins.append(float(t[-1] + tau_s - max(start, settle)))  # open at the end, already overdue
    rmse = tracking_rmse(err[judged], t[judged], settle)
    converged = (
        outcome == "tracking" and rmse is not None and rmse <= bound and all(r <= rejoin_s for r in rejoins)
    )
    blocked_s = float(np.sum(~reference_reachable)) * tau_s
    return TrackingJudgement(rmse, blocked_s, tuple(rejoins), bool(converged))


def _clear_ahead(reachable: np.ndarray, steps: int) -> np.ndarray:
    """Whether the reference stays reachable from each instant through the next `steps` ones."""
    blocked = ~reachable
    ahead = blocked.copy()
    for k in range(1, steps + 1):
        ahead[:-k] |= blocked[k:]
    return ~ahead


@dataclass(frozen=True)
class EpisodeMetrics:
    """Headline figures of one episode (units in the names)."""

    outcome: str
    collided: bool
    converged: bool
    min_clearance_m: float | None
    final_position_error_m: float
    final_heading_error_rad: float
    tracking_rmse_m: float | None  # all instants after settle (the old rule's figure)
    tracking_rmse_reachable_m: float | None  # judged instants after settle (judge_tracking)
    reference_blocked_s: float | None  # time the reference was unreachable; None for set-points
    rejoin_time_max_s: float | None  # longest measured rejoin; None if none
    time_to_goal_s: float | None
    path_length_m: float
    reversals: int  # times the command went from forward/standing to backward (v < -0.01 m/s)
    reverse_steps: int  # control steps commanding v < -0.01 m/s
    max_abs_v_mps: float  # applied (after the drive's limits)
    max_abs_omega_radps: float
    max_abs_linear_accel_mps2: float
    max_abs_angular_accel_radps2: float
    # solve times over the steps that ran their solver (solver_times); None when none did
    solve_ms_median: float | None
    solve_ms_p95: float | None
    solve_ms_p99: float | None
    solve_ms_max: float | None
    solve_budget_ms: float  # tau: a solve slower than this delivers its command late on a robot
    solves_over_budget: int  # solves that took longer than tau (wall clock)
    repeated_steps: int  # steps that ran no solver, their problems answered before (solver_times)
    fallbacks: int
    solver_fallbacks: int  # steps whose structured solver (FATROP) failed and handed IPOPT a problem
    # of those, steps where IPOPT solved the step's first problem from the same guess: FATROP's own
    # failures (in the others IPOPT failed too: the problem was infeasible from that guess)
    solver_fallbacks_ipopt_solved: int
    recoveries: int  # failed solves solved again from a retry guess (controllers.recovery)
    recovered_by: str  # how often each retry guess succeeded, e.g. "reverse=2 straight=1"
    soft_constraint_steps: int  # steps solved only with the obstacle constraint's penalised slack
    guided_steps: int  # steps that tracked a guidance waypoint (the straight path was blocked)
    escapes: int  # deadlock escapes started: the controller found no progress (husky-cbf)
    escape_steps: int  # steps that followed an escape's waypoint
    deadline_misses: int
    safety_active_steps: int
    steps: int
    sim_time_s: float
    wall_time_s: float
    robot_radius_m: float | None
    footprint_radius_m: float
    robot_radius_below_footprint: bool  # the controller's circle is smaller than the real body
    interrupted_by: str | None = None  # "SIGINT" / "SIGTERM" when outcome is "interrupted"
    # the first contact of a collided episode (husky_sim.sim.contact); all None without a collision
    collision_at_fault: bool | None = None  # the robot moved faster than AT_FAULT_SPEED_MPS into it
    collision_obstacle: int | None = None  # index of the obstacle touched; None for a wall
    collision_relative_speed_mps: float | None = None  # |robot velocity - touched body's velocity|
    #: steps whose command a safety filter replaced with its committed or braking backup (husky-cbf's)
    filter_interventions: int = 0
    #: steps whose behaviour (the log's `mode`) differs from the step before's: a count far above
    #: the behaviours a run needs is a controller switching back and forth between them
    mode_changes: int = 0

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def summarise(
    record: Rollout,
    applied: np.ndarray,
    physics_dt_s: float,
    outcomes: Outcomes,
    wall_time_s: float,
    *,
    robot_radius_m: float | None,
    footprint_radius_m: float,
    sim_time_s: float,
) -> EpisodeMetrics:
    """Metrics of a PyBullet episode from what its rollout recorded (possibly no rows, when a
    signal ended it before the first control step), the drive's applied command after every
    physics step of physics_dt_s (s), and the run's wall and simulated time (s)."""
    rows, monitor, final_pose = record.rows, record.monitor, record.final_pose
    reference, is_setpoint, tau_s = monitor.reference, monitor.is_setpoint, record.tau_s
    interrupted_by = record.interrupted_by
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
    contact = record.first_contact if collided else None  # a contact after the last row is not judged
    outcome = final_outcome(
        monitor.outcome, collided=collided, is_setpoint=is_setpoint, interrupted=interrupted_by is not None
    )
    rmse, judgement = None, None
    if not is_setpoint:
        errs = np.hypot(col["x_m"] - col["ref_x_m"], col["y_m"] - col["ref_y_m"])
        rmse = tracking_rmse(errs, col["t_s"], outcomes.tracking_settle_s)
        judgement = judge_tracking(outcome, col["t_s"], errs, col["ref_reachable"] > 0, tau_s, outcomes)
    converged = (outcome == "reached") if is_setpoint else judgement.converged
    reversals, reverse_steps = count_reversals(col["v_cmd_mps"])
    accel = np.abs(np.diff(applied, axis=0)) / physics_dt_s if len(applied) > 1 else np.zeros((1, 2))
    solve = solver_times(col["solve_ms"], col["repeated"])
    escaping = np.array([r["escape"] != "" for r in rows], dtype=bool)  # on an escape's waypoint

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
        **(NO_TRACKING_FIELDS if judgement is None else judgement.fields()),
        time_to_goal_s=monitor.reached_at if outcome == "reached" else None,
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
        repeated_steps=int(np.sum(col["repeated"])),
        fallbacks=int(np.sum(col["fallback"] != "none")),
        solver_fallbacks=int(np.sum(col["solver_fallback"] != "")),
        solver_fallbacks_ipopt_solved=int(
            np.sum(
                (col["solver_fallback"] != "")
                & (col["recovered_by"] == "")
                & (col["fallback"] == "none")
                & ~col["soft_constraint"].astype(bool)
            )
        ),
        recoveries=int(np.sum(col["recovered_by"] != "")),
        recovered_by=" ".join(
            f"{name}={int(np.sum(col['recovered_by'] == name))}"
            for name in dict.fromkeys(col["recovered_by"])
            if name
        ),
        soft_constraint_steps=int(np.sum(col["soft_constraint"])),
        guided_steps=int(np.sum(col["guided"])),
        escapes=int(np.sum(escaping & ~np.concatenate([[False], escaping[:-1]]))),
        escape_steps=int(np.sum(escaping)),
        deadline_misses=int(np.sum(col["deadline_miss"])),
        safety_active_steps=int(np.sum(col["safety_active"] > 0)),
        steps=len(rows),
        sim_time_s=sim_time_s,
        wall_time_s=wall_time_s,
        robot_radius_m=robot_radius_m,
        footprint_radius_m=footprint_radius_m,
        robot_radius_below_footprint=robot_radius_m is not None and robot_radius_m < footprint_radius_m,
        interrupted_by=None if interrupted_by is None else signal.Signals(interrupted_by).name,
        collision_at_fault=None if contact is None else contact.at_fault,
        collision_obstacle=None if contact is None else contact.obstacle,
        collision_relative_speed_mps=None if contact is None else contact.relative_speed_mps,
        filter_interventions=int(np.sum(col["filtered"])),
        mode_changes=int(np.sum(col["mode"][1:] != col["mode"][:-1])),
    )
