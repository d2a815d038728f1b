"""`husky-sim bench-sim`: real-time factor of a closed-loop PyBullet episode and of bare physics
stepping with 8 obstacles, the same for a large world (1,000 static obstacles,
scenarios/large/large_world_1000.yaml, through the scenario schema as `husky-sim run` builds it),
plus the process's peak memory."""

from __future__ import annotations

import math
import resource
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from controllers import NMPCConfig, NMPCController, SetPoint, SolverOptions
from controllers.config import SolverBackend
from husky_sim.paths import SCENARIO_DIR
from husky_sim.runs.paper_problems import CLUTTERED_POINT_STABILISATION
from husky_sim.sim.drive import DriveConfig
from husky_sim.sim.environment import PhysicsEnvironment
from husky_sim.sim.episode import EpisodeConfig, run_episode
from husky_sim.sim.ground import load_ground, with_friction
from husky_sim.sim.open_loop import simulate_commands
from husky_sim.sim.outcomes import Outcomes
from husky_sim.sim.world import ObstacleSpec, WorldConfig, obstacle_specs_from

#: The kinematic benchmark's seven obstacles (two moving) plus one beyond the goal.
BENCH_OBSTACLES = (
    *obstacle_specs_from(CLUTTERED_POINT_STABILISATION.obstacles),
    ObstacleSpec(0.0, 12.5, 0.4),
)
#: The large world `bench-sim` times: 1,000 seeded static cylinders, the goal 30 m away.
LARGE_WORLD = SCENARIO_DIR / "large" / "large_world_1000.yaml"


@dataclass(frozen=True)
class SimBench:
    episode_sim_s: float
    episode_wall_s: float
    episode_outcome: str
    solve_ms_median: float
    stepping_steps: int
    stepping_wall_s: float
    checked_stepping_wall_s: float
    peak_rss_mb: float

    def report(self) -> str:
        ep_rtf = self.episode_sim_s / self.episode_wall_s
        bare = self.stepping_steps / self.stepping_wall_s
        checked = self.stepping_steps / self.checked_stepping_wall_s
        return "\n".join(
            [
                f"closed-loop episode (relax-cbf, N = 5, tau = 0.1 s, 240 Hz physics, 8 obstacles): "
                f"{self.episode_sim_s:.1f} s simulated in {self.episode_wall_s:.2f} s wall "
                f"= {ep_rtf:.1f}x real time "
                f"(outcome {self.episode_outcome}, solve median {self.solve_ms_median:.2f} ms)",
                f"bare physics stepping, Husky + 8 obstacles: {bare:.0f} steps/s "
                f"= {bare / 240:.1f}x real time",
                f"stepping + per-step clearance check: {checked:.0f} steps/s "
                f"= {checked / 240:.1f}x real time",
                f"peak resident memory of this process: {self.peak_rss_mb:.0f} MB",
            ]
        )


