"""Configuration of husky-cbf: the paper's NMPC-CLF settings plus what the Husky's physics needs.

The paper's part (tau, N, weights, alpha, gamma, velocity bounds) is an `NMPCConfig` with
Relax-CBF as its obstacle constraint, so its defaults live in one place (controllers.config).
The robot's own figures (acceleration limits, yaw-rate response, body size, pose noise, latency)
are facts, not tuning: they come from the robot description and the identified response in the
scenario file, never from literals in code.

The tuning settings are grouped by the component that reads them: the NMPC (top level), the mover
model (`movers`), the global planner (`planner`), and the behaviours (`approach`, `yielding`,
`recovery`). Each carries its range and a one-line contract (`doc`); `husky-sim settings
--controller husky-cbf` prints them as a table. Every other number is a named constant in the
module that uses it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from controllers.config import ConfigError, NMPCConfig
from controllers.settings import check_ranges, flag, setting


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
    #: a skid-steer's yaw rate stick-slips about the identified lag by tenths of a rad/s
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
class MoverConfig:
    """The one mover model (movers.py): constant-velocity prediction and swept footprint, read by
    the NMPC's obstacle constraints, the planner's circles and the yielding behaviours."""

    sweep_s: float = setting(
        1.5,
        0.0,
        10.0,
        "s",
        doc="a mover at a predicted instant blocks its track over the next sweep_s: the time the "
        "robot needs to turn away (yaw lag) and brake",
    )
    margin_per_m: float = setting(
        0.3,
        0.0,
        5.0,
        "m/m",
        doc="a mover's circle grows by this per metre of predicted travel: its velocity is an "
        "estimate, and a walker does not keep a straight line",
    )
    accel_bound_mps2: float = setting(
        0.5,
        0.0,
        10.0,
        "m/s^2",
        doc="the safety filter's bound on a mover's change of velocity: its circle grows by half "
        "this times the squared time since it was measured",
    )

    def __post_init__(self) -> None:
        check_ranges(self, "movers.")


@dataclass(frozen=True)
class PlannerConfig:
    """The global planner (planner.py): a cost grid round the static layer and the swept movers."""

    grid_resolution_m: float = setting(
        0.1, 0.01, 1.0, "m", doc="cell size of the cost grid: the finest gap the planner resolves"
    )
    max_grid_cells: int = setting(
        200_000,
        1_000,
        5_000_000,
        doc="a larger area is searched on a coarser grid: bounds the search's time and memory",
    )
    clearance_cost_m: float = setting(
        0.6,
        0.0,
        5.0,
        "m",
        lo_open=True,
        doc="cells closer than this to an inflated obstacle cost more: the path keeps its distance",
    )
    clearance_cost_gain: float = setting(
        4.0,
        0.0,
        100.0,
        doc="a cell at an inflated obstacle costs (1 + this) times its length: how far the path "
        "detours for clearance",
    )
    lookahead_m: float = setting(
        1.5,
        0.0,
        20.0,
        "m",
        lo_open=True,
        doc="the waypoint is the farthest path point within this that the robot can see: how far "
        "ahead the NMPC is led",
    )

    def __post_init__(self) -> None:
        check_ranges(self, "planner.")


@dataclass(frozen=True)
class ApproachConfig:
    """Approach behaviours (behaviours/approach.py): onto a set-point along its line (docking,
    pivot), and at the point of a trajectory too slow to come to the robot."""

    radius_m: float = setting(
        3.0,
        0.0,
        20.0,
        "m",
        lo_open=True,
        doc="within this of a set-point a robot off the goal's line is led onto it (or docks): a "
        "short horizon cannot close a lateral gap by itself",
    )
    speed_mps: float = setting(
        0.6,
        0.0,
        5.0,
        "m/s",
        lo_open=True,
        doc="|v| cap near a (nearly) stationary goal: leaves time for the yaw lag while lining up",
    )
    slow_radius_m: float = setting(
        1.5,
        0.0,
        20.0,
        "m",
        lo_open=True,
        doc="distance from the goal within which speed_mps caps the speed",
    )
    pivot_radius_m: float = setting(
        1.0,
        0.0,
        20.0,
        "m",
        doc="within this of a set-point and off its line the robot pivots in place rather than "
        "docks: a skid-steer barely answers small turns",
    )

    def __post_init__(self) -> None:
        check_ranges(self, "approach.")


@dataclass(frozen=True)
class YieldConfig:
    """Yielding to movers (behaviours/yield_to_movers.py): stepping aside, waiting beside a slow
    reference's point, and bracing across a mover's track there."""

    horizon_s: float = setting(
        6.0,
        0.0,
        30.0,
        "s",
        doc="a mover whose closest approach comes within this is on a collision course: the "
        "robot's time to turn and move aside",
    )
    margin_m: float = setting(
        0.5,
        0.0,
        5.0,
        "m",
        doc="a mover passing closer than its radius + the robot's inflation + this is on a "
        "collision course, and the step aside clears it by as much",
    )

    def __post_init__(self) -> None:
        check_ranges(self, "yielding.")


@dataclass(frozen=True)
class RecoveryConfig:
    """Recovery from a stall (behaviours/recovery.py): a progress checker and recovery phases, as
    Nav2 has them."""

    enabled: bool = flag(True, doc="whether a stalled robot runs the recovery phases at all")
    progress_window_s: float = setting(
        3.0,
        0.0,
        60.0,
        "s",
        lo_open=True,
        doc="stalled: over this window the robot neither came progress_min_m closer to its target "
        "nor moved that far: longer than any purposeful manoeuvre at cruise speed",
    )
    progress_min_m: float = setting(
        0.25,
        0.0,
        5.0,
        "m",
        lo_open=True,
        doc="the progress (closer, or moved) that a window must show: above pose noise and scrub",
    )
    idle_s: float = setting(
        0.5,
        0.0,
        60.0,
        "s",
        lo_open=True,
        doc="stalled too: commanded to stand still this long away from the target (nothing in the "
        "horizon to wait for)",
    )

    def __post_init__(self) -> None:
        check_ranges(self, "recovery.")


@dataclass(frozen=True)
class HuskyCBFConfig:
    """husky-cbf: Relax-CBF NMPC-CLF on a dynamically extended model with a multi-disc body."""

    nmpc: NMPCConfig  # the paper's part; its safety must be relax-cbf
    response: RobotResponse
    footprint: Footprint
    omega_cmd_max_radps: float = 2.0  # commanded yaw-rate bound (the drive's limit, rad/s)
    wheel_speed_ratio: float = setting(
        1.0,
        0.0,
        3.0,
        lo_open=True,
        doc="each side's wheel speed at most this times the drive's linear limit: beyond it a "
        "skid-steer turns far less than its wheels imply, so plans would promise turns it cannot make",
    )
    margin_m: float = setting(
        0.1,
        0.0,
        2.0,
        "m",
        doc="margin between each body disc and an obstacle: sensing noise and the drive's tracking "
        "error (braking distance is in the model)",
    )
    disc_excess_m: float = setting(
        0.05,
        0.01,
        1.0,
        "m",
        doc="the body is the fewest discs along its axis whose radius exceeds the half width by at "
        "most this: how tightly the discs hug the sides",
    )
    accel_weight: tuple[float, float] = setting(
        (0.2, 0.05),
        0.0,
        1e6,
        doc="cost on (dv/dt, d omega_cmd/dt) squared: smooth commands a drive can follow",
    )
    terminal_weight: tuple[float, float, float] = setting(
        (20.0, 200.0, 5.0),
        0.0,
        1e6,
        doc="terminal cost in the reference's frame (along, across, heading): a heavy lateral "
        "weight, so that a short horizon does not settle beside its goal",
    )
    terminal_lookahead_m: float = setting(
        0.5,
        0.0,
        5.0,
        "m",
        doc="the terminal lateral error is taken this far ahead of the robot (behind it when "
        "reversing): turning toward the line pays within a short horizon",
    )
    terminal_speed_weight: float = setting(
        5.0,
        0.0,
        1e6,
        doc="terminal cost on the speed error ((m/s)^-2): a set-point is reached at rest",
    )
    #: the localisation's reported pose noise: the set-point approach decides on a filtered pose
    #: (localisation.PoseFilter); none declared, the measured pose as it is
    pose_noise: PoseNoise = field(default_factory=PoseNoise)
    #: how old the measured pose and obstacles are when they arrive (s): each plan starts from the
    #: pose predicted over this plus the drive's dead time under the commands already sent, and
    #: the obstacles predicted as far (delay.CommandPipe); a robot fact, not a tuning setting
    sensing_latency_s: float = 0.0
    #: the obstacle sensor's field of view (deg, centred on the heading): what leaves it is
    #: remembered (obstacle_memory.py); a robot fact, not a tuning setting
    sensor_fov_deg: float = 360.0
    soft_penalty: float = setting(
        1e4,
        0.0,
        1e9,
        lo_open=True,
        doc="exact-penalty weight on the obstacle slack of the re-solve: large enough that a "
        "feasible hard plan is the penalised problem's optimum",
    )
    slots: int = setting(
        6,
        1,
        64,
        doc="the nearest obstacles in the NLP (at most): each adds a constraint per body disc and "
        "step, so this bounds the solve time",
    )
    safety_filter: bool = flag(
        True,
        doc="check each plan's braking tail against every obstacle's prediction before its "
        "first command is sent, else send a checked fallback (safety_filter.py); off: the NMPC's "
        "command as it is",
    )
    movers: MoverConfig = field(default_factory=MoverConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    approach: ApproachConfig = field(default_factory=ApproachConfig)
    yielding: YieldConfig = field(default_factory=YieldConfig)
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)

    @property
    def tau_s(self) -> float:
        """Sampling time (s), the paper part's."""
        return self.nmpc.tau_s

    @property
    def measurement_delay_s(self) -> float:
        """From the instant a measurement was taken to the one its plan's first command acts (s):
        the sensing latency plus the drive's dead time."""
        return self.sensing_latency_s + self.response.command_delay_s

    @property
    def horizon(self) -> int:
        """Prediction steps N, the paper part's."""
        return self.nmpc.horizon

    def __post_init__(self) -> None:
        if self.nmpc.safety != "relax-cbf":
            raise ConfigError(f"nmpc.safety: husky-cbf is built on relax-cbf, got {self.nmpc.safety!r}")
        _positive("omega_cmd_max_radps", self.omega_cmd_max_radps)
        _non_negative("sensing_latency_s", self.sensing_latency_s)
        if not 0.0 < self.sensor_fov_deg <= 360.0:
            raise ConfigError(f"sensor_fov_deg: must be in (0, 360] deg, got {self.sensor_fov_deg}")
        if len(self.accel_weight) != 2 or len(self.terminal_weight) != 3:
            raise ConfigError("accel_weight, terminal_weight: two and three weights")
        check_ranges(self, "")
