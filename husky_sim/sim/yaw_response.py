"""The Husky's yaw-rate response as a first-order lag, and its identification.

Model (continuous time):  d(omega_body)/dt = (K * omega_applied(t - D) - omega_body) / T,  with
omega_applied the drive's rate-limited yaw-rate command (husky_sim.sim.drive.SkidSteerDrive.limit,
rad/s), omega_body the measured body yaw rate (rad/s), K the steady-state gain (dimensionless), T
the time constant (s) and D the drive's dead time (s; the ground's `drive.command_delay_s`, measured
from the real robot's recordings, not fitted here: a lag alone lumps that dead time into T, as
0.50 s did). Discretised exactly with the delayed omega_applied held between samples (zero-order
hold). `identify_in_simulation` drives the simulated Husky through yaw-rate steps and fits one
(K, T) to all of them; `fit_yaw_response` fits a recorded signal (husky-sim replay).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from husky_sim.paths import ASSETS_DIR, DEFAULT_ROBOT

if TYPE_CHECKING:
    from husky_sim.sim.drive import DriveConfig
    from husky_sim.sim.world import WorldConfig

#: The identified default of the simulated Husky, written by `husky-sim identify`.
DEFAULT_FILE: Path = ASSETS_DIR / "yaw_response.yaml"
#: Bounds of the fit: gain (dimensionless), time constant (s); the scenario schema uses the same.
GAIN_BOUNDS = (0.05, 2.0)
TIME_CONSTANT_BOUNDS_S = (0.01, 10.0)
#: Starting points (gain, time constant s) of the fit; the best local minimum is kept (a simulated
#: skid-steer turn's yaw rate swings about the lag's curve, so the output error can have more than one).
FIT_STARTS = ((0.5, 0.5), (0.3, 0.2), (1.0, 0.2), (0.3, 2.0), (1.0, 2.0))
#: The payloads `husky-sim identify` fits at, as fractions of the robot's maximum payload: the
#: unloaded robot first (the file's headline), then four loads up to the maximum (the Husky: 0,
#: 18.75, 37.5, 56.25 and 75 kg).
PAYLOAD_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
#: A signal whose applied yaw rate never exceeds this (rad/s) does not identify a gain.
MIN_EXCITATION_RADPS = 0.05


@dataclass(frozen=True)
class YawResponse:
    """First-order yaw-rate lag behind a dead time, d(omega_body)/dt = (gain * omega_applied(t -
    delay_s) - omega_body) / time_constant_s: gain dimensionless, time_constant_s and delay_s in s,
    yaw rates in rad/s. The dead time delays the drive's linear speed alike."""

    gain: float
    time_constant_s: float
    delay_s: float = 0.0


#: One recorded or simulated signal: sample times (s), applied yaw rate held from each sample to
#: the next (rad/s), measured body yaw rate at each sample (rad/s).
Segment = tuple[np.ndarray, np.ndarray, np.ndarray]


def simulate_lag(
    t_s: np.ndarray,
    omega_applied: np.ndarray,
    gain: float,
    time_constant_s: float,
    omega0: float = 0.0,
) -> np.ndarray:
    """Body yaw rate (rad/s) at the times t_s (s) from omega0 (rad/s) at t_s[0], with
    omega_applied[k] (rad/s) held over [t_s[k], t_s[k+1]); exact discretisation of the lag."""
    t = np.asarray(t_s, dtype=float)
    u = np.asarray(omega_applied, dtype=float)
    decay = np.exp(-np.diff(t) / time_constant_s)
    out = np.empty(len(t))
    if len(t) == 0:
        return out
    out[0] = w = float(omega0)
    for k, a in enumerate(decay):
        w = a * w + (1.0 - a) * gain * u[k]
        out[k + 1] = w
    return out


