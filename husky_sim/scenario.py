"""Scenario files: a validated YAML schema (pydantic) and its translation into a controller
configuration, an episode configuration and a reference.

Every value carries its unit in its name. Unknown keys are rejected, and so is a start or goal
inside an obstacle, before anything runs. Validation errors become one line naming the field
(ScenarioError).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from controllers import CircleTrajectory, NMPCConfig, Reference, SafetyConstraint, SetPoint
from husky_sim.drive import DriveConfig
from husky_sim.episode import EpisodeConfig, Outcomes
from husky_sim.robot import WheelFriction
from husky_sim.robot_geometry import load_geometry
from husky_sim.sensing import SensingConfig
from husky_sim.world import ObstacleSpec, WorldConfig

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]


class ScenarioError(ValueError):
    """A scenario that cannot run; the message is one line naming the field."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Pose(_Strict):
    x_m: float
    y_m: float
    yaw_rad: float = 0.0


class Circle(_Strict):
    """Reference circle p(t) = c + R [cos(w t + phi), sin(w t + phi)]."""

    radius_m: Positive
    angular_rate_radps: float = Field(allow_inf_nan=False)
    center_x_m: float = 0.0
    center_y_m: float = 0.0
    phase_rad: float = 0.0

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

    x_m: float
    y_m: float
    radius_m: Positive
    height_m: Positive = 1.0
    vx_mps: float = 0.0
    vy_mps: float = 0.0
    heading_rad: float | None = None
    speed_mps: NonNegative | None = None
    waypoints: list[tuple[float, float]] = Field(default_factory=list)

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

    count: Annotated[int, Field(ge=1, le=64)]
    seed: int = 0
    x_range_m: tuple[float, float]
    y_range_m: tuple[float, float]
    radius_range_m: tuple[Positive, Positive] = (0.2, 0.4)
    keep_clear_m: NonNegative = 1.5  # no obstacle surface within this of start or goal

    def specs(self, keep_clear_of: list[tuple[float, float]]) -> list[ObstacleSpec]:
        rng = np.random.default_rng(self.seed)
        out: list[ObstacleSpec] = []
        for _ in range(1000 * self.count):
            if len(out) == self.count:
                break
            x, y = rng.uniform(*self.x_range_m), rng.uniform(*self.y_range_m)
            r = rng.uniform(*self.radius_range_m)
            if all(math.hypot(x - px, y - py) - r > self.keep_clear_m for px, py in keep_clear_of) and all(
                math.hypot(x - o.x_m, y - o.y_m) > r + o.radius_m + 0.1 for o in out
            ):
                out.append(ObstacleSpec(float(x), float(y), float(r)))
        return out


class RobotSpec(_Strict):
    """Start pose and the controller's robot circle: the URDF footprint radius plus a margin, or
    an explicit radius (a radius below the footprint is flagged in every summary)."""

    start: Pose
    radius_margin_m: NonNegative | None = None
    radius_m: Positive | None = None
    payload_kg: Annotated[float, Field(ge=0, le=75)] = 0.0  # Husky maximum payload 75 kg

    @model_validator(mode="after")
    def _one_radius(self) -> RobotSpec:
        if (self.radius_m is None) == (self.radius_margin_m is None):
            raise ValueError("give exactly one of radius_m or radius_margin_m")
        return self

    def radius(self) -> float:
        if self.radius_m is not None:
            return self.radius_m
        return load_geometry().footprint_radius_m + self.radius_margin_m


class ControllerSpec(_Strict):
    """NMPC parameters; omitted ones take the paper's simulation defaults (NMPCConfig)."""

    horizon: Annotated[int, Field(ge=1, le=50)] = 5
    gamma: Annotated[float, Field(ge=0, le=1)] = 0.1
    alpha: Annotated[float, Field(ge=0, le=1)] = 0.3
    state_weight: tuple[Positive, Positive, Positive] = (10.0, 15.0, 0.7)
    input_weight: tuple[Positive, Positive] = (1.0, 0.1)
    clf_weight: tuple[Positive, Positive, Positive] = (1.0, 1.0, 1.0)
    clf_slack_weight: Positive = 70.0
    decay_slack_weight: Positive = 10.0
    v_min_mps: Annotated[float, Field(le=0)] = -1.0
    v_max_mps: Positive = 1.0
    omega_max_radps: Positive = math.pi / 4
    obstacle_prediction: Literal["constant-velocity", "frozen"] = "constant-velocity"


class FrictionSpec(_Strict):
    ground: Positive = 1.0
    wheel_longitudinal: Positive = 1.0
    wheel_lateral_scale: Positive = 1.0


class SensingSpec(_Strict):
    pose_xy_std_m: NonNegative = 0.0
    pose_yaw_std_rad: NonNegative = 0.0
    obstacle_xy_std_m: NonNegative = 0.0
    latency_steps: Annotated[int, Field(ge=0, le=20)] = 0
    obstacle_velocity_scale: NonNegative = 1.0  # reported / true obstacle velocity


