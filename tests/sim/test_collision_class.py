"""Collision classes (husky_sim.sim.contact): each collision is classified at its first contact,
the robot moving into it (at fault) or standing still when hit (passive motion safety), with the
body touched and the speed relative to it. Real PyBullet episodes with the real NMPC; the rule
itself and the kinematic plant's circle model are pure."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from controllers import NMPCConfig, NMPCController, Obstacle, SetPoint
from husky_sim.sim.contact import AT_FAULT_SPEED_MPS, classify
from husky_sim.sim.episode import EpisodeConfig, run_episode
from husky_sim.sim.kinematic import KinematicEnvironment
from husky_sim.sim.world import ObstacleSpec, WorldConfig

ROBOT_RADIUS_M = 0.65  # the footprint (0.570 m) plus 8 cm


def unconstrained() -> NMPCController:
    """The NMPC with no obstacle constraint: it drives to its goal, or holds it, whatever comes."""
    return NMPCController(NMPCConfig(safety="none", horizon=5, robot_radius_m=ROBOT_RADIUS_M))


def test_the_rule_is_the_robots_speed_going_into_the_contact() -> None:
    assert AT_FAULT_SPEED_MPS == 0.05
    standing = classify(1.0, 0, (0.03, -0.04), (0.0, -0.8))  # 0.05 m/s: not above the threshold
    assert not standing.at_fault and standing.robot_speed_mps == pytest.approx(0.05)
    assert standing.relative_speed_mps == pytest.approx(math.hypot(0.03, 0.76))
    moving = classify(1.0, None, (0.0, 0.051))
    assert moving.at_fault and moving.obstacle is None and moving.relative_speed_mps == pytest.approx(0.051)


@pytest.mark.physics
def test_a_standing_husky_hit_by_a_person_is_not_at_fault(tmp_path: Path) -> None:
    """The Husky holds its start (the goal) while a person (r 0.3 m) walks into its side at
    0.8 m/s: a collision, not the robot's fault, with obstacle 1 (obstacle 0 stands far away),
    at about the person's speed; summary.json says so."""
    from husky_sim.runs.run import run_scenario
    from husky_sim.runs.scenario import load_scenario, scenario_from_data

    data = load_scenario("head_on_moving_obstacle").model_dump()
    data.update(name="person_walks_into_a_standing_husky", duration_s=6.0, random_obstacles=None)
    data["robot"]["start"] = {"x_m": 0.0, "y_m": 0.0, "yaw_rad": 0.0}
    data["reference"] = {"goal": {"x_m": 0.0, "y_m": 0.0, "yaw_rad": 0.0}, "circle": None}
    data["success"]["goal_hold_s"] = 30.0  # held from the start: not "reached" before the person comes
    data["obstacles"] = [
        {"x_m": -6.0, "y_m": 5.0, "radius_m": 0.4},
        {"x_m": 0.0, "y_m": 3.0, "radius_m": 0.3, "vx_mps": 0.0, "vy_mps": -0.8},
    ]
    scenario = scenario_from_data(data, "test")
    metrics = run_scenario(scenario, "none", out_dir=tmp_path).metrics
    assert metrics.outcome == "collided" and metrics.max_abs_v_mps < 0.01  # it never moved
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["collision_at_fault"] is False and summary["collision_obstacle"] == 1
    assert summary["collision_relative_speed_mps"] == pytest.approx(0.8, abs=0.02)


@pytest.mark.physics
def test_a_husky_driven_into_a_post_is_at_fault_with_the_posts_index() -> None:
    """The NMPC without an obstacle constraint drives the Husky at a post (obstacle 1) on its way
    to a goal beyond it: at fault, the post touched, at the robot's own speed (the post stands)."""
    posts = (ObstacleSpec(-3.0, 3.0, 0.3), ObstacleSpec(2.5, 0.0, 0.3))
    config = EpisodeConfig(start=(0.0, 0.0, 0.0), duration_s=8.0, world=WorldConfig(obstacles=posts))
    result = run_episode(unconstrained(), SetPoint(5.0, 0.0, 0.0), config, robot_radius_m=ROBOT_RADIUS_M)
    m = result.metrics
    assert m.outcome == "collided" and m.collision_at_fault is True and m.collision_obstacle == 1
    assert 0.3 < m.collision_relative_speed_mps <= m.max_abs_v_mps + 0.05  # about its speed then
    v_last = abs(float(result.rows[-1]["v_body_mps"]))  # the step that ended in contact began at it
    assert m.collision_relative_speed_mps == pytest.approx(v_last, abs=0.15)


