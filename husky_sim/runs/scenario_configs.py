"""What a scenario builds: the controller's configuration (the paper's NMPC or husky-cbf), the
PyBullet episode's configuration, the reference and the kinematic problem. The schema
(husky_sim.runs.scenario) says what a scenario file may hold; this module says what it means to
the controllers and the simulator."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from controllers import (
    CircleTrajectory,
    Controller,
    NMPCConfig,
    NMPCController,
    Reference,
    SafetyConstraint,
    SetPoint,
    SolverOptions,
)
from controllers.husky_cbf import Footprint, HuskyCBFConfig, HuskyCBFController, RobotResponse
from controllers.husky_cbf.config import PoseNoise
from husky_sim.runs.settings_schema import apply_settings
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.geometry import load_geometry
from husky_sim.sim.ground import load_ground, with_friction
from husky_sim.sim.kinematic import KinematicProblem
from husky_sim.sim.outcomes import Outcomes
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.world import WorldConfig

if TYPE_CHECKING:
    from husky_sim.runs.scenario import Scenario


def kinematic_problem(
    sc: Scenario, robot_radius_m: float | None = None, allow_waypoints: bool = False
) -> KinematicProblem:
    """This scenario for the kinematic loop (husky_sim.sim.kinematic), with the controller's
    circle unless robot_radius_m (m) is given. An obstacle on waypoints has no constant-velocity
    model (ValueError), unless `allow_waypoints`: then it moves on at its velocity at t = 0 (the
    solve-time audit needs problems of the scenario's size, not its exact motion)."""
    specs = sc.obstacle_specs()
    if not allow_waypoints and any(o.waypoints for o in specs):
        raise ValueError(f"{sc.name}: waypoint obstacles have no constant-velocity kinematic model")
    start = sc.robot.start
    return KinematicProblem(
        name=sc.name,
        start=(start.x_m, start.y_m, start.yaw_rad),
        reference=reference_object(sc),
        obstacles=tuple(spec.circle_at(0.0) for spec in specs),
        robot_radius_m=sc.robot.radius() if robot_radius_m is None else robot_radius_m,
        duration_s=sc.duration_s,
    )


def reference_object(sc: Scenario) -> Reference:
    """The reference a controller tracks: the goal as a set point, or the circle."""
    if sc.reference.goal is not None:
        g = sc.reference.goal
        return SetPoint(g.x_m, g.y_m, g.yaw_rad)
    c = sc.reference.circle
    return CircleTrajectory(c.radius_m, c.angular_rate_radps, c.center_x_m, c.center_y_m, c.phase_rad)


def controller_config(sc: Scenario, safety: SafetyConstraint) -> NMPCConfig:
    """The NMPC's configuration for this scenario with the obstacle constraint `safety` (N and
    gamma are the file's: overrides are applied once, by `with_overrides`)."""
    # ControllerSpec's fields are NMPCConfig's fields by name; `solver` names SolverOptions.backend
    fields = sc.controller.model_dump()
    fields.pop("husky_cbf")  # husky-cbf's own (husky_cbf_config)
    backend = fields.pop("solver")
    if backend is not None:
        fields["solver"] = SolverOptions(backend=backend)
    return NMPCConfig(
        **fields,
        tau_s=sc.tau_s,
        safety=safety,
        robot_radius_m=sc.robot.radius(),
        obstacle_slots=max(len(sc.obstacle_specs()), 1),
    )


def husky_cbf_config(sc: Scenario) -> HuskyCBFConfig:
    """husky-cbf's configuration: the file's NMPC settings (Relax-CBF), the drive's limits, the
    robot's identified yaw response and the URDF's footprint."""
    drive = sc.drive.config()
    yaw = sc.robot.yaw_response_params()
    geometry = load_geometry()
    config = HuskyCBFConfig(
        nmpc=controller_config(sc, "relax-cbf"),
        response=RobotResponse(
            drive.max_linear_accel_mps2,
            drive.max_angular_accel_radps2,
            yaw.gain,
            yaw.time_constant_s,
            command_delay_s=yaw.delay_s,
            half_separation_m=0.5 * geometry.track_width_m * drive.wheel_separation_multiplier,
            max_linear_mps=drive.max_linear_mps,
        ),
        footprint=Footprint(*geometry.footprint_half_extents_m),
        omega_cmd_max_radps=drive.max_angular_radps,
        # what a localisation would report about its own noise
        pose_noise=PoseNoise(sc.sensing.pose_xy_std_m, sc.sensing.pose_yaw_std_rad),
    )
    config = apply_settings(config, sc.controller.husky_cbf)
    # no more obstacle slots than the scenario has obstacles: each costs OCP rows
    return dataclasses.replace(config, slots=min(max(len(sc.obstacle_specs()), 1), config.slots))


def make_controller(sc: Scenario, name: str) -> Controller:
    """The controller called `name` (controllers.CONTROLLER_NAMES) configured for this scenario."""
    if name == "husky-cbf":
        return HuskyCBFController(husky_cbf_config(sc))
    return NMPCController(controller_config(sc, name))


def episode_config(sc: Scenario) -> EpisodeConfig:
    """Everything the PyBullet episode needs besides the controller and the reference."""
    ground = with_friction(load_ground(sc.ground), sc.friction.ground)
    if sc.friction.lateral_stiffness_ratio is not None:
        tyre = dataclasses.replace(ground.tyre, lateral_stiffness_ratio=sc.friction.lateral_stiffness_ratio)
        ground = dataclasses.replace(ground, tyre=tyre)
    return EpisodeConfig(
        start=(sc.robot.start.x_m, sc.robot.start.y_m, sc.robot.start.yaw_rad),
        tau_s=sc.tau_s,
        duration_s=sc.duration_s,
        world=WorldConfig(
            physics_hz=sc.physics_hz,
            ground_friction=ground.tyre.friction,
            obstacles=tuple(sc.obstacle_specs()),
        ),
        drive=sc.drive.config(),
        ground=ground,
        sensing=SensingConfig(**sc.sensing.model_dump()),  # same field names
        outcomes=Outcomes(**sc.success.model_dump()),  # same field names
        payload_kg=sc.robot.payload_kg,
        seed=sc.seed,
    )
