"""The dynamically extended prediction model of husky-cbf, discretised with RK4 over tau.

State z = [x, y, theta, v, omega_cmd, omega] (m, m, rad, m/s, rad/s, rad/s): the pose, the
commanded velocities (what the drive is told, ramping at bounded rates), and the body yaw rate,
which lags the command (first-order, gain K, time constant T; husky-cbf's RobotResponse).
Control a = [dv/dt, d omega_cmd/dt] (m/s^2, rad/s^2), bounded by the drive's limits, so a plan
never asks for a braking or a turn the drive cannot make. The command sent at step k is the
planned (v, omega_cmd) at k + 1.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca

from controllers.husky_cbf.config import RobotResponse

STATE_DIM = 6
CONTROL_DIM = 2


def extended_rhs(z: ca.SX, a: ca.SX, response: RobotResponse) -> ca.SX:
    """dz/dt of the extended unicycle."""
    theta, v, omega_cmd, omega = z[2], z[3], z[4], z[5]
    return ca.vertcat(
        v * ca.cos(theta),
        v * ca.sin(theta),
        omega,
        a[0],
        a[1],
        (response.yaw_gain * omega_cmd - omega) / response.yaw_time_constant_s,
    )


@lru_cache(maxsize=32)
def extended_step(tau_s: float, response: RobotResponse) -> ca.Function:
    """F(z, a) -> z after tau_s with a held (RK4), as a CasADi Function (cached)."""
    z = ca.SX.sym("z", STATE_DIM)
    a = ca.SX.sym("a", CONTROL_DIM)
    k1 = extended_rhs(z, a, response)
    k2 = extended_rhs(z + 0.5 * tau_s * k1, a, response)
    k3 = extended_rhs(z + 0.5 * tau_s * k2, a, response)
    k4 = extended_rhs(z + tau_s * k3, a, response)
    return ca.Function("F_ext", [z, a], [z + (tau_s / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)])