class SuccessSpec(_Strict):
    goal_position_m: Positive = 0.1
    goal_heading_rad: Positive = 0.1
    goal_hold_s: Positive = 1.0
    tracking_rmse_m: Positive = 0.3
    tracking_settle_s: NonNegative = 10.0
    stuck_window_steps: Annotated[int, Field(ge=1)] = 10
    stuck_speed_mps: Positive = 0.05
    stuck_yaw_rate_radps: Positive = 0.05


class Scenario(_Strict):
    """One scenario file."""

    name: str
    description: str = ""
    seed: int = 0
    tau_s: Positive = 0.1
    duration_s: Positive = 30.0
    physics_hz: Annotated[float, Field(ge=60, le=2000)] = 240.0
    robot: RobotSpec
    reference: ReferenceSpec
    obstacles: list[ObstacleEntry] = Field(default_factory=list)
    random_obstacles: RandomObstacles | None = None
    controller: ControllerSpec = ControllerSpec()
    drive: dict[str, float] = Field(default_factory=dict)
    friction: FrictionSpec = FrictionSpec()
    sensing: SensingSpec = SensingSpec()
    success: SuccessSpec = SuccessSpec()

    @model_validator(mode="after")
    def _drive_keys_known(self) -> Scenario:
        known = set(DriveConfig.__dataclass_fields__)
        unknown = sorted(set(self.drive) - known)
        if unknown:
            names = ", ".join(sorted(known))
            raise ValueError(f"drive: unknown key(s) {', '.join(unknown)} (known: {names})")
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
                        f"{label} ({pose.x_m}, {pose.y_m}) lies inside obstacle {i} at "
                        f"({ob.x_m}, {ob.y_m}) r {ob.radius_m} m with robot radius {r_robot:.3f} m"
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

    def reference_object(self) -> Reference:
        if self.reference.goal is not None:
            g = self.reference.goal
            return SetPoint(g.x_m, g.y_m, g.yaw_rad)
        c = self.reference.circle
        return CircleTrajectory(c.radius_m, c.angular_rate_radps, c.center_x_m, c.center_y_m, c.phase_rad)

    def controller_config(
        self, safety: SafetyConstraint, horizon: int | None = None, gamma: float | None = None
    ) -> NMPCConfig:
        # ControllerSpec's fields are NMPCConfig's fields by name
        fields = self.controller.model_dump()
        fields.update(horizon=horizon or fields["horizon"], gamma=fields["gamma"] if gamma is None else gamma)
        return NMPCConfig(
            **fields,
            tau_s=self.tau_s,
            safety=safety,
            robot_radius_m=self.robot.radius(),
            obstacle_slots=max(len(self.obstacle_specs()), 1),
        )

    def episode_config(self, seed: int | None = None) -> EpisodeConfig:
        f = self.friction
        drive = DriveConfig(**self.drive)  # keys checked by _drive_keys_known
        return EpisodeConfig(
            start=(self.robot.start.x_m, self.robot.start.y_m, self.robot.start.yaw_rad),
            tau_s=self.tau_s,
            duration_s=self.duration_s,
            world=WorldConfig(
                physics_hz=self.physics_hz, ground_friction=f.ground, obstacles=tuple(self.obstacle_specs())
            ),
            drive=drive,
            wheel_friction=WheelFriction(
                longitudinal=f.wheel_longitudinal, lateral_scale=f.wheel_lateral_scale
            ),
            sensing=SensingConfig(**self.sensing.model_dump()),  # same field names
            outcomes=Outcomes(**self.success.model_dump()),  # same field names
            payload_kg=self.robot.payload_kg,
            seed=self.seed if seed is None else seed,
        )


def _one_line(error: ValidationError, source: str) -> str:
    first = error.errors()[0]
    loc = ".".join(str(x) for x in first["loc"]) or "scenario"
    msg = first["msg"].removeprefix("Value error, ")
    got = first.get("input")
    got_text = "" if isinstance(got, dict | list) or got is None else f" (got {got!r})"
    more = f" [+{error.error_count() - 1} more]" if error.error_count() > 1 else ""
    return f"{source}: {loc}: {msg}{got_text}{more}"


def resolve(name_or_path: str) -> Path:
    """A scenario file path, or the name of a shipped scenario."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") and path.exists():
        return path
    shipped = SCENARIO_DIR / f"{name_or_path}.yaml"
    if shipped.exists():
        return shipped
    names = ", ".join(sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml")))
    raise ScenarioError(f"scenario: no file or shipped scenario named {name_or_path!r} (shipped: {names})")


def load_scenario(name_or_path: str) -> Scenario:
    """Load and validate a scenario; every problem is a one-line ScenarioError."""
    path = resolve(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ScenarioError(f"{path}: expected a mapping of scenario fields at the top level")
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(_one_line(exc, str(path))) from None


def shipped_scenarios() -> list[Path]:
    return sorted(SCENARIO_DIR.glob("*.yaml"))
