"""References for the NMPC: a fixed set-point or a time-varying trajectory with feed-forward.

A reference is sampled along the horizon as xi_r(k) at t + k tau (k = 0..N) and u_r(k) for
k = 0..N-1. For a trajectory, theta_r, v_r and omega_r come from the position's derivatives:
theta_r = atan2(dy, dx), v_r = |p'|, omega_r = (dx ddy - dy ddx) / |p'|^2.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


class Reference(ABC):
    """Anything the NMPC can track: returns reference states and feed-forward inputs."""

    @abstractmethod
    def sample(self, t_s: float, tau_s: float, horizon: int) -> tuple[np.ndarray, np.ndarray]:
        """Return xi_r with shape (N+1, 3) and u_r with shape (N, 2) for times t + k tau."""

    def state_at(self, t_s: float) -> np.ndarray:
        """Reference state [x, y, theta] at time t_s (s)."""
        return self.sample(t_s, 1.0, 1)[0][0]

    def states_at(self, times_s: np.ndarray) -> np.ndarray:
        """Reference states [x, y, theta], shape (len(times_s), 3), each exactly `state_at`'s, the
        first state of `sample` (a whole path at once: a trace or a recording draws it)."""
        return np.array([self.state_at(float(t)) for t in np.asarray(times_s, dtype=float)]).reshape(-1, 3)


@dataclass(frozen=True)
class SetPoint(Reference):
    """Point stabilisation target (m, m, rad); u_r = 0."""

    x_m: float
    y_m: float
    theta_rad: float

    def sample(self, t_s: float, tau_s: float, horizon: int) -> tuple[np.ndarray, np.ndarray]:
        states = np.tile([self.x_m, self.y_m, self.theta_rad], (horizon + 1, 1)).astype(float)
        return states, np.zeros((horizon, 2))


class Trajectory(Reference):
    """A planar path p(t) with first and second derivatives; heading and inputs derived from them."""

    @abstractmethod
    def position(self, t: np.ndarray) -> np.ndarray:
        """p(t), shape (len(t), 2), in m."""

    @abstractmethod
    def velocity(self, t: np.ndarray) -> np.ndarray:
        """dp/dt, shape (len(t), 2), in m/s."""

    @abstractmethod
    def acceleration(self, t: np.ndarray) -> np.ndarray:
        """d2p/dt2, shape (len(t), 2), in m/s^2."""

    def state_at(self, t_s: float) -> np.ndarray:
        return self.states_at(np.array([t_s]))[0]

    def states_at(self, times_s: np.ndarray) -> np.ndarray:
        # the heading is that of sample()'s first state, which unwrapping leaves as atan2 gives it
        times = np.asarray(times_s, dtype=float).reshape(-1)
        vel = self.velocity(times)
        return np.column_stack([self.position(times), np.arctan2(vel[:, 1], vel[:, 0])])

    def sample(self, t_s: float, tau_s: float, horizon: int) -> tuple[np.ndarray, np.ndarray]:
        times = t_s + tau_s * np.arange(horizon + 1)
        pos, vel, acc = self.position(times), self.velocity(times), self.acceleration(times)
        speed_sq = np.sum(vel**2, axis=1)
        heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
        speed = np.sqrt(speed_sq)
        with np.errstate(divide="ignore", invalid="ignore"):
            omega = np.where(
                speed_sq > 1e-12, (vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]) / speed_sq, 0.0
            )
        states = np.column_stack([pos, heading])
        controls = np.column_stack([speed, omega])[:horizon]
        return states, controls


@dataclass(frozen=True)
class CircleTrajectory(Trajectory):
    """p(t) = c + R [cos(w t + phi), sin(w t + phi)]; the paper's circles have c = 0, phi = 0."""

    radius_m: float
    angular_rate_radps: float
    center_x_m: float = 0.0
    center_y_m: float = 0.0
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        if not self.radius_m > 0:
            raise ValueError(f"radius_m: must be > 0 m, got {self.radius_m}")
        if self.angular_rate_radps == 0 or not math.isfinite(self.angular_rate_radps):
            raise ValueError(
                f"angular_rate_radps: must be non-zero and finite, got {self.angular_rate_radps}"
            )

    def _angle(self, t: np.ndarray) -> np.ndarray:
        return self.angular_rate_radps * np.asarray(t, dtype=float) + self.phase_rad

    def position(self, t: np.ndarray) -> np.ndarray:
        a = self._angle(t)
        return np.column_stack(
            [
                self.center_x_m + self.radius_m * np.cos(a),
                self.center_y_m + self.radius_m * np.sin(a),
            ]
        )

    def velocity(self, t: np.ndarray) -> np.ndarray:
        a, w = self._angle(t), self.angular_rate_radps
        return self.radius_m * w * np.column_stack([-np.sin(a), np.cos(a)])

    def acceleration(self, t: np.ndarray) -> np.ndarray:
        a, w = self._angle(t), self.angular_rate_radps
        return -self.radius_m * w**2 * np.column_stack([np.cos(a), np.sin(a)])
