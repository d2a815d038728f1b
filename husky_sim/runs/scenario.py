"""Scenario files: a validated YAML schema (pydantic). What a scenario builds (a controller's
configuration, an episode's, a reference) is husky_sim.runs.scenario_configs'.

Every value carries its unit in its name and must be a finite number within a stated physical
range (`_real` / `_whole` below say which); types are strict (no bool, string or sexagesimal
coercion: a number is a number). Unknown keys are rejected, and so are a start or goal inside an
obstacle, a random field that cannot be placed, and work that would not fit a run (more than
`MAX_OBSTACLES` obstacles, `MAX_CONTROL_STEPS` control steps or a control period that is not a
whole number of physics steps), all before anything runs. Validation errors become one line
naming the field, the allowed range and at most a short excerpt of the value (ScenarioError).
Command-line overrides (horizon, gamma, seed, solver) are applied by `with_overrides`, which validates
them with the same schema.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    create_model,
    model_validator,
)

from controllers import NMPCConfig
from controllers.settings import Range
from husky_sim.paths import DEFAULT_ROBOT, SCENARIO_DIR
from husky_sim.runs.ranged import ranged
from husky_sim.runs.scenario_errors import ScenarioError, excerpt, one_line
from husky_sim.runs.settings_schema import settings_fields
from husky_sim.scenario_file import ScenarioFileError, read_scenario_data
from husky_sim.sim.drive import DriveConfig
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.ground import DRIVE_TIME_BOUNDS_S, Ground, load_ground
from husky_sim.sim.kinematic import KinematicProblem
from husky_sim.sim.outcomes import Outcomes
from husky_sim.sim.robot_description import RobotDescription, load_robot, robot_names
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.world import ObstacleSpec, WorldConfig
from husky_sim.sim.yaw_response import GAIN_BOUNDS, TIME_CONSTANT_BOUNDS_S, YawResponse, lag_for_payload

if TYPE_CHECKING:
    from controllers import Controller, Reference
    from controllers.registry import PlanProfile

#: Most obstacles in one scenario (explicit plus random). The NLP is built for the nearest
#: `controller.max_obstacle_slots` of them only, so its solve time does not grow with this; the
#: physics, the clearance check, husky-cbf's guidance (which sees every obstacle), the sensing and
#: the recordings do, about linearly (`husky-sim bench-sim` times 1,000 static ones). 5,000
#: validate in well under a second (a random field that cannot be placed: a few seconds); a trace
#: holds every obstacle's centre 60 times a second of sim time (16 bytes each: 1,000 obstacles for
#: 10 minutes is 0.6 GB) unless none moves, when it holds them once.
MAX_OBSTACLES = 5000
#: Most obstacle slots an NLP may be built for (`controller.max_obstacle_slots`): each adds its
#: constraints at every predicted step, and solve time grows with them (`husky-sim bench`).
MAX_OBSTACLE_SLOTS = 64
#: Least gap (m) between the surfaces of two obstacles of a random field.
RANDOM_GAP_M = 0.1
#: Longest episode, in control steps (an hour at tau = 0.1 s).
MAX_CONTROL_STEPS = 36_000
#: Largest |x| or |y| of any position (m).
MAX_COORDINATE_M = 500.0
#: Longest lidar range (m) a scenario or `husky-sim check --sensing-range-m` takes (beyond it:
#: leave the range out, unlimited).
MAX_SENSING_RANGE_M = 1000.0
#: Most payload (kg) the schema reads at all; the robot's own maximum (specs.yaml) is then checked.
MAX_PAYLOAD_KG = 1000.0
#: Scenario names: what a run directory is named after, so no path separators or controls.
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,79}$"
TWO_PI = 2 * math.pi


def _real(lo: float, hi: float, unit: str = "", *, lo_open: bool = False) -> Any:
    """A float field: a finite number in [lo, hi] (or (lo, hi]); the error names the range."""
    return ranged(Range(lo, hi, unit, lo_open))


#: The longest prediction horizon N (steps) a scenario, a command-line override or a check takes.
MAX_HORIZON = 50


def _whole(lo: int, hi: int, unit: str = "") -> Any:
    """An integer field in [lo, hi] (bools and floats such as 5.0 are not integers here)."""
    return ranged(Range(lo, hi, unit, integer=True))


def _name(value: object) -> str:
    if not isinstance(value, str) or not re.fullmatch(NAME_PATTERN, value):
        raise ValueError(
            "must be 1 to 80 letters, digits or _ . + - starting with a letter or digit "
            "(it names the run's folder, so no path separators, spaces or control characters)"
        )
    return value


Coordinate = _real(-MAX_COORDINATE_M, MAX_COORDINATE_M, "m")
Angle = _real(-TWO_PI, TWO_PI, "rad")
Speed = _real(-5.0, 5.0, "m/s")
Weight = _real(0.0, 1e6, lo_open=True)
ObstacleRadius = _real(0.0, 20.0, "m", lo_open=True)
Seed = _whole(0, 2**32 - 1)


def _diagonal(matrix: tuple[tuple[float, ...], ...]) -> tuple[float, ...]:
    """The diagonal of a weight matrix (a scenario file gives diagonal weights only)."""
    return tuple(float(matrix[i][i]) for i in range(len(matrix)))


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class Pose(_Strict):
    x_m: Coordinate
    y_m: Coordinate
    yaw_rad: Angle = 0.0


class Circle(_Strict):
    """Reference circle p(t) = c + R [cos(w t + phi), sin(w t + phi)]."""

    radius_m: _real(0.0, 100.0, "m", lo_open=True)
    angular_rate_radps: _real(-2.0, 2.0, "rad/s")
    center_x_m: Coordinate = 0.0
    center_y_m: Coordinate = 0.0
    phase_rad: Angle = 0.0

    @model_validator(mode="after")
    def _nonzero_rate(self) -> Circle:
        if self.angular_rate_radps == 0:
            raise ValueError("angular_rate_radps must be non-zero")
        return self


class ReferenceSpec(_Strict):
    """Exactly one of a goal pose (point stabilisation) or a circle (tracking)."""

    goal: Pose | None = None
    circle: Circle | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> ReferenceSpec:
        if (self.goal is None) == (self.circle is None):
            raise ValueError("give exactly one of goal or circle")
        return self


class ObstacleEntry(_Strict):
    """A cylinder; motion as (vx, vy), or as the paper's (heading, speed), or waypoints."""

    x_m: Coordinate
    y_m: Coordinate
    radius_m: ObstacleRadius
    height_m: _real(0.0, 10.0, "m", lo_open=True) = 1.0
    vx_mps: Speed = 0.0
    vy_mps: Speed = 0.0
    heading_rad: Angle | None = None
    speed_mps: _real(0.0, 5.0, "m/s") | None = None
    waypoints: list[tuple[Coordinate, Coordinate]] = Field(default_factory=list, max_length=100)

    @model_validator(mode="after")
    def _one_motion(self) -> ObstacleEntry:
        polar = self.heading_rad is not None or self.speed_mps is not None
        if polar and (self.vx_mps or self.vy_mps):
            raise ValueError("give either vx_mps/vy_mps or heading_rad/speed_mps, not both")
        if self.waypoints and (self.vx_mps or self.vy_mps or self.heading_rad is not None):
            raise ValueError("waypoints move at speed_mps; do not also give a velocity or heading")
        if self.heading_rad is not None and self.speed_mps is None:
            raise ValueError("heading_rad needs speed_mps")
        return self

    def spec(self) -> ObstacleSpec:
        vx, vy = self.vx_mps, self.vy_mps
        if self.heading_rad is not None:
            vx = self.speed_mps * math.cos(self.heading_rad)
            vy = self.speed_mps * math.sin(self.heading_rad)
        return ObstacleSpec(
            self.x_m,
            self.y_m,
            self.radius_m,
            self.height_m,
            vx,
            vy,
            tuple(self.waypoints),
            self.speed_mps or 0.0 if self.waypoints else 0.0,
        )


