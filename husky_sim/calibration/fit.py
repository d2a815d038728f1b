"""`husky-sim calibrate`: fit a ground (tyre contact and drive response) to a real recording.

Each steady step of the recording is replayed from rest in the simulator with the body velocity its
measured wheels imply, sent as wheel speeds of our own geometry, so that the simulated and the real
robot are asked the same thing; both are then measured the same way (husky_sim.calibration).

What is fitted, on the even-numbered steps (the odd ones are held out and only evaluated):
- the lateral / longitudinal tyre stiffness ratio, to the median yaw ratio (with a linear contact
  the yaw ratio is 1 / (1 + c k): each round solves that for k);
- the rolling-radius scale, to the median forward ratio;
- the slip speed (the tyre's stiffness), to the median motor current of the in-place steps, when
  the recording logs currents (else the base ground's is kept);
- the drive's dead time and lag, to the recording's median wheel-speed rise times (63 %, 95 %),
  corrected once by the simulated wheels' own rise times.
The friction coefficient is not identifiable apart from the stiffness on these recordings (the
tyres rarely saturate): it stays the base ground's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from husky_sim.calibration.drive_response import ResponseRow, steady_answer
from husky_sim.calibration.recordings import (
    COMMAND_CLASSES,
    DriveRecording,
    SteadyStep,
    StepTimes,
    rise_times,
)
from husky_sim.sim.geometry import load_geometry
from husky_sim.sim.ground import DriveResponse, Ground, write_ground
from husky_sim.sim.open_loop import simulate_commands
from husky_sim.sim.tyre import TyreContact

#: Hold of each replayed step from rest (s), steady over its second half.
STEP_HOLD_S = 4.0
#: Steps per command class simulated in each fitting round (evenly spread over the class's yaw rates).
STEPS_PER_CLASS = 3
FIT_ROUNDS = 6
#: Stiffest tyre the fit may choose: the tyre force is applied explicitly once per physics step, and
#: 4 mu N / (slip speed x robot mass) x dt must stay well below 2 (here about 0.7 at 240 Hz, mu 1,
#: 50 kg) for the body's slip not to oscillate.
MIN_SLIP_SPEED_MPS = 0.06
#: A wheel-speed step (rad/s, both sides opposite: a turn in place) to measure the simulated wheels'
#: rise times.
WHEEL_STEP_RADPS = 2.0


@dataclass(frozen=True)
class StepResult:
    """One recorded step and its simulated replay."""

    step: SteadyStep
    sim: ResponseRow
    held_out: bool


@dataclass(frozen=True)
class Calibration:
    """The fitted ground and what it was measured against."""

    recording: DriveRecording
    ground: Ground
    results: tuple[StepResult, ...]
    wheel_times_recorded: StepTimes | None
    wheel_times_simulated: tuple[float | None, float | None]
    yaw_times_recorded: StepTimes | None


def merge_windows(steps: tuple[SteadyStep, ...]) -> list[SteadyStep]:
    """One SteadyStep per recorded step: the steady windows of a step averaged."""
    by_step: dict[int, list[SteadyStep]] = {}
    for s in steps:
        by_step.setdefault(s.step, []).append(s)
    merged = []
    for index, group in sorted(by_step.items()):
        if len(group) == 1:
            merged.append(group[0])
            continue
        fields = ("left_radps", "right_radps", "v_wheels_mps", "w_wheels_radps", "v_mps", "w_radps")
        means = {f: float(np.mean([getattr(g, f) for g in group])) for f in fields}
        currents = [g.current_a for g in group if g.current_a is not None]
        merged.append(
            SteadyStep(
                step=index, window=-1, current_a=float(np.mean(currents)) if currents else None, **means
            )
        )
    return merged


def simulate_step(ground: Ground, step: SteadyStep, hold_s: float = STEP_HOLD_S) -> ResponseRow:
    """The step replayed from rest: its wheel-implied body velocity as our wheels' speeds."""
    geometry = load_geometry()
    v, w = step.v_wheels_mps, step.w_wheels_radps
    half = 0.5 * geometry.track_width_m * w
    wheels = np.array([[(v - half) / geometry.wheel_radius_m, (v + half) / geometry.wheel_radius_m]])
    track = simulate_commands(
        np.zeros(1), np.array([[v, w]]), hold_s, (0.0, 0.0, 0.0), ground=ground, wheel_targets=wheels
    )
    return steady_answer(track, (v, w), 0.5 * hold_s)