def drive_open_loop(
    command: tuple[float, float],
    ground_friction: float,
    seconds: float = 6.0,
    physics_hz: float = 240.0,
    payload_kg: float = 0.0,
    torque_scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Hold a body command [v, omega] on flat ground (with a payload in kg and the wheel torque
    limit scaled as `husky-sim check` does); return the mean achieved [v, yaw rate] over the
    second half of the run and the applied (limited) command of every physics step."""
    nominal = DriveConfig()
    track = simulate_commands(
        np.zeros(1),
        np.array([command], dtype=float),
        seconds,
        (0.0, 0.0, 0.0),
        world=WorldConfig(physics_hz=physics_hz, ground_friction=ground_friction),
        drive=replace(
            nominal,
            motor=replace(nominal.motor, current_limit_a=nominal.motor.current_limit_a * torque_scale),
        ),
        ground=with_friction(load_ground(), ground_friction),
        payload_kg=payload_kg,
    )
    steps = len(track.applied)
    return np.mean(track.body_velocity[steps // 2 + 1 :], axis=0), track.applied


DRIVE_TABLE_COMMANDS = ((0.5, 0.0), (1.0, 0.0), (0.0, 0.5), (0.0, 1.0), (0.5, 0.5), (0.3, -0.3))

#: Turning commands of the turn table: in place at the drive's limit, and an arc.
TURN_TABLE_COMMANDS = ((0.0, 2.0), (0.5, 1.0))


def turn_table(
    payloads_kg: tuple[float, ...] = (0.0, 25.0, 50.0, 75.0),
    torque_scales: tuple[float, ...] = (1.0, 0.85, 0.7),
    frictions: tuple[float, ...] = (0.4, 0.7, 1.0),
) -> str:
    """Markdown table of the yaw rate achieved over the corners of `husky-sim check`'s payload,
    torque and ground-friction ranges: where a loaded, derated skid-steer on grippy ground can no
    longer turn, no controller can steer round an obstacle."""
    head = " | ".join(f"omega for ({v:g}, {w:g}) | ratio" for v, w in TURN_TABLE_COMMANDS)
    lines = [
        f"| payload (kg) | torque scale | ground mu | {head} |",
        "|---" * (3 + 2 * len(TURN_TABLE_COMMANDS)) + "|",
    ]
    for payload in payloads_kg:
        for scale in torque_scales:
            for mu in frictions:
                cells = []
                for command in TURN_TABLE_COMMANDS:
                    (_, achieved), _ = drive_open_loop(
                        command, mu, 4.0, payload_kg=payload, torque_scale=scale
                    )
                    cells.append(f"{achieved:.3f} | {achieved / command[1]:.2f}")
                lines.append(f"| {payload:g} | {scale:g} | {mu:g} | {' | '.join(cells)} |")
    return "\n".join(lines)


def drive_table(frictions: tuple[float, ...] = (1.0, 0.5)) -> str:
    """Markdown table of achieved versus commanded v and omega on flat ground."""
    lines = [
        "| ground mu | v cmd (m/s) | omega cmd (rad/s) | v achieved | omega achieved "
        "| v ratio | omega ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for mu in frictions:
        for v, w in DRIVE_TABLE_COMMANDS:
            (va, wa), _ = drive_open_loop((v, w), mu)
            vr = f"{va / v:.2f}" if v else "-"
            wr = f"{wa / w:.2f}" if w else "-"
            lines.append(f"| {mu} | {v} | {w} | {va:.3f} | {wa:.3f} | {vr} | {wr} |")
    return "\n".join(lines)


def run_sim_bench(
    duration_s: float = 30.0, stepping_steps: int = 7200, solver: SolverBackend | None = None
) -> SimBench:
    """The benchmark episode (with `solver`'s NLP backend; None: the default), and stepping_steps
    physics steps (rounded down to whole control periods) bare and through the episode's own
    physics loop with its clearance check."""
    start = (0.0, 0.0, math.pi / 2)
    config = EpisodeConfig(
        start=start,
        tau_s=0.1,
        duration_s=duration_s,
        world=WorldConfig(obstacles=BENCH_OBSTACLES),
        outcomes=Outcomes(stop_early=False, stop_on_collision=False),
    )
    nmpc_config = NMPCConfig(safety="relax-cbf", horizon=5, gamma=0.1, robot_radius_m=0.65, obstacle_slots=8)
    if solver is not None:
        nmpc_config = nmpc_config.with_(solver=SolverOptions(backend=solver))
    nmpc = NMPCController(nmpc_config)
    t0 = time.perf_counter()
    result = run_episode(nmpc, SetPoint(0.0, 10.0, math.pi / 2), config, robot_radius_m=0.65)
    episode_wall = time.perf_counter() - t0

    stepping = time_physics_steps(config, stepping_steps)
    walls = [stepping.bare_wall_s, stepping.checked_wall_s]
    stepping_steps = stepping.steps
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return SimBench(
        result.metrics.sim_time_s,
        episode_wall,
        result.metrics.outcome,
        result.metrics.solve_ms_median,
        stepping_steps,
        walls[0],
        walls[1],
        peak_mb,
    )


@dataclass(frozen=True)
class PhysicsStepping:
    """Physics stepping timed in one world: `steps` physics steps (whole control periods) bare
    (the drive and the engine) and checked (the episode's own loop, with the clearance check), in s."""

    steps: int
    bare_wall_s: float
    checked_wall_s: float
    checked_cpu_s: float


def time_physics_steps(config: EpisodeConfig, steps: int) -> PhysicsStepping:
    """About `steps` physics steps (rounded to whole control periods, at least one) of a fixed
    command, timed bare and checked, each in a fresh world of `config`."""
    command = np.array([0.5, 0.1])
    with PhysicsEnvironment(config) as env:  # bare: the drive and the physics, no clearance check
        world, robot, drive = env.world, env.robot, env.drive
        periods = max(steps // env.substeps, 1)
        steps = periods * env.substeps
        t0 = time.perf_counter()
        for _ in range(steps):
            drive.step(robot, command, world.dt_s)
            world.step()
        bare = time.perf_counter() - t0
    with PhysicsEnvironment(config) as env:  # checked: the episode's own physics loop
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(periods):
            env.advance(command)
        checked, checked_cpu = time.perf_counter() - t0, time.process_time() - c0
    return PhysicsStepping(steps, bare, checked, checked_cpu)


@dataclass(frozen=True)
class LargeWorldBench:
    """One closed-loop episode of a large world (times in s of wall or CPU time, as named), and
    physics stepping in the same world: bare (drive and engine) and with the clearance check."""

    scenario: str
    controller: str
    obstacles: int
    build_wall_s: float  # validating the file and building the controller and the episode
    episode_sim_s: float
    episode_wall_s: float
    episode_cpu_s: float  # this process's CPU time (every thread)
    episode_outcome: str
    control_steps: int
    solve_ms_median: float
    solve_ms_p99: float
    solve_total_s: float
    stepping_steps: int
    stepping_wall_s: float
    checked_stepping_wall_s: float
    checked_stepping_cpu_s: float
    physics_hz: float
    peak_rss_mb: float  # the process's, so far (a `bench-sim` run's small world included)

    def report(self) -> str:
        rtf_wall = self.episode_sim_s / self.episode_wall_s
        rtf_cpu = self.episode_sim_s / self.episode_cpu_s
        outside_ms = 1000.0 * (self.episode_wall_s - self.solve_total_s) / max(self.control_steps, 1)
        bare_us = 1e6 * self.stepping_wall_s / self.stepping_steps
        checked_us = 1e6 * self.checked_stepping_wall_s / self.stepping_steps
        checked_cpu_us = 1e6 * self.checked_stepping_cpu_s / self.stepping_steps
        budget_us = 1e6 / self.physics_hz
        return "\n".join(
            [
                f"large world ({self.scenario}: {self.obstacles} static obstacles, {self.controller}, "
                f"{self.physics_hz:g} Hz physics; built and validated in {self.build_wall_s:.2f} s): "
                f"{self.episode_sim_s:.1f} s simulated in {self.episode_wall_s:.2f} s wall "
                f"= {rtf_wall:.2f}x real time, {self.episode_cpu_s:.2f} s CPU = {rtf_cpu:.2f}x "
                f"(outcome {self.episode_outcome})",
                f"  solve per control step: median {self.solve_ms_median:.2f} ms, p99 "
                f"{self.solve_ms_p99:.2f} ms; the rest of the loop (physics, clearance, sensing, "
                f"log): {outside_ms:.2f} ms per control step",
                f"  physics step: {bare_us:.0f} us bare, {checked_us:.0f} us with the clearance check "
                f"({checked_cpu_us:.0f} us CPU; real time allows {budget_us:.0f} us)",
                f"  peak resident memory of this process: {self.peak_rss_mb:.0f} MB",
            ]
        )


def run_large_world_bench(
    controller: str = "husky-cbf",
    duration_s: float | None = None,
    stepping_steps: int = 2400,
    solver: SolverBackend | None = None,
    scenario: Path = LARGE_WORLD,
) -> LargeWorldBench:
    """The large world's episode with `controller` for at most duration_s (s; None: the
    scenario's own) of sim time (it ends early once the outcome is decided), timed in wall and
    CPU time, then stepping_steps physics steps (rounded down to whole control periods, at least
    one) bare and through the episode's own physics loop with its clearance check."""
    from husky_sim.runs.run import run_settings
    from husky_sim.runs.scenario import load_scenario

    t0 = time.perf_counter()
    sc = load_scenario(str(scenario)).with_overrides(solver=solver)
    _, robot_radius_m = run_settings(sc, controller)
    nmpc = sc.make_controller(controller)
    config = sc.episode_config()
    if duration_s is not None:
        config = replace(config, duration_s=duration_s)
    build_wall = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_episode(nmpc, sc.reference_object(), config, robot_radius_m=robot_radius_m)
    episode_wall, episode_cpu = time.perf_counter() - t0, time.process_time() - c0
    solve_ms = np.array([float(row["solve_ms"]) for row in result.rows])

    stepping = time_physics_steps(config, stepping_steps)
    walls = [stepping.bare_wall_s, stepping.checked_wall_s]
    stepping_steps, checked_cpu = stepping.steps, stepping.checked_cpu_s
    return LargeWorldBench(
        scenario=sc.name,
        controller=controller,
        obstacles=len(config.world.obstacles),
        build_wall_s=build_wall,
        episode_sim_s=result.metrics.sim_time_s,
        episode_wall_s=episode_wall,
        episode_cpu_s=episode_cpu,
        episode_outcome=result.metrics.outcome,
        control_steps=len(result.rows),
        solve_ms_median=float(np.median(solve_ms)),
        solve_ms_p99=float(np.percentile(solve_ms, 99)),
        solve_total_s=float(np.sum(solve_ms)) / 1000.0,
        stepping_steps=stepping_steps,
        stepping_wall_s=walls[0],
        checked_stepping_wall_s=walls[1],
        checked_stepping_cpu_s=checked_cpu,
        physics_hz=config.world.physics_hz,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    )
