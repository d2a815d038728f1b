"""What a scenario builds: a controller's inputs and configuration (through its registry entry), the
PyBullet episode's configuration, the reference and the kinematic problem. The schema
(husky_sim.runs.scenario) says what a scenario file may hold; this module says what it means to
the controllers and the simulator."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from controllers import CircleTrajectory, Controller, NMPCConfig, Reference, SetPoint, SolverOptions, registry
from controllers.registry import ControllerInputs, PlanProfile, RobotFacts
from husky_sim.runs.settings_schema import given_settings
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.ground import with_friction
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


def nmpc_config(sc: Scenario) -> NMPCConfig:
    """The scenario's NMPC settings (the paper's part, N and gamma the file's: overrides are
    applied once, by `with_overrides`), with its robot circle and one obstacle slot per obstacle,
    at least one and at most `controller.max_obstacle_slots` (more obstacles: the nearest fill
    them, controllers.obstacles); each controller sets its own obstacle constraint on it (its
    registry entry's `configure`)."""
    from husky_sim.runs.scenario import NMPC_FIELDS  # the schema imports this module's callers

    # the NMPC fields of ControllerSpec are NMPCConfig's by name; `solver` names SolverOptions.backend
    fields = {name: getattr(sc.controller, name) for name in NMPC_FIELDS}
    backend = fields.pop("solver")
    if backend is not None:
        fields["solver"] = SolverOptions(backend=backend)
    most = fields.pop("max_obstacle_slots")
    return NMPCConfig(
        **fields,
        tau_s=sc.tau_s,
        robot_radius_m=sc.robot.radius(),
        obstacle_slots=min(max(len(sc.obstacle_specs()), 1), most),
    )


def robot_facts(sc: Scenario) -> RobotFacts:
    """What a controller is told of the robot: the drive's limits, the identified yaw response, the
    URDF's footprint and the localisation's reported noise and latency."""
    drive = sc.drive_config()
    yaw = sc.robot.yaw_response_params()
    geometry = sc.robot.description().geometry
    return RobotFacts(
        max_linear_mps=drive.max_linear_mps,
        max_angular_radps=drive.max_angular_radps,
        max_linear_accel_mps2=drive.max_linear_accel_mps2,
        max_angular_accel_radps2=drive.max_angular_accel_radps2,
        yaw_gain=yaw.gain,
        yaw_time_constant_s=yaw.time_constant_s,
        command_delay_s=yaw.delay_s,
        half_separation_m=0.5 * geometry.track_width_m * drive.wheel_separation_multiplier,
        footprint_half_extents_m=geometry.footprint_half_extents_m,
        pose_xy_std_m=sc.sensing.pose_xy_std_m,
        pose_yaw_std_rad=sc.sensing.pose_yaw_std_rad,
        sensing_latency_s=sc.sensing.latency_steps * sc.tau_s,
        sensor_fov_deg=sc.sensing.fov_deg,
    )


def controller_inputs(sc: Scenario, name: str) -> ControllerInputs:
    """What the controller `name` is built from for this scenario (controllers.registry)."""
    return ControllerInputs(
        nmpc=nmpc_config(sc),
        robot=robot_facts(sc),
        obstacle_count=len(sc.obstacle_specs()),
        settings=given_settings(sc.controller, name),
    )


def controller_config(sc: Scenario, name: str) -> Any:
    """The configuration of the controller `name` (a registered one) for this scenario."""
    return registry.entry(name).configure(controller_inputs(sc, name))


def plan_profile(sc: Scenario, name: str) -> PlanProfile:
    """What the plans of the controller `name` promise on this scenario."""
    entry = registry.entry(name)
    return entry.profile(entry.configure(controller_inputs(sc, name)))


def make_controller(sc: Scenario, name: str) -> Controller:
    """The controller called `name` (a registered one) configured for this scenario."""
    return registry.entry(name).make(controller_inputs(sc, name))


def episode_config(sc: Scenario) -> EpisodeConfig:
    """Everything the PyBullet episode needs besides the controller and the reference."""
    ground = with_friction(sc.ground_config(), sc.friction.ground)
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
        drive=sc.drive_config(),
        ground=ground,
        sensing=SensingConfig(**sc.sensing.model_dump()),  # same field names
        outcomes=Outcomes(**sc.success.model_dump()),  # same field names
        payload_kg=sc.robot.payload_kg,
        robot=sc.robot.model,
        seed=sc.seed,
    )
