"""A world of a thousand obstacles in PyBullet: `husky-sim run` completes one, its static obstacles
(static rigid bodies beyond RIGID_STATICS_ABOVE) stop and clear the Husky bit for bit as the
multibodies of a small world do, and the clearance check's numpy path still reports the engine's
own minimum."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from husky_sim.cli import main
from husky_sim.paths import SCENARIO_DIR
from husky_sim.sim.bullet import pybullet as p
from husky_sim.sim.collision import NUMPY_FROM
from husky_sim.sim.environment import PhysicsEnvironment
from husky_sim.sim.episode import EpisodeConfig
from husky_sim.sim.trace import EpisodeTrace
from husky_sim.sim.world import RIGID_STATICS_ABOVE, ObstacleSpec, World, WorldConfig

pytestmark = pytest.mark.physics

#: Round the start: two posts the Husky drives into and one walking across, in a 3 m arena.
NEAR = (
    ObstacleSpec(2.0, 0.1, 0.4),
    ObstacleSpec(2.5, -1.5, 0.3),
    ObstacleSpec(1.0, 1.6, 0.3, vy_mps=-0.2),
)


def _far(count: int) -> tuple[ObstacleSpec, ...]:
    """`count` static posts far outside the arena (they never touch the Husky)."""
    return tuple(ObstacleSpec(50.0 + 2.0 * (i % 40), 40.0 + 2.0 * (i // 40), 0.3) for i in range(count))


#: PyBullet's body types (getDynamicsInfo's eleventh value).
RIGID_BODY, MULTIBODY = 1, 2


def _body_types(obstacles: tuple[ObstacleSpec, ...]) -> list[int]:
    with World(WorldConfig(obstacles=obstacles)) as world:
        return [p.getDynamicsInfo(b, -1, physicsClientId=world.client)[10] for b in world.obstacle_ids]


def _drive(obstacles: tuple[ObstacleSpec, ...]) -> np.ndarray:
    """(x, y, yaw, clearance) after each of 80 control periods of a weaving drive into the posts."""
    config = EpisodeConfig(
        start=(0.0, 0.0, 0.0), world=WorldConfig(obstacles=obstacles, arena_half_size_m=3.0)
    )
    with PhysicsEnvironment(config) as env:
        rows = []
        for k in range(80):
            _, clearance = env.advance(np.array([0.9, 0.4 * math.sin(k / 6)]))
            rows.append((*env.robot.pose(), clearance))
    return np.array(rows)


def test_a_large_worlds_static_bodies_stop_the_husky_as_a_small_worlds_do() -> None:
    small = NEAR + _far(RIGID_STATICS_ABOVE - len(NEAR))  # fixed-base multibodies
    large = NEAR + _far(RIGID_STATICS_ABOVE - len(NEAR) + 1)  # statics as static rigid bodies
    assert [_body_types(small)[i] for i in (0, 2)] == [MULTIBODY, MULTIBODY]
    assert [_body_types(large)[i] for i in (0, 2)] == [RIGID_BODY, MULTIBODY]  # the mover stays one
    in_small, in_large = _drive(small), _drive(large)
    assert in_small[:, 3].min() < 0.0  # the Husky pressed into a post: contact was exercised
    assert np.array_equal(in_small, in_large)


def test_the_clearance_of_a_large_world_is_the_engines_minimum() -> None:
    """With NUMPY_FROM obstacles or more, ClearanceMonitor.smallest's numpy path reports, after
    every period, what asking every body in full gives within the exact band."""
    obstacles = NEAR + _far(max(NUMPY_FROM, RIGID_STATICS_ABOVE) + 10)
    config = EpisodeConfig(
        start=(0.0, 0.0, 0.0), world=WorldConfig(obstacles=obstacles, arena_half_size_m=3.0)
    )
    with PhysicsEnvironment(config) as env:
        world, robot = env.world, env.robot
        bodies = world.obstacle_ids + world.wall_ids
        in_period: list[float] = []

        def ask_every_body(_applied: np.ndarray) -> None:
            points = [p.getClosestPoints(robot.body, b, 10.0, physicsClientId=world.client) for b in bodies]
            in_period.append(min(pt[8] for body_points in points for pt in body_points))

        checked = 0
        for k in range(60):
            in_period.clear()
            _, ours = env.advance(np.array([0.9, 0.4 * math.sin(k / 6)]), on_physics_step=ask_every_body)
            theirs = min(in_period)
            if theirs <= env.monitor.exact_within_m:
                assert ours == pytest.approx(theirs, abs=1e-12), f"period {k}"
                checked += 1
            else:
                assert env.monitor.exact_within_m < ours <= theirs
    assert checked >= 10
    assert env.monitor.queries < 60 * env.substeps * 4  # a handful of bodies a step, not every one


def test_husky_sim_run_completes_a_thousand_obstacle_scenario(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = yaml.safe_load((SCENARIO_DIR / "large" / "large_world_1000.yaml").read_text())
    data["duration_s"] = 2.0
    path = tmp_path / "large_world_short.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "run"
    assert main(["run", str(path), "--controller", "husky-cbf", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] in ("timeout", "reached") and not summary["collided"]
    assert summary["sim_time_s"] == pytest.approx(2.0)
    trace = EpisodeTrace.load(out / "trace.npz")
    assert trace.obstacle_xy_m.shape == (len(trace.sample_t_s), 1000, 2)
    assert np.array_equal(trace.obstacle_xy_m[-1], trace.obstacle_xy_m[0])  # static: where placed
    assert "large_world_1000 husky-cbf" in capsys.readouterr().out
