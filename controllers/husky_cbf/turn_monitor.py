"""How well the robot turns compared with its yaw model: a loaded skid-steer may not.

A skid-steer with a payload, on grippy ground, can turn at a small fraction of the arc its
identified yaw lag predicts: an NMPC planning the turn round an obstacle that its model promises
keeps its speed until braking is too late (and a skid-steer that scrubs through a hard turn also
brakes at a fraction of its limit). The monitor compares the heading change measured over the last
window with the one the model predicted; while the ratio is low, the controller caps the speed
(controller.WEAK_TURN_*), so that a robot that cannot steer round an obstacle stops before it.
"""

from __future__ import annotations

import math
from collections import deque


class TurnMonitor:
    """Ratio of measured to model-predicted heading change (rad/rad) over a sliding window of
    control steps, judged only when the prediction turned enough to tell (min_turn_rad)."""

    def __init__(self, window_steps: int, min_turn_rad: float) -> None:
        self.min_turn_rad = min_turn_rad
        self._steps: deque[tuple[float, float]] = deque(maxlen=max(window_steps, 1))
        self.ratio = 1.0  # the last judged ratio (1: as the model predicts)

    def reset(self) -> None:
        self._steps.clear()
        self.ratio = 1.0

    def update(self, predicted_rad: float, measured_rad: float) -> float:
        """Add one step's predicted and measured heading change (rad); return the ratio, held
        while the window's predicted turn is below min_turn_rad (then noise would decide it)."""
        if math.isfinite(predicted_rad) and math.isfinite(measured_rad):
            self._steps.append((predicted_rad, measured_rad))
        predicted = sum(p for p, _ in self._steps)
        if abs(predicted) >= self.min_turn_rad:
            measured = sum(m for _, m in self._steps)
            self.ratio = min(max(measured / predicted, 0.0), 1.0)
        return self.ratio
