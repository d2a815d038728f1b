"""husky-cbf's memory of obstacles out of its sensor's view (controllers.husky_cbf.obstacle_memory).
Pure tests: no physics, no solver."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.husky_cbf.obstacle_memory import MOVER_MEMORY_S, ObstacleMemory
from controllers.obstacles import Obstacle

FACING_EAST = np.array([0.0, 0.0, 0.0])
FACING_WEST = np.array([0.0, 0.0, math.pi])
POST = Obstacle(2.0, 0.0, 0.3)  # east of the robot


def test_a_post_behind_the_robot_is_remembered_until_the_sensor_could_see_it_again() -> None:
    memory = ObstacleMemory(270.0)
    assert memory.update(FACING_EAST, [POST], 0.0)[0] == [POST]
    # turned away: the post is behind, in the blind sector, and not measured: still there
    kept, ages = memory.update(FACING_WEST, [], 1.0)
    assert kept == [POST] and ages.tolist() == [1.0]
    # facing it again and not measuring it: it is gone
    assert memory.update(FACING_EAST, [], 2.0)[0] == []


def test_a_full_circle_of_view_remembers_nothing() -> None:
    memory = ObstacleMemory(360.0)
    memory.update(FACING_EAST, [POST], 0.0)
    assert memory.update(FACING_WEST, [], 1.0)[0] == []


def test_a_post_hidden_behind_another_is_kept_and_a_neighbour_is_not_taken_for_it() -> None:
    """Three posts in a row east of the robot, 0.64 m apart: the far one hidden behind the near one
    is kept (the sensor could not see it); the near ones, measured, are not the far one again."""
    row = [Obstacle(2.0, 0.0, 0.3), Obstacle(2.64, 0.0, 0.3), Obstacle(3.28, 0.0, 0.3)]
    memory = ObstacleMemory(270.0)
    memory.update(FACING_EAST, row, 0.0)
    kept, _ = memory.update(FACING_EAST, row[:1], 0.1)  # the others hidden behind the first
    assert kept == row


def test_a_mover_out_of_view_is_predicted_at_its_velocity_for_a_bounded_time() -> None:
    walker = Obstacle(-2.0, 1.0, 0.3, vx_mps=0.0, vy_mps=-0.5)  # behind a robot facing east
    memory = ObstacleMemory(270.0)
    memory.update(FACING_WEST, [walker], 0.0)
    kept, ages = memory.update(FACING_EAST, [], 1.0)
    assert len(kept) == 1 and kept[0].y_m == pytest.approx(0.5) and ages.tolist() == [1.0]
    assert memory.update(FACING_EAST, [], MOVER_MEMORY_S + 0.5)[0] == []
    # measured again where it was predicted: the measurement replaces it
    memory = ObstacleMemory(270.0)
    memory.update(FACING_WEST, [walker], 0.0)
    again = Obstacle(-2.0, 0.4, 0.3, vx_mps=0.0, vy_mps=-0.5)
    assert memory.update(FACING_WEST, [again], 1.0)[0] == [again]