class RandomObstacles(_Strict):
    """A seeded field of static cylinders in a box, kept clear of the start and the goal."""

    count: _whole(1, MAX_OBSTACLES)
    seed: Seed = 0
    x_range_m: tuple[Coordinate, Coordinate]
    y_range_m: tuple[Coordinate, Coordinate]
    radius_range_m: tuple[ObstacleRadius, ObstacleRadius] = (0.2, 0.4)
    keep_clear_m: _real(0.0, 100.0, "m") = 1.5  # no obstacle surface within this of start or goal

    @model_validator(mode="after")
    def _ordered_ranges(self) -> RandomObstacles:
        for name in ("x_range_m", "y_range_m", "radius_range_m"):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"{name}: low ({low:g}) must not exceed high ({high:g})")
        return self

    def specs(self, keep_clear_of: list[tuple[float, float]]) -> list[ObstacleSpec]:
        """The field: candidates (x, y, r) drawn in turn from the seeded generator, each kept when
        its surface is more than keep_clear_m from every point of `keep_clear_of` (m) and more than
        RANDOM_GAP_M from every obstacle kept before it, until `count` are kept or 1,000 x count
        have been drawn (fewer kept: the field cannot be placed). The same seed gives the same
        field (_random_field: the same decisions as judging one candidate at a time)."""
        return list(_random_field(self, tuple((float(x), float(y)) for x, y in keep_clear_of)))


