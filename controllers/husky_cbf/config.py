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
from controllers.settings import check_ranges, setting


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

    grid_resolution_m: float = setting(0.1, 0.01, 1.0, "m")  # cost-grid cell size
    #: a larger area is searched on a coarser grid: the search's time and memory grow with it
    max_grid_cells: int = setting(200_000, 1_000, 5_000_000)
    grid_padding_m: float = setting(3.0, 0.0, 20.0, "m", lo_open=True)  # beyond robot and goal
    #: cells closer than clearance_cost_m (m) to an inflated obstacle cost more, up to
    #: (1 + clearance_cost_gain) times their length: the path keeps its distance
    clearance_cost_m: float = setting(0.6, 0.0, 5.0, "m", lo_open=True)
    clearance_cost_gain: float = setting(4.0, 0.0, 100.0)
    lookahead_m: float = setting(1.5, 0.0, 20.0, "m", lo_open=True)  # waypoint: farthest in sight
    #: a waypoint's heading points along the path this many cells further on: one cell gives only
    #: the grid's eight directions
    path_heading_cells: int = setting(3, 1, 50)
    mover_sweep_s: float = setting(2.0, 0.0, 20.0, "s")  # a mover blocks where it will be
    release_margin_m: float = setting(0.1, 0.0, 2.0, "m")  # leave guidance only with this to spare
    #: an obstacle slower than this counts as static (guidance's hysteresis; evasion ignores it):
    #: the noise of a tracked obstacle's velocity estimate
    static_speed_mps: float = setting(0.05, 0.0, 1.0, "m/s")
    #: among static obstacles, cells within path_hysteresis_width_m (m) of the last path cost this
    #: fraction less: with an obstacle dead ahead and a few cm of obstacle noise, the shortest way
    #: round changed sides from one step to the next and a loaded Husky, turning neither way,
    #: drove into it (check). Not among movers: there a mover crossing the path taken made the
    #: robot keep to it and touch the mover (paper_dynamic_tracking_crossing, N = 5)
    path_hysteresis: float = setting(0.2, 0.0, 0.99)
    path_hysteresis_width_m: float = setting(0.2, 0.0, 2.0, "m")
    #: a way round movers longer than the way round the static obstacles alone is taken only if
    #: the movers clear the shorter way no sooner than its extra length takes at this speed (m/s):
    #: a Husky's cruise, with its turns (guidance.Guidance._wait_for_movers)
    detour_speed_mps: float = setting(0.6, 0.0, 5.0, "m/s", lo_open=True)
    #: Mover evasion (guidance.MoverEvasion): a mover whose track relative to the robot comes
    #: within its radius + the robot's inflation + evade_margin_m (or + the NMPC's sweep of that
    #: mover + release_margin_m, if more) in the next evade_horizon_s makes the robot step aside now
    evade_horizon_s: float = setting(6.0, 0.0, 30.0, "s")
    evade_margin_m: float = setting(0.5, 0.0, 5.0, "m")
    #: a mover passing within this of dead ahead (m) is stepped round on the robot's left: a
    #: fixed side, so sensing noise cannot flip it from step to step
    evade_dead_ahead_m: float = setting(0.02, 0.0, 1.0, "m")
    tracking_preview_s: float = setting(1.0, 0.0, 10.0, "s")  # tracking: the path's goal this far ahead
    #: Set-point approach (guidance.LineApproach): within approach_radius_m of the goal, a robot
    #: off the goal's line (|lateral| > approach_exit_m) is led onto it by a waypoint on the line
    #: approach_lookahead_m ahead of it, or, beside or past the goal by more than
    #: approach_enter_m, behind it (docking: it backs up onto the line and leaves only aligned
    #: within approach_exit_rad): a unicycle beside its goal cannot close the gap within a short
    #: horizon, and the skid-steer barely answers small turns.
    approach_radius_m: float = setting(3.0, 0.0, 20.0, "m", lo_open=True)
    approach_lookahead_m: float = setting(1.0, 0.0, 10.0, "m", lo_open=True)
    approach_enter_m: float = setting(0.07, 0.0, 2.0, "m", lo_open=True)
    approach_exit_m: float = setting(0.03, 0.0, 2.0, "m", lo_open=True)
    approach_exit_rad: float = setting(0.05, 0.0, math.pi, "rad", lo_open=True)
    #: first a pre-goal this many approach lookaheads before the goal on its line, so that the
    #: robot arrives straight; docking backs up at least as far behind the goal
    pre_goal_lookaheads: float = setting(1.5, 0.0, 10.0, lo_open=True)
    #: the pre-goal counts as reached within this (m): a robot that gets near it is lined up
    #: well enough for the run-in, which the docking corrects
    pre_goal_reached_m: float = setting(0.3, 0.0, 5.0, "m", lo_open=True)
    #: docking backs up this far behind the goal per metre of lateral error (m/m): at the Husky's
    #: yaw response a turn onto the line and a straight run-in need about four times the offset
    docking_back_per_lateral: float = setting(4.0, 0.0, 20.0, lo_open=True)
    #: ... and at most approach_radius_m less this (m), so that it stays within the approach
    docking_radius_margin_m: float = setting(0.3, 0.0, 5.0, "m")
    #: ... and drives in once it has backed up this fraction of the way: the last few per cent
    #: of a back-up cost seconds at the approach speed's braking, and the run-in gains them back
    docking_backed_up: float = setting(0.93, 0.0, 1.0, lo_open=True)
    #: |v| cap within slow_radius_m of a set-point: time for the yaw lag
    approach_speed_mps: float = setting(0.6, 0.0, 5.0, "m/s", lo_open=True)
    #: Pivot (guidance.LineApproach): within pivot_radius_m of a set-point and off its line, turn
    #: where it stands until aimed at the goal within pivot_aim_rad, drive to within
    #: pivot_arrive_m of it, and turn to its heading there; pivot again if it drifts beyond
    #: pivot_restart_m, or, once turned to within pivot_aim_rad of the goal's heading, is more
    #: than approach_enter_m off its line (m, rad). Also wherever docking has no room behind the
    #: goal.
    pivot_radius_m: float = setting(1.0, 0.0, 20.0, "m")
    pivot_aim_rad: float = setting(0.2, 0.0, math.pi, "rad", lo_open=True)
    pivot_arrive_m: float = setting(0.05, 0.0, 2.0, "m", lo_open=True)
    pivot_restart_m: float = setting(0.1, 0.0, 2.0, "m", lo_open=True)
    slow_radius_m: float = setting(1.5, 0.0, 20.0, "m", lo_open=True)
    #: a trajectory slower than this (m/s) will not come to the robot (the paper's dynamic
    #: tracking circle moves at 0.02 m/s): the robot drives at its point (guidance.point_approach)
    #: along the bearing beyond point_approach_far_m, turning to the reference's heading closer in,
    #: and tracks the reference itself within point_approach_near_m (m). Brought onto its tangent
    #: like onto a set-point's line instead, the Husky backed up metres to dock and rejoined 6.7
    #: to 9.3 s after a mover had passed (issue 10).
    approach_max_reference_speed_mps: float = setting(0.1, 0.0, 5.0, "m/s", lo_open=True)
    point_approach_near_m: float = setting(0.1, 0.0, 5.0, "m", lo_open=True)
    point_approach_far_m: float = setting(0.3, 0.0, 10.0, "m", lo_open=True)
    #: a robot at a slow trajectory's point turns its axis across the track of a mover on course
    #: to the point this long (s) before the mover's closest approach, so that its step aside
    #: (evasion, evade_horizon_s) is a drive along its axis; 4 s more than evasion's: a quarter
    #: turn in place takes an unloaded Husky about 1.6 s (1 rad/s), a loaded one longer
    brace_horizon_s: float = setting(10.0, 0.0, 30.0, "s")

    def __post_init__(self) -> None:
        check_ranges(self, "guidance.")


