"""A safety filter on husky-cbf's commands, in the manner of gatekeeper (Agrawal and Panagou) and
backup control barrier functions (Gurriet et al.): the robot always holds a committed trajectory
that ends standing and was checked clear of every obstacle; a new plan replaces it only if it
passes the same check.

The check. From the extended state at the instant the next command acts (after the drive's dead
time and the sensing latency, husky-cbf's `z0`), a candidate holds each of its commands for one
control period, then the drive brakes (v and omega commanded 0, ramped at its acceleration limits,
the body's yaw rate lagging as the model says) until the robot stands. Along it each body disc
must clear each obstacle: a static one as measured; a mover at constant velocity from its
measurement, its radius grown by half a stated bound on its change of velocity times the squared
time since it was measured (`mover_accel_bound_mps2`: a walker that speeds up, slows down or turns
within that bound stays inside its circle). The discs are wider than the body, so a robot may
stand closer to a static obstacle than they allow (pushed, or braked late); that obstacle is
checked shrunk by the discs' overlap where the candidate starts: no disc may go deeper into it,
and the robot may leave it (else no candidate would ever pass again).

The choice, each step. Candidates are the NMPC's plan cut after k of its commands, then braking,
for k = N down to 1; the first that passes the check and ends out of every mover's way (below)
becomes the committed trajectory; if each that passes ends in a way, a way out (below), else the
one of them, or braking now, whose stand a mover reaches last (the most time for the next plan to
find a way out, rather than a plan that drives deeper into a mover's way). If none passes, the
committed trajectory is kept, one command further on. If that fails too (an assumption broke),
the filter sends whichever braking manoeuvre keeps the most clearance: the committed trajectory,
or braking now, straight or along the arc now commanded.

Standing in a mover's way. Braking is no refuge where a mover's constant-velocity track reaches
the robot standing within the threat horizon (husky-cbf's yielding horizon: the horizon over
which it steps aside from movers). There, if no cut passes the check, the filter looks for a
way out: a manoeuvre that passes the same full check and ends out of every mover's way, among
the committed trajectory, braking, and the evasive backups (a command at the drive's full speed
forwards or backwards, straight or on an arc, held for a few periods, then braking: Gurriet et
al.'s set of backups); the committed one if it is a way out (a way out taken goes on), else the
one that keeps the most clearance. The same holds, over the shorter trap horizon (how soon a
standing robot could leave a mover's track), where every cut that passes ends in a mover's way.
A mover whose track meets a static obstacle within the threat horizon turns before it, and no
prediction says where: its track counts only for a fallback and where a cut passes but one short
of the whole plan (the robot is about to brake where that cut ends). A way out is a checked
trajectory like any other. If none exists, the robot brakes as above all the same: no command is
sent that no check passed, since a robot moving on an unchecked manoeuvre may be at fault for a
contact, and a robot standing is not.

Why this bounds the robot's fault. A robot that stands cannot be at fault for a contact (passive
motion safety: Macek et al. 2009; Bouraine, Fraichard and Salhi 2012), and every committed
trajectory ends standing. A committed trajectory stays clear one step later: the robot is where
the drive model put it, and a mover measured again is inside its old grown circle, since a change
of velocity of at most a over tau moves a mover at most a tau^2 / 2 off its old prediction and its
new velocity at most a tau off the old, which is exactly what the old circle's larger growth
covers. So while the assumptions hold, a checked trajectory exists every step. What breaks them: a
drive that brakes slower than its limits say (a heavy payload on low friction), a mover that
changes velocity faster than the bound, velocity estimates off by more than the bound allows, and
an obstacle first seen inside the stopping distance (the sensing model's occlusion and range).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from controllers.husky_cbf.config import RobotResponse
from controllers.husky_cbf.movers import free_run_m
from controllers.obstacles import Obstacle

#: Integration step of a checked manoeuvre (s): a disc moves at most 2 cm between checks at 1 m/s.
STEP_S = 0.02
#: Longest braking simulated (s): braking from the drive's top speed takes far less.
MAX_BRAKING_S = 4.0
#: A robot below these speeds (m/s, rad/s) stands.
STANDING_MPS = 0.02
STANDING_RADPS = 0.05
#: Evasive backups: a command at the drive's full speed forwards and backwards, times these
#: fractions of the commanded yaw-rate bound (straight, and arcs either way) ...
EVASION_TURNS = (-0.5, 0.0, 0.5)
#: ... held for these many seconds, then braking: from a short dash to a metre clear of a track
EVASION_HOLDS_S = (0.3, 0.6, 1.0)


@dataclass(frozen=True)
class FilterVerdict:
    """The command to send; whether the filter intervened (the command is not the plan's first:
    it is the committed trajectory's, or a braking or evasive backup's); and the smallest
    clearance (m) of the trajectory it begins, as checked (negative: a predicted contact)."""

    command: np.ndarray
    intervened: bool
    clearance_m: float


class SafetyFilter:
    """Holds and checks committed trajectories (see the module docstring) for a body covered by
    discs at `disc_offsets_m` along its axis, of radius `disc_radius_m`."""

    def __init__(
        self,
        response: RobotResponse,
        tau_s: float,
        disc_offsets_m: np.ndarray,
        disc_radius_m: float,
        mover_accel_bound_mps2: float,
        lead_s: float,
        threat_horizon_s: float,
        omega_cmd_max_radps: float = 0.0,
        trap_horizon_s: float = 0.0,
    ) -> None:
        self._r = response
        self._tau_s = tau_s
        self._hold_steps = max(round(tau_s / STEP_S), 1)
        self._offsets = np.asarray(disc_offsets_m, dtype=float)
        self._disc_radius = disc_radius_m
        self._accel_bound = mover_accel_bound_mps2
        self._lead_s = lead_s  # from the measurement to the instant z0 stands for (s)
        self._threat_s = threat_horizon_s  # how far ahead a standing robot looks for movers (s)
        self._evasions = self._evasive_backups(omega_cmd_max_radps)
        #: a plan cut short whose stand a mover reaches this soon (s) gives way to a way out, if
        #: one exists: from that stand the robot could not leave in time
        self._trap_s = trap_horizon_s
        self.reset()

    def reset(self) -> None:
        """Commit braking now: at the start, and whenever the loop sent a braking command unchecked
        (a failed solve)."""
        self._committed = np.zeros((0, 2))

    def manoeuvre(self, z0: np.ndarray, commands: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The manoeuvre from the extended state z0 = [x, y, theta, v, omega_cmd, omega]: each of
        `commands` (k, 2) [v, omega] held one control period (None or empty: none), then braking
        until the robot stands. Returns its times (s, from z0) and poses (n, 3)."""
        r = self._r
        plan = np.zeros((0, 2)) if commands is None else np.asarray(commands, dtype=float).reshape(-1, 2)
        x, y, th, v, w_cmd, w = (float(c) for c in z0[:6])
        limit_v, limit_w = r.max_linear_accel_mps2 * STEP_S, r.max_angular_accel_radps2 * STEP_S
        held = len(plan) * self._hold_steps
        times, poses = [0.0], [(x, y, th)]
        for k in range(held + round(MAX_BRAKING_S / STEP_S)):
            target_v, target_w = plan[k // self._hold_steps] if k < held else (0.0, 0.0)
            v += min(max(target_v - v, -limit_v), limit_v)
            w_cmd += min(max(target_w - w_cmd, -limit_w), limit_w)
            w += STEP_S * (r.yaw_gain * w_cmd - w) / r.yaw_time_constant_s
            th += STEP_S * w
            x += STEP_S * v * math.cos(th)
            y += STEP_S * v * math.sin(th)
            times.append((k + 1) * STEP_S)
            poses.append((x, y, th))
            if k >= held and abs(v) < STANDING_MPS and abs(w) < STANDING_RADPS:
                break
        return np.array(times), np.array(poses)

    def _braking(self, z0: np.ndarray) -> list[np.ndarray]:
        """Braking now as command sequences: straight (none), and along the arc commanded now
        (v commanded 0 and the yaw rate held, for the periods braking takes)."""
        periods = max(math.ceil(abs(float(z0[3])) / (self._r.max_linear_accel_mps2 * self._tau_s)), 1)
        return [np.zeros((0, 2)), np.tile([0.0, float(z0[4])], (periods, 1))]

    def _evasive_backups(self, omega_cmd_max_radps: float) -> list[np.ndarray]:
        """The evasive backups as command sequences (EVASION_TURNS, EVASION_HOLDS_S); none without
        a yaw-rate bound."""
        if omega_cmd_max_radps <= 0.0:
            return []
        v = self._r.max_linear_mps
        return [
            np.tile([sign * v, turn * omega_cmd_max_radps], (max(round(hold_s / self._tau_s), 1), 1))
            for sign in (1.0, -1.0)
            for turn in EVASION_TURNS
            for hold_s in EVASION_HOLDS_S
        ]

    def clearance(
        self,
        times_s: np.ndarray,
        poses: np.ndarray,
        obstacles: Sequence[Obstacle],
        accel_bound_mps2: float | None = None,
    ) -> float:
        """The smallest clearance (m) of the body discs along a manoeuvre to the obstacles, movers
        grown at `accel_bound_mps2` (default: the filter's bound; see the module docstring); inf
        when none can come within the manoeuvre's reach."""
        return self._clearance(times_s, poses, _obstacle_rows(obstacles), accel_bound_mps2)

    def _clearance(
        self, times_s: np.ndarray, poses: np.ndarray, data: np.ndarray, accel_bound_mps2: float | None
    ) -> float:
        """clearance() against obstacle rows [x, y, vx, vy, r, age] (_obstacle_rows)."""
        if len(data) == 0:
            return math.inf
        bound_mps2 = self._accel_bound if accel_bound_mps2 is None else accel_bound_mps2
        if not (np.all(np.isfinite(data)) and np.all(np.isfinite(poses))):
            return -math.inf  # what cannot be checked does not pass
        since = self._lead_s + times_s  # time since the obstacles were given (s), (T,)
        speed = np.hypot(data[:, 2], data[:, 3])
        growth = np.where(speed > 0.0, 0.5 * bound_mps2 * (data[:, 5] + since[-1]) ** 2, 0.0)
        # only obstacles that can come within the manoeuvre's reach need the full check
        reach = float(np.max(np.hypot(*(poses[:, :2] - poses[0, :2]).T))) + np.max(np.abs(self._offsets))
        start = data[:, 0:2] + data[:, 2:4] * since[0]
        bound = reach + self._disc_radius + data[:, 4] + growth + speed * (since[-1] - since[0])
        near = np.hypot(*(start - poses[0, :2]).T) <= bound
        if not np.any(near):
            return math.inf
        data, speed = data[near], speed[near]
        centres = data[None, :, 0:2] + data[None, :, 2:4] * since[:, None, None]  # (T, M, 2)
        aged = data[None, :, 5] + since[:, None]  # time since each was measured (s), (T, M)
        grown = data[None, :, 4] + np.where(speed[None, :] > 0.0, 0.5 * bound_mps2 * aged**2, 0.0)
        heading = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=1)  # (T, 2)
        discs = poses[:, None, :2] + self._offsets[None, :, None] * heading[:, None, :]  # (T, D, 2)
        gaps = np.linalg.norm(discs[:, :, None, :] - centres[:, None, :, :], axis=3)  # (T, D, M)
        return float(np.min(gaps - self._disc_radius - grown[:, None, :]))

    def filter(
        self,
        z0: np.ndarray,
        plan: np.ndarray,
        obstacles: Sequence[Obstacle],
        ages_s: Sequence[float] | None = None,
    ) -> FilterVerdict:
        """The command to send now, given the NMPC's planned commands `plan` ((k, 2) [v, omega]
        per control period, one (2,) command, or none): its first, if a cut of the plan passes the
        check (the longest that ends out of every mover's way within the trap horizon becomes the
        committed trajectory); where each passing cut ends in a way, a way out if one exists, else
        the passing cut or braking now whose stand a mover reaches last (module docstring: which
        movers count); if no cut passes, the committed trajectory's next command if it still
        passes, else the braking manoeuvre that keeps the most clearance; where that fallback would
        stand in a mover's way within the threat horizon, a way out if one exists (else that
        fallback all the same). A plan that is not finite has no cut that passes. `ages_s`: how
        long before now each obstacle was measured (obstacle_memory.py; default all now): a mover's
        circle grows over its age too."""
        plan = np.asarray(plan, dtype=float).reshape(-1, 2)
        if not (np.all(np.isfinite(plan)) and np.all(np.isfinite(z0))):
            plan = np.zeros((0, 2))
        measured = _obstacle_rows(obstacles, ages_s)
        data = self._overlap_allowed(z0, measured)  # what the check reads
        runs: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # each manoeuvre, integrated once

        def run_of(commands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """The manoeuvre of a command sequence from z0 (SafetyFilter.manoeuvre), this step."""
            key = np.ascontiguousarray(commands, dtype=float).reshape(-1, 2).tobytes()
            if key not in runs:
                runs[key] = self.manoeuvre(z0, commands)
            return runs[key]

        @functools.cache
        def credible() -> np.ndarray:
            """The movers whose constant-velocity track says where they will be over the threat
            horizon: one that meets the static layer sooner turns before it, and no prediction
            says where."""
            return data[free_run_m(measured) > np.hypot(data[:, 2], data[:, 3]) * self._threat_s]

        @functools.cache
        def trap_way_out() -> tuple[np.ndarray, float] | None:
            """A way out over the trap horizon (_way_out), looked for at most once per step; the
            rest of a way out already taken goes on, if it still is one: no dithering."""
            return self._way_out(run_of, data, [self._committed, *self._evasions], self._trap_s)

        # of the cuts that pass, the one that movers reach last from now (s), the longest of those
        passing: tuple[float, int, float] | None = None  # (reached, k, clearance)
        longest = True  # the cut at hand is the longest that passes
        for k in range(len(plan), 0, -1):  # the longest passing cut that stands out of the way
            times, poses = run_of(plan[:k])
            clearance_m = self._clearance(times, poses, data, None)
            if clearance_m < 0.0:
                continue
            # the plan is being cut: the robot is about to brake where its cut ends
            if longest and k < len(plan) and self._hit_standing(times[-1], poses[-1], data, self._trap_s):
                way_out = trap_way_out()
                if way_out is not None:
                    return self._commit(*way_out)
            longest = False
            reached_s = times[-1] + self._reached_s(times[-1], poses[-1], credible(), self._trap_s)
            if math.isfinite(reached_s):
                if passing is None or reached_s > passing[0]:
                    passing = (reached_s, k, clearance_m)
                continue
            self._committed = plan[1:k].copy()
            return FilterVerdict(plan[0].copy(), False, clearance_m)
        if passing is not None:
            # every passing cut stands in a credible mover's way: a way out, if one exists
            way_out = trap_way_out()
            if way_out is not None:
                return self._commit(*way_out)
            # no way out: braking now, if movers reach the robot later where it would stand
            times, poses = run_of(np.zeros((0, 2)))
            clearance_m = self._clearance(times, poses, data, None)
            reached_s = times[-1] + self._reached_s(times[-1], poses[-1], credible(), self._trap_s)
            if clearance_m >= 0.0 and reached_s > passing[0]:
                return self._commit(np.zeros((0, 2)), clearance_m)
            _, k, clearance_m = passing
            self._committed = plan[1:k].copy()
            return FilterVerdict(plan[0].copy(), False, clearance_m)
        chosen, run = self._committed, run_of(self._committed)
        clearance_m = self._clearance(*run, data, None)
        if clearance_m < 0.0:
            options = [(clearance_m, chosen, run)]
            for backup in self._braking(z0):
                backup_run = run_of(backup)
                options.append((self._clearance(*backup_run, data, None), backup, backup_run))
            clearance_m, chosen, run = max(options, key=lambda option: option[0])
        times, poses = run
        if self._hit_standing(times[-1], poses[-1], data, self._threat_s):
            way_out = self._way_out(
                run_of, data, [self._committed, *self._braking(z0), *self._evasions], self._threat_s
            )
            if way_out is not None:
                return self._commit(*way_out)
        command = chosen[0].copy() if len(chosen) else np.zeros(2)
        self._committed = chosen[1:].copy()
        return FilterVerdict(command, True, clearance_m)

    def _discs_at(self, pose: np.ndarray) -> np.ndarray:
        """(D, 2) the body discs' centres (m) at `pose` [x, y, theta, ...]."""
        heading = np.array([math.cos(pose[2]), math.sin(pose[2])])
        return pose[None, :2] + self._offsets[:, None] * heading[None, :]

    def _overlap_allowed(self, z0: np.ndarray, data: np.ndarray) -> np.ndarray:
        """`data` with each static obstacle that the body discs at z0 already overlap shrunk by
        that overlap: the discs are wider than the body, so a robot may stand closer than they
        allow (pushed, or braked late), and from there no candidate would pass; checked against
        the shrunk obstacle, a candidate may not bring a disc deeper into it, and may leave it.
        The shrunk radius is only the check's threshold, so it may fall below zero (a disc deeper
        than the obstacle's radius); where movers meet the static layer is read as measured."""
        static = _still(data)
        if not np.any(static) or not np.all(np.isfinite(z0[:3])):
            return data
        discs = self._discs_at(z0)
        rows = data[static]
        gaps = np.hypot(*(discs[:, None, :] - rows[None, :, 0:2]).transpose(2, 0, 1))
        overlap = np.minimum(np.min(gaps, axis=0) - self._disc_radius - rows[:, 4], 0.0)
        out = data.copy()
        out[static, 4] = rows[:, 4] + overlap
        return out

    def _commit(self, commands: np.ndarray, clearance_m: float) -> FilterVerdict:
        """Commit a way out (command sequence `commands`, empty: braking now) and send its first
        command, as an intervention."""
        self._committed = commands[1:].copy()
        return FilterVerdict(commands[0].copy() if len(commands) else np.zeros(2), True, clearance_m)

    def _way_out(
        self,
        run_of: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        data: np.ndarray,
        candidates: Sequence[np.ndarray],
        horizon_s: float,
    ) -> tuple[np.ndarray, float] | None:
        """The first of the command sequences `candidates` if it is a way out, else the one with
        the most clearance among those that are (a way out: its manoeuvre passes the full check
        and ends out of every mover's way within `horizon_s`, _hit_standing), and its clearance
        (m); None when none is. The first is the committed trajectory: a way out already taken
        goes on. `run_of` gives a sequence's manoeuvre (integrated once per step)."""
        best: tuple[np.ndarray, float] | None = None
        for i, commands in enumerate(candidates):
            times, poses = run_of(commands)
            clearance_m = self._clearance(times, poses, data, None)
            if clearance_m < 0.0 or (best is not None and clearance_m <= best[1]):
                continue
            if not self._hit_standing(times[-1], poses[-1], data, horizon_s):
                best = (commands, clearance_m)
                if i == 0 and len(commands):
                    return best
        return best

    def _hit_standing(self, stand_s: float, pose: np.ndarray, data: np.ndarray, horizon_s: float) -> bool:
        """Whether a mover reaches the robot standing at `pose` from `stand_s` within `horizon_s`
        (_reached_s)."""
        return math.isfinite(self._reached_s(stand_s, pose, data, horizon_s))

    def _reached_s(self, stand_s: float, pose: np.ndarray, data: np.ndarray, horizon_s: float) -> float:
        """How soon (s) after `stand_s` (s from z0) a mover (a row of `data` with a velocity,
        _obstacle_rows) at constant velocity, not grown, first reaches a body disc of a robot
        standing at `pose`, within `horizon_s`; inf if none does."""
        data = data[~_still(data)]
        if len(data) == 0 or horizon_s <= 0.0:
            return math.inf
        discs = self._discs_at(pose)
        # each mover's centre relative to each disc at the stand, and when their gap closes
        rel = data[:, None, 0:2] + data[:, None, 2:4] * (self._lead_s + stand_s) - discs[None, :, :]
        reach = data[:, 4, None] + self._disc_radius  # (M, 1)
        a = np.sum(data[:, 2:4] ** 2, axis=1)[:, None]  # (M, 1)
        b = np.einsum("mdk,mk->md", rel, data[:, 2:4])  # half the linear coefficient, (M, D)
        c = np.sum(rel**2, axis=2) - reach**2  # (M, D)
        root = b**2 - a * c
        first = np.where(root >= 0.0, (-b - np.sqrt(np.maximum(root, 0.0))) / a, math.inf)
        first = np.where(c <= 0.0, 0.0, np.where(first >= 0.0, first, math.inf))
        soonest = float(np.min(first))
        return soonest if soonest <= horizon_s else math.inf


def _obstacle_rows(obstacles: Sequence[Obstacle], ages_s: Sequence[float] | None = None) -> np.ndarray:
    """(M, 6) rows [x, y, vx, vy, r, age] (m, m/s, s) of the obstacles, read once per filtered
    step; age: how long before they were given each was measured (0: just now)."""
    ages = np.zeros(len(obstacles)) if ages_s is None else np.asarray(ages_s, dtype=float)
    rows = [(o.x_m, o.y_m, o.vx_mps, o.vy_mps, o.radius_m, a) for o, a in zip(obstacles, ages, strict=True)]
    return np.array(rows, dtype=float).reshape(-1, 6)


def _still(data: np.ndarray) -> np.ndarray:
    """(M,) which rows of `data` (_obstacle_rows) stand exactly still: the static layer, checked as
    measured; any other row is a mover, predicted and grown."""
    return (data[:, 2] == 0.0) & (data[:, 3] == 0.0)
