"""The one closed loop: a controller driving a plant (the PyBullet Husky, husky_sim.sim.environment,
or the controller's own unicycle, husky_sim.sim.kinematic) one control period at a time, judged
after every step by husky_sim.sim.outcomes.OutcomeMonitor.

Every control step at t = k * tau: read the true state and the measurement, solve, hold the
command through the plant for tau (deadline mode keeps the previous command when a solve took
longer than tau), log one row (husky_sim.sim.step_log), let an observer see it, and ask the
monitor whether the episode ends. A signal (Ctrl-C, SIGTERM; husky_sim.interrupts) ends the loop
at once with the outcome `interrupted` and the steps completed, so an interrupted run can never
pass for a result.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controllers import Controller, ControlResult, Reference
from controllers.model import wrap_angle
from husky_sim import interrupts
from husky_sim.interrupts import RunInterrupted
from husky_sim.sim.contact import Contact
from husky_sim.sim.outcomes import OutcomeMonitor, ReferenceBlockage, mover_within_reach, reference_reachable
from husky_sim.sim.sensing import Measurement
from husky_sim.sim.step_log import StepLog, format_visible


class Plant(Protocol):
    """What a rollout drives: a simulated robot among obstacles, advanced one control period at a
    time (units: m, rad, s)."""

    #: the body's circle (m): a reference point inside an obstacle inflated by it is unreachable
    footprint_radius_m: float
    #: the obstacles' radii (m), in the order of `obstacle_centres`
    obstacle_radii_m: np.ndarray
    #: the episode's first contact (husky_sim.sim.contact) once it happened, else None
    first_contact: Contact | None

    def pose(self) -> np.ndarray:
        """The true pose [x m, y m, yaw rad] now."""
        ...

    def body_velocity(self) -> np.ndarray:
        """The true body velocity [v m/s, omega rad/s] now."""
        ...

    def wheel_speeds(self) -> np.ndarray:
        """Wheel speeds (rad/s) [l1, l2, r1, r2]; NaN where the plant has no wheels."""
        ...

    def motor_currents(self) -> np.ndarray:
        """The left and right motor currents (A) in the last physics step; NaN without motors."""
        ...

    def measure(self) -> Measurement:
        """What the controller is told now (pose and obstacles, as sensed)."""
        ...

    def obstacle_centres(self, t_s: float) -> np.ndarray:
        """True obstacle centres (m), shape (n, 2), at time t_s."""
        ...

    def advance(
        self, command: np.ndarray, on_physics_step: Callable[[np.ndarray], None] | None = None
    ) -> tuple[np.ndarray, float]:
        """Hold `command` [v, omega] for one control period; return the last applied command and
        the smallest clearance (m) over the period (inf without obstacles). `on_physics_step` is
        called with the applied command after each integration step (it must only read)."""
        ...


class StepObserver(Protocol):
    """Something that watches the loop (a recorder): called after each control step's row is
    logged, with the row, the controller's result and the true obstacle centres (m) at the step's
    start. It only reads, so it cannot change the physics."""

    def on_step(self, row: dict[str, object], result: ControlResult, obstacle_xy: np.ndarray) -> None: ...


def control_steps(duration_s: float, tau_s: float) -> int:
    """Control steps in an episode of duration_s (s) at period tau_s (s): the last one starts
    before duration_s."""
    return int(math.ceil(duration_s / tau_s - 1e-9))


@dataclass
class Rollout:
    """What one rollout recorded: a row per control step of tau_s (s) (step_log.LOG_COLUMNS), the
    plan of each step (N+1, 3), the monitor that judged it, the pose after the last step, the
    signal that ended it early (None: it ran to its end or the monitor stopped it) and the
    plant's first contact (None: none happened)."""

    tau_s: float
    rows: list[dict[str, object]]
    plans: list[np.ndarray]
    monitor: OutcomeMonitor
    final_pose: np.ndarray
    interrupted_by: int | None
    first_contact: Contact | None = None


