"""husky-cbf's pose filter (controllers.husky_cbf.localisation): the measurement unchanged when no
noise is declared, the steady-state Kalman gain, and less noise than the measurement on a drive."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.husky_cbf.config import PoseNoise
from controllers.husky_cbf.localisation import PoseFilter, steady_state_gain

TAU_S = 0.1


def test_without_declared_noise_the_measurement_is_returned_unchanged() -> None:
    pose_filter = PoseFilter(PoseNoise(), TAU_S)
    rng = np.random.default_rng(0)
    for _ in range(20):
        measured = rng.normal(size=3)
        assert np.array_equal(pose_filter.update(measured, 0.7, -0.3), measured)


def test_the_gain_is_the_fixed_point_of_the_kalman_recursion() -> None:
    process, measurement = 0.01, 0.04
    gain = steady_state_gain(process, measurement)
    variance = measurement**2
    for _ in range(500):  # predict (+ process^2), update (x (1 - K))
        prior = variance + process**2
        variance = prior * measurement**2 / (prior + measurement**2)
    assert gain == pytest.approx(prior / (prior + measurement**2), rel=1e-9)
    assert 0.0 < gain < 1.0
    assert steady_state_gain(process, 0.0) == 1.0 and steady_state_gain(0.0, measurement) == 0.0


def test_a_straight_drive_is_estimated_with_less_noise_than_measured() -> None:
    """4 cm of white position noise, 0.03 rad of heading noise, driving at 0.5 m/s with the drive
    really 0.05 m/s slower than commanded: the filtered lateral error is under half the
    measurement's, and the speed error biases it by less than the noise."""
    noise = PoseNoise(position_std_m=0.04, yaw_std_rad=0.03)
    pose_filter = PoseFilter(noise, TAU_S)
    rng = np.random.default_rng(1)
    true = np.array([0.0, 0.0, 0.3])
    measured_err, filtered_err = [], []
    for _ in range(400):
        true = true + [0.45 * TAU_S * math.cos(true[2]), 0.45 * TAU_S * math.sin(true[2]), 0.0]
        measured = true + rng.normal(size=3) * [0.04, 0.04, 0.03]
        estimate = pose_filter.update(measured, 0.5, 0.0)
        measured_err.append(measured - true)
        filtered_err.append(estimate - true)
    measured_err, filtered_err = np.array(measured_err[50:]), np.array(filtered_err[50:])
    assert np.std(filtered_err[:, :2]) < 0.5 * np.std(measured_err[:, :2])
    assert np.std(filtered_err[:, 2]) < 0.8 * np.std(measured_err[:, 2])
    assert np.linalg.norm(np.mean(filtered_err[:, :2], axis=0)) < 0.04


def test_the_heading_estimate_stays_next_to_the_measurement_across_pi() -> None:
    pose_filter = PoseFilter(PoseNoise(position_std_m=0.02, yaw_std_rad=0.02), TAU_S)
    for k in range(40):
        yaw = math.remainder(math.pi - 0.2 + 0.01 * k, 2 * math.pi)  # crosses +pi -> -pi
        estimate = pose_filter.update(np.array([0.0, 0.0, yaw]), 0.0, 0.1)
        assert abs(math.remainder(estimate[2] - yaw, 2 * math.pi)) < 0.05
        assert abs(estimate[2] - yaw) < 0.05  # next to it, not 2 pi away


def test_pose_noise_is_range_checked_by_name() -> None:
    with pytest.raises(ValueError, match="pose_noise.position_std_m"):
        PoseNoise(position_std_m=-0.1)
