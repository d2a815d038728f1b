"""husky-cbf, registered: configured from the scenario's NMPC settings (with Relax-CBF), the
robot's drive limits, identified yaw response, footprint, reported pose noise and latency, and the
scenario's `controller.husky_cbf` settings."""

from __future__ import annotations

import dataclasses

from controllers.husky_cbf.config import Footprint, HuskyCBFConfig, PoseNoise, RobotResponse
from controllers.husky_cbf.footprint import disc_cover
from controllers.interface import Controller
from controllers.registry import BodyDiscs, ControllerEntry, ControllerInputs, PlanProfile, register
from controllers.settings import apply_settings


def configure(inputs: ControllerInputs) -> HuskyCBFConfig:
    """husky-cbf's configuration for a scenario; no more obstacle slots than it has obstacles (each
    costs OCP rows)."""
    robot = inputs.robot
    config = HuskyCBFConfig(
        nmpc=dataclasses.replace(inputs.nmpc, safety="relax-cbf"),
        response=RobotResponse(
            robot.max_linear_accel_mps2,
            robot.max_angular_accel_radps2,
            robot.yaw_gain,
            robot.yaw_time_constant_s,
            command_delay_s=robot.command_delay_s,
            half_separation_m=robot.half_separation_m,
            max_linear_mps=robot.max_linear_mps,
        ),
        footprint=Footprint(*robot.footprint_half_extents_m),
        omega_cmd_max_radps=robot.max_angular_radps,
        # what a localisation would report about its own noise
        pose_noise=PoseNoise(robot.pose_xy_std_m, robot.pose_yaw_std_rad),
        sensing_latency_s=robot.sensing_latency_s,
        sensor_fov_deg=robot.sensor_fov_deg,
    )
    config = apply_settings(config, inputs.settings)
    return dataclasses.replace(config, slots=min(max(inputs.obstacle_count, 1), config.slots))


def build(config: HuskyCBFConfig) -> Controller:
    from controllers.husky_cbf.controller import HuskyCBFController  # CasADi: only when built

    return HuskyCBFController(config)


def profile(config: HuskyCBFConfig) -> PlanProfile:
    """Its body of discs, the accelerations and the dead time in its model."""
    centres, radius = disc_cover(config.footprint, config.disc_excess_m)
    f = config.footprint
    return PlanProfile(
        nmpc=config.nmpc,
        omega_cmd_max_radps=config.omega_cmd_max_radps,
        body=BodyDiscs(len(centres), radius, (f.half_length_m, f.half_width_m), config.margin_m),
        planned_accel=(config.response.max_linear_accel_mps2, config.response.max_angular_accel_radps2),
        planned_dead_time_s=config.response.command_delay_s,
        planned_latency_s=config.sensing_latency_s,
    )


HUSKY_CBF = register(
    ControllerEntry(
        "husky-cbf",
        "ours: Relax-CBF on the Husky's drive dynamics, a body of discs, a planner and behaviours",
        configure,
        build,
        profile,
        settings=HuskyCBFConfig,
        decay_slack=True,
    )
)
