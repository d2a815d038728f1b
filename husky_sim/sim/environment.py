"""The simulated Husky as an environment: one PyBullet world with the robot, its skid-steer drive,
the sensor and the clearance monitor, advanced one control period at a time.

`PhysicsEnvironment` is the physics side of a control step. The closed loop (husky_sim.sim.rollout,
through husky_sim.sim.episode.run_episode) steps it with the NMPC's commands, and the gymnasium
environment `HuskyNavEnv` (husky_sim.runs.environment, "HuskyNav-v0") steps the same class
with an agent's actions, so both simulate the same thing: the command is held for tau through the
drive's velocity and acceleration limits, and the clearance is the physics engine's, every physics
step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from husky_sim.sim.collision import ClearanceMonitor
from husky_sim.sim.contact import Contact, classify, planar_velocity, touched_body
from husky_sim.sim.drive import SkidSteerDrive
from husky_sim.sim.robot import SkidSteerRobot
from husky_sim.sim.robot_description import load_robot
from husky_sim.sim.sensing import Measurement, Sensor
from husky_sim.sim.world import World

if TYPE_CHECKING:
    from husky_sim.sim.episode import EpisodeConfig

#: Margin (m) added to the footprint radius below which the clearance monitor asks the physics
#: engine for exact distances (husky_sim.sim.collision).
CLEARANCE_PREFILTER_MARGIN_M = 0.02


class PhysicsEnvironment:
    """One episode's simulated robot (EpisodeConfig: robot, world, start, drive, ground, payload,
    sensing and its seed), a husky_sim.sim.rollout.Plant. Call `close` (or use it as a context
    manager) to free the world."""

    def __init__(self, config: EpisodeConfig) -> None:
        self.config = config
        self.world = World(config.world)
        try:
            ground = config.ground
            self.robot = SkidSteerRobot(
                self.world.client,
                config.start,
                ground.tyre,
                config.payload_kg,
                coulomb=not ground.calibrated,
                robot=load_robot(config.robot),
            )
            geometry = self.robot.geometry
            self.drive = SkidSteerDrive(config.drive, geometry.wheel_radius_m, geometry.track_width_m, ground)
            self.sensor = Sensor(config.sensing, config.seed, [not o.moving for o in config.world.obstacles])
            walls = zip(self.world.wall_ids, self.world.wall_planes, strict=True)
            self.monitor = ClearanceMonitor(
                self.world.client,
                self.robot.body,
                self.world.obstacle_ids,
                [o.radius_m for o in config.world.obstacles],
                geometry.footprint_radius_m + CLEARANCE_PREFILTER_MARGIN_M,
                walls=[(body, n, d) for body, (n, d) in walls],
            )
        except BaseException:
            self.world.close()
            raise
        self.substeps = round(config.world.physics_hz * config.tau_s)  # physics steps per control step
        self.footprint_radius_m = self.robot.geometry.footprint_radius_m
        self.obstacle_radii_m = np.array([o.radius_m for o in config.world.obstacles])
        #: the episode's first contact (husky_sim.sim.contact), recorded once; None before it
        self.first_contact: Contact | None = None

    def pose(self) -> np.ndarray:
        """The true base pose [x m, y m, yaw rad]."""
        return self.robot.pose()

    def body_velocity(self) -> np.ndarray:
        """The true body velocity [v m/s, omega rad/s]."""
        return self.robot.body_velocity()

    def wheel_speeds(self) -> np.ndarray:
        """The four wheels' speeds (rad/s) [l1, l2, r1, r2]."""
        return self.robot.wheel_speeds()

    def motor_currents(self) -> np.ndarray:
        """The left and right motor currents (A) in the last physics step (husky_sim.sim.drive)."""
        return np.array(self.drive.motor_currents(self.robot))

    def obstacle_centres(self, t_s: float) -> np.ndarray:
        """True obstacle centres (m), shape (n, 2), at time t_s (s)."""
        return self.world.obstacle_centres(t_s)

    def measure(self) -> Measurement:
        """What the controller is told now: the sensor's (noisy, delayed) pose and the obstacles
        its lidar sees from the true base pose (husky_sim.sim.sensing)."""
        return self.sensor.measure(self.robot.pose(), self.world.obstacle_states())

    def advance(
        self, command: np.ndarray, on_physics_step: Callable[[np.ndarray], None] | None = None
    ) -> tuple[np.ndarray, float]:
        """Hold `command` [v m/s, omega rad/s] for one control period through the drive's limits;
        return the last applied (limited) command and the smallest clearance (m) to obstacles and
        walls over its physics steps (inf with neither). `on_physics_step(applied)` is called after
        every physics step (recorders: it must only read). The first physics step of the episode
        whose clearance is <= 0 records `first_contact`, with the speeds going into that step."""
        world, robot, drive = self.world, self.robot, self.drive
        clearance = math.inf
        applied = drive.applied
        checked = bool(world.obstacle_ids or world.wall_ids)
        for _ in range(self.substeps):
            watching = checked and self.first_contact is None
            if watching:  # the velocities going into the step, should it be the first contact
                t_before, velocity = world.time_s, planar_velocity(world.client, robot.body)
            applied = drive.step(robot, command, world.dt_s)
            world.step()
            if on_physics_step is not None:
                on_physics_step(applied)
            if checked:
                clearance = self.monitor.smallest(robot.position_xy(), world.obstacle_centres(), clearance)
                if watching and clearance <= 0.0:
                    self.first_contact = self._contact(t_before, velocity)
        return applied, clearance

    def _contact(self, t_s: float, robot_velocity_mps: tuple[float, float]) -> Contact:
        """The first contact, found in the physics step that began at t_s (s): the touched body
        (husky_sim.sim.contact.touched_body) and the velocities (m/s) going into that step."""
        world = self.world
        index = touched_body(
            world.client,
            self.robot.body,
            self.robot.position_xy(),
            world.obstacle_ids,
            world.obstacle_centres().tolist(),
            self.obstacle_radii_m.tolist(),
            world.wall_ids,
        )
        if index is None:
            return classify(t_s, None, robot_velocity_mps)
        _, _, vx, vy = world.config.obstacles[index].motion_at(t_s)
        return classify(t_s, index, robot_velocity_mps, (vx, vy))

    def close(self) -> None:
        self.world.close()

    def __enter__(self) -> PhysicsEnvironment:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