#: Candidates judged together by _random_field, at first and at most; a block that keeps none
#: doubles the next (a full field rejects nearly every draw). Draws past the last kept obstacle
#: are discarded, so the sizes change the time taken, never the field.
_FIELD_BLOCK = (1024, 65536)
#: Below this (m) from a threshold a gap worked out by numpy is decided again by the scalar
#: expression (math.hypot and numpy's hypot may differ in the last bit).
_TIE_M = 1e-9


def _farther(dx: np.ndarray, dy: np.ndarray, less_m: Any, than_m: Any) -> np.ndarray:
    """math.hypot(dx, dy) - less_m > than_m elementwise (m; arrays or numbers, broadcast): numpy
    decides, except within _TIE_M of the threshold, where math.hypot does."""
    dx, dy, less, than = np.broadcast_arrays(dx, dy, less_m, than_m)
    margin = np.hypot(dx, dy) - less - than
    out = margin > 0
    for i in np.flatnonzero(np.abs(margin) <= _TIE_M).tolist():
        out[i] = math.hypot(dx[i], dy[i]) - less[i] > than[i]
    return out


@functools.lru_cache(maxsize=32)
def _random_field(field: RandomObstacles, keep: tuple[tuple[float, float], ...]) -> tuple[ObstacleSpec, ...]:
    """RandomObstacles.specs, worked out once per field and points (validation and building ask
    for it several times). Candidates are judged a block at a time with numpy (a k-d tree finds
    the obstacles kept before the block that could be too near), then the block's survivors in
    turn against those kept within it, with the scalar comparisons wherever numpy's are within
    _TIE_M of deciding otherwise: the same field as judging each candidate alone, at any count."""
    from scipy.spatial import cKDTree  # the schema's import stays light without a random field

    rng = np.random.default_rng(field.seed)
    (x_lo, x_hi), (y_lo, y_hi), (r_lo, r_hi) = field.x_range_m, field.y_range_m, field.radius_range_m
    clear, count, attempts = field.keep_clear_m, field.count, 1000 * field.count
    kept = np.empty((count, 3))  # x, y, r (m) of the obstacles kept so far
    n = drawn = 0
    size = _FIELD_BLOCK[0]
    while n < count and drawn < attempts:
        block = min(size, attempts - drawn)
        u = rng.random((block, 3))  # as `block` draws of uniform(x), uniform(y), uniform(r)
        drawn += block
        xs, ys = x_lo + (x_hi - x_lo) * u[:, 0], y_lo + (y_hi - y_lo) * u[:, 1]
        rs = r_lo + (r_hi - r_lo) * u[:, 2]
        ok = np.ones(block, dtype=bool)
        for px, py in keep:
            ok &= _farther(xs - px, ys - py, rs, clear)
        if n:  # against those kept before the block: the nearest first (in a full field, the
            # nearest refuses nearly every draw), then all within the largest distance that counts
            tree = cKDTree(kept[:n, :2])
            xy = np.column_stack([xs, ys])
            nearest_m, nearest = tree.query(xy)
            ok &= nearest_m - (rs + kept[nearest, 2] + RANDOM_GAP_M) >= -_TIE_M
            left = np.flatnonzero(ok)
            near = tree.query_ball_point(xy[left], rs[left] + r_hi + RANDOM_GAP_M + _TIE_M)
            lengths = np.fromiter(map(len, near), dtype=int, count=len(left))
            if lengths.any():
                cand = np.repeat(left, lengths)
                other = np.fromiter((j for js in near for j in js), dtype=int, count=int(lengths.sum()))
                o = kept[other]
                far = _farther(xs[cand] - o[:, 0], ys[cand] - o[:, 1], 0.0, rs[cand] + o[:, 2] + RANDOM_GAP_M)
                ok &= np.bincount(cand[~far], minlength=block) == 0
        start = n  # the block's survivors in turn, against those kept within the block
        for i in np.flatnonzero(ok).tolist():
            if n == count:
                break
            x, y, r = float(xs[i]), float(ys[i]), float(rs[i])
            o = kept[start:n]
            if _farther(x - o[:, 0], y - o[:, 1], 0.0, r + o[:, 2] + RANDOM_GAP_M).all():
                kept[n] = x, y, r
                n += 1
        if n == start:
            size = min(2 * size, _FIELD_BLOCK[1])
    return tuple(ObstacleSpec(float(x), float(y), float(r)) for x, y, r in kept[:n])


