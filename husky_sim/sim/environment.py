"""The simulated Husky as an environment: one PyBullet world with the robot, its skid-steer drive,
the sensor and the clearance monitor, advanced one control period at a time.

`HuskyEnvironment` is the physics side of a control step. The closed loop (husky_sim.sim.rollout,
through husky_sim.sim.episode.run_episode) steps it with the NMPC's commands, and the gymnasium
environment `HuskyNavEnv` (registered as "HuskyNav-v0" by `import husky_sim`) steps the same class
with an agent's actions, so both simulate the same thing: the command is held for tau through the
drive's velocity and acceleration limits, and the clearance is the physics engine's, every physics
step.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import gymnasium
import numpy as np
from gymnasium import spaces

from controllers import Reference
from controllers.model import wrap_angle
from husky_sim.sim.collision import ClearanceMonitor
from husky_sim.sim.drive import SkidSteerDrive
from husky_sim.sim.outcomes import OutcomeMonitor, reference_error
from husky_sim.sim.robot import HuskyRobot
from husky_sim.sim.rollout import control_steps
from husky_sim.sim.sensing import Measurement, Sensor
from husky_sim.sim.world import World

if TYPE_CHECKING:
    from husky_sim.sim.episode import EpisodeConfig

#: Margin (m) added to the footprint radius below which the clearance monitor asks the physics
#: engine for exact distances (husky_sim.sim.collision).
CLEARANCE_PREFILTER_MARGIN_M = 0.02


class HuskyEnvironment:
    """One episode's simulated Husky (EpisodeConfig: world, start, drive, ground, payload,
    sensing and its seed), a husky_sim.sim.rollout.Plant. Call `close` (or use it as a context
    manager) to free the world."""

    def __init__(self, config: EpisodeConfig) -> None:
        self.config = config
        self.world = World(config.world)
        try:
            ground = config.ground
            self.robot = HuskyRobot(
                self.world.client, config.start, ground.tyre, config.payload_kg, coulomb=not ground.calibrated
            )
            geometry = self.robot.geometry
            self.drive = SkidSteerDrive(config.drive, geometry.wheel_radius_m, geometry.track_width_m, ground)
            self.sensor = Sensor(config.sensing, config.seed)
            walls = zip(self.world.wall_ids, self.world.wall_planes, strict=True)
            self.monitor = ClearanceMonitor(
                self.world.client,
                self.robot.body,
                self.world.obstacle_ids,
                [o.radius_m for o in config.world.obstacles],
                geometry.footprint_radius_m + CLEARANCE_PREFILTER_MARGIN_M,
                walls=[(body, n, d) for body, (n, d) in walls],
            )
        except BaseException:
            self.world.close()
            raise
        self.substeps = round(config.world.physics_hz * config.tau_s)  # physics steps per control step
        self.footprint_radius_m = self.robot.geometry.footprint_radius_m
        self.obstacle_radii_m = np.array([o.radius_m for o in config.world.obstacles])

    def pose(self) -> np.ndarray:
        """The true base pose [x m, y m, yaw rad]."""
        return self.robot.pose()

    def body_velocity(self) -> np.ndarray:
        """The true body velocity [v m/s, omega rad/s]."""
        return self.robot.body_velocity()

    def wheel_speeds(self) -> np.ndarray:
        """The four wheels' speeds (rad/s) [l1, l2, r1, r2]."""
        return self.robot.wheel_speeds()

    def motor_currents(self) -> np.ndarray:
        """The left and right motor currents (A) in the last physics step (husky_sim.sim.drive)."""
        return np.array(self.drive.motor_currents(self.robot))

    def obstacle_centres(self, t_s: float) -> np.ndarray:
        """True obstacle centres (m), shape (n, 2), at time t_s (s)."""
        return self.world.obstacle_centres(t_s)

    def measure(self) -> Measurement:
        """What the controller is told now: the sensor's (noisy, delayed) pose and obstacles."""
        return self.sensor.measure(self.robot.pose(), self.world.obstacle_states())

    def advance(
        self, command: np.ndarray, on_physics_step: Callable[[np.ndarray], None] | None = None
    ) -> tuple[np.ndarray, float]:
        """Hold `command` [v m/s, omega rad/s] for one control period through the drive's limits;
        return the last applied (limited) command and the smallest clearance (m) to obstacles and
        walls over its physics steps (inf with neither). `on_physics_step(applied)` is called after
        every physics step (recorders: it must only read)."""
        world, robot, drive = self.world, self.robot, self.drive
        clearance = math.inf
        applied = drive.applied
        checked = bool(world.obstacle_ids or world.wall_ids)
        for _ in range(self.substeps):
            applied = drive.step(robot, command, world.dt_s)
            world.step()
            if on_physics_step is not None:
                on_physics_step(applied)
            if checked:
                clearance = self.monitor.smallest(robot.position_xy(), world.obstacle_centres(), clearance)
        return applied, clearance

    def close(self) -> None:
        self.world.close()

    def __enter__(self) -> HuskyEnvironment:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: Obstacles in an observation: the nearest ones (by clearance), padded to this many rows.
OBSERVED_OBSTACLES = 8
#: Reward on the step that collides (on top of the tracking term).
COLLISION_PENALTY = 100.0


