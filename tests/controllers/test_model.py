"""RK4 unicycle model against the closed-form solution, and angle wrapping."""

import math

import numpy as np
import pytest

from controllers.model import step, wrap_angle


def exact_unicycle(state: np.ndarray, v: float, omega: float, t: float) -> np.ndarray:
    """Closed-form unicycle motion for constant (v, omega): a straight line or a circular arc."""
    x, y, th = state
    if abs(omega) < 1e-12:
        return np.array([x + v * t * math.cos(th), y + v * t * math.sin(th), th])
    th1 = th + omega * t
    return np.array(
        [x + v / omega * (math.sin(th1) - math.sin(th)), y - v / omega * (math.cos(th1) - math.cos(th)), th1]
    )


@pytest.mark.parametrize(
    "v,omega", [(1.0, 0.0), (0.5, math.pi / 4), (-0.7, -0.3), (0.0, 0.6), (1.0, -math.pi / 4)]
)
@pytest.mark.parametrize("tau", [0.1, 0.2])
def test_rk4_matches_closed_form(v: float, omega: float, tau: float) -> None:
    state = np.array([0.3, -1.2, 2.5])
    x = state.copy()
    steps = 50
    for _ in range(steps):
        x = step(x, np.array([v, omega]), tau)
    exact = exact_unicycle(state, v, omega, steps * tau)
    # RK4 local error is O(tau^5); over 5-10 s of arc the global error stays far below 1e-5 m.
    assert np.max(np.abs(x - exact)) < 1e-5


def test_rk4_single_step_is_fourth_order() -> None:
    state = np.array([0.0, 0.0, 0.4])
    errors = [
        np.linalg.norm(step(state, np.array([1.0, 1.0]), tau) - exact_unicycle(state, 1.0, 1.0, tau))
        for tau in (0.2, 0.1)
    ]
    # Halving tau divides the local error by ~2^5 = 32.
    assert errors[0] / errors[1] > 20


@pytest.mark.parametrize(
    "angle,expected",
    [
        (0.0, 0.0),
        (math.pi, math.pi),
        (-math.pi, math.pi),
        (3 * math.pi, math.pi),
        (2 * math.pi + 0.1, 0.1),
        (-0.5, -0.5),
        (-2 * math.pi - 0.2, -0.2),
    ],
)
def test_wrap_angle_to_half_open_interval(angle: float, expected: float) -> None:
    assert wrap_angle(angle) == pytest.approx(expected, abs=1e-12)


def test_the_extended_model_stays_stable_for_a_robot_whose_yaw_follows_within_a_step() -> None:
    """A yaw lag ten times shorter than tau (a light robot on unfitted tyres) in one RK4 step
    diverged, and the structured solver then never returned; in substeps the body yaw rate settles
    on gain x command. The Husky's lag (0.11 s at tau <= 0.2 s) keeps its single step."""
    from controllers.husky_cbf.config import RobotResponse
    from controllers.husky_cbf.model import extended_step, rk4_substeps

    fast = RobotResponse(20.0, 25.0, 1.0, 0.01, 0.19, 2.0)
    assert rk4_substeps(0.1, fast) == 5
    assert rk4_substeps(0.2, RobotResponse(3.0, 6.0, 0.85, 0.11, 0.53, 1.0)) == 1
    step = extended_step(0.1, fast)
    z = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])  # commanded 1 rad/s, body at rest
    for _ in range(10):
        z = np.asarray(step(z, np.zeros(2))).ravel()
    assert z[5] == pytest.approx(1.0, abs=1e-6) and np.all(np.isfinite(z))