def representatives(steps: list[SteadyStep]) -> list[SteadyStep]:
    """Up to STEPS_PER_CLASS steps of each command class, evenly spread over its |yaw rate|."""
    chosen = []
    for name in COMMAND_CLASSES:
        members = sorted((s for s in steps if s.command_class == name), key=lambda s: abs(s.w_wheels_radps))
        if not members:
            continue
        picks = np.unique(
            np.linspace(0, len(members) - 1, min(STEPS_PER_CLASS, len(members))).round().astype(int)
        )
        chosen += [members[i] for i in picks]
    return chosen


def _median(values: list[float | None]) -> float | None:
    kept = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.median(kept)) if kept else None


#: Classes whose forward ratio is measured: in place the wheel-implied speed is too small.
DRIVING_CLASSES = ("tight_arc", "wide_arc", "straight")


def _forward(steps: list[SteadyStep], rows: list[ResponseRow] | None = None) -> float | None:
    """Median forward ratio over the driving steps (in place the wheel-implied speed is too small to
    divide by, and the wet-grass ICP jumps make those ratios scatter): the recording's, or the
    simulated rows'."""
    if rows is None:
        return _median([s.forward_ratio for s in steps if s.command_class in DRIVING_CLASSES])
    pairs = zip(steps, rows, strict=True)
    return _median([r.forward_ratio for s, r in pairs if s.command_class in DRIVING_CLASSES])


def wheel_rise_times(ground: Ground) -> tuple[float | None, float | None]:
    """63 % and 95 % rise times (s) of the simulated wheels after a wheel-speed step from rest."""
    track = simulate_commands(
        np.zeros(1),
        np.zeros((1, 2)),
        2.5,
        (0.0, 0.0, 0.0),
        ground=ground,
        wheel_targets=np.array([[-WHEEL_STEP_RADPS, WHEEL_STEP_RADPS]]),
    )
    right = np.mean(track.wheel_speeds[:, 2:], axis=1)
    times = rise_times(track.t_s, right, 0.0, float(np.mean(right[-60:])))
    return (None, None) if times is None else (times.t63_s, times.t95_s)


def _current_ratio(steps: list[SteadyStep], rows: list[ResponseRow]) -> float | None:
    """Simulated / recorded motor current: the geometric mean over the command classes of each
    class's median ratio (in place and on arcs weigh the same, however many steps each has)."""
    per_class = []
    for name in COMMAND_CLASSES:
        pairs = zip(steps, rows, strict=True)
        ratios = [r.current_a / s.current_a for s, r in pairs if s.command_class == name and s.current_a]
        if ratios and name != "straight":  # driving straight, the current is rolling resistance alone
            per_class.append(float(np.median(ratios)))
    return float(np.exp(np.mean(np.log(per_class)))) if per_class else None


def _step_times(recording: DriveRecording, kind: str) -> StepTimes | None:
    try:
        return recording.median_step_times(kind)
    except ValueError:  # the recording has none of that kind
        return None


def drive_targets(wheel: StepTimes, yaw: StepTimes | None) -> StepTimes:
    """Rise times the simulated wheels are fitted to: the recording's wheel times, or, where it has
    body yaw-rate steps too (tile), halfway between the two. The real body lags its wheels by more
    than our chassis does (0.29 s at 95 % on tile, against about 0.03 s in simulation: our tyres
    are stiffer in yaw than the deflated ones), so the halfway point keeps both within the band."""
    if yaw is None:
        return wheel
    return StepTimes(0.5 * (wheel.t63_s + yaw.t63_s), 0.5 * (wheel.t95_s + yaw.t95_s))


