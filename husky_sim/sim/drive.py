"""Skid-steer drive of the Husky: (v, omega) command -> limited command -> wheel speed targets ->
motors (current-limited) -> four wheels with tyre forces.

Mirrors what Husky's own diff_drive_controller does: clip to the velocity limits, rate-limit to
the acceleration limits at its update rate (here: every physics step), and split into left/right
wheel speeds with an *effective* wheel separation (track x wheel_separation_multiplier, 1.875 on
the Husky) that compensates the scrubbing of a skid-steer turn. Defaults are the published
ROS 1 husky_control limits (husky_sim.sim.specs, [CONTROL]).

Below the controller, what the real Husky's recordings show and a velocity motor lacks: the wheel
speed follows its target after a dead time and with a first-order lag (the motor driver's speed
loop; fitted per recording by `husky-sim calibrate`, kept with the ground: DriveResponse), and each side's
gearmotor (one motor drives both wheels of a side through a belt) gives torque from current
through the published constants, up to the motor controller's current limit (MotorConfig).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from husky_sim.sim import specs as specs
from husky_sim.sim.ground import DriveResponse, Ground

if TYPE_CHECKING:
    from husky_sim.sim.robot import SkidSteerRobot


@dataclass(frozen=True)
class MotorConfig:
    """One side's gearmotor and its controller (husky_sim.sim.specs, [MOTOR]); it drives the side's
    two wheels through one belt, at one speed (husky_sim.sim.robot.SkidSteerRobot.drive_wheels)."""

    torque_constant_nm_per_a: float = specs.MOTOR_TORQUE_CONSTANT_NM_PER_A  # N m / A
    gear_ratio: float = specs.MOTOR_GEAR_RATIO  # motor turns per wheel turn
    gearbox_efficiency: float = specs.MOTOR_GEARBOX_EFFICIENCY  # output / input power
    current_limit_a: float = specs.MOTOR_CURRENT_LIMIT_A  # the motor controller's limit (A)
    wheels_per_motor: int = 2
    #: the robot's published current limit (A): what current_limit_a is scaled from (the check)
    nominal_current_limit_a: float = specs.MOTOR_CURRENT_LIMIT_A

    @classmethod
    def for_robot(cls, robot: specs.RobotSpecs) -> MotorConfig:
        """A robot's published gearmotor (its specs file's `motor`)."""
        m = robot.motor
        return cls(
            m.torque_constant_nm_per_a,
            m.gear_ratio,
            m.gearbox_efficiency,
            m.current_limit_a,
            nominal_current_limit_a=m.current_limit_a,
        )

    def __post_init__(self) -> None:
        checks = {
            "torque_constant_nm_per_a": (1e-4, 1.0),
            "gear_ratio": (1.0, 1000.0),
            "gearbox_efficiency": (0.05, 1.0),
            "current_limit_a": (0.1, 500.0),
        }
        for name, (lo, hi) in checks.items():
            value = getattr(self, name)
            if not (math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"drive.motor.{name}: must be in [{lo:g}, {hi:g}], got {value}")

    @property
    def newton_metres_per_amp(self) -> float:
        """Torque at the wheels of one side (N m) per ampere of motor current."""
        return self.torque_constant_nm_per_a * self.gear_ratio * self.gearbox_efficiency

    @property
    def side_torque_limit_nm(self) -> float:
        """Torque limit (N m at the wheels, summed over the side's wheels) at the current limit."""
        return self.current_limit_a * self.newton_metres_per_amp

    def current_a(self, side_torque_nm: float, side_speed_radps: float) -> float:
        """Motor current (A) as the motor controller reports it, for the side's wheel torque (N m,
        summed over its wheels) at the side's wheel speed (rad/s): the current that gives the
        torque while the motor drives (torque along the rotation), 0 while it brakes (the real
        Husky's log reads about 0 A on the inner side of every arc: wet_grass_raw.csv)."""
        if side_torque_nm * side_speed_radps < 0.0:
            return 0.0
        return abs(side_torque_nm) / self.newton_metres_per_amp


@dataclass(frozen=True)
class DriveConfig:
    """Limits and kinematic parameters of the skid-steer drive."""

    wheel_separation_multiplier: float = specs.WHEEL_SEPARATION_MULTIPLIER  # dimensionless
    max_linear_mps: float = specs.LINEAR_MAX_VELOCITY_MPS  # |v| limit, m/s
    max_angular_radps: float = specs.ANGULAR_MAX_VELOCITY_RADPS  # |omega| limit, rad/s
    max_linear_accel_mps2: float = specs.LINEAR_MAX_ACCELERATION_MPS2  # |dv/dt| limit, m/s^2
    max_angular_accel_radps2: float = specs.ANGULAR_MAX_ACCELERATION_RADPS2  # rad/s^2
    motor: MotorConfig = field(default_factory=lambda: MotorConfig())

    @classmethod
    def for_robot(cls, robot: specs.RobotSpecs) -> DriveConfig:
        """A robot's published drive: its ROS 1 diff_drive_controller limits and its gearmotor
        (the defaults are the default robot's, the Husky's)."""
        d = robot.ros1_diff_drive
        return cls(
            wheel_separation_multiplier=d.wheel_separation_multiplier,
            max_linear_mps=d.linear_max_velocity_mps,
            max_angular_radps=d.angular_max_velocity_radps,
            max_linear_accel_mps2=d.linear_max_acceleration_mps2,
            max_angular_accel_radps2=d.angular_max_acceleration_radps2,
            motor=MotorConfig.for_robot(robot),
        )

    def __post_init__(self) -> None:
        for name in (
            "wheel_separation_multiplier",
            "max_linear_mps",
            "max_angular_radps",
            "max_linear_accel_mps2",
            "max_angular_accel_radps2",
        ):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"drive.{name}: must be > 0 and finite, got {value}")


