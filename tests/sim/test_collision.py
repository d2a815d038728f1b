"""The clearance check against the engine's own distances: the episode's physics loop, through
ClearanceMonitor.smallest with its skipped bodies and narrowed queries, reports exactly the minimum
a full query of every body gives."""

import math

import numpy as np
import pytest

from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.environment import PhysicsEnvironment
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.robot import SkidSteerRobot
from husky_sim.sim.world import ObstacleSpec, WorldConfig

pytestmark = pytest.mark.physics

#: Obstacles round the start, one walking across, inside a 2.2 m arena: the Husky turns among
#: them, so clearances rise and fall through (0, 0.5] m, and it ends pushing into one.
OBSTACLES = (
    ObstacleSpec(1.3, 0.2, 0.3),
    ObstacleSpec(-0.2, 1.25, 0.25),
    ObstacleSpec(-1.1, -0.9, 0.3),
    ObstacleSpec(1.6, -1.4, 0.2, vx_mps=-0.3, vy_mps=0.25),
)


def engine_minimum(robot: SkidSteerRobot, bodies: list[int], client: int) -> float:
    """The smallest signed distance of the robot to any body, every body asked in full."""
    points = [p.getClosestPoints(robot.body, b, distance=10.0, physicsClientId=client) for b in bodies]
    return min((pt[8] for body_points in points for pt in body_points), default=math.inf)


def test_the_episodes_clearance_is_the_engines_minimum_over_each_period() -> None:
    """The clearance PhysicsEnvironment.advance reports for a control period (ClearanceMonitor.smallest,
    a running minimum) against every body asked in full after each of its physics steps."""
    world_config = WorldConfig(obstacles=OBSTACLES, arena_half_size_m=2.2)
    config = EpisodeConfig(start=(0.0, 0.0, 0.3), tau_s=0.1, world=world_config)
    with PhysicsEnvironment(config) as env:
        bodies = env.world.obstacle_ids + env.world.wall_ids
        in_period: list[float] = []  # the engine's minimum after each physics step of a period

        def ask_every_body(_applied: np.ndarray) -> None:
            in_period.append(engine_minimum(env.robot, bodies, env.world.client))

        checked, contacts, full_queries = 0, 0, 0
        for period in range(60):
            command = np.array([0.6, 1.2 if period < 35 else 0.0])  # turn among them, then push
            in_period.clear()
            _, ours = env.advance(command, on_physics_step=ask_every_body)
            theirs = min(in_period)
            full_queries += len(in_period) * len(bodies)
            if theirs <= env.monitor.exact_within_m:
                assert ours == pytest.approx(theirs, abs=1e-12), f"period {period}"
                checked += 1
                contacts += theirs <= 0.0
            else:  # far: a bound, never above the truth, never inside the exact band
                assert env.monitor.exact_within_m < ours <= theirs
    assert checked >= 30 and contacts >= 1  # the exact band and a contact were both exercised
    assert env.monitor.queries < full_queries / 4