class HuskyNavEnv(gymnasium.Env):
    """The simulated Husky as a gymnasium environment (`gymnasium.make("HuskyNav-v0",
    scenario=...)` after `import husky_sim`; husky_sim.runs.environment builds it from a scenario).

    Action: the (v m/s, omega rad/s) command, held for one control period tau through the drive's
    limits (the action space is the drive's velocity limits). Observation (what a controller is
    told, plus the body's velocity): `pose` [x m, y m, yaw rad] as sensed (the scenario's noise
    and latency), `velocity` [v m/s, omega rad/s] of the body, `reference` [x m, y m, yaw rad] at
    the current time, `obstacles` the nearest OBSERVED_OBSTACLES sensed circles as rows [dx m, dy
    m (from the sensed pose, world frame), radius m, vx m/s, vy m/s], and `obstacle_mask` (1 where
    a row is an obstacle). Reward: minus the position error (m) to the reference at the step's end
    times tau, and -COLLISION_PENALTY on a collision. `terminated` on reached (a set-point held
    within the scenario's tolerance) or collided (physics clearance <= 0, the episode's rules:
    husky_sim.sim.outcomes), `truncated` when the scenario's duration is up; `info` carries
    `t_s`, `clearance_m`, `applied` and `outcome`.

    `reset(seed=s)` builds a fresh world whose sensor noise is seeded with s (the same as
    `husky-sim run --seed s`); without a seed the first reset uses the scenario's seed, later ones
    draw theirs from the environment's generator, so a seeded environment repeats exactly."""

    metadata = {"render_modes": []}

    def __init__(self, config: EpisodeConfig, reference: Reference) -> None:
        self.config, self.reference = config, reference
        drive = config.drive
        high = np.array([drive.max_linear_mps, drive.max_angular_radps])
        self.action_space = spaces.Box(-high, high, dtype=np.float64)
        unbounded = {"low": -np.inf, "high": np.inf, "dtype": np.float64}
        self.observation_space = spaces.Dict(
            {
                "pose": spaces.Box(shape=(3,), **unbounded),
                "velocity": spaces.Box(shape=(2,), **unbounded),
                "reference": spaces.Box(shape=(3,), **unbounded),
                "obstacles": spaces.Box(shape=(OBSERVED_OBSTACLES, 5), **unbounded),
                "obstacle_mask": spaces.MultiBinary(OBSERVED_OBSTACLES),
            }
        )
        self._steps = control_steps(config.duration_s, config.tau_s)
        self._sim: HuskyEnvironment | None = None
        self._monitor: OutcomeMonitor | None = None
        self._k = 0
        self._resets = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is None:
            seed = self.config.seed if self._resets == 0 else int(self.np_random.integers(0, 2**32))
        self._resets += 1
        self.close()
        config = self.config
        self._sim = HuskyEnvironment(dataclasses.replace(config, seed=int(seed)))
        self._monitor = OutcomeMonitor(self.reference, config.outcomes, config.tau_s)
        self._k = 0
        return self._observe(), {"t_s": 0.0, "clearance_m": math.inf, "outcome": None}

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self._sim is None or self._monitor is None:
            raise RuntimeError("HuskyNavEnv.step: call reset() first")
        command = np.asarray(action, dtype=float).reshape(2)
        if not np.all(np.isfinite(command)):
            raise ValueError(f"action: must be a finite (v m/s, omega rad/s) pair, got {command.tolist()}")
        applied, clearance = self._sim.advance(command)
        self._k += 1
        t_s = self._k * self.config.tau_s
        pose = self._sim.robot.pose()
        self._monitor.update(t_s, pose, clearance, ())  # no rows: an agent is never called stuck
        error, _ = reference_error(pose, self.reference.state_at(t_s))
        outcome = self._monitor.outcome
        terminated = outcome in ("reached", "collided")
        truncated = not terminated and self._k >= self._steps
        if truncated:
            outcome = "timeout" if self._monitor.is_setpoint else "tracking"
        reward = -error * self.config.tau_s - (COLLISION_PENALTY if clearance <= 0.0 else 0.0)
        info = {"t_s": t_s, "clearance_m": clearance, "applied": applied, "outcome": outcome}
        return self._observe(), float(reward), terminated, truncated, info

    def _observe(self) -> dict[str, np.ndarray]:
        sim = self._sim
        assert sim is not None
        t_s = self._k * self.config.tau_s
        measured = sim.measure()
        rows = np.zeros((OBSERVED_OBSTACLES, 5))
        mask = np.zeros(OBSERVED_OBSTACLES, dtype=np.int8)
        if measured.obstacles:
            table = np.array([[o.x_m, o.y_m, o.radius_m, o.vx_mps, o.vy_mps] for o in measured.obstacles])
            table[:, :2] -= measured.pose[:2]
            nearest = np.argsort(np.hypot(table[:, 0], table[:, 1]) - table[:, 2], kind="stable")
            chosen = table[nearest[:OBSERVED_OBSTACLES]]
            rows[: len(chosen)] = chosen
            mask[: len(chosen)] = 1
        ref = np.asarray(self.reference.state_at(t_s), dtype=float)
        return {
            "pose": np.asarray(measured.pose, dtype=float),
            "velocity": np.asarray(sim.robot.body_velocity(), dtype=float),
            "reference": np.array([ref[0], ref[1], float(wrap_angle(ref[2]))]),
            "obstacles": rows,
            "obstacle_mask": mask,
        }

    def close(self) -> None:
        if self._sim is not None:
            self._sim.close()
            self._sim = None