class YawResponseSpec(_Strict):
    """First-order yaw-rate lag of the robot behind its drive's dead time
    (husky_sim.sim.yaw_response.YawResponse): gain (dimensionless), time constant (s), dead time (s)."""

    gain: _real(*GAIN_BOUNDS)
    time_constant_s: _real(*TIME_CONSTANT_BOUNDS_S, "s")
    delay_s: _real(*DRIVE_TIME_BOUNDS_S, "s") = 0.0

    def params(self) -> YawResponse:
        return YawResponse(self.gain, self.time_constant_s, self.delay_s)


@functools.cache
def identified_yaw_responses(robot: str = DEFAULT_ROBOT) -> tuple[tuple[float, YawResponse], ...]:
    """The robot's yaw lags identified in PyBullet (`husky-sim identify`) by payload (kg), read
    once from its folder's yaw_response.yaml (without `by_payload`, its headline lag for every
    payload); a missing or malformed file is a one-line ScenarioError."""
    path = load_robot(robot).yaw_response_file
    source = f"{path} (the identified yaw response; `husky-sim identify` writes it)"
    try:
        data = read_scenario_data(path)
    except ScenarioFileError as exc:
        raise ScenarioError(f"{exc} (`husky-sim identify` writes it)") from None
    headline = {key: data[key] for key in YawResponseSpec.model_fields if key in data}
    lags = []
    for i, row in enumerate(data.get("by_payload") or [{"payload_kg": 0.0}]):
        if not isinstance(row, dict) or not isinstance(row.get("payload_kg"), int | float):
            raise ScenarioError(f"{source}: by_payload[{i}]: needs a payload_kg number")
        fields = {**headline, **{k: row[k] for k in ("gain", "time_constant_s") if k in row}}
        try:
            spec = YawResponseSpec.model_validate_json(json.dumps(fields, default=str), strict=True)
        except ValidationError as exc:
            raise ScenarioError(one_line(exc, source)) from None
        lags.append((float(row["payload_kg"]), spec.params()))
    return tuple(lags)


def identified_yaw_response(robot: str = DEFAULT_ROBOT, payload_kg: float = 0.0) -> YawResponse:
    """The robot's identified yaw lag with payload_kg (kg) on board: linear between the
    identified payloads (husky_sim.sim.yaw_response.lag_for_payload)."""
    return lag_for_payload(identified_yaw_responses(robot), payload_kg)


def _robot_name(value: object) -> str:
    if not isinstance(value, str) or value not in robot_names():
        raise ValueError(f"must name a robot folder under assets/ ({', '.join(robot_names())})")
    return value