def _checked(segment: Segment) -> Segment:
    t, u, w = (np.asarray(x, dtype=float).ravel() for x in segment)
    if not len(t) == len(u) == len(w):
        raise ValueError(
            f"yaw fit: t_s, omega_applied and omega_body differ in length ({len(t)}, {len(u)}, {len(w)})"
        )
    if len(t) < 3:
        raise ValueError(f"yaw fit: need at least 3 samples, got {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u)) and np.all(np.isfinite(w))):
        raise ValueError("yaw fit: a non-finite sample")
    if np.any(np.diff(t) <= 0):
        raise ValueError("yaw fit: sample times must be strictly increasing")
    return t, u, w


def segment_residual(response: YawResponse, segment: Segment) -> np.ndarray:
    """Simulated minus measured body yaw rate (rad/s), the lag started at the first measured value."""
    t, u, w = segment
    return simulate_lag(t, u, response.gain, response.time_constant_s, w[0]) - w


def rms(values: np.ndarray) -> float:
    """Root mean square (units of the values)."""
    return float(np.sqrt(np.mean(np.square(values))))


def fit_segments(segments: Sequence[Segment], delay_s: float = 0.0) -> tuple[YawResponse, float]:
    """One (gain, time constant) for all segments by bounded least squares on the simulated output
    (each segment simulated from its own first measured yaw rate); with the overall rms error (rad/s).
    The segments' applied yaw rates are already delayed by `delay_s` (s), which the result carries."""
    from scipy.optimize import least_squares  # heavy; only a fit needs it

    checked = [_checked(s) for s in segments]
    if not checked:
        raise ValueError("yaw fit: no samples")
    if max(float(np.max(np.abs(u))) for _, u, _ in checked) < MIN_EXCITATION_RADPS:
        raise ValueError(
            f"yaw fit: the applied yaw rate never exceeds {MIN_EXCITATION_RADPS} rad/s; nothing to identify"
        )

    def residuals(x: np.ndarray) -> np.ndarray:
        response = YawResponse(float(x[0]), float(x[1]), delay_s)
        return np.concatenate([segment_residual(response, s) for s in checked])

    lower, upper = (GAIN_BOUNDS[0], TIME_CONSTANT_BOUNDS_S[0]), (GAIN_BOUNDS[1], TIME_CONSTANT_BOUNDS_S[1])
    solutions = [
        least_squares(residuals, x0=x0, bounds=(lower, upper), x_scale=(0.5, 0.5)) for x0 in FIT_STARTS
    ]
    best = min(solutions, key=lambda s: s.cost)  # the first of equals: deterministic
    return YawResponse(float(best.x[0]), float(best.x[1]), delay_s), rms(residuals(best.x))


def fit_yaw_response(
    t_s: np.ndarray, omega_applied_radps: np.ndarray, omega_body_radps: np.ndarray
) -> tuple[YawResponse, float]:
    """Fit the lag to one signal (times s, applied and measured yaw rate rad/s); returns the fit
    (gain bounded to GAIN_BOUNDS, T to TIME_CONSTANT_BOUNDS_S) and its rms error (rad/s)."""
    return fit_segments([(t_s, omega_applied_radps, omega_body_radps)])


def interval_means(t_fine_s: np.ndarray, values: np.ndarray, t_samples_s: np.ndarray) -> np.ndarray:
    """Mean of a finely sampled signal over each [t_samples[k], t_samples[k+1]) (the zero-order-hold
    value that interval is given); the last sample, which starts no interval, takes the value at it."""
    t_fine, v = np.asarray(t_fine_s, dtype=float), np.asarray(values, dtype=float)
    edges = np.searchsorted(t_fine, np.asarray(t_samples_s, dtype=float) - 1e-9, side="left")
    out = np.empty(len(edges))
    for k in range(len(edges) - 1):
        lo, hi = edges[k], max(edges[k + 1], edges[k] + 1)
        out[k] = float(np.mean(v[lo:hi]))
    out[-1] = v[min(edges[-1], len(v) - 1)]
    return out


# --------------------------------------------------------------------------------------------
# identification in PyBullet


@dataclass(frozen=True)
class StepFit:
    """One step of the identification: its command, the joint fit's rms error on it, and a lag
    fitted to this step alone (to show whether one lag fits all)."""

    linear_mps: float  # commanded linear speed (m/s)
    yaw_rate_radps: float  # commanded yaw rate (rad/s)
    rms_error_radps: float  # rms of the joint fit on this step (rad/s)
    own_gain: float  # lag fitted to this step alone: gain (dimensionless)
    own_time_constant_s: float  # ... and time constant (s)
    late_ratio: float  # mean measured / commanded yaw rate over the second half of the step


@dataclass(frozen=True)
class Identification:
    """The joint fit of all steps and the fit quality per step."""

    response: YawResponse
    rms_error_radps: float  # over all steps (rad/s)
    steps: tuple[StepFit, ...]
    hold_s: float  # how long each step is held (s)
    sample_s: float  # sampling period of the fit (s)
    payload_kg: float = 0.0  # on the robot's top plate while identified (kg)

    def lines(self) -> list[str]:
        """A human-readable report."""
        r = self.response
        out = [
            f"yaw-rate lag at {self.payload_kg:g} kg payload: gain {r.gain:.3f}, time constant "
            f"{r.time_constant_s:.3f} s behind the "
            f"ground's dead time {r.delay_s:.3f} s, rms error "
            f"{self.rms_error_radps:.4f} rad/s over {len(self.steps)} steps of {self.hold_s:g} s "
            f"(sampled every {self.sample_s:g} s)",
            "   v (m/s)  omega (rad/s)  rms (rad/s)  own gain  own T (s)  late ratio",
        ]
        for s in self.steps:
            out.append(
                f"  {s.linear_mps:8.2f}  {s.yaw_rate_radps:13.2f}  {s.rms_error_radps:11.4f}  "
                f"{s.own_gain:8.3f}  {s.own_time_constant_s:9.3f}  {s.late_ratio:10.3f}"
            )
        return out

    def data(self) -> dict[str, object]:
        """Plain data for the YAML file: gain and time_constant_s first (what a scenario reads)."""
        return {
            "gain": round(self.response.gain, 4),
            "time_constant_s": round(self.response.time_constant_s, 4),
            "delay_s": round(self.response.delay_s, 4),
            "rms_error_radps": round(self.rms_error_radps, 5),
            "hold_s": self.hold_s,
            "sample_s": self.sample_s,
            "steps": [{k: round(float(v), 4) for k, v in s.__dict__.items()} for s in self.steps],
        }


def step_signal(
    linear_mps: float,
    yaw_rate_radps: float,
    hold_s: float,
    sample_s: float,
    world: WorldConfig | None = None,
    drive: DriveConfig | None = None,
    delay_s: float = 0.0,
    robot: str = DEFAULT_ROBOT,
    payload_kg: float = 0.0,
) -> Segment:
    """Simulate the robot (its folder's name, with payload_kg on its top plate) from rest with
    (linear_mps, yaw_rate_radps) commanded from t = 0 for hold_s (s) on its default ground; the
    applied yaw rate delayed by delay_s (s, interval means) and the body yaw rate every sample_s (s)."""
    from husky_sim.sim.open_loop import simulate_commands  # commands in, track out

    track = simulate_commands(
        np.array([0.0]),
        np.array([[linear_mps, yaw_rate_radps]]),
        hold_s,
        (0.0, 0.0, 0.0),
        world=world,
        drive=drive,
        robot=robot,
        payload_kg=payload_kg,
    )
    every = max(round(sample_s / float(track.t_s[1] - track.t_s[0])), 1)
    idx = np.arange(0, len(track.t_s), every)
    t = track.t_s[idx]
    fine_t = track.t_s[:-1]
    delayed = np.interp(fine_t - delay_s, fine_t, track.applied[:, 1], left=0.0)  # at rest before
    return t, interval_means(fine_t, delayed, t), track.body_velocity[idx, 1]


def identify_in_simulation(
    yaw_rates_radps: Sequence[float] = (0.4, 0.8, 1.2, -0.4, -0.8, -1.2),
    linear_speeds_mps: Sequence[float] = (0.0, 0.5),
    hold_s: float = 4.0,
    sample_s: float = 0.1,
    world: WorldConfig | None = None,
    drive: DriveConfig | None = None,
    robot: str = DEFAULT_ROBOT,
    payload_kg: float = 0.0,
) -> Identification:
    """Yaw-rate steps (rad/s) at each linear speed (m/s), each from rest and held hold_s (s), on
    the robot's default ground with payload_kg (kg) on its top plate and the default (or given)
    WorldConfig and DriveConfig; one lag fitted to all, behind the ground's dead time.
    Deterministic (PyBullet DIRECT, no noise)."""
    from husky_sim.sim.ground import load_ground

    if not (0 < sample_s <= hold_s) or not math.isfinite(hold_s):
        raise ValueError(f"identify: need 0 < sample_s <= hold_s, got {sample_s:g} and {hold_s:g}")
    delay_s = load_ground(robot=robot).drive.command_delay_s
    commands = [(v, w) for v in linear_speeds_mps for w in yaw_rates_radps]
    segments = [
        step_signal(v, w, hold_s, sample_s, world, drive, delay_s, robot, payload_kg) for v, w in commands
    ]
    response, total = fit_segments(segments, delay_s)
    steps = []
    for (v, w), segment in zip(commands, segments, strict=True):
        own, _ = fit_segments([segment], delay_s)
        steps.append(
            StepFit(
                linear_mps=v,
                yaw_rate_radps=w,
                rms_error_radps=rms(segment_residual(response, segment)),
                own_gain=own.gain,
                own_time_constant_s=own.time_constant_s,
                late_ratio=float(np.mean(segment[2][len(segment[2]) // 2 :]) / w),
            )
        )
    return Identification(response, total, tuple(steps), hold_s, sample_s, payload_kg)


def identify_by_payload(
    payloads_kg: Sequence[float], robot: str = DEFAULT_ROBOT
) -> tuple[Identification, ...]:
    """`identify_in_simulation` at each payload (kg; the first is the file's headline, the
    unloaded robot's): a loaded skid-steer turns less and later than an empty one, and a
    controller told its payload plans with the lag of that load (`lag_for_payload`)."""
    return tuple(identify_in_simulation(robot=robot, payload_kg=float(p)) for p in payloads_kg)


def lag_for_payload(by_payload: Sequence[tuple[float, YawResponse]], payload_kg: float) -> YawResponse:
    """The lag at payload_kg (kg), linear in the payload between the identified ones (gain and
    time constant; held beyond the ends); the dead time is the ground's, the same for all."""
    points = sorted(by_payload, key=lambda item: item[0])
    loads = [p for p, _ in points]
    gain = float(np.interp(payload_kg, loads, [r.gain for _, r in points]))
    lag = float(np.interp(payload_kg, loads, [r.time_constant_s for _, r in points]))
    return YawResponse(gain, lag, points[0][1].delay_s)


def write_identification(
    identifications: Sequence[Identification], path: Path, command: str, robot_title: str = "Husky A200"
) -> None:
    """Write the identification of the robot `robot_title` as YAML to path, with a comment header
    naming `command` and the UTC time: the first (unloaded) one in full, and the lag at every
    payload under `by_payload`, which a scenario's default yaw response reads for its payload."""
    from datetime import UTC, datetime

    from husky_sim.scenario_file import scenario_yaml

    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    header = (
        f"Produced by `{command}` on {when}.\n"
        f"{robot_title} yaw-rate lag in PyBullet (husky_sim/sim/yaw_response.py):\n"
        "d(omega_body)/dt = (gain * omega_applied(t - delay_s) - omega_body) / time_constant_s;\n"
        "gain dimensionless, time_constant_s in s, delay_s the robot's default ground's dead time\n"
        "(s, not fitted), omega_applied the drive's rate-limited yaw-rate command, omega_body the\n"
        "body yaw rate (rad/s).\n"
        "Fitted to yaw-rate steps from rest at each linear speed; steps: the joint fit's rms error on\n"
        "each step, a lag fitted to that step alone, and the mean measured / commanded yaw rate over\n"
        "the step's second half, all unloaded. by_payload: the same fit with each payload (kg) on\n"
        "the top plate. The default of every scenario without robot.yaw_response, at its payload\n"
        "(linear between these)."
    )
    first, *_ = identifications
    data = first.data()
    data["by_payload"] = [
        {
            "payload_kg": round(i.payload_kg, 4),
            "gain": round(i.response.gain, 4),
            "time_constant_s": round(i.response.time_constant_s, 4),
            "rms_error_radps": round(i.rms_error_radps, 5),
        }
        for i in identifications
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scenario_yaml(data, header))
