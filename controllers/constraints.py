"""Obstacle (safety) constraints over the horizon, one per obstacle and predicted step.

Every function returns expressions g that the OCP requires to be >= 0. `position` is the robot's
predicted (2, N+1) xy track, `centre` the obstacle's predicted (2, N+1) track, `r_sum` the sum of
robot and obstacle radii (m). Expressions work for CasADi SX and MX alike.

- bt:        L(k) = ||p(k) - o(k)|| - r_sum >= 0 for k = 1..N (paper eq. 17; k = 0 is the
             measured state, which no decision can change).
- cbf:       B(k+1) - (1 - gamma) B(k) >= 0 for k = 0..N-1, B = ||p - o||^2 - r_sum^2 (eq. 15).
- relax-cbf: B(k+1) - s_h(k) (1 - gamma) B(k) >= 0 with s_h(k) in [0, 1] a decision variable.
             Both bounds are ours; the paper leaves s_h free. With s_h < 0 the constraint no
             longer implies B(k+1) >= 0 from B(k) >= 0. With s_h > 1 it is stricter than CBF
             while B(k) > 0 (never optimal, it only costs), but once B(k) < 0 (a measured state a
             hair inside the set, e.g. at IPOPT's 1e-9 tolerance while hugging an obstacle) a
             large s_h makes the right side arbitrarily negative: a kinematic closed loop of ours
             used s_h ~ 9 to drive straight into the obstacle. With s_h <= 1 a state inside the
             set must recover at least at the CBF rate, B(k+1) >= (1 - gamma) B(k).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca

from controllers.config import SafetyConstraint

Expr = ca.SX | ca.MX


def barrier(position: Expr, centre: Expr, r_sum: Expr) -> Expr:
    """B = squared centre distance minus squared radii sum (m^2), per column."""
    diff = position - centre
    return diff[0, :] ** 2 + diff[1, :] ** 2 - r_sum**2


def euclidean_clearance(position: Expr, centre: Expr, r_sum: Expr) -> Expr:
    """L = centre distance minus radii sum (m), per column."""
    diff = position - centre
    return ca.sqrt(diff[0, :] ** 2 + diff[1, :] ** 2) - r_sum


def bt_constraints(position: Expr, centre: Expr, r_sum: Expr, gamma: float, s_h: Expr) -> Expr:
    """Bug-type (BT): Euclidean clearance >= 0 at predicted steps k = 1..N."""
    return euclidean_clearance(position[:, 1:], centre[:, 1:], r_sum)


def cbf_constraints(position: Expr, centre: Expr, r_sum: Expr, gamma: float, s_h: Expr) -> Expr:
    """Discrete CBF: B(k+1) >= (1 - gamma) B(k), k = 0..N-1."""
    b = barrier(position, centre, r_sum)
    return b[1:] - (1.0 - gamma) * b[:-1]


def relax_cbf_constraints(position: Expr, centre: Expr, r_sum: Expr, gamma: float, s_h: Expr) -> Expr:
    """Relaxed-decay CBF: B(k+1) >= s_h(k) (1 - gamma) B(k), k = 0..N-1."""
    b = barrier(position, centre, r_sum)
    return b[1:] - s_h.T * (1.0 - gamma) * b[:-1]


SafetyBuilder = Callable[[Expr, Expr, Expr, float, Expr], Expr]

#: The obstacle constraint for each variant; `none` has no obstacle constraint.
SAFETY_BUILDERS: dict[SafetyConstraint, SafetyBuilder | None] = {
    "none": None,
    "bt": bt_constraints,
    "cbf": cbf_constraints,
    "relax-cbf": relax_cbf_constraints,
}