class RobotSpec(_Strict):
    """Which robot (its folder under assets/: the Husky A200 unless named), its start pose and the
    controller's robot circle: the URDF footprint radius plus a margin, or an explicit radius (a
    radius below the footprint is flagged in every summary)."""

    model: Annotated[str, BeforeValidator(_robot_name)] = DEFAULT_ROBOT
    start: Pose
    radius_margin_m: _real(0.0, 2.0, "m") | None = None
    radius_m: _real(0.0, 5.0, "m", lo_open=True) | None = None
    #: kg on the top plate, up to the robot's published maximum payload (specs.yaml)
    payload_kg: _real(0.0, MAX_PAYLOAD_KG, "kg") = 0.0
    yaw_response: YawResponseSpec | None = None  # default: the lag identified in PyBullet

    @model_validator(mode="after")
    def _one_radius(self) -> RobotSpec:
        if (self.radius_m is None) == (self.radius_margin_m is None):
            raise ValueError("give exactly one of radius_m or radius_margin_m")
        return self

    @model_validator(mode="after")
    def _payload_carried(self) -> RobotSpec:
        most = self.description().specs.spec_sheet.max_payload_kg
        if self.payload_kg > most:
            raise ValueError(f"payload_kg: at most {most:g} kg on a {self.description().title}")
        return self

    def description(self) -> RobotDescription:
        """The robot's folder, loaded (husky_sim.sim.robot_description)."""
        return load_robot(self.model)

    def radius(self) -> float:
        if self.radius_m is not None:
            return self.radius_m
        return self.description().geometry.footprint_radius_m + self.radius_margin_m

    def yaw_response_params(self) -> YawResponse:
        """The robot's yaw-rate lag (gain, time constant s): the file's `yaw_response`, else the
        one identified in PyBullet with its payload (its folder's yaw_response.yaml)."""
        if self.yaw_response is not None:
            return self.yaw_response.params()
        return identified_yaw_response(self.model, self.payload_kg)


class NMPCSpec(_Strict):
    """NMPC parameters; omitted ones take the paper's simulation defaults, NMPCConfig's own.

    Commanded limits may exceed the Husky's (the audit of `husky-sim check` flags that), within
    what a command can physically mean."""

    horizon: _whole(1, MAX_HORIZON, "steps") = NMPCConfig.horizon
    gamma: _real(0.0, 1.0) = NMPCConfig.gamma
    alpha: _real(0.0, 1.0) = NMPCConfig.alpha
    state_weight: tuple[Weight, Weight, Weight] = _diagonal(NMPCConfig.state_weight)
    input_weight: tuple[Weight, Weight] = _diagonal(NMPCConfig.input_weight)
    clf_weight: tuple[Weight, Weight, Weight] = _diagonal(NMPCConfig.clf_weight)
    clf_slack_weight: Weight = NMPCConfig.clf_slack_weight
    decay_slack_weight: Weight = NMPCConfig.decay_slack_weight
    v_min_mps: _real(-5.0, 0.0, "m/s") = NMPCConfig.v_min_mps
    v_max_mps: _real(0.0, 5.0, "m/s", lo_open=True) = NMPCConfig.v_max_mps
    omega_max_radps: _real(0.0, 10.0, "rad/s", lo_open=True) = NMPCConfig.omega_max_radps
    obstacle_prediction: Literal["constant-velocity", "frozen"] = NMPCConfig.obstacle_prediction
    #: the most obstacles the paper's NLP is built for (NMPCConfig.obstacle_slots: the scenario's
    #: count up to this); with more, each step's are its nearest by surface distance to the robot
    #: now (controllers.obstacles: cheap and exact for what is near, though a fast mover still far
    #: off can lose its slot to near static posts). 16: above every shipped scenario's count, so
    #: they keep one slot per obstacle; husky-cbf has its own, controller.husky_cbf.slots
    max_obstacle_slots: _whole(1, MAX_OBSTACLE_SLOTS, "obstacles") = 16
    #: NLP solver (controllers.backends); omitted: the controllers' default (SolverOptions)
    solver: Literal["ipopt", "fatrop"] | None = None


#: The NMPC settings every controller is given (scenario_configs.nmpc_config).
NMPC_FIELDS = tuple(NMPCSpec.model_fields)
#: The `controller` block: the NMPC settings, and each registered controller's own settings under
#: its name (`husky_cbf:`; controllers.registry), omitted ones keeping their defaults; a
#: controller ignores the others'.
ControllerSpec = create_model(
    "ControllerSpec", __base__=NMPCSpec, __doc__=NMPCSpec.__doc__, **settings_fields()
)


