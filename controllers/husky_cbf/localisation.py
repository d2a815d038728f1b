"""A steady-state Kalman filter on the measured pose, for husky-cbf's set-point approach decisions.

The set-point approach (behaviours.approach.SetPointApproach) switches on centimetres: it docks
when the robot is a few centimetres off the goal's line and leaves once aligned within fewer. A
localisation with centimetres of white noise would flip those decisions from step to step. The
filter predicts the pose from the commands the drive is applying (unicycle over tau) and corrects
it with the measurement at a constant gain per coordinate, the steady state of a scalar Kalman
filter for a random walk (process noise: the drive's speed and yaw-rate error over tau). With no
noise declared, the measurement is returned unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from controllers.husky_cbf.config import PoseNoise


def steady_state_gain(process_std: float, measurement_std: float) -> float:
    """The steady-state Kalman gain in [0, 1] of a random walk with process noise `process_std`
    per step observed with white noise `measurement_std` (same unit): 1 without measurement
    noise (the measurement itself), 0 without process noise (the prediction alone)."""
    if measurement_std <= 0.0:
        return 1.0
    if process_std <= 0.0:
        return 0.0
    q, r = process_std**2, measurement_std**2
    return (-q + math.sqrt(q * q + 4.0 * q * r)) / (2.0 * r)


class PoseFilter:
    """Filtered pose [x m, y m, yaw rad] from noisy measurements and the applied commands."""

    def __init__(self, noise: PoseNoise, tau_s: float) -> None:
        self.noise = noise
        self.tau_s = tau_s
        self.position_gain = steady_state_gain(noise.speed_error_mps * tau_s, noise.position_std_m)
        self.yaw_gain = steady_state_gain(noise.yaw_rate_error_radps * tau_s, noise.yaw_std_rad)
        self.reset()

    @property
    def exact(self) -> bool:
        """No noise declared: `update` returns the measurement itself."""
        return self.noise.position_std_m == 0.0 and self.noise.yaw_std_rad == 0.0

    def reset(self) -> None:
        self._pose: np.ndarray | None = None

    def update(self, measured: np.ndarray, speed_mps: float, yaw_rate_radps: float) -> np.ndarray:
        """The filtered pose now, given this step's measurement and the body speed (m/s) and yaw
        rate (rad/s) expected over the step that just ended."""
        measured = np.asarray(measured, dtype=float)
        if self.exact or self._pose is None:
            self._pose = measured.copy()
            return self._pose.copy()
        x, y, yaw = self._pose
        mid = yaw + 0.5 * yaw_rate_radps * self.tau_s
        predicted = np.array(
            [
                x + speed_mps * self.tau_s * math.cos(mid),
                y + speed_mps * self.tau_s * math.sin(mid),
                yaw + yaw_rate_radps * self.tau_s,
            ]
        )
        innovation = measured - predicted
        innovation[2] = math.remainder(float(innovation[2]), 2 * math.pi)
        gains = np.array([self.position_gain, self.position_gain, self.yaw_gain])
        pose = predicted + gains * innovation
        pose[2] = measured[2] + math.remainder(float(pose[2] - measured[2]), 2 * math.pi)
        self._pose = pose
        return pose.copy()
