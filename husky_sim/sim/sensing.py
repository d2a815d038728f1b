"""What the controller is told: the Husky's pose and the obstacle circles, from the simulator,
with optional seeded Gaussian noise, a latency of k control steps, and a scale error on the
obstacles' velocities (an estimator that over- or under-reads how fast they move)."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from controllers import Obstacle


@dataclass(frozen=True)
class SensingConfig:
    """Noise standard deviations, latency (control steps) and the factor (dimensionless) by which
    the reported obstacle velocities differ from the true ones (1: exact, 0: reported static)."""

    pose_xy_std_m: float = 0.0
    pose_yaw_std_rad: float = 0.0
    obstacle_xy_std_m: float = 0.0
    latency_steps: int = 0
    obstacle_velocity_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("pose_xy_std_m", "pose_yaw_std_rad", "obstacle_xy_std_m", "obstacle_velocity_scale"):
            value = getattr(self, name)
            if not (value >= 0 and math.isfinite(value)):
                raise ValueError(f"sensing.{name}: must be >= 0, got {value}")
        if self.latency_steps < 0:
            raise ValueError(f"sensing.latency_steps: must be >= 0, got {self.latency_steps}")


@dataclass(frozen=True)
class Measurement:
    pose: np.ndarray  # [x, y, yaw] (m, m, rad)
    obstacles: list[Obstacle]


class Sensor:
    """Seeded noisy, delayed measurements; the same seed gives the same noise sequence."""

    def __init__(self, config: SensingConfig, seed: int) -> None:
        self.config = config
        self._rng = np.random.default_rng(seed)
        self._queue: deque[Measurement] = deque()

    def measure(self, pose: np.ndarray, obstacles: Sequence[Obstacle]) -> Measurement:
        """Record the true state now; return the (noisy) measurement taken latency_steps ago."""
        cfg = self.config
        noisy_pose = pose + self._rng.normal(0.0, 1.0, 3) * [
            cfg.pose_xy_std_m,
            cfg.pose_xy_std_m,
            cfg.pose_yaw_std_rad,
        ]
        offsets = self._rng.normal(0.0, cfg.obstacle_xy_std_m, (len(obstacles), 2)) if obstacles else []
        scale = cfg.obstacle_velocity_scale
        noisy_obstacles = [
            replace(
                o,
                x_m=o.x_m + float(d[0]),
                y_m=o.y_m + float(d[1]),
                vx_mps=o.vx_mps * scale,
                vy_mps=o.vy_mps * scale,
            )
            for o, d in zip(obstacles, offsets, strict=True)
        ]
        self._queue.append(Measurement(noisy_pose, noisy_obstacles))
        while len(self._queue) > cfg.latency_steps + 1:
            self._queue.popleft()
        return self._queue[0]