class DriveSpec(_Strict):
    """Overrides of the skid-steer drive (husky_sim.sim.drive.DriveConfig); omitted ones keep the
    published Husky values."""

    wheel_separation_multiplier: _real(0.5, 5.0) | None = None
    max_linear_mps: _real(0.0, 5.0, "m/s", lo_open=True) | None = None
    max_angular_radps: _real(0.0, 10.0, "rad/s", lo_open=True) | None = None
    max_linear_accel_mps2: _real(0.0, 50.0, "m/s^2", lo_open=True) | None = None
    max_angular_accel_radps2: _real(0.0, 100.0, "rad/s^2", lo_open=True) | None = None
    #: the motor controller's current limit per side (A); it sets the wheels' torque limit
    current_limit_a: _real(0.1, 500.0, "A") | None = None

    def config(self, robot: str = DEFAULT_ROBOT) -> DriveConfig:
        """The robot's published drive with these overrides."""
        limits = self.model_dump(exclude_none=True)
        current = limits.pop("current_limit_a", None)
        base = dataclasses.replace(DriveConfig.for_robot(load_robot(robot).specs), **limits)
        if current is None:
            return base
        return dataclasses.replace(base, motor=dataclasses.replace(base.motor, current_limit_a=current))


class FrictionSpec(_Strict):
    """Override of the ground's tyre friction coefficient (husky_sim.sim.tyre); omitted: the
    ground file's own."""

    ground: _real(0.01, 5.0) | None = None
    #: the tyres' lateral / longitudinal stiffness (sets the yaw ratio: husky_sim.sim.tyre)
    lateral_stiffness_ratio: _real(0.05, 20.0) | None = None


class SensingSpec(_Strict):
    """husky_sim.sim.sensing.SensingConfig: the same fields, its defaults, and their ranges;
    `range_m` omitted (null) is an unlimited range. The defaults see every obstacle."""

    pose_xy_std_m: _real(0.0, 5.0, "m") = SensingConfig.pose_xy_std_m
    pose_yaw_std_rad: _real(0.0, math.pi, "rad") = SensingConfig.pose_yaw_std_rad
    obstacle_xy_std_m: _real(0.0, 5.0, "m") = SensingConfig.obstacle_xy_std_m
    latency_steps: _whole(0, 20, "steps") = SensingConfig.latency_steps
    obstacle_velocity_scale: _real(0.0, 5.0) = SensingConfig.obstacle_velocity_scale
    #: the lidar's range (m); None: unlimited
    range_m: _real(0.0, MAX_SENSING_RANGE_M, "m", lo_open=True) | None = None
    #: the lidar's field of view (deg), centred on the robot's heading
    fov_deg: _real(0.0, 360.0, "deg", lo_open=True) = SensingConfig.fov_deg
    #: static obstacles hide what lies wholly behind them (husky_sim.sim.sensing.visible_mask)
    occlusion: bool = SensingConfig.occlusion


class SuccessSpec(_Strict):
    """husky_sim.sim.outcomes.Outcomes (what each threshold means and why): the same fields, its
    defaults, and their ranges."""

    goal_position_m: _real(0.0, 10.0, "m", lo_open=True) = Outcomes.goal_position_m
    goal_heading_rad: _real(0.0, math.pi, "rad", lo_open=True) = Outcomes.goal_heading_rad
    goal_hold_s: _real(0.0, 3600.0, "s", lo_open=True) = Outcomes.goal_hold_s
    tracking_rmse_m: _real(0.0, 10.0, "m", lo_open=True) = Outcomes.tracking_rmse_m
    tracking_settle_s: _real(0.0, 3600.0, "s") = Outcomes.tracking_settle_s
    rejoin_s: _real(0.0, 3600.0, "s") = Outcomes.rejoin_s
    leave_s: _real(0.0, 3600.0, "s") = Outcomes.leave_s
    stuck_window_steps: _whole(1, 1000, "steps") = Outcomes.stuck_window_steps
    stuck_speed_mps: _real(0.0, 1.0, "m/s", lo_open=True) = Outcomes.stuck_speed_mps
    stuck_yaw_rate_radps: _real(0.0, 2.0, "rad/s", lo_open=True) = Outcomes.stuck_yaw_rate_radps