def fit_drive_response(ground: Ground, times: StepTimes) -> DriveResponse:
    """Dead time and lag whose first-order response has the recorded t63 and t95 (t63 = d + T,
    t95 = d + 3 T), corrected once by what the simulated wheels add (motor, inertia, tyre)."""
    lag = max((times.t95_s - times.t63_s) / 2.0, 0.01)
    response = DriveResponse(max(times.t63_s - lag, 0.0), lag)
    t63, t95 = wheel_rise_times(replace(ground, drive=response))
    if t63 is None or t95 is None:
        return response
    lag = max(lag + ((times.t95_s - t95) - (times.t63_s - t63)) / 2.0, 0.01)
    delay = max(response.command_delay_s + (times.t63_s - t63) - (lag - response.wheel_time_constant_s), 0.0)
    return DriveResponse(round(min(delay, 2.0), 3), round(min(lag, 2.0), 3))


def fit_ground(recording: DriveRecording, base: Ground, name: str, log=print) -> Calibration:
    """Fit the ground to the recording's even-numbered steps; evaluate on all of them."""
    steps = merge_windows(recording.steps)
    fit_steps = [s for s in steps if s.step % 2 == 0]
    reps = representatives(fit_steps)
    target_yaw = _median([s.yaw_ratio for s in fit_steps])
    target_forward = _forward(fit_steps)
    logs_current = any(s.current_a is not None for s in fit_steps)
    if target_yaw is None or target_forward is None:
        raise ValueError(f"{recording.path}: the recording has no steady turning or driving steps to fit")
    tyre = base.tyre
    for round_ in range(FIT_ROUNDS):
        ground = Ground(name, tyre, base.drive)
        sims = [simulate_step(ground, s) for s in reps]
        yaw = _median([r.yaw_ratio for r in sims])
        forward = _forward(reps, sims)
        current = _current_ratio(reps, sims)
        log(
            f"  round {round_ + 1}: k {tyre.lateral_stiffness_ratio:.3f}, "
            f"rolling x{tyre.rolling_radius_scale:.3f}, "
            f"slip speed {tyre.slip_speed_mps:.3f} m/s -> yaw ratio {yaw:.3f} (target {target_yaw:.3f}), "
            f"forward {forward:.3f} ({target_forward:.3f}), current sim / real "
            f"{'-' if current is None else f'{current:.2f}'}"
        )
        if yaw is None or forward is None or not (0.0 < yaw < 1.0 and forward > 0.0):
            raise ValueError(
                f"calibrate: round {round_ + 1}: the simulated steps give yaw ratio {yaw} and forward ratio "
                f"{forward}; cannot fit (the ground {name!r} does not turn or drive as a skid-steer)"
            )
        k = tyre.lateral_stiffness_ratio
        c = (1.0 / yaw - 1.0) / k  # yaw ratio = 1 / (1 + c k)
        updates = {
            "lateral_stiffness_ratio": float(np.clip((1.0 / target_yaw - 1.0) / c, 0.05, 20.0)),
            "rolling_radius_scale": float(
                np.clip(tyre.rolling_radius_scale * target_forward / forward, 0.5, 2.0)
            ),
        }
        if logs_current and current is not None and current > 0:
            factor = float(np.clip(current**1.5, 0.5, 2.0))
            updates["slip_speed_mps"] = float(np.clip(tyre.slip_speed_mps * factor, MIN_SLIP_SPEED_MPS, 5.0))
        tyre = TyreContact(**{**tyre.__dict__, **{key: round(value, 4) for key, value in updates.items()}})
    wheel_times, yaw_times = _step_times(recording, "wheel"), _step_times(recording, "yaw")
    if wheel_times is None:  # no wheel steps (a bag of commands and odometry): keep the base's
        response = base.drive
    else:
        response = fit_drive_response(Ground(name, tyre, base.drive), drive_targets(wheel_times, yaw_times))
    ground = Ground(name, tyre, response)
    log(
        f"  drive response: delay {response.command_delay_s:.3f} s, "
        f"lag {response.wheel_time_constant_s:.3f} s"
    )
    results = tuple(StepResult(s, simulate_step(ground, s), s.step % 2 == 1) for s in steps)
    return Calibration(recording, ground, results, wheel_times, wheel_rise_times(ground), yaw_times)


