"""`gymnasium.make("HuskyNav-v0", scenario=...)`: the simulated Husky as a gymnasium environment,
stepping the same PhysicsEnvironment as every run, built from a scenario file resolved by the same
schema (husky_sim.runs.scenario). Gymnasium is the `gym` extra."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from controllers import Reference
from controllers.model import wrap_angle
from husky_sim.extras import missing
from husky_sim.runs.scenario import Scenario, load_scenario
from husky_sim.sim.environment import PhysicsEnvironment
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.outcomes import OutcomeMonitor, reference_error
from husky_sim.sim.rollout import control_steps

try:
    import gymnasium
    from gymnasium import spaces
except ImportError:  # the core install has no gymnasium
    raise missing("gymnasium", "gym", "the gymnasium environment") from None


def make_husky_nav(
    scenario: str | Scenario = "husky_point_stabilisation", seed: int | None = None
) -> HuskyNavEnv:
    """HuskyNavEnv for a shipped scenario's name, a scenario file's path or a loaded Scenario;
    `seed` overrides the file's (the first reset's sensor seed, as `husky-sim run --seed`)."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if seed is not None:
        sc = sc.with_overrides(seed=seed)
    return HuskyNavEnv(sc.episode_config(), sc.reference_object())


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
    the current time, `obstacles` the nearest OBSERVED_OBSTACLES sensed circles (of those the
    scenario's sensing model sees: husky_sim.sim.sensing; by default every one) as rows [dx m, dy
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
        self._sim: PhysicsEnvironment | None = None
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
        self._sim = PhysicsEnvironment(dataclasses.replace(config, seed=int(seed)))
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