@dataclass(frozen=True)
class EscapeConfig:
    """Deadlock escape (controllers.husky_cbf.escape): Nav2's progress checker and recovery
    behaviours, sized for a Husky and the suite's scenarios."""

    #: stalled: over this window (s) the robot came less than progress_min_m (m) closer to its
    #: target and moved less than that. Nav2's SimpleProgressChecker asks for 0.5 m in 10 s; a
    #: Husky at its 0.4 to 1 m/s cruise covers 0.25 m in well under a second, so 3 s of less is
    #: no longer a slow manoeuvre but one that leads nowhere
    progress_window_s: float = setting(3.0, 0.0, 60.0, "s", lo_open=True)
    progress_min_m: float = setting(0.25, 0.0, 5.0, "m", lo_open=True)
    #: ... or its commands were idle (below idle_speed_mps and idle_yaw_rate_radps, the suite's
    #: stuck thresholds) for idle_s (s): a robot told to stand still away from its target waits
    #: for nothing it can see within its horizon
    idle_s: float = setting(0.5, 0.0, 60.0, "s", lo_open=True)
    idle_speed_mps: float = setting(0.05, 0.0, 1.0, "m/s", lo_open=True)
    idle_yaw_rate_radps: float = setting(0.05, 0.0, 1.0, "rad/s", lo_open=True)
    #: within this of the target (m) the set-point approach (docking, pivot) owns the robot
    near_m: float = setting(0.3, 0.0, 5.0, "m")
    aim_rad: float = setting(0.35, 0.0, math.pi, "rad", lo_open=True)  # turn first beyond this
    drive_m: float = setting(1.0, 0.0, 10.0, "m", lo_open=True)  # then along the way: past one obstacle
    arrive_m: float = setting(0.15, 0.0, 2.0, "m", lo_open=True)  # a phase's point is reached within
    back_up_m: float = setting(0.5, 0.0, 5.0, "m")  # a pinned robot backs up this far: room to turn
    phase_timeout_s: float = setting(5.0, 0.0, 60.0, "s", lo_open=True)  # a phase ends after this
    #: a stall within memory_radius_m (m) of an earlier one in the last tabu_s (s) is a repeat:
    #: that spot becomes a virtual obstacle of tabu_radius_m (m) for guidance for tabu_s
    memory_radius_m: float = setting(0.6, 0.0, 10.0, "m", lo_open=True)
    tabu_radius_m: float = setting(0.5, 0.0, 5.0, "m")
    tabu_s: float = setting(20.0, 0.0, 600.0, "s", lo_open=True)
    enabled: bool = True
    #: on trajectories too, while the NMPC tracks the reference itself (never on a slow one, whose
    #: robot waits for movers on purpose): a robot that stood 8 s beside a cylinder, unable to
    #: swing round to its reference, tracked again once the escape took it forward to room to turn
    #: (paper_dynamic_tracking_crossing, check). Its target is the tracking goal, which is past any
    #: obstacle the reference runs through
    on_trajectories: bool = True

    def __post_init__(self) -> None:
        check_ranges(self, "escape.")


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
    wheel_speed_ratio: float = setting(1.0, 0.0, 3.0, lo_open=True)
    #: margin (m) between each body disc and an obstacle: sensing noise and the drive's
    #: tracking error; braking distance is in the model, so this need not cover it.
    margin_m: float = setting(0.1, 0.0, 2.0, "m")
    #: a mover's circle grows by this much per metre of its predicted travel (m/m): its velocity
    #: is an estimate, and a person does not walk a straight line.
    mover_margin_per_m: float = setting(0.3, 0.0, 5.0, "m/m")
    #: a mover at a predicted step blocks its whole track over the next this many seconds (s):
    #: the time a skid-steer needs to turn away (yaw lag) and brake
    mover_sweep_s: float = setting(1.5, 0.0, 10.0, "s")
    #: disc count: the fewest discs along the body whose radius exceeds the half width by at most
    #: this (m); 3 for a Husky (radius 0.38 m, against 0.57 m for one enclosing circle).
    disc_excess_m: float = setting(0.05, 0.01, 1.0, "m")
    #: cost on (dv/dt, d omega_cmd/dt) squared: smooth commands a drive can follow
    accel_weight: tuple[float, float] = setting((0.2, 0.05), 0.0, 1e6)
    #: terminal cost in the reference's frame (along, across, heading): a heavy lateral weight,
    #: so that a short horizon does not settle beside its goal (a unicycle beside its goal lowers
    #: a stage cost only by backing up and turning).
    terminal_weight: tuple[float, float, float] = setting((20.0, 200.0, 5.0), 0.0, 1e6)
    #: the terminal lateral error is taken this far ahead of the robot (behind it while it backs
    #: up onto a goal's line; at it while it settles on the goal), so that turning toward the line
    #: pays within a short horizon (m)
    terminal_lookahead_m: float = setting(0.5, 0.0, 5.0, "m")
    terminal_speed_weight: float = setting(5.0, 0.0, 1e6)  # set-points: arrive at rest ((m/s)^-2 in the cost)
    #: the localisation's reported pose noise: the set-point approach decides on a filtered pose
    #: (localisation.PoseFilter); none declared, the measured pose as it is
    pose_noise: PoseNoise = field(default_factory=PoseNoise)
    #: how old the measured pose and obstacles are when they arrive (s): each plan starts from the
    #: pose predicted over this plus the drive's dead time under the commands already sent, and
    #: the obstacles predicted as far (delay.CommandPipe); a robot fact, not a tuning setting
    sensing_latency_s: float = 0.0
    #: turn monitor (turn_monitor.py): over the last weak_turn_window_s (s), once the model
    #: predicted at least weak_turn_min_rad of heading change, a robot on its way to a set-point
    #: that turned less than weak_turn_ratio of it is held to weak_turn_speed_mps (m/s): it may
    #: not steer round what its plan goes round, and must be able to stop before it
    weak_turn_window_s: float = setting(1.6, 0.0, 10.0, "s", lo_open=True)
    weak_turn_min_rad: float = setting(0.3, 0.0, 2 * math.pi, "rad", lo_open=True)
    weak_turn_ratio: float = setting(0.4, 0.0, 1.0)
    weak_turn_speed_mps: float = setting(0.4, 0.0, 5.0, "m/s", lo_open=True)
    #: exact-penalty weight on the obstacle slack of the re-solve: large enough that a feasible
    #: hard plan is the penalised problem's optimum
    soft_penalty: float = setting(1e4, 0.0, 1e9, lo_open=True)
    #: the nearest obstacles in the NLP (at most; fewer when the scenario has fewer): each slot
    #: adds a constraint per body disc and step to the OCP
    slots: int = setting(6, 1, 64)
    #: the safety filter (safety_filter.py): a command is sent only if braking to a stop after it
    #: keeps every body disc clear of every obstacle until the robot stands; else the backup. Off
    #: by default: braking is its only backup, and a robot that brakes in a mover's path where the
    #: NMPC would have stepped aside is hit standing (not at fault, but hit)
    safety_filter: bool = False
    #: the filter's bound on how fast a mover changes its velocity (m/s^2): its circle grows by
    #: half this times the squared time since it was measured
    mover_accel_bound_mps2: float = setting(0.5, 0.0, 10.0, "m/s^2")
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)
    escape: EscapeConfig = field(default_factory=EscapeConfig)

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
        if len(self.accel_weight) != 2 or len(self.terminal_weight) != 3:
            raise ConfigError("accel_weight, terminal_weight: two and three weights")
        check_ranges(self, "")
