"""Open-loop driving of the simulated Husky: a timed sequence of (v, omega) commands in, the track
of poses and velocities out, through the same drive limits and wheel-speed split as a closed-loop
episode. Used by the replay of real recordings, the yaw-response identification and the bench."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controllers.model import wrap_angle
from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.sim.drive import DriveConfig, SkidSteerDrive
from husky_sim.sim.ground import Ground, load_ground
from husky_sim.sim.robot import SkidSteerRobot
from husky_sim.sim.robot_description import load_robot
from husky_sim.sim.world import World, WorldConfig

#: A command stamped up to this long after a physics step still drives that step (s); absorbs the
#: nanosecond rounding of bag timestamps.
HOLD_TOLERANCE_S = 1e-6


@dataclass(frozen=True)
class SimTrack:
    """Simulated state at every physics step k, at time t_s[k] = k / physics_hz (s) after start."""

    t_s: np.ndarray  # (n + 1,) s
    poses: np.ndarray  # (n + 1, 3) base_link x (m), y (m), yaw (rad)
    body_velocity: np.ndarray  # (n + 1, 2) achieved v (m/s) and yaw rate (rad/s)
    applied: np.ndarray  # (n, 2) limited command [v (m/s), omega (rad/s)] during step k
    wheel_speeds: np.ndarray  # (n + 1, 4) measured wheel speeds (rad/s), left joints then right
    motor_currents: np.ndarray  # (n + 1, 2) left and right motor current (A) in the step before

    def poses_at(self, t_s: np.ndarray) -> np.ndarray:
        """Poses (x m, y m, yaw rad) at times t_s (s), linearly interpolated between steps."""
        yaw = np.unwrap(self.poses[:, 2])
        columns = [np.interp(t_s, self.t_s, c) for c in (self.poses[:, 0], self.poses[:, 1], yaw)]
        columns[2] = wrap_angle(columns[2])
        return np.column_stack(columns)


def held_commands(cmd_t_s: np.ndarray, commands: np.ndarray, step_t_s: np.ndarray) -> np.ndarray:
    """Zero-order hold: for each step time (s) the latest command [v m/s, omega rad/s] stamped at
    or before it, zeros before the first command."""
    idx = np.searchsorted(np.asarray(cmd_t_s, dtype=float), step_t_s + HOLD_TOLERANCE_S, side="right")
    padded = np.vstack([np.zeros((1, 2)), np.asarray(commands, dtype=float).reshape(-1, 2)])
    return padded[idx]


def simulate_commands(
    cmd_t_s: np.ndarray,
    commands: np.ndarray,
    duration_s: float,
    start: tuple[float, float, float],
    *,
    world: WorldConfig | None = None,
    drive: DriveConfig | None = None,
    ground: Ground | None = None,
    payload_kg: float = 0.0,
    wheel_targets: np.ndarray | None = None,
    robot: str = DEFAULT_ROBOT,
) -> SimTrack:
    """Drive the robot `robot` (its folder's name; with `payload_kg` on its top plate) on `ground`
    (default: the robot's default ground) from `start` (x m, y m, yaw rad, at rest) for
    `duration_s` (rounded up to whole physics steps) with the commands held from their times
    `cmd_t_s` (s). `wheel_targets`, if given, are (left, right) wheel speeds (rad/s) per command,
    sent in place of the drive's split of the body command (a recording's measured wheel speeds,
    for the calibration)."""
    description = load_robot(robot)
    world = world or WorldConfig()
    drive = drive or DriveConfig.for_robot(description.specs)
    ground = ground or load_ground(robot=robot)
    with World(world) as sim:
        body = SkidSteerRobot(
            sim.client, start, ground.tyre, payload_kg, coulomb=not ground.calibrated, robot=description
        )
        skid = SkidSteerDrive(drive, body.geometry.wheel_radius_m, body.geometry.track_width_m, ground)
        steps = max(math.ceil(duration_s * world.physics_hz - 1e-6), 0)
        t_s = np.arange(steps + 1) * sim.dt_s
        poses, velocities, applied = [body.pose()], [body.body_velocity()], []
        wheels, currents = [body.wheel_speeds()], [(0.0, 0.0)]
        held = held_commands(cmd_t_s, commands, t_s[:-1])
        held_wheels = None if wheel_targets is None else held_commands(cmd_t_s, wheel_targets, t_s[:-1])
        for k, command in enumerate(held):
            if held_wheels is None:
                applied.append(skid.step(body, command, sim.dt_s))
            else:
                applied.append(skid.step_wheels(body, command, tuple(held_wheels[k]), sim.dt_s))
            sim.step()
            poses.append(body.pose())
            velocities.append(body.body_velocity())
            wheels.append(body.wheel_speeds())
            currents.append(skid.motor_currents(body))
    return SimTrack(
        t_s,
        np.array(poses),
        np.array(velocities),
        np.array(applied).reshape(-1, 2),
        np.array(wheels),
        np.array(currents),
    )