class SkidSteerDrive:
    """Velocity and acceleration limiting plus skid-steer wheel-speed mapping."""

    def __init__(
        self,
        config: DriveConfig,
        wheel_radius_m: float,
        track_width_m: float,
        ground: Ground | None = None,
    ) -> None:
        self.config = config
        self.response = ground.drive if ground is not None else DriveResponse()
        motor = config.motor
        #: torque limit of one side's motor at its wheels (N m)
        self.side_torque_limit_nm = motor.side_torque_limit_nm
        if ground is not None and ground.wheel_torque_limit_nm is not None:
            # the uncalibrated plant's per-wheel literal, scaled as the current limit is (the check)
            scale = motor.current_limit_a / motor.nominal_current_limit_a
            self.side_torque_limit_nm = ground.wheel_torque_limit_nm * scale * motor.wheels_per_motor
        self.wheel_radius_m = wheel_radius_m
        self.effective_separation_m = track_width_m * config.wheel_separation_multiplier
        self._applied = (0.0, 0.0)
        self._pending: deque[tuple[float, float]] = deque()
        self._targets = (0.0, 0.0)
        self._delay_steps = -1  # worked out on the first step, when the physics step is known

    def reset(self) -> None:
        self._applied = (0.0, 0.0)
        self._pending.clear()
        self._targets = (0.0, 0.0)
        self._delay_steps = -1

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

    def wheel_targets(self, wheel_speeds: tuple[float, float], dt_s: float) -> tuple[float, float]:
        """The speed loop's targets (rad/s) one physics step dt_s later: `wheel_speeds` delayed by
        the response's dead time, then through its first-order lag."""
        cfg = self.response
        if self._delay_steps < 0:
            self._delay_steps = round(cfg.command_delay_s / dt_s)
        self._pending.append(wheel_speeds)
        delayed = self._pending.popleft() if len(self._pending) > self._delay_steps else (0.0, 0.0)
        if cfg.wheel_time_constant_s <= 0.0:
            self._targets = delayed
        else:
            a = 1.0 - math.exp(-dt_s / cfg.wheel_time_constant_s)
            left, right = self._targets
            self._targets = (left + a * (delayed[0] - left), right + a * (delayed[1] - right))
        return self._targets

    def step(self, robot: SkidSteerRobot, command: np.ndarray, dt_s: float) -> np.ndarray:
        """One physics step's drive: limit `command` [v m/s, omega rad/s], send the delayed and
        lagged wheel targets to the motors with the current-limited torque, and apply the tyre
        forces. Call it before the world's step; returns the limited command."""
        applied = self.limit(command, dt_s)
        return self.step_wheels(robot, applied, self.wheel_speeds(applied), dt_s)

    def step_wheels(
        self, robot: SkidSteerRobot, applied: np.ndarray, wheel_speeds: tuple[float, float], dt_s: float
    ) -> np.ndarray:
        """`step` from given (left, right) wheel speeds (rad/s) in place of the split of the
        limited command `applied` (returned as is): a recording's wheel speeds, for calibration."""
        left, right = self.wheel_targets(wheel_speeds, dt_s)
        robot.drive_wheels(left, right, self.side_torque_limit_nm)
        return applied

    def motor_currents(self, robot: SkidSteerRobot) -> tuple[float, float]:
        """Left and right motor currents (A) from the wheel torques of the last physics step."""
        (left, right), speeds = robot.side_torques(), robot.wheel_speeds()
        half = len(speeds) // 2
        motor = self.config.motor
        return motor.current_a(left, float(speeds[:half].mean())), motor.current_a(
            right, float(speeds[half:].mean())
        )
