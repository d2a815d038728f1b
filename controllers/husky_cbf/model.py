"""The dynamically extended prediction model of husky-cbf, discretised with RK4 over tau.

State z = [x, y, theta, v, omega_cmd, omega] (m, m, rad, m/s, rad/s, rad/s): the pose, the
commanded velocities (what the drive is told, ramping at bounded rates), and the body yaw rate,
which lags the command (first-order, gain K, time constant T; husky-cbf's RobotResponse).
Control a = [dv/dt, d omega_cmd/dt] (m/s^2, rad/s^2), bounded by the drive's limits, so a plan
never asks for a braking or a turn the drive cannot make. The command sent at step k is the
planned (v, omega_cmd) at k + 1.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca

from controllers.husky_cbf.config import RobotResponse

STATE_DIM = 6
CONTROL_DIM = 2


#: Longest RK4 step of the extended model, in yaw time constants (explicit RK4 is stable on a
#: first-order lag up to about 2.8).
MAX_STEP_PER_LAG = 2.0


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


def rk4_substeps(tau_s: float, response: RobotResponse) -> int:
    """RK4 steps per tau_s (s): enough that each is at most MAX_STEP_PER_LAG yaw time constants.
    Explicit RK4 on the lag d(omega)/dt = -omega / T diverges once a step exceeds about 2.8 T, so a
    robot whose yaw follows within a fraction of tau needs several steps per tau; a Husky
    (T about 0.1 s, tau <= 0.2 s) takes one."""
    return max(1, math.ceil(tau_s / (MAX_STEP_PER_LAG * response.yaw_time_constant_s) - 1e-9))


@lru_cache(maxsize=32)
def extended_step(tau_s: float, response: RobotResponse) -> ca.Function:
    """F(z, a) -> z after tau_s with a held (RK4, in rk4_substeps steps), as a CasADi Function."""
    z0 = ca.SX.sym("z", STATE_DIM)
    a = ca.SX.sym("a", CONTROL_DIM)
    steps = rk4_substeps(tau_s, response)
    h, z = tau_s / steps, z0
    for _ in range(steps):
        k1 = extended_rhs(z, a, response)
        k2 = extended_rhs(z + 0.5 * h * k1, a, response)
        k3 = extended_rhs(z + 0.5 * h * k2, a, response)
        k4 = extended_rhs(z + h * k3, a, response)
        z = z + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F_ext", [z0, a], [z])
