"""Skid-steer drive of the Husky: (v, omega) command -> limited command -> four wheel speeds.

Mirrors what Husky's own diff_drive_controller does: clip to the velocity limits, rate-limit to
the acceleration limits at its update rate (here: every physics step), and split into left/right
wheel speeds with an *effective* wheel separation (track x wheel_separation_multiplier, 1.875 on
the Husky) that compensates the scrubbing of a skid-steer turn. Defaults are the published
ROS 1 husky_control limits (husky_sim.sim.specs, [CONTROL]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from husky_sim.sim import specs as specs


@dataclass(frozen=True)
class DriveConfig:
    """Limits and kinematic parameters of the skid-steer drive."""

    wheel_separation_multiplier: float = specs.WHEEL_SEPARATION_MULTIPLIER  # dimensionless
    max_linear_mps: float = specs.LINEAR_MAX_VELOCITY_MPS  # |v| limit, m/s
    max_angular_radps: float = specs.ANGULAR_MAX_VELOCITY_RADPS  # |omega| limit, rad/s
    max_linear_accel_mps2: float = specs.LINEAR_MAX_ACCELERATION_MPS2  # |dv/dt| limit, m/s^2
    max_angular_accel_radps2: float = specs.ANGULAR_MAX_ACCELERATION_RADPS2  # rad/s^2
    #: Per-wheel motor torque limit (N m). Clearpath publishes no wheel torque; 40 N m lets the
    #: 50 kg robot reach its 3 m/s^2 limit and scrub through a turn on mu = 1 ground (about
    #: 15 N m per wheel), with headroom. A scenario may lower it (the sim-to-real sweep does).
    wheel_torque_limit_nm: float = 40.0

    def __post_init__(self) -> None:
        for name in (
            "wheel_separation_multiplier",
            "max_linear_mps",
            "max_angular_radps",
            "max_linear_accel_mps2",
            "max_angular_accel_radps2",
            "wheel_torque_limit_nm",
        ):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"drive.{name}: must be > 0 and finite, got {value}")


class SkidSteerDrive:
    """Velocity and acceleration limiting plus skid-steer wheel-speed mapping."""

    def __init__(self, config: DriveConfig, wheel_radius_m: float, track_width_m: float) -> None:
        self.config = config
        self.wheel_radius_m = wheel_radius_m
        self.effective_separation_m = track_width_m * config.wheel_separation_multiplier
        self._applied = (0.0, 0.0)

    def reset(self) -> None:
        self._applied = (0.0, 0.0)

    @property
    def applied(self) -> np.ndarray:
        """The last limited command [v, omega] actually sent to the wheels."""
        return np.array(self._applied)

    def limit(self, command: np.ndarray, dt_s: float) -> np.ndarray:
        """Clip to the velocity limits, then move at most a_max dt towards it (one update; plain
        floats, as it runs every physics step)."""
        cfg = self.config
        v = min(max(float(command[0]), -cfg.max_linear_mps), cfg.max_linear_mps)
        w = min(max(float(command[1]), -cfg.max_angular_radps), cfg.max_angular_radps)
        dv_max, dw_max = cfg.max_linear_accel_mps2 * dt_s, cfg.max_angular_accel_radps2 * dt_s
        v0, w0 = self._applied
        self._applied = (v0 + min(max(v - v0, -dv_max), dv_max), w0 + min(max(w - w0, -dw_max), dw_max))
        return np.array(self._applied)

    def wheel_speeds(self, command: np.ndarray) -> tuple[float, float]:
        """Left and right wheel angular speeds (rad/s) for a body command [v, omega]."""
        half = 0.5 * self.effective_separation_m * command[1]
        return (command[0] - half) / self.wheel_radius_m, (command[0] + half) / self.wheel_radius_m