class Scenario(_Strict):
    """One scenario file."""

    name: Annotated[str, BeforeValidator(_name)]
    description: Annotated[str, Field(max_length=500, pattern=r"^[^\x00-\x1f\x7f]*$")] = ""
    seed: Seed = 0
    tau_s: _real(0.0005, 1.0, "s") = EpisodeConfig.tau_s  # down to one physics step at 2,000 Hz
    duration_s: _real(0.0, 3600.0, "s", lo_open=True) = EpisodeConfig.duration_s
    physics_hz: _real(60.0, 2000.0, "Hz") = WorldConfig.physics_hz
    robot: RobotSpec
    reference: ReferenceSpec
    obstacles: list[ObstacleEntry] = Field(default_factory=list, max_length=MAX_OBSTACLES)
    random_obstacles: RandomObstacles | None = None
    controller: ControllerSpec = ControllerSpec()
    drive: DriveSpec = DriveSpec()
    #: a ground shipped for the robot (its folder's grounds/) or a ground file's path; omitted: the
    #: robot's default ground (its robot.yaml)
    ground: Annotated[str, Field(min_length=1, max_length=500)] | None = None
    friction: FrictionSpec = FrictionSpec()
    sensing: SensingSpec = SensingSpec()
    success: SuccessSpec = SuccessSpec()

    @model_validator(mode="after")
    def _work_fits(self) -> Scenario:
        ratio = self.physics_hz * self.tau_s
        if abs(ratio - round(ratio)) > 1e-6:
            raise ValueError(
                f"tau_s: must be a whole number of physics steps (physics_hz x tau_s = {ratio:.6g})"
            )
        steps = math.ceil(self.duration_s / self.tau_s - 1e-9)
        if steps < 1:
            raise ValueError(f"duration_s: must last at least one control step (tau_s = {self.tau_s:g} s)")
        if steps > MAX_CONTROL_STEPS:
            raise ValueError(
                f"duration_s: {self.duration_s:g} s is {steps} control steps at tau_s = {self.tau_s:g} s; "
                f"at most {MAX_CONTROL_STEPS} are allowed"
            )
        return self

    @model_validator(mode="after")
    def _ground_known(self) -> Scenario:
        ground = self.ground_config()  # a GroundError (a ValueError) names the ground and what is wrong
        if not ground.calibrated and self.friction.lateral_stiffness_ratio is not None:
            raise ValueError(
                f"friction.lateral_stiffness_ratio: ground {self.ground!r} has no tyre model (contact "
                f"{ground.contact!r}); use a calibrated ground or leave it out"
            )
        return self

    @model_validator(mode="after")
    def _obstacles_placed(self) -> Scenario:
        total = len(self.obstacles) + (self.random_obstacles.count if self.random_obstacles else 0)
        if total > MAX_OBSTACLES:
            raise ValueError(f"obstacles: {total} in all (with random_obstacles); at most {MAX_OBSTACLES}")
        if self.random_obstacles is not None:
            placed = len(self.obstacle_specs()) - len(self.obstacles)
            if placed < self.random_obstacles.count:
                raise ValueError(
                    f"random_obstacles: placed only {placed} of {self.random_obstacles.count} obstacles "
                    "clear of the start, the goal and each other; widen x_range_m / y_range_m or lower "
                    "count, radius_range_m or keep_clear_m"
                )
        return self

    @model_validator(mode="after")
    def _start_and_goal_clear(self) -> Scenario:
        r_robot = self.robot.radius()
        points = [("robot.start", self.robot.start)]
        if self.reference.goal is not None:
            points.append(("reference.goal", self.reference.goal))
        for i, ob in enumerate(self.obstacle_specs()):
            for label, pose in points:
                gap = math.hypot(pose.x_m - ob.x_m, pose.y_m - ob.y_m) - ob.radius_m - r_robot
                if gap <= 0:
                    raise ValueError(
                        f"{label} ({pose.x_m:g}, {pose.y_m:g}) lies inside obstacle {i} at "
                        f"({ob.x_m:g}, {ob.y_m:g}) r {ob.radius_m:g} m with robot radius {r_robot:.3f} m"
                    )
        return self

    def obstacle_specs(self) -> list[ObstacleSpec]:
        specs = [o.spec() for o in self.obstacles]
        if self.random_obstacles is not None:
            keep = [(self.robot.start.x_m, self.robot.start.y_m)]
            if self.reference.goal is not None:
                keep.append((self.reference.goal.x_m, self.reference.goal.y_m))
            specs += self.random_obstacles.specs(keep)
        return specs

    def with_overrides(
        self,
        horizon: int | None = None,
        gamma: float | None = None,
        seed: int | None = None,
        solver: str | None = None,
    ) -> Scenario:
        """This scenario with command-line overrides applied and validated by the same schema
        (so `--horizon 500` is the same one-line error as `horizon: 500` in the file); `solver`
        names the NLP backend (controller.solver)."""
        data = self.model_dump()
        if solver is not None:
            data["controller"]["solver"] = solver
        if horizon is not None:
            data["controller"]["horizon"] = horizon
        if gamma is not None:
            data["controller"]["gamma"] = gamma
        if seed is not None:
            data["seed"] = seed
        return scenario_from_data(data, "override")

    # What the scenario builds lives in husky_sim.runs.scenario_configs (the schema stays apart)
    def kinematic_problem(
        self, robot_radius_m: float | None = None, allow_waypoints: bool = False
    ) -> KinematicProblem:
        """This scenario for the kinematic loop (scenario_configs.kinematic_problem)."""
        from husky_sim.runs import scenario_configs

        return scenario_configs.kinematic_problem(self, robot_radius_m, allow_waypoints)

    def ground_config(self) -> Ground:
        """The ground the robot drives on: the named one of its robot, else its default."""
        return load_ground(self.ground, self.robot.model)

    def drive_config(self) -> DriveConfig:
        """The robot's drive with the file's overrides."""
        return self.drive.config(self.robot.model)

    def reference_object(self) -> Reference:
        from husky_sim.runs import scenario_configs

        return scenario_configs.reference_object(self)

    def controller_config(self, name: str) -> Any:
        """The configuration of the controller `name` (a registered one) for this scenario: the
        paper's an NMPCConfig with its obstacle constraint, husky-cbf's a HuskyCBFConfig."""
        from husky_sim.runs import scenario_configs

        return scenario_configs.controller_config(self, name)

    def plan_profile(self, name: str) -> PlanProfile:
        """What the plans of the controller `name` promise here (controllers.registry.PlanProfile)."""
        from husky_sim.runs import scenario_configs

        return scenario_configs.plan_profile(self, name)

    def make_controller(self, name: str) -> Controller:
        """The controller called `name` (a registered one) configured for this scenario."""
        from husky_sim.runs import scenario_configs

        return scenario_configs.make_controller(self, name)

    def episode_config(self) -> EpisodeConfig:
        from husky_sim.runs import scenario_configs

        return scenario_configs.episode_config(self)


