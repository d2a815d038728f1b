"""Closed-loop episode: the Husky in PyBullet driven by a controller, gymnasium-style.

Physics runs at `physics_hz`; every tau seconds the runner senses, calls the controller and holds
its command (through the drive's limits) until the next control step. Collision is checked by the
physics engine every physics step (husky_sim.sim.collision). The physics side of a control step is
husky_sim.sim.environment.HuskyEnvironment, the one the gymnasium environment HuskyNav-v0 steps,
and the outcome is named by husky_sim.sim.outcomes.OutcomeMonitor, as there. Each control step
writes one log row, flushed at once, so a run that is interrupted or fails keeps what it logged.
A signal (Ctrl-C, SIGTERM; husky_sim.interrupts) ends the loop at once with the outcome
`interrupted` and the steps completed, so an interrupted run can never pass for a result.

Determinism: the same scenario, seed and code give the same log, except the wall-clock columns
(`solve_ms`, and anything that depends on it: deadline mode holds a command when a solve is slower
than tau, so deadline-mode runs are only as repeatable as the machine's timing).
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from controllers import Controller, ControlResult, Reference, SetPoint
from controllers.model import wrap_angle
from husky_sim import interrupts
from husky_sim.interrupts import RunInterrupted
from husky_sim.sim.drive import DriveConfig
from husky_sim.sim.environment import HuskyEnvironment
from husky_sim.sim.metrics import EpisodeMetrics, reference_reachable, summarise
from husky_sim.sim.outcomes import OutcomeMonitor, Outcomes
from husky_sim.sim.robot import HuskyRobot, WheelFriction
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.trace import TRACE_HZ, EpisodeTrace
from husky_sim.sim.world import World, WorldConfig

#: One row per control step at time t_s: the true pose, body velocity and wheel speeds at t_s,
#: the reference at t_s, the command issued at t_s (`*_cmd`) and the drive's limited command at
#: the end of the step (`*_applied`), the smallest clearance (m) to obstacles and walls over the
#: step's physics steps, whether the reference point at t_s was reachable (1: outside every
#: obstacle's circle at t_s inflated by the footprint radius; metrics.reference_reachable), and the
#: solve's slacks, activity, status and wall time.
#: Columns whose values are wall-clock measurements (excluded from determinism comparisons).
WALL_CLOCK_COLUMNS = ("solve_ms",)

LOG_COLUMNS = (
    "step",
    "t_s",
    "x_m",
    "y_m",
    "yaw_rad",
    "ref_x_m",
    "ref_y_m",
    "ref_yaw_rad",
    "v_cmd_mps",
    "omega_cmd_radps",
    "v_applied_mps",
    "omega_applied_radps",
    "v_body_mps",
    "omega_body_radps",
    "wheel_l1_radps",
    "wheel_l2_radps",
    "wheel_r1_radps",
    "wheel_r2_radps",
    "clearance_m",
    "ref_reachable",
    "s_h_min",
    "s_v_max",
    "safety_active",
    "iterations",
    "status",
    "solver",
    "solver_fallback",
    "fallback",
    "recovered_by",
    "soft_constraint",
    "guided",
    "deadline_miss",
    "solve_ms",
)


@dataclass(frozen=True)
class EpisodeConfig:
    """Everything the runner needs besides the controller and the reference."""

    start: tuple[float, float, float]  # (x m, y m, yaw rad)
    tau_s: float = 0.1
    duration_s: float = 30.0
    world: WorldConfig = field(default_factory=WorldConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    wheel_friction: WheelFriction = field(default_factory=WheelFriction)
    sensing: SensingConfig = field(default_factory=SensingConfig)
    outcomes: Outcomes = field(default_factory=Outcomes)
    payload_kg: float = 0.0
    deadline_mode: bool = False  # a solve slower than tau holds the previous command
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.tau_s > 0:
            raise ValueError(f"tau_s: must be > 0 s, got {self.tau_s}")
        if not self.duration_s > 0:
            raise ValueError(f"duration_s: must be > 0 s, got {self.duration_s}")
        ratio = self.world.physics_hz * self.tau_s
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(
                f"tau_s: must be a whole number of physics steps (physics_hz x tau_s = {ratio:g})"
            )


@dataclass
class EpisodeResult:
    """Metrics plus the per-step arrays (the same data as the log)."""

    metrics: EpisodeMetrics
    rows: list[dict[str, object]]
    predicted_states: list[np.ndarray]  # per control step, (N+1, 3)
    trace: EpisodeTrace  # poses and obstacles at TRACE_HZ, plans, reference path (for rendering)
    interrupted_by: int | None = None  # the signal that ended the run early (outcome "interrupted")


class _Log:
    """CSV log flushed row by row."""

    def __init__(self, path: Path | None) -> None:
        self._file = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file = path.open("w", newline="")
            self._writer = csv.DictWriter(self._file, fieldnames=LOG_COLUMNS)
            self._writer.writeheader()
            self._file.flush()

    def write(self, row: dict[str, object]) -> None:
        if self._file is not None:
            self._writer.writerow({k: _fmt(row[k]) for k in LOG_COLUMNS})
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


def _fmt(value: object) -> object:
    return f"{value:.9g}" if isinstance(value, float) else value


class StepObserver(Protocol):
    """Something that watches the loop (a recorder): called after each control step's row is
    logged, with the row, the controller's result and the true obstacle centres (m) at the step's
    start. It only reads, so it cannot change the physics."""

    def on_step(self, row: dict[str, object], result: ControlResult, obstacle_xy: np.ndarray) -> None: ...


def run_episode(
    controller: Controller,
    reference: Reference,
    config: EpisodeConfig,
    log_path: Path | None = None,
    robot_radius_m: float | None = None,
    observer: StepObserver | None = None,
) -> EpisodeResult:
    """Run one closed-loop episode in a fresh PyBullet world and return its metrics."""
    wall_start = time.perf_counter()
    controller_tau = getattr(getattr(controller, "config", None), "tau_s", None)
    if controller_tau is not None and abs(controller_tau - config.tau_s) > 1e-9:
        raise ValueError(
            f"tau_s: the episode's control period ({config.tau_s} s) must equal the controller's "
            f"sampling time ({controller_tau} s)"
        )
    interrupts.check()
    env = HuskyEnvironment(config)
    log = _Log(log_path)
    try:
        return _run(env, log, controller, reference, config, robot_radius_m, wall_start, observer)
    finally:
        log.close()
        env.close()


def _run(
    env: HuskyEnvironment,
    log: _Log,
    controller: Controller,
    reference: Reference,
    config: EpisodeConfig,
    robot_radius_m: float | None,
    wall_start: float,
    observer: StepObserver | None,
) -> EpisodeResult:
    world, robot = env.world, env.robot
    steps = int(math.ceil(config.duration_s / config.tau_s - 1e-9))
    obstacle_radii = np.array([o.radius_m for o in config.world.obstacles])
    footprint = robot.geometry.footprint_radius_m
    monitor = OutcomeMonitor(reference, config.outcomes, config.tau_s)
    controller.reset()

    rows: list[dict[str, object]] = []
    plans: list[np.ndarray] = []
    applied_history: list[np.ndarray] = [env.drive.applied]
    command = np.zeros(2)
    recorder = _TraceRecorder(robot, world, max(round(config.world.physics_hz / TRACE_HZ), 1))

    def on_physics_step(applied: np.ndarray) -> None:
        applied_history.append(applied)
        recorder.sample()

    interrupted_by: int | None = None
    try:
        for k in range(steps):
            interrupts.check()  # also a signal that a library swallowed
            t = k * config.tau_s
            pose, body, wheels = robot.pose(), robot.body_velocity(), robot.wheel_speeds()
            measurement = env.measure()
            result = controller.solve(measurement.pose, reference, measurement.obstacles, t)
            deadline_miss = config.deadline_mode and result.solve_time_s > config.tau_s
            if not deadline_miss:
                command = np.asarray(result.control, dtype=float)
            applied, clearance = env.advance(command, on_physics_step)
            new_pose = robot.pose()
            ref_now = reference.state_at(t)
            reachable = reference_reachable(ref_now[:2], world.obstacle_centres(t), obstacle_radii, footprint)
            row = {
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
                "clearance_m": clearance,
                "ref_reachable": int(reachable),
                "s_h_min": float(np.min(result.decay_slack)),
                "s_v_max": float(np.max(result.clf_slack)),
                "safety_active": int(result.safety_active),
                "iterations": int(result.iterations),
                "status": result.status,
                "solver": result.solver,
                "solver_fallback": result.solver_fallback,
                "fallback": result.fallback,
                "recovered_by": result.recovered_by,
                "soft_constraint": int(result.soft_constraint),
                "guided": int(result.guided),
                "deadline_miss": int(deadline_miss),
                "solve_ms": 1000.0 * result.solve_time_s,
            }
            with interrupts.deferred():  # a row is written whole or not at all
                log.write(row)
                rows.append(row)
                plans.append(result.predicted_states)
            if observer is not None:
                observer.on_step(row, result, world.obstacle_centres(t))

            if monitor.update(t + config.tau_s, new_pose, clearance, rows):
                break
    except (RunInterrupted, KeyboardInterrupt) as exc:  # the steps so far are kept and judged as such
        interrupted_by = interrupts.signum_of(exc)
        monitor.outcome = "interrupted"
    except Exception:
        # A signal whose handler raised inside a C extension comes back as that extension's error
        # (NumPy converting a CasADi matrix: "SystemError: ... returned a result with an exception
        # set"); with a signal received, that error is the interrupt, not a crash.
        interrupted_by = interrupts.pending()
        if interrupted_by is None:
            raise
        monitor.outcome = "interrupted"
    metrics = summarise(
        rows,
        np.array(applied_history),
        world.dt_s,
        reference,
        monitor.is_setpoint,
        monitor.outcome,
        monitor.reached_at,
        config.outcomes,
        config.tau_s,
        time.perf_counter() - wall_start,
        robot_radius_m=robot_radius_m,
        footprint_radius_m=robot.geometry.footprint_radius_m,
        final_pose=robot.pose(),
        sim_time_s=world.time_s,
        interrupted_by=interrupted_by,
    )
    trace = recorder.finish(rows, plans, reference, config, robot_radius_m, robot.geometry.footprint_radius_m)
    return EpisodeResult(metrics, rows, plans, trace, interrupted_by)


class _TraceRecorder:
    """Samples the true base pose and obstacle centres every `every` physics steps (reads only)."""

    def __init__(self, robot: HuskyRobot, world: World, every: int) -> None:
        self._robot, self._world, self._every = robot, world, every
        self._count = 0
        self._t: list[float] = []
        self._pos: list[tuple[float, ...]] = []
        self._orn: list[tuple[float, ...]] = []
        self._obs: list[np.ndarray] = []
        self._take()

    def _take(self) -> None:
        pos, orn = self._robot.base_com_pose()
        self._t.append(self._world.time_s)
        self._pos.append(tuple(pos))
        self._orn.append(tuple(orn))
        self._obs.append(self._world.obstacle_centres())  # a fresh array each call

    def sample(self) -> None:
        self._count += 1
        if self._count % self._every == 0:
            self._take()

    def finish(
        self,
        rows: list[dict[str, object]],
        plans: list[np.ndarray],
        reference: Reference,
        config: EpisodeConfig,
        robot_radius_m: float | None,
        footprint_radius_m: float,
    ) -> EpisodeTrace:
        specs = config.world.obstacles
        t_end = max(self._t[-1], config.duration_s)
        ref_t = np.arange(0.0, t_end + 1e-9, min(config.tau_s, 0.05))
        goal = (
            np.array([reference.x_m, reference.y_m, reference.theta_rad])
            if isinstance(reference, SetPoint)
            else np.full(3, np.nan)
        )
        arena = config.world.arena_half_size_m
        return EpisodeTrace(
            sample_t_s=np.array(self._t),
            base_position_m=np.array(self._pos),
            base_orientation_xyzw=np.array(self._orn),
            obstacle_xy_m=np.array(self._obs).reshape(len(self._t), len(specs), 2),
            obstacle_radius_m=np.array([o.radius_m for o in specs]),
            obstacle_height_m=np.array([o.height_m for o in specs]),
            control_t_s=np.array([float(r["t_s"]) for r in rows]),
            predicted_states=np.array(plans) if plans else np.zeros((0, 1, 3)),
            reference_path=np.array([reference.state_at(t) for t in ref_t]),
            goal=goal,
            robot_radius_m=float("nan") if robot_radius_m is None else float(robot_radius_m),
            footprint_radius_m=float(footprint_radius_m),
            arena_half_size_m=float("nan") if arena is None else float(arena),
        )


def compare_logs(a: Sequence[dict[str, object]], b: Sequence[dict[str, object]]) -> list[str]:
    """Columns (other than wall-clock ones) that differ between two logs; empty if identical."""
    if len(a) != len(b):
        return ["length"]
    diff = set()
    for ra, rb in zip(a, b, strict=True):
        for key in LOG_COLUMNS:
            if key not in WALL_CLOCK_COLUMNS and ra[key] != rb[key]:
                diff.add(key)
    return sorted(diff)
