"""Closed-loop episode: the Husky in PyBullet driven by a controller, gymnasium-style.

Physics runs at `physics_hz`; every tau seconds the loop (husky_sim.sim.rollout, the one closed
loop) senses, calls the controller and holds its command through the drive's limits until the next
control step. The physics side of a control step is husky_sim.sim.environment.PhysicsEnvironment, the
one the gymnasium environment HuskyNav-v0 steps, and the outcome is named by
husky_sim.sim.outcomes.OutcomeMonitor, as there. Collision is checked by the physics engine every
physics step (husky_sim.sim.collision). Each control step writes one log row, flushed at once
(husky_sim.sim.step_log), so a run that is interrupted or fails keeps what it logged.

Determinism: the same scenario, seed and code give the same log, except the wall-clock columns
(`solve_ms`, and anything that depends on it: deadline mode holds a command when a solve is slower
than tau, so deadline-mode runs are only as repeatable as the machine's timing).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from controllers import Controller, Reference, SetPoint
from husky_sim import interrupts
from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.sim.drive import DriveConfig
from husky_sim.sim.environment import PhysicsEnvironment
from husky_sim.sim.ground import Ground, load_ground
from husky_sim.sim.metrics import EpisodeMetrics, summarise
from husky_sim.sim.outcomes import OutcomeMonitor, Outcomes
from husky_sim.sim.robot import SkidSteerRobot
from husky_sim.sim.rollout import StepObserver, control_steps, rollout
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.step_log import StepLog
from husky_sim.sim.trace import TRACE_HZ, EpisodeTrace
from husky_sim.sim.world import World, WorldConfig


@dataclass(frozen=True)
class EpisodeConfig:
    """Everything the runner needs besides the controller and the reference."""

    start: tuple[float, float, float]  # (x m, y m, yaw rad)
    tau_s: float = 0.1
    duration_s: float = 30.0
    world: WorldConfig = field(default_factory=WorldConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    ground: Ground = field(default_factory=load_ground)  # tyre contact and drive response
    sensing: SensingConfig = field(default_factory=SensingConfig)
    outcomes: Outcomes = field(default_factory=Outcomes)
    payload_kg: float = 0.0
    robot: str = DEFAULT_ROBOT  # the robot's folder under assets/ (husky_sim.sim.robot_description)
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
    env = PhysicsEnvironment(config)
    log = StepLog(log_path)
    try:
        return _run(env, log, controller, reference, config, robot_radius_m, wall_start, observer)
    finally:
        log.close()
        env.close()


def _run(
    env: PhysicsEnvironment,
    log: StepLog,
    controller: Controller,
    reference: Reference,
    config: EpisodeConfig,
    robot_radius_m: float | None,
    wall_start: float,
    observer: StepObserver | None,
) -> EpisodeResult:
    world, robot = env.world, env.robot
    applied_history: list[np.ndarray] = [env.drive.applied]
    recorder = _TraceRecorder(robot, world, max(round(config.world.physics_hz / TRACE_HZ), 1))

    def on_physics_step(applied: np.ndarray) -> None:
        applied_history.append(applied)
        recorder.sample()

    record = rollout(
        env,
        controller,
        reference,
        OutcomeMonitor(reference, config.outcomes, config.tau_s),
        control_steps(config.duration_s, config.tau_s),
        config.tau_s,
        deadline_mode=config.deadline_mode,
        log=log,
        observer=observer,
        on_physics_step=on_physics_step,
    )
    metrics = summarise(
        record,
        np.array(applied_history),
        world.dt_s,
        config.outcomes,
        time.perf_counter() - wall_start,
        robot_radius_m=robot_radius_m,
        footprint_radius_m=env.footprint_radius_m,
        sim_time_s=world.time_s,
    )
    trace = recorder.finish(
        record.rows, record.plans, reference, config, robot_radius_m, env.footprint_radius_m
    )
    return EpisodeResult(metrics, record.rows, record.plans, trace, record.interrupted_by)


class _TraceRecorder:
    """Samples the true base pose and obstacle centres every `every` physics steps (reads only).

    Only the moving obstacles' centres are sampled; the static ones' stand for every sample. A
    world with no mover gets its (S, M, 2) centres as a read-only broadcast of the M static ones,
    so a thousand posts cost no memory per sample (the trace file still holds them all)."""

    def __init__(self, robot: SkidSteerRobot, world: World, every: int) -> None:
        self._robot, self._world, self._every = robot, world, every
        self._count = 0
        self._t: list[float] = []
        self._pos: list[tuple[float, ...]] = []
        self._orn: list[tuple[float, ...]] = []
        self._moving = np.array([i for i, o in enumerate(world.config.obstacles) if o.moving], dtype=int)
        self._obs: list[np.ndarray] = []  # the movers' centres (K, 2) at each sample
        self._take()

    def _take(self) -> None:
        """One sample, appended whole: a signal may raise after any PyBullet call, and columns of
        different lengths would make the interrupted run's trace (and its summary) unsavable."""
        pos, orn = self._robot.base_com_pose()
        t_s, centres = self._world.time_s, self._world.obstacle_centres()[self._moving]  # a fresh array
        with interrupts.deferred():
            self._t.append(t_s)
            self._pos.append(tuple(pos))
            self._orn.append(tuple(orn))
            self._obs.append(centres)

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
            obstacle_xy_m=self._obstacle_xy(len(self._t)),
            obstacle_radius_m=np.array([o.radius_m for o in specs]),
            obstacle_height_m=np.array([o.height_m for o in specs]),
            control_t_s=np.array([float(r["t_s"]) for r in rows]),
            predicted_states=np.array(plans) if plans else np.zeros((0, 1, 3)),
            reference_path=reference.states_at(ref_t),
            goal=goal,
            robot_radius_m=float("nan") if robot_radius_m is None else float(robot_radius_m),
            footprint_radius_m=float(footprint_radius_m),
            arena_half_size_m=float("nan") if arena is None else float(arena),
        )

    def _obstacle_xy(self, samples: int) -> np.ndarray:
        """(samples, M, 2) true obstacle centres (m): the static ones where the world placed
        them, the movers' as sampled."""
        static = self._world.obstacle_centres(0.0)  # a fresh array: statics are where they began
        shape = (samples, len(static), 2)
        if not len(self._moving):
            return np.broadcast_to(static, shape)
        xy = np.repeat(static[None], samples, axis=0)
        xy[:, self._moving] = np.array(self._obs).reshape(samples, len(self._moving), 2)
        return xy