# --------------------------------------------------------------------------------------------
# report


def _class_rows(results: list[StepResult]) -> list[str]:
    lines = [
        "| class | steps | yaw ratio real | yaw ratio sim | forward ratio real | forward ratio sim "
        "| current real (A) | current sim (A) | rms yaw-rate error (rad/s) | rms speed error (m/s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def fmt(value: float | None, digits: int = 3) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    for name in (*COMMAND_CLASSES, "all"):
        group = [r for r in results if name == "all" or r.step.command_class == name]
        if not group:
            continue
        yaw_err = math.sqrt(np.mean([(r.sim.w - r.step.w_radps) ** 2 for r in group]))
        v_err = math.sqrt(np.mean([(r.sim.v - r.step.v_mps) ** 2 for r in group]))
        logged = group[0].step.current_a is not None
        sim_current = _median([r.sim.current_a for r in group]) if logged else None
        lines.append(
            f"| {name} | {len(group)} | {fmt(_median([r.step.yaw_ratio for r in group]))} | "
            f"{fmt(_median([r.sim.yaw_ratio for r in group]))} | "
            f"{fmt(_median([r.step.forward_ratio for r in group]))} | "
            f"{fmt(_median([r.sim.forward_ratio for r in group]))} | "
            f"{fmt(_median([r.step.current_a for r in group]), 1)} | "
            f"{fmt(sim_current, 1)} | "
            f"{yaw_err:.3f} | {v_err:.3f} |"
        )
    return lines


def report_lines(cal: Calibration, command: str, figure: str) -> list[str]:
    """calibration.md."""
    g = cal.ground
    held = [r for r in cal.results if r.held_out]
    fitted = [r for r in cal.results if not r.held_out]
    w_sim = cal.wheel_times_simulated
    lines = [
        f"# Calibration of ground `{g.name}`",
        "",
        f"Produced by `{command}` from `{cal.recording.path}` "
        f"({len(cal.results)} steady steps; fitted on the {len(fitted)} even-numbered, "
        f"held out: the {len(held)} odd-numbered).",
        "",
        "## Fitted parameters",
        "",
        f"- tyre: friction {g.tyre.friction:g} (kept), slip speed {g.tyre.slip_speed_mps:g} m/s, "
        f"lateral / longitudinal stiffness {g.tyre.lateral_stiffness_ratio:g}, rolling radius x "
        f"{g.tyre.rolling_radius_scale:g}",
        f"- drive: dead time {g.drive.command_delay_s:g} s, wheel lag {g.drive.wheel_time_constant_s:g} s",
        "",
        "## Held-out steps (not used by the fit)",
        "",
        *_class_rows(held),
        "",
        "## Fitted steps",
        "",
        *_class_rows(fitted),
        "",
        "## Step responses (delay included)",
        "",
        "| response | real t63 (s) | sim t63 (s) | real t95 (s) | sim t95 (s) |",
        "|---|---|---|---|---|",
    ]
    if cal.wheel_times_recorded is None:
        lines.append(
            f"| wheel speed (not recorded: the base ground's kept) | - | {_fmt_time(w_sim[0])} | - | "
            f"{_fmt_time(w_sim[1])} |"
        )
    else:
        lines.append(
            f"| wheel speed | {cal.wheel_times_recorded.t63_s:.2f} | {_fmt_time(w_sim[0])} | "
            f"{cal.wheel_times_recorded.t95_s:.2f} | {_fmt_time(w_sim[1])} |"
        )
    if cal.yaw_times_recorded is not None:
        yaw63 = _median([r.sim.t63_yaw_s for r in cal.results if r.step.command_class == "in_place"])
        yaw95 = _median([r.sim.t95_yaw_s for r in cal.results if r.step.command_class == "in_place"])
        lines.append(
            f"| body yaw rate (sim: in-place steps) | {cal.yaw_times_recorded.t63_s:.2f} | "
            f"{_fmt_time(yaw63)} | "
            f"{cal.yaw_times_recorded.t95_s:.2f} | {_fmt_time(yaw95)} |"
        )
    lines += [
        "",
        "Ratios: measured / implied by the wheels' own speeds (the real robot's with its recorded radius "
        "0.15875 m and baseline 0.53846 m, ours with the URDF's). Errors: simulated minus measured "
        "yaw rate and forward speed of each step.",
        "",
        f"![measured against simulated]({figure})",
        "",
    ]
    return lines


def _fmt_time(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def plot_calibration(cal: Calibration, path: Path) -> None:
    """Measured against simulated yaw rate and forward speed, step by step."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 4.6), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, (real, sim, label, unit) in zip(
        axes,
        (
            (lambda r: r.step.w_radps, lambda r: r.sim.w, "yaw rate", "rad/s"),
            (lambda r: r.step.v_mps, lambda r: r.sim.v, "forward speed", "m/s"),
        ),
        strict=True,
    ):
        for held, marker, name in ((False, "o", "fitted steps"), (True, "x", "held-out steps")):
            group = [r for r in cal.results if r.held_out == held]
            ax.plot([real(r) for r in group], [sim(r) for r in group], marker, ms=4, ls="none", label=name)
        values = [real(r) for r in cal.results] + [sim(r) for r in cal.results]
        lo, hi = min(values), max(values)
        ax.plot([lo, hi], [lo, hi], color="black", lw=0.8, label="equal")
        ax.set(xlabel=f"measured {label} ({unit})", ylabel=f"simulated {label} ({unit})", title=label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{cal.recording.name}: real Husky against ground {cal.ground.name!r}, step by step")
    fig.savefig(path, dpi=100)


def write_calibration(cal: Calibration, out_dir: Path, command: str) -> list[Path]:
    """ground.yaml, calibration.md and calibration.png in out_dir."""
    out_dir.mkdir(parents=True, exist_ok=True)
    ground_path, report_path, figure_path = (
        out_dir / "ground.yaml",
        out_dir / "calibration.md",
        out_dir / "calibration.png",
    )
    held = [r for r in cal.results if r.held_out]
    fit_summary = {
        "recording": cal.recording.path,
        "held_out_steps": len(held),
        "held_out_yaw_ratio_real": _median([r.step.yaw_ratio for r in held]),
        "held_out_yaw_ratio_sim": _median([r.sim.yaw_ratio for r in held]),
        "held_out_rms_yaw_rate_error_radps": float(
            math.sqrt(np.mean([(r.sim.w - r.step.w_radps) ** 2 for r in held]))
        )
        if held
        else None,
    }
    fit_summary = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in fit_summary.items()}
    header = (
        f"Ground {cal.ground.name!r}, fitted by `{command}`\n"
        "Tyre: husky_sim/sim/tyre.py; drive: husky_sim/sim/drive.py.\n"
        "See calibration.md beside this file for what it was measured against."
    )
    write_ground(cal.ground, ground_path, header, fit_summary)
    report_path.write_text("\n".join(report_lines(cal, command, figure_path.name)))
    plot_calibration(cal, figure_path)
    return [ground_path, report_path, figure_path]
