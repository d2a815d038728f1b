"""World obstacle motion, arena walls, sensing noise/latency and deadline mode."""

import numpy as np
import pybullet as p
import pytest

from controllers import NMPCConfig, NMPCController, Obstacle, SetPoint
from controllers.config import SolverOptions
from husky_sim.sim.episode import EpisodeConfig, run_episode
from husky_sim.sim.sensing import SensingConfig, Sensor
from husky_sim.sim.world import ObstacleSpec, World, WorldConfig

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)


def test_waypoint_obstacle_follows_its_path_and_stops() -> None:
    spec = ObstacleSpec(0.0, 0.0, 0.3, waypoints=((2.0, 0.0), (2.0, 1.0)), speed_mps=0.5)
    centre, vel = spec.state_at(2.0)  # 1 m along the first leg
    assert centre == pytest.approx([1.0, 0.0]) and vel == pytest.approx([0.5, 0.0])
    centre, vel = spec.state_at(5.0)  # 2.5 m: half way up the second leg
    assert centre == pytest.approx([2.0, 0.5]) and vel == pytest.approx([0.0, 0.5])
    centre, vel = spec.state_at(100.0)
    assert centre == pytest.approx([2.0, 1.0]) and vel == pytest.approx([0.0, 0.0])


def test_moving_obstacle_body_moves_with_the_clock() -> None:
    spec = ObstacleSpec(1.0, 2.0, 0.3, vx_mps=0.6, vy_mps=-0.3)
    with World(WorldConfig(obstacles=(spec,))) as world:
        for _ in range(240):
            world.step()
        pos, _ = p.getBasePositionAndOrientation(world.obstacle_ids[0], physicsClientId=world.client)
        assert world.time_s == pytest.approx(1.0)
        assert pos[:2] == pytest.approx((1.6, 1.7), abs=1e-9)
        assert world.obstacle_centres() == pytest.approx(np.array([[1.6, 1.7]]))
        (seen,) = world.obstacle_states()
        assert (seen.vx_mps, seen.vy_mps) == (0.6, -0.3)


def test_arena_walls_exist() -> None:
    with World(WorldConfig(arena_half_size_m=5.0)) as world:
        assert len(world.wall_ids) == 4
        aabb = p.getAABB(world.wall_ids[0], physicsClientId=world.client)
        assert aabb[0][0] == pytest.approx(4.9, abs=1e-2)


def test_sensor_latency_and_seeded_noise() -> None:
    truth = [np.array([float(k), 0.0, 0.0]) for k in range(6)]
    delayed = Sensor(SensingConfig(latency_steps=2), seed=0)
    seen = [delayed.measure(pose, [Obstacle(5.0, 5.0, 0.3)]).pose[0] for pose in truth]
    assert seen == [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]
    noisy = SensingConfig(pose_xy_std_m=0.05, obstacle_xy_std_m=0.1)
    a = [Sensor(noisy, seed=1).measure(truth[0], [Obstacle(5.0, 5.0, 0.3)]) for _ in range(2)]
    assert np.array_equal(a[0].pose, a[1].pose) and a[0].obstacles == a[1].obstacles
    assert not np.array_equal(a[0].pose, truth[0])
    with pytest.raises(ValueError, match="latency_steps"):
        SensingConfig(latency_steps=-1)


def test_deadline_mode_holds_the_command_and_counts_misses() -> None:
    """tau = 1 ms is shorter than any IPOPT solve of an N = 12 Relax-CBF problem here (>= 3 ms)."""
    cfg = EpisodeConfig(
        start=(0.0, 0.0, 0.0),
        tau_s=0.001,
        duration_s=0.05,
        deadline_mode=True,
        world=WorldConfig(physics_hz=1000.0, obstacles=(ObstacleSpec(2.0, 0.3, 0.3),)),
    )
    # on IPOPT, as the docstring says: the default FATROP solves this in about 1 ms on a fast CPU
    config = NMPCConfig(
        safety="relax-cbf",
        horizon=12,
        tau_s=0.001,
        robot_radius_m=0.65,
        solver=SolverOptions(backend="ipopt"),
    )
    m = run_episode(NMPCController(config), SetPoint(4.0, 0.0, 0.0), cfg).metrics
    assert m.deadline_misses >= 40 and m.steps == 50
    assert m.max_abs_v_mps == 0.0  # every command was held at the initial standstill