@pytest.mark.physics
def test_a_wall_is_no_obstacle_and_no_collision_leaves_every_field_null() -> None:
    """Driven into the arena's wall: at fault, no obstacle index. A run without contact: nulls."""
    config = EpisodeConfig(
        start=(0.0, 0.0, 0.0),
        duration_s=8.0,
        world=WorldConfig(obstacles=(ObstacleSpec(0.0, 2.5, 0.3),), arena_half_size_m=3.0),
    )
    m = run_episode(unconstrained(), SetPoint(4.5, 0.0, 0.0), config, robot_radius_m=ROBOT_RADIUS_M).metrics
    assert m.outcome == "collided" and m.collision_at_fault is True and m.collision_obstacle is None
    assert m.collision_relative_speed_mps > AT_FAULT_SPEED_MPS
    clear = EpisodeConfig(
        start=(0.0, 0.0, 0.0), duration_s=1.0, world=WorldConfig(obstacles=(ObstacleSpec(4.0, 3.0, 0.3),))
    )
    m = run_episode(unconstrained(), SetPoint(1.0, 0.0, 0.0), clear, robot_radius_m=ROBOT_RADIUS_M).metrics
    assert not m.collided
    assert (m.collision_at_fault, m.collision_obstacle, m.collision_relative_speed_mps) == (None, None, None)


def test_the_kinematic_plant_classifies_on_its_circles() -> None:
    """The unicycle driven at 0.5 m/s into the second of two circles: at fault, that circle, and
    the speed relative to it (it walks towards the robot at 0.3 m/s); standing still while a
    circle walks into it: not at fault."""
    circles = [Obstacle(0.0, 5.0, 0.3), Obstacle(2.0, 0.0, 0.3, vx_mps=-0.3)]
    plant = KinematicEnvironment((0.0, 0.0, 0.0), circles, 0.1, robot_radius_m=0.5)
    for _ in range(30):
        plant.advance(np.array([0.5, 0.0]))
    contact = plant.first_contact
    assert contact is not None and contact.at_fault and contact.obstacle == 1
    assert contact.relative_speed_mps == pytest.approx(0.8)
    standing = KinematicEnvironment((0.0, 0.0, 0.0), circles, 0.1, robot_radius_m=0.5)
    for _ in range(60):
        standing.advance(np.zeros(2))
    assert standing.first_contact is not None and not standing.first_contact.at_fault
    assert standing.first_contact.relative_speed_mps == pytest.approx(0.3)


@pytest.mark.physics
def test_the_touched_body_is_the_nearest_by_the_engine_not_by_the_centres() -> None:
    """The Husky at rest with a post 1 cm into its front face (obstacle 1) and another 3 cm off its
    side (obstacle 2), whose centre distance minus radius is the smaller (the side is nearer the
    centre than the front), a far post and the arena's walls: the engine's distances pick 1."""
    from husky_sim.sim.bullet import pybullet as p
    from husky_sim.sim.contact import touched_body
    from husky_sim.sim.environment import PhysicsEnvironment

    front_m, side_m = 0.4937, 0.343  # the chassis' half length and half width (URDF)
    centres = [(-4.0, 4.0), (front_m - 0.01 + 0.3, 0.0), (0.0, -(side_m + 0.03 + 0.3))]
    posts = tuple(ObstacleSpec(x, y, 0.3) for x, y in centres)
    config = EpisodeConfig(start=(0.0, 0.0, 0.0), world=WorldConfig(obstacles=posts, arena_half_size_m=5.0))
    with PhysicsEnvironment(config) as env:
        world, robot = env.world, env.robot

        def engine_m(i: int) -> float:
            points = p.getClosestPoints(robot.body, world.obstacle_ids[i], 0.1, physicsClientId=world.client)
            return min(point[8] for point in points)

        assert engine_m(1) < 0.0 < engine_m(2) < 0.05  # touching the front; within reach at the side
        bounds = [math.dist(c, robot.position_xy()) - 0.3 for c in centres]
        assert bounds[2] < bounds[1]  # by the centres, the side post would be the one
        found = touched_body(
            world.client,
            robot.body,
            robot.position_xy(),
            world.obstacle_ids,
            centres,
            [0.3] * 3,
            world.wall_ids,
        )
    assert found == 1
