"""Unicycle kinematics xi = [x, y, theta] (m, m, rad), u = [v, omega] (m/s, rad/s), and RK4 over tau.

The same CasADi expressions serve the OCP (symbolic) and the kinematic plant (numeric), so the
prediction model and the kinematic simulation can never drift apart.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

STATE_DIM = 3
CONTROL_DIM = 2


def unicycle_rhs(state: ca.SX | ca.MX, control: ca.SX | ca.MX) -> ca.SX | ca.MX:
    """Continuous-time unicycle: d/dt [x, y, theta] = [v cos theta, v sin theta, omega]."""
    theta = state[2]
    return ca.vertcat(control[0] * ca.cos(theta), control[0] * ca.sin(theta), control[1])


def rk4_step(state: ca.SX | ca.MX, control: ca.SX | ca.MX, tau_s: float) -> ca.SX | ca.MX:
    """One classic Runge-Kutta-4 step over tau_s (s) with the control held constant."""
    k1 = unicycle_rhs(state, control)
    k2 = unicycle_rhs(state + 0.5 * tau_s * k1, control)
    k3 = unicycle_rhs(state + 0.5 * tau_s * k2, control)
    k4 = unicycle_rhs(state + tau_s * k3, control)
    return state + (tau_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


@lru_cache(maxsize=32)
def discrete_dynamics(tau_s: float) -> ca.Function:
    """F(xi, u) -> xi_next as a CasADi Function (cached per tau_s)."""
    x = ca.SX.sym("x", STATE_DIM)
    u = ca.SX.sym("u", CONTROL_DIM)
    return ca.Function("F", [x, u], [rk4_step(x, u, tau_s)], ["x", "u"], ["x_next"])


def step(state: np.ndarray, control: np.ndarray, tau_s: float) -> np.ndarray:
    """Numeric RK4 step of the kinematic model (used as the kinematic plant)."""
    return np.asarray(discrete_dynamics(float(tau_s))(state, control), dtype=float).reshape(-1)


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Wrap an angle (rad) to (-pi, pi]."""
    wrapped = np.mod(np.asarray(angle, dtype=float) + math.pi, 2.0 * math.pi) - math.pi
    wrapped = np.where(wrapped == -math.pi, math.pi, wrapped)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def wrap_angle_sym(angle: ca.SX | ca.MX) -> ca.SX | ca.MX:
    """Symbolic heading-error wrap to (-pi, pi] via atan2(sin a, cos a): unit slope everywhere,
    one jump at +-pi (a robot facing exactly opposite to the reference heading, where turning
    either way is equally good), and invariant to 2 pi k in the state or the reference, so a
    heading that grows without bound (circle tracking) costs the same as its wrapped value."""
    return ca.atan2(ca.sin(angle), ca.cos(angle))
