"""The drive's dead time as husky-cbf sees it: commands sent that the drive has not acted on yet.

A drive acts on a command some time after it is sent (its dead time, RobotResponse.command_delay_s;
for a Husky a few tenths of a second, assets/husky_a200/grounds/). Planned from the measured pose,
a plan's first command would take effect only after the robot had driven on for that long under
the commands before it, so a plan that stops or turns at the edge of an obstacle's margin would
act late. So each plan starts where the robot will be when its first command takes effect: the
pose and body yaw rate predicted over the dead time under the commands already sent, replayed
through the drive's acceleration limiter as the drive applies them.
"""

from __future__ import annotations

from collections import deque

import casadi as ca
import numpy as np

from controllers.husky_cbf.config import RobotResponse
from controllers.husky_cbf.model import CONTROL_DIM, STATE_DIM, extended_step

#: Samples of the sent-command stream per control step (the prediction's integration step, tau / 10).
SUBSTEPS = 10


class CommandPipe:
    """The commands sent so far as the drive applies them: rate-limited at the drive's acceleration
    limits (m/s^2, rad/s^2), one sample per tau / SUBSTEPS (s), acted on after `delay_s` (rounded
    to a whole sample): the drive's dead time, plus the sensing latency when the pose predicted
    from is that old (HuskyCBFConfig.measurement_delay_s)."""

    def __init__(self, response: RobotResponse, tau_s: float, delay_s: float | None = None) -> None:
        self._h = tau_s / SUBSTEPS
        self._delay = round((response.command_delay_s if delay_s is None else delay_s) / self._h)
        self._step_limit = (
            np.array([response.max_linear_accel_mps2, response.max_angular_accel_radps2]) * self._h
        )
        sample_step = extended_step(self._h, response)
        self._dead_time = _held_samples(sample_step, self._delay)
        self._control_step = _held_samples(sample_step, SUBSTEPS)
        self.reset()

    def reset(self) -> None:
        """At rest, nothing sent."""
        self._stream: deque[np.ndarray] = deque(
            [np.zeros(2)] * (self._delay + SUBSTEPS), maxlen=self._delay + SUBSTEPS
        )

    @property
    def delay_s(self) -> float:
        """The dead time the prediction uses (s): the response's, to a whole sample."""
        return self._delay * self._h

    @property
    def current(self) -> np.ndarray:
        """The limited command [v m/s, omega rad/s] sent last: what the drive acts on once the dead
        time is over, and what the next command ramps from."""
        return self._stream[-1].copy()

    def send(self, command: np.ndarray) -> None:
        """Append one control step of the drive's limiter moving toward `command` [v, omega]."""
        target = np.asarray(command, dtype=float)
        for _ in range(SUBSTEPS):
            last = self._stream[-1]
            self._stream.append(last + np.clip(target - last, -self._step_limit, self._step_limit))

    def _acting(self, count: int, sent_since: int) -> list[np.ndarray]:
        """The commands acting over the first `count` samples after the last control instant,
        `sent_since` samples having been sent since that instant."""
        return [self._stream[-(self._delay - i + sent_since)] for i in range(count)]

    def predict_dead_time(self, pose: np.ndarray, omega_radps: float) -> tuple[np.ndarray, float]:
        """Pose (x m, y m, theta rad) and body yaw rate (rad/s) after the dead time, from `pose` and
        `omega_radps` now, under the commands already sent (call before `send`)."""
        return self._integrate(self._dead_time, pose, omega_radps, self._acting(self._delay, 0))

    def predict_step(self, pose: np.ndarray, omega_radps: float) -> tuple[np.ndarray, float, float]:
        """Over the control step that starts now (call after `send`-ing its command): the pose
        and body yaw rate at its end, and the mean body speed over it (m/s)."""
        acting = self._acting(SUBSTEPS, SUBSTEPS)
        end_pose, end_omega = self._integrate(self._control_step, pose, omega_radps, acting)
        return end_pose, end_omega, float(np.mean([a[0] for a in acting]))

    @staticmethod
    def _integrate(
        samples: ca.Function | None, pose: np.ndarray, omega_radps: float, acting: list[np.ndarray]
    ) -> tuple[np.ndarray, float]:
        """The prediction model (model.py) with each sample's command held over the sample, in one
        call of `samples` (_held_samples of len(acting); None for no sample)."""
        z = np.array([*np.asarray(pose, dtype=float)[:3], 0.0, 0.0, omega_radps])
        if samples is not None:
            states = np.asarray(samples(z, np.column_stack(acting)), dtype=float)
            z = states[:, -1]
        return z[:3], float(z[5])


def _held_samples(sample_step: ca.Function, count: int) -> ca.Function | None:
    """F(z, U) -> the states after each of `count` samples (STATE_DIM, count), the k-th sample
    integrating `sample_step` from the state before it with its command set to U[:, k] and no
    acceleration; None for count 0."""
    if count == 0:
        return None
    z = ca.MX.sym("z", STATE_DIM)
    u = ca.MX.sym("u", CONTROL_DIM)
    held = sample_step(ca.vertcat(z[:3], u, z[5:]), ca.DM.zeros(CONTROL_DIM))
    return ca.Function("held_sample", [z, u], [held]).mapaccum(count)
