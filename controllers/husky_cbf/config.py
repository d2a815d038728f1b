"""Configuration of husky-cbf: the paper's NMPC-CLF settings plus what the Husky's physics needs.

The paper's part (tau, N, weights, alpha, gamma, velocity bounds) is an `NMPCConfig` with
Relax-CBF as its obstacle constraint, so its defaults live in one place (controllers.config).
Everything else is here, with the reason for each default. The robot's own figures (acceleration
limits, yaw-rate response, body size) have no defaults: they come from the robot description and
the identified response in the scenario file, never from literals in code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from controllers.config import ConfigError, NMPCConfig


def _positive(name: str, value: float) -> None:
    if not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name}: must be > 0 and finite, got {value}")


def _non_negative(name: str, value: float) -> None:
    if not (value >= 0 and math.isfinite(value)):
        raise ConfigError(f"{name}: must be >= 0 and finite, got {value}")


@dataclass(frozen=True)
class RobotResponse:
    """How the drive follows a command: acceleration limits (m/s^2, rad/s^2) of the commanded
    velocities, the drive's dead time command_delay_s (s) before it acts on a command, the body yaw
    rate's first-order lag behind the (delayed) commanded yaw rate,
    d(omega_body)/dt = (yaw_gain * omega_cmd - omega_body) / yaw_time_constant_s, and the wheel
    drive's linear velocity limit max_linear_mps (m/s); each side's wheels run at
    v -+ half_separation_m * omega_cmd (m/s, with the drive's effective separation), which
    HuskyCBFConfig.wheel_speed_ratio bounds."""

    max_linear_accel_mps2: float
    max_angular_accel_radps2: float
    yaw_gain: float
    yaw_time_constant_s: float
    half_separation_m: float
    max_linear_mps: float
    command_delay_s: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "max_linear_accel_mps2",
            "max_angular_accel_radps2",
            "yaw_gain",
            "yaw_time_constant_s",
            "half_separation_m",
            "max_linear_mps",
        ):
            _positive(f"response.{name}", getattr(self, name))
        _non_negative("response.command_delay_s", self.command_delay_s)


@dataclass(frozen=True)
class PoseNoise:
    """What the robot's localisation reports about its pose estimate: white-noise standard
    deviations of position (m, per axis) and heading (rad); and how far the commands predict the
    motion over one step: the drive's speed error (m/s) and yaw-rate error (rad/s)."""

    position_std_m: float = 0.0
    yaw_std_rad: float = 0.0
    speed_error_mps: float = 0.1  # the drive follows a speed command within about 0.1 m/s
    #: the skid-steer's yaw rate stick-slips about the identified lag by tenths of a rad/s
    yaw_rate_error_radps: float = 0.3

    def __post_init__(self) -> None:
        for name in ("position_std_m", "yaw_std_rad", "speed_error_mps", "yaw_rate_error_radps"):
            _non_negative(f"pose_noise.{name}", getattr(self, name))


@dataclass(frozen=True)
class Footprint:
    """The body's ground projection as a rectangle about the base origin (m): half length along
    x (forward), half width along y, wheels included."""

    half_length_m: float
    half_width_m: float

    def __post_init__(self) -> None:
        _positive("footprint.half_length_m", self.half_length_m)
        _positive("footprint.half_width_m", self.half_width_m)


@dataclass(frozen=True)
class GuidanceConfig:
    """Waypoint guidance around blocked straight paths (controllers.husky_cbf.guidance)."""

    grid_resolution_m: float = 0.1  # cost-grid cell size
    grid_padding_m: float = 3.0  # grid extends this far beyond the robot and the goal
    clearance_cost_m: float = 0.6  # cells closer than this to an inflated obstacle cost more ...
    clearance_cost_gain: float = 4.0  # ... up to (1 + gain) times their length
    lookahead_m: float = 1.5  # the waypoint: the farthest path point within this, in sight
    mover_sweep_s: float = 2.0  # a mover blocks where it will be over the next seconds
    release_margin_m: float = 0.1  # a guided robot leaves guidance only with this much to spare
    #: among static obstacles, cells within path_hysteresis_width_m (m) of the last path cost this
    #: fraction less: with an obstacle dead ahead and a few cm of obstacle noise, the shortest way
    #: round changed sides from one step to the next and a loaded Husky, turning neither way,
    #: drove into it (check). Not among movers: there a mover crossing the path taken made the
    #: robot keep to it and touch the mover (paper_dynamic_tracking_crossing, N = 5)
    path_hysteresis: float = 0.2
    path_hysteresis_width_m: float = 0.2
    #: Mover evasion (guidance.MoverEvasion): a mover whose track relative to the robot comes
    #: within its radius + the robot's inflation + evade_margin_m in the next evade_horizon_s
    #: makes the robot step aside now
    evade_horizon_s: float = 6.0
    evade_margin_m: float = 0.5
    tracking_preview_s: float = 1.0  # tracking: the reference this far ahead is the path's goal
    #: Set-point approach (guidance.LineApproach): within approach_radius_m of the goal, a robot
    #: off the goal's line (|lateral| > approach_exit_m) is led onto it
    #: by a waypoint on the line approach_lookahead_m ahead of it, or, beside or past the goal by
    #: more than approach_enter_m, behind it (it backs up onto the line, 1.5 lookaheads or 4 m
    #: per m of lateral error behind the goal, and leaves only aligned
    #: within approach_exit_rad): a unicycle beside its goal cannot close the gap within a short
    #: horizon, and the skid-steer barely answers small turns.
    approach_radius_m: float = 3.0
    approach_lookahead_m: float = 1.0
    approach_enter_m: float = 0.07
    approach_exit_m: float = 0.03
    approach_exit_rad: float = 0.05
    approach_speed_mps: float = 0.6  # |v| cap within slow_radius_m of a set-point: time for the yaw lag
    #: Pivot (guidance.LineApproach): within pivot_radius_m of a set-point and off its line, turn
    #: where it stands until aimed at the goal within pivot_aim_rad, drive to within
    #: pivot_arrive_m of it, and turn to its heading there; pivot again if it drifts beyond
    #: pivot_restart_m (m, rad)
    pivot_radius_m: float = 1.0
    pivot_aim_rad: float = 0.2
    pivot_arrive_m: float = 0.05
    pivot_restart_m: float = 0.1
    slow_radius_m: float = 1.5
    #: a trajectory slower than this (m/s) will not come to the robot (the paper's dynamic
    #: tracking circle moves at 0.02 m/s): the robot drives at its point (guidance.point_approach)
    #: along the bearing beyond point_approach_far_m, turning to the reference's heading closer in,
    #: and tracks the reference itself within point_approach_near_m (m). Brought onto its tangent
    #: like onto a set-point's line instead, the Husky backed up metres to dock and rejoined 6.7
    #: to 9.3 s after a mover had passed (issue 10).
    approach_max_reference_speed_mps: float = 0.1
    point_approach_near_m: float = 0.1
    point_approach_far_m: float = 0.3

    def __post_init__(self) -> None:
        if not 0.0 <= self.path_hysteresis < 1.0:
            raise ConfigError(f"guidance.path_hysteresis: must be in [0, 1), got {self.path_hysteresis}")
        for name in (
            "grid_resolution_m",
            "grid_padding_m",
            "clearance_cost_m",
            "lookahead_m",
            "approach_radius_m",
            "approach_lookahead_m",
            "approach_enter_m",
            "approach_exit_m",
            "approach_exit_rad",
            "approach_speed_mps",
            "pivot_aim_rad",
            "pivot_arrive_m",
            "pivot_restart_m",
            "slow_radius_m",
            "approach_max_reference_speed_mps",
            "point_approach_near_m",
            "point_approach_far_m",
        ):
            _positive(f"guidance.{name}", getattr(self, name))
        for name in (
            "clearance_cost_gain",
            "path_hysteresis_width_m",
            "pivot_radius_m",
            "mover_sweep_s",
            "release_margin_m",
            "tracking_preview_s",
            "evade_horizon_s",
            "evade_margin_m",
        ):
            _non_negative(f"guidance.{name}", getattr(self, name))


@dataclass(frozen=True)
class HuskyCBFConfig:
    """husky-cbf: Relax-CBF NMPC-CLF on a dynamically extended model with a multi-disc body."""

    nmpc: NMPCConfig  # the paper's part; its safety must be relax-cbf
    response: RobotResponse
    footprint: Footprint
    omega_cmd_max_radps: float = 2.0  # commanded yaw-rate bound (the Husky's drive limit, rad/s)
    #: each side's wheel speed at most this times the drive's linear limit (response's
    #: max_linear_mps, the Husky's 1 m/s top speed). The real recordings reach 0.9 m/s a side and
    #: turn at 0.5 of the wheel-implied yaw rate up to there; beyond, the calibrated plant turns
    #: far less (1 m/s and 0.93 rad/s, wheels at 1.5 and 0.5 m/s: 0.16 rad/s, a yaw ratio of
    #: 0.11, `husky-sim drive-response`), and 1.5x (the uncalibrated plant's setting) made the
    #: robot plan turns it could not make and touch obstacles on the circle scenarios
    wheel_speed_ratio: float = 1.0
    #: margin (m) between each body disc and an obstacle: sensing noise and the drive's
    #: tracking error; braking distance is in the model, so this need not cover it.
    margin_m: float = 0.1
    #: a mover's circle grows by this much per metre of its predicted travel (m/m): its velocity
    #: is an estimate, and a person does not walk a straight line.
    mover_margin_per_m: float = 0.3
    #: a mover at a predicted step blocks its whole track over the next this many seconds (s):
    #: the time a skid-steer needs to turn away (yaw lag) and brake
    mover_sweep_s: float = 1.5
    #: disc count: the fewest discs along the body whose radius exceeds the half width by at most
    #: this (m); 3 for a Husky (radius 0.38 m, against 0.57 m for one enclosing circle).
    disc_excess_m: float = 0.05
    accel_weight: tuple[float, float] = (0.2, 0.05)  # cost on (dv/dt, d omega_cmd/dt) squared
    #: terminal cost in the reference's frame (along, across, heading): a heavy lateral weight,
    #: so that a short horizon does not settle beside its goal (a unicycle beside its goal lowers
    #: a stage cost only by backing up and turning).
    terminal_weight: tuple[float, float, float] = (20.0, 200.0, 5.0)
    #: the terminal lateral error is taken this far ahead of the robot (behind it while it backs
    #: up onto a goal's line), so that turning toward the line pays within a short horizon (m)
    terminal_lookahead_m: float = 0.5
    terminal_speed_weight: float = 5.0  # set-points: arrive at rest ((m/s)^-2 in the cost)
    #: the localisation's reported pose noise: the set-point approach decides on a filtered pose
    #: (localisation.PoseFilter); none declared, the measured pose as it is
    pose_noise: PoseNoise = field(default_factory=PoseNoise)
    #: turn monitor (turn_monitor.py): over the last weak_turn_window_s (s), once the model
    #: predicted at least weak_turn_min_rad of heading change, a robot on its way to a set-point
    #: that turned less than weak_turn_ratio of it is held to weak_turn_speed_mps (m/s): it may
    #: not steer round what its plan goes round, and must be able to stop before it
    weak_turn_window_s: float = 1.6
    weak_turn_min_rad: float = 0.3
    weak_turn_ratio: float = 0.4
    weak_turn_speed_mps: float = 0.4
    soft_penalty: float = 1e4  # exact-penalty weight on the obstacle slack of the re-solve
    slots: int = 6  # nearest obstacles in the NLP
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)

    @property
    def tau_s(self) -> float:
        """Sampling time (s), the paper part's."""
        return self.nmpc.tau_s

    @property
    def horizon(self) -> int:
        """Prediction steps N, the paper part's."""
        return self.nmpc.horizon

    def __post_init__(self) -> None:
        if self.nmpc.safety != "relax-cbf":
            raise ConfigError(f"nmpc.safety: husky-cbf is built on relax-cbf, got {self.nmpc.safety!r}")
        _positive("omega_cmd_max_radps", self.omega_cmd_max_radps)
        _positive("wheel_speed_ratio", self.wheel_speed_ratio)
        for name in (
            "margin_m",
            "mover_margin_per_m",
            "mover_sweep_s",
            "disc_excess_m",
            "terminal_speed_weight",
            "terminal_lookahead_m",
        ):
            _non_negative(name, getattr(self, name))
        _positive("soft_penalty", self.soft_penalty)
        for name in ("weak_turn_window_s", "weak_turn_min_rad", "weak_turn_speed_mps"):
            _positive(name, getattr(self, name))
        if not 0.0 <= self.weak_turn_ratio <= 1.0:
            raise ConfigError(f"weak_turn_ratio: must be in [0, 1], got {self.weak_turn_ratio}")
        if len(self.accel_weight) != 2 or min(self.accel_weight) < 0:
            raise ConfigError(f"accel_weight: two weights >= 0, got {self.accel_weight}")
        if len(self.terminal_weight) != 3 or min(self.terminal_weight) < 0:
            raise ConfigError(f"terminal_weight: three weights >= 0, got {self.terminal_weight}")
        if not 1 <= self.slots <= 64:
            raise ConfigError(f"slots: must be in [1, 64], got {self.slots}")
