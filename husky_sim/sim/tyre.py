"""Tyre-ground contact of the Husky's wheels: a slip-dependent tyre force, applied by us, in place
of PyBullet's Coulomb friction (which the wheels then do not get: their contact friction is 0, so
the engine gives them only the normal force).

Why: a real Husky turns at about 0.52-0.54 of the yaw rate its wheels imply, the same in place and
on arcs (husky_sim/calibration; the DRIVE recordings in assets/husky_a200/drive_recordings). A
Coulomb contact solved by the engine gave 0.22-0.44 depending on the command. A tyre whose force
grows with the slip velocity before it saturates fixes the skid-steer's centres of rotation
independently of the command: with a linear contact the ratio is b^2 / (b^2 + k a^2) (a half the
wheelbase, b half the track, k the lateral / longitudinal stiffness ratio), whatever the command.

The force on a wheel with normal load N (N) and slip velocity s (m/s) at its contact patch, split
into s_x along the wheel and s_y along the axle (s_x counted with the rolling radius r_eff):

    sigma = (s_x, k s_y) / slip_speed_mps,   F = -mu N sigma / (1 + |sigma|^4)^(1/4)

linear for small slip (stiffness mu N / slip_speed_mps, N s/m; within 2 % of it up to half the slip
speed), saturating isotropically at mu N (0.84 mu N at the slip speed). A tanh saturation was tried
first: it bends away from linear early (0.76 mu N at the slip speed), so a tyre stiff enough for the
recorded motor currents saturated in place but not on wide arcs, whose yaw ratio then read 0.59
against the recording's 0.52.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from husky_sim.sim.geometry import RobotGeometry


@dataclass(frozen=True)
class TyreContact:
    """Parameters of the tyre force on one ground (fitted by `husky-sim calibrate`)."""

    friction: float = 1.0  # mu: peak force / normal load (dimensionless)
    slip_speed_mps: float = 0.3  # slip speed (m/s) where the linear force would reach mu N
    lateral_stiffness_ratio: float = 1.0  # k: lateral / longitudinal slip stiffness
    rolling_radius_scale: float = 1.0  # effective rolling radius / URDF wheel radius

    def __post_init__(self) -> None:
        bounds = {
            "friction": (0.01, 5.0),
            "slip_speed_mps": (0.01, 5.0),
            "lateral_stiffness_ratio": (0.05, 20.0),
            "rolling_radius_scale": (0.5, 2.0),
        }
        for name, (lo, hi) in bounds.items():
            value = getattr(self, name)
            real = isinstance(value, int | float) and not isinstance(value, bool)
            if not (real and math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"ground.tyre.{name}: must be in [{lo:g}, {hi:g}], got {value}")


def stiffness_ratio_for_yaw_ratio(
    yaw_ratio: float, geometry: RobotGeometry, rolling_radius_scale: float
) -> float:
    """The lateral / longitudinal stiffness k whose linear contact gives the steady yaw ratio
    `yaw_ratio` = s b^2 / (b^2 + k a^2) (a half the wheelbase, b half the track, s the rolling-radius
    scale: the ratio is taken against the URDF radius). Exact while the tyres do not saturate."""
    if not 0.0 < yaw_ratio < rolling_radius_scale:
        raise ValueError(f"yaw_ratio: must be in (0, {rolling_radius_scale:g}), got {yaw_ratio}")
    return (rolling_radius_scale / yaw_ratio - 1.0) * (geometry.track_width_m / geometry.wheelbase_m) ** 2


def tyre_force(
    contact: TyreContact, normal_n: float, slip_long_mps: float, slip_lat_mps: float
) -> tuple[float, float]:
    """Longitudinal and lateral tyre force (N) of one wheel, from its normal load (N) and its slip
    velocities (m/s) along the wheel and along the axle. Plain floats: it runs for every wheel at
    every physics step."""
    sx = slip_long_mps / contact.slip_speed_mps
    sy = contact.lateral_stiffness_ratio * slip_lat_mps / contact.slip_speed_mps
    norm2 = sx * sx + sy * sy
    scale = (1.0 + norm2 * norm2) ** -0.25
    magnitude = contact.friction * max(normal_n, 0.0) * scale
    return -magnitude * sx, -magnitude * sy
