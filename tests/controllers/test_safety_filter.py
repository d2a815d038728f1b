"""husky-cbf's safety filter (controllers.husky_cbf.safety_filter): the backup manoeuvre, and when
the filter keeps the NMPC's command or brakes instead. Pure tests: no physics, no solver."""

from __future__ import annotations

import math

import numpy as np

from controllers.husky_cbf.config import RobotResponse
from controllers.husky_cbf.safety_filter import SafetyFilter
from controllers.obstacles import Obstacle

RESPONSE = RobotResponse(
    max_linear_accel_mps2=1.0,
    max_angular_accel_radps2=2.0,
    yaw_gain=1.0,
    yaw_time_constant_s=0.1,
    half_separation_m=0.3,
    max_linear_mps=1.0,
)
DISCS = np.array([-0.33, 0.0, 0.33])


def _filter(accel_bound: float = 0.5, lead_s: float = 0.0) -> SafetyFilter:
    return SafetyFilter(RESPONSE, 0.1, DISCS, 0.38, accel_bound, lead_s)


def _moving_at(v_mps: float) -> np.ndarray:
    """The extended state [x, y, theta, v, omega_cmd, omega] of a robot at the origin facing +x."""
    return np.array([0.0, 0.0, 0.0, v_mps, 0.0, 0.0])


def test_the_backup_holds_the_command_one_period_then_brakes_to_a_stand_at_the_drive_s_limit() -> None:
    times, poses = _filter().backup(_moving_at(1.0), np.array([1.0, 0.0]))
    assert np.all(np.diff(times) > 0)
    # 0.1 s at 1 m/s, then v^2 / (2 a) = 0.5 m of braking at 1 m/s^2
    assert poses[-1, 0] == np.float64(poses[-1, 0]) and 0.55 <= poses[-1, 0] <= 0.65
    assert 1.0 <= times[-1] <= 1.2
    _, braking = _filter().backup(_moving_at(1.0), None)
    assert 0.45 <= braking[-1, 0] <= 0.55


def test_a_clear_way_keeps_the_command_and_a_post_within_the_stopping_distance_brakes() -> None:
    command = np.array([1.0, 0.0])
    far = [Obstacle(3.0, 0.0, 0.3)]
    kept = _filter().filter(_moving_at(1.0), command, far)
    assert not kept.intervened and np.array_equal(kept.command, command) and kept.clearance_m > 1.0
    # the front disc reaches 0.33 + 0.6 + 0.38 = 1.31 m on the command's backup, 1.21 m braking now
    near = [Obstacle(1.55, 0.0, 0.3)]
    verdict = _filter().filter(_moving_at(1.0), command, near)
    assert verdict.intervened and np.array_equal(verdict.command, np.zeros(2))
    assert verdict.clearance_m > 0 > _filter().clearance(*_filter().backup(_moving_at(1.0), command), near)


def test_a_mover_on_course_to_the_way_is_braked_for_and_one_walking_away_is_not() -> None:
    command = np.array([0.5, 0.0])
    assert (
        not _filter(accel_bound=0.0)
        .filter(_moving_at(0.5), command, [Obstacle(0.6, 1.2, 0.3, 0, 1.0)])
        .intervened
    )
    assert (
        _filter(accel_bound=0.0)
        .filter(_moving_at(0.5), command, [Obstacle(0.6, 1.2, 0.3, 0, -1.0)])
        .intervened
    )


def test_a_mover_s_circle_grows_with_the_bound_on_its_change_of_velocity() -> None:
    command = np.array([0.5, 0.0])
    beside = [Obstacle(1.0, 1.5, 0.3, 0.0, 1e-3)]  # a walker standing beside the way
    assert not _filter(accel_bound=0.0).filter(_moving_at(0.5), command, beside).intervened
    assert _filter(accel_bound=10.0).filter(_moving_at(0.5), command, beside).intervened
    static = [Obstacle(1.0, 1.5, 0.3)]  # a static obstacle does not move whatever the bound
    assert not _filter(accel_bound=10.0).filter(_moving_at(0.5), command, static).intervened


def test_the_time_since_the_measurement_counts_for_the_mover() -> None:
    walker = [Obstacle(0.6, 1.4, 0.3, 0.0, -1.0)]
    command = np.array([0.5, 0.0])
    assert not _filter(accel_bound=0.0).filter(_moving_at(0.5), command, walker).intervened
    assert _filter(accel_bound=0.0, lead_s=0.8).filter(_moving_at(0.5), command, walker).intervened


def test_when_no_backup_clears_the_one_that_keeps_more_clearance_is_sent() -> None:
    post = [Obstacle(1.5, 0.0, 0.3)]  # within reach of both the command's backup and braking now
    command = np.array([1.0, 0.0])
    f = _filter()
    kept = f.clearance(*f.backup(_moving_at(1.0), command), post)
    braking = f.clearance(*f.backup(_moving_at(1.0), None), post)
    verdict = f.filter(_moving_at(1.0), command, post)
    assert kept < 0 and verdict.clearance_m == max(kept, braking) and verdict.intervened
    assert math.isinf(f.clearance(*f.backup(_moving_at(1.0), command), []))
