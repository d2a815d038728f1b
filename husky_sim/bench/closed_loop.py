"""`husky-sim bench-sim`: real-time factor of a closed-loop PyBullet episode and of bare physics
stepping with 8 obstacles, plus the process's peak memory."""

from __future__ import annotations

import math
import resource
import time
from dataclasses import dataclass, replace

import numpy as np

from controllers import NMPCConfig, NMPCController, SetPoint, SolverOptions
from controllers.config import SolverBackend
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

    walls = []
    command = np.array([0.5, 0.1])
    with PhysicsEnvironment(config) as env:  # bare: the drive and the physics, no clearance check
        world, robot, drive, periods = env.world, env.robot, env.drive, stepping_steps // env.substeps
        stepping_steps = periods * env.substeps  # whole control periods, for the checked loop
        t0 = time.perf_counter()
        for _ in range(stepping_steps):
            drive.step(robot, command, world.dt_s)
            world.step()
        walls.append(time.perf_counter() - t0)
    with PhysicsEnvironment(config) as env:  # checked: the episode's own physics loop
        t0 = time.perf_counter()
        for _ in range(periods):
            env.advance(command)
        walls.append(time.perf_counter() - t0)
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
