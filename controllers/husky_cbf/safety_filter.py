"""A safety filter on husky-cbf's command, in the manner of gatekeeper (Agrawal and Panagou) and
backup control barrier functions (Gurriet et al.): a command is sent only if, once it acts, a
backup manoeuvre (braking to a stop under the drive's limits) keeps every body disc clear of
every obstacle until the robot stands; otherwise the backup that keeps the most clearance is sent.

What is checked: from the extended state at the instant the command acts (after the drive's dead
time and the sensing latency, husky-cbf's `z0`), the command is held for one control period and
then the drive brakes (v and omega commanded 0, ramped at its acceleration limits, the body's
yaw rate lagging as the model says) until the robot stands. Along that manoeuvre each body disc
must clear each obstacle: a static one as measured, a mover at constant velocity from its
measurement, its radius grown by half a stated bound on its change of velocity times the squared
time since it was measured (`mover_accel_bound_mps2`: a walker that speeds up, slows down or
turns within that bound stays inside). The alternative, braking now, is checked the same way.

Why braking: a robot that stands cannot be at fault for a contact (passive motion safety, Macek
et al. 2009; Bouraine, Fraichard and Salhi 2012). If the command sent last step passed the check,
braking now is that step's backup continued, so a backup that passed the check exists every step
while the assumptions hold: the drive brakes as modelled, movers keep within the bound, and every
obstacle that matters was measured. What breaks it: a drive that brakes slower than its limits say
(a heavy payload on low friction), a mover that turns harder than the bound (a walker's sudden
turn), and an obstacle first seen inside the stopping distance (stepping out from behind a pillar
with the sensing model on); then the filter sends the backup that keeps the most clearance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.husky_cbf.config import RobotResponse
from controllers.obstacles import Obstacle

#: Integration step of the backup manoeuvre (s).
STEP_S = 0.02
#: Longest backup simulated (s): braking from the drive's top speed takes far less.
MAX_BACKUP_S = 4.0
#: A robot below these speeds (m/s, rad/s) stands.
STANDING_MPS = 0.02
STANDING_RADPS = 0.05


@dataclass(frozen=True)
class FilterVerdict:
    """The command to send, whether it is the filter's backup rather than the NMPC's command, and
    the smallest clearance (m) of the manoeuvre it begins (negative: a predicted contact)."""

    command: np.ndarray
    intervened: bool
    clearance_m: float


class SafetyFilter:
    """Checks a command's backup manoeuvre (see the module docstring) for a body covered by discs
    at `disc_offsets_m` along its axis, of radius `disc_radius_m`."""

    def __init__(
        self,
        response: RobotResponse,
        tau_s: float,
        disc_offsets_m: np.ndarray,
        disc_radius_m: float,
        mover_accel_bound_mps2: float,
        lead_s: float,
    ) -> None:
        self._r = response
        self._tau_s = tau_s
        self._offsets = np.asarray(disc_offsets_m, dtype=float)
        self._disc_radius = disc_radius_m
        self._accel_bound = mover_accel_bound_mps2
        self._lead_s = lead_s  # from the measurement to the instant z0 stands for (s)

    def backup(self, z0: np.ndarray, command: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The manoeuvre from the extended state z0 = [x, y, theta, v, omega_cmd, omega]: `command`
        [v, omega] held for one control period (None: none), then braking until the robot stands.
        Returns its times (s, from z0) and poses (n, 3)."""
        r = self._r
        x, y, th, v, w_cmd, w = (float(c) for c in z0[:6])
        limit_v, limit_w = r.max_linear_accel_mps2 * STEP_S, r.max_angular_accel_radps2 * STEP_S
        hold = 0 if command is None else round(self._tau_s / STEP_S)
        times, poses = [0.0], [(x, y, th)]
        steps = round(MAX_BACKUP_S / STEP_S)
        for k in range(steps):
            target_v, target_w = (command[0], command[1]) if k < hold else (0.0, 0.0)
            v += min(max(target_v - v, -limit_v), limit_v)
            w_cmd += min(max(target_w - w_cmd, -limit_w), limit_w)
            w += STEP_S * (r.yaw_gain * w_cmd - w) / r.yaw_time_constant_s
            th += STEP_S * w
            x += STEP_S * v * math.cos(th)
            y += STEP_S * v * math.sin(th)
            times.append((k + 1) * STEP_S)
            poses.append((x, y, th))
            if k >= hold and abs(v) < STANDING_MPS and abs(w) < STANDING_RADPS:
                break
        return np.array(times), np.array(poses)

    def clearance(self, times_s: np.ndarray, poses: np.ndarray, obstacles: Sequence[Obstacle]) -> float:
        """The smallest clearance (m) of the body discs along a manoeuvre to the obstacles (see
        the module docstring); inf when none can come within the manoeuvre's reach."""
        if not obstacles:
            return math.inf
        data = np.array([(o.x_m, o.y_m, o.vx_mps, o.vy_mps, o.radius_m) for o in obstacles])
        since = self._lead_s + times_s  # time since the measurement (s), (T,)
        speed = np.hypot(data[:, 2], data[:, 3])
        growth = np.where(speed > 0.0, 0.5 * self._accel_bound * since[-1] ** 2, 0.0)
        # only obstacles that can come within the manoeuvre's reach need the full check
        reach = float(np.max(np.hypot(*(poses[:, :2] - poses[0, :2]).T))) + np.max(np.abs(self._offsets))
        start = data[:, 0:2] + data[:, 2:4] * since[0]
        bound = reach + self._disc_radius + data[:, 4] + growth + speed * (since[-1] - since[0])
        near = np.hypot(*(start - poses[0, :2]).T) <= bound
        if not np.any(near):
            return math.inf
        data, speed = data[near], speed[near]
        centres = data[None, :, 0:2] + data[None, :, 2:4] * since[:, None, None]  # (T, M, 2)
        grown = data[None, :, 4] + np.where(
            speed[None, :] > 0.0, 0.5 * self._accel_bound * since[:, None] ** 2, 0.0
        )
        heading = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=1)  # (T, 2)
        discs = poses[:, None, :2] + self._offsets[None, :, None] * heading[:, None, :]  # (T, D, 2)
        gaps = np.linalg.norm(discs[:, :, None, :] - centres[:, None, :, :], axis=3)  # (T, D, M)
        return float(np.min(gaps - self._disc_radius - grown[:, None, :]))

    def filter(self, z0: np.ndarray, command: np.ndarray, obstacles: Sequence[Obstacle]) -> FilterVerdict:
        """The NMPC's `command` if its backup clears every obstacle, else whichever of it and
        braking now keeps the most clearance."""
        kept = self.clearance(*self.backup(z0, command), obstacles)
        if kept >= 0.0:
            return FilterVerdict(np.asarray(command, dtype=float), False, kept)
        braking = self.clearance(*self.backup(z0, None), obstacles)
        if braking > kept:
            return FilterVerdict(np.zeros(2), True, braking)
        return FilterVerdict(np.asarray(command, dtype=float), False, kept)