def scenario_from_data(data: dict[str, Any], source: str = "scenario") -> Scenario:
    """Validate plain data (a parsed file, or `Scenario.model_dump()` with changes) strictly:
    numbers must be numbers, sequences become tuples where the schema says so. One-line
    ScenarioError on any problem."""
    try:
        text = json.dumps(data, default=str)  # dates and other YAML types become strings: rejected
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{source}: values the schema cannot hold ({exc})") from None
    try:
        return Scenario.model_validate_json(text, strict=True)
    except ValidationError as exc:
        raise ScenarioError(one_line(exc, source)) from None
    except (OverflowError, ArithmeticError) as exc:  # a last line of defence: never a traceback
        raise ScenarioError(f"{source}: a value out of any usable range ({exc})") from None


def resolve(name_or_path: str) -> Path:
    """A scenario file path, or the name of a shipped scenario."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") and (path.exists() or path.is_symlink()):
        return path
    if re.fullmatch(NAME_PATTERN, name_or_path):
        shipped = SCENARIO_DIR / f"{name_or_path}.yaml"
        if shipped.is_file():
            return shipped
    names = ", ".join(sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml")))
    raise ScenarioError(
        f"scenario: no file or shipped scenario named {excerpt(name_or_path, 80)} (shipped: {names})"
    )


def load_scenario(name_or_path: str) -> Scenario:
    """Load and validate a scenario; every problem is a one-line ScenarioError."""
    path = resolve(name_or_path)
    try:
        data = read_scenario_data(path)
    except ScenarioFileError as exc:
        raise ScenarioError(str(exc)) from None
    return scenario_from_data(data, str(path))


def shipped_scenarios() -> list[Path]:
    """The scenario files directly in scenarios/, which `suite`, `check` and the test suite run
    with every controller at every horizon. Its sub-folders (scenarios/large/: worlds of a
    thousand obstacles) are not among them: run those by path."""
    return sorted(SCENARIO_DIR.glob("*.yaml"))