def rollout(
    plant: Plant,
    controller: Controller,
    reference: Reference,
    monitor: OutcomeMonitor,
    steps: int,
    tau_s: float,
    *,
    deadline_mode: bool = False,
    log: StepLog | None = None,
    observer: StepObserver | None = None,
    on_physics_step: Callable[[np.ndarray], None] | None = None,
) -> Rollout:
    """Run the closed loop for at most `steps` control periods of tau_s (s)."""
    controller.reset()
    rows: list[dict[str, object]] = []
    plans: list[np.ndarray] = []
    command = np.zeros(2)
    interrupted_by: int | None = None
    blockage = ReferenceBlockage(
        reference,
        plant.obstacle_centres,
        plant.obstacle_radii_m,
        plant.footprint_radius_m,
        tau_s,
        monitor.outcomes.leave_s,
    )
    try:
        for k in range(steps):
            interrupts.check()  # also a signal that a library swallowed
            t = k * tau_s
            pose, body, wheels = plant.pose(), plant.body_velocity(), plant.wheel_speeds()
            currents = plant.motor_currents()
            measurement = plant.measure()
            result = controller.solve(measurement.pose, reference, measurement.obstacles, t)
            deadline_miss = deadline_mode and result.solve_time_s > tau_s
            if not deadline_miss:
                command = np.asarray(result.control, dtype=float)
            applied, clearance = plant.advance(command, on_physics_step)
            new_pose = plant.pose()
            ref_now = reference.state_at(t)
            centres = plant.obstacle_centres(t)
            reachable = reference_reachable(
                ref_now[:2], centres, plant.obstacle_radii_m, plant.footprint_radius_m
            )
            row = _row(k, t, pose, body, wheels, currents, ref_now, command, applied, clearance, reachable)
            row["visible_obstacles"] = format_visible(measurement.visible)  # what the controller got
            row.update(_solve_columns(result, deadline_miss))
            with interrupts.deferred():  # a row is written whole or not at all
                if log is not None:
                    log.write(row)
                rows.append(row)
                plans.append(result.predicted_states)
            if observer is not None:
                observer.on_step(row, result, centres)
            waiting = blockage.waiting(k) or mover_within_reach(
                new_pose[:2],
                plant.obstacle_centres,
                plant.obstacle_radii_m,
                plant.footprint_radius_m,
                t + tau_s,
                tau_s,
                monitor.outcomes.leave_s,
            )
            if monitor.update(t + tau_s, new_pose, clearance, rows, waiting):
                break
    except (RunInterrupted, KeyboardInterrupt) as exc:  # the steps so far are kept and judged as such
        interrupted_by = interrupts.signum_of(exc)
    except Exception:
        # A signal whose handler raised inside a C extension comes back as that extension's error
        # (NumPy converting a CasADi matrix: "SystemError: ... returned a result with an exception
        # set"); with a signal received, that error is the interrupt, not a crash.
        interrupted_by = interrupts.pending()
        if interrupted_by is None:
            raise
    if interrupted_by is None:
        monitor.finish(rows)
    else:
        monitor.outcome = "interrupted"
    return Rollout(tau_s, rows, plans, monitor, plant.pose(), interrupted_by, plant.first_contact)


def _row(
    k: int,
    t: float,
    pose: np.ndarray,
    body: np.ndarray,
    wheels: np.ndarray,
    currents: np.ndarray,
    ref_now: np.ndarray,
    command: np.ndarray,
    applied: np.ndarray,
    clearance: float,
    reachable: bool,
) -> dict[str, object]:
    """The state columns of a control step's row (step_log.LOG_COLUMNS)."""
    return {
        "step": k,
        "t_s": t,
        "x_m": pose[0],
        "y_m": pose[1],
        "yaw_rad": pose[2],
        "ref_x_m": ref_now[0],
        "ref_y_m": ref_now[1],
        "ref_yaw_rad": float(wrap_angle(ref_now[2])),
        "v_cmd_mps": float(command[0]),
        "omega_cmd_radps": float(command[1]),
        "v_applied_mps": float(applied[0]),
        "omega_applied_radps": float(applied[1]),
        "v_body_mps": float(body[0]),
        "omega_body_radps": float(body[1]),
        "wheel_l1_radps": float(wheels[0]),
        "wheel_l2_radps": float(wheels[1]),
        "wheel_r1_radps": float(wheels[2]),
        "wheel_r2_radps": float(wheels[3]),
        "motor_left_a": float(currents[0]),
        "motor_right_a": float(currents[1]),
        "clearance_m": clearance,
        "ref_reachable": int(reachable),
    }


def _solve_columns(result: ControlResult, deadline_miss: bool) -> dict[str, object]:
    """The solver columns of a control step's row: slacks, activity, status, fallbacks, time."""
    return {
        "s_h_min": float(np.min(result.decay_slack)),
        "s_v_max": float(np.max(result.clf_slack)),
        "safety_active": int(result.safety_active),
        "iterations": int(result.iterations),
        "status": result.status,
        "solver": result.solver,
        "solver_fallback": result.solver_fallback,
        "repeated": int(result.repeated),
        "fallback": result.fallback,
        "recovered_by": result.recovered_by,
        "soft_constraint": int(result.soft_constraint),
        "guided": int(result.guided),
        "mode": result.mode,
        "escape": result.escape,
        "filtered": int(result.filtered),
        "deadline_miss": int(deadline_miss),
        "solve_ms": 1000.0 * result.solve_time_s,
    }
