"""Run one scenario with one controller in PyBullet and write `summary.json` and `log.csv`."""

from __future__ import annotations

import signal
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from controllers import Controller, Reference, registry
from husky_sim import interrupts
from husky_sim.extras import MissingExtra
from husky_sim.interrupts import RunInterrupted
from husky_sim.runs.run_folder import LOG_FILE, TRACE_FILE, prepare_out_dir, write_summary
from husky_sim.runs.scenario import Scenario, load_scenario
from husky_sim.runs.summary import KinematicMetrics, Model, RunSettings, RunSummary
from husky_sim.sim.episode import run_episode

if TYPE_CHECKING:
    from husky_sim.runs.foxglove_record import FoxgloveRecorder


def resolved(
    scenario: Scenario | str,
    horizon: int | None = None,
    gamma: float | None = None,
    seed: int | None = None,
    solver: str | None = None,
) -> Scenario:
    """The scenario (a shipped name, a path or a Scenario) with the overrides applied and validated
    by the schema: the one place a run's N, gamma, seed and solver backend are decided
    (Scenario.with_overrides)."""
    sc = load_scenario(scenario) if isinstance(scenario, str) else scenario
    overrides = (horizon, gamma, seed, solver)
    return sc.with_overrides(*overrides) if overrides != (None, None, None, None) else sc


def run_settings(sc: Scenario, controller: str, model: Model = "physics") -> tuple[RunSettings, float]:
    """Which controller runs on the resolved scenario with which settings (building the controller
    is not needed), and the controller's robot circle (m)."""
    plan = sc.plan_profile(controller)
    nmpc_config, omega_max = plan.nmpc, plan.omega_cmd_max_radps
    settings = RunSettings(
        scenario=sc.name,
        controller=controller,
        horizon=nmpc_config.horizon,
        gamma=nmpc_config.gamma,
        seed=sc.seed,
        model=model,
        tau_s=nmpc_config.tau_s,
        prediction_time_s=nmpc_config.horizon * nmpc_config.tau_s,
        v_min_mps=nmpc_config.v_min_mps,
        v_max_mps=nmpc_config.v_max_mps,
        omega_max_radps=omega_max,
        solver=nmpc_config.solver.backend,
        robot=sc.robot.model,
    )
    return settings, nmpc_config.robot_radius_m


def run_scenario(
    scenario: Scenario | str,
    controller: str,
    horizon: int | None = None,
    gamma: float | None = None,
    seed: int | None = None,
    out_dir: Path | None = None,
    implementation: Controller | None = None,
    live_port: int | None = None,
    solver: str | None = None,
    full_record: bool = True,
) -> RunSummary:
    """Run a scenario; return the summary (also written to out_dir/summary.json, with the log,
    the trace and run.mcap for Foxglove; `live_port` also streams it to Foxglove while it runs).
    Without `full_record` out_dir gets the summary and the log only (a campaign's many runs: the
    trace and the recording hold every obstacle at every sample and are the bulk of a folder).

    `implementation` runs in the controller's place (a rehearsal's DDS robot, whose decisions come
    from the named controller in another process); by default the named controller is built here.
    """
    sc = resolved(scenario, horizon, gamma, seed, solver)
    settings, robot_radius_m = run_settings(sc, controller)
    nmpc = implementation if implementation is not None else sc.make_controller(controller)
    episode_config = sc.episode_config()
    if out_dir is not None:
        prepare_out_dir(out_dir)
    log_path = out_dir / LOG_FILE if out_dir is not None else None
    reference = sc.reference_object()
    recorder = _recorder(sc, reference, out_dir if full_record else None, live_port)
    finished = False
    try:
        result = run_episode(
            nmpc, reference, episode_config, log_path, robot_radius_m=robot_radius_m, observer=recorder
        )
        finished = True
    except (RunInterrupted, KeyboardInterrupt) as exc:  # before the first control step
        signum = interrupts.signum_of(exc)
        if out_dir is not None:
            name = signal.Signals(signum).name
            partial = {"outcome": "interrupted", "interrupted_by": name, "steps": 0}
            write_summary(out_dir, {**asdict(settings), **partial})
        raise RunInterrupted(signum) from None
    finally:  # a recording cut short is still a valid file, and says so
        if recorder is not None and not finished:
            with interrupts.deferred():
                recorder.close("ended early", "(interrupted or failed before its first control step)")
    summary = RunSummary(settings, result.metrics)
    if recorder is not None:
        with interrupts.deferred():
            recorder.close(result.metrics.outcome, f"after {result.metrics.steps} steps")
    if out_dir is not None:
        if full_record:
            with interrupts.deferred():
                result.trace.save(out_dir / TRACE_FILE)
        write_summary(out_dir, summary)
    if result.interrupted_by is not None:
        raise RunInterrupted(result.interrupted_by)
    return summary


def _recorder(
    sc: Scenario, reference: Reference, out_dir: Path | None, live_port: int | None
) -> FoxgloveRecorder | None:
    """The run's Foxglove recorder (run.mcap in out_dir, and live on live_port), or None when
    neither is asked for, or when only run.mcap is and the Foxglove SDK (the `foxglove` extra) is
    not installed: then the run folder has no run.mcap, and a warning says why."""
    if out_dir is None and live_port is None:
        return None
    try:
        from husky_sim.runs.foxglove_record import MCAP_NAME, FoxgloveRecorder
    except MissingExtra as exc:
        if live_port is not None:
            raise
        warnings.warn(f"no run.mcap: {exc}", stacklevel=2)
        return None
    specs = sc.obstacle_specs()
    path = out_dir / MCAP_NAME if out_dir is not None else None
    return FoxgloveRecorder(
        path,
        reference,
        [o.radius_m for o in specs],
        [o.height_m for o in specs],
        sc.robot.description().geometry.footprint_half_extents_m,
        sc.tau_s,
        sc.duration_s,
        live_port,
    )


def run_scenario_kinematic(
    scenario: Scenario | str,
    controller: str,
    horizon: int | None = None,
    gamma: float | None = None,
    robot_radius_m: float | None = None,
) -> RunSummary:
    """The same scenario on the controller's own unicycle model (no physics; the paper's setting).

    Clearance is measured on the circle model; `robot_radius_m` overrides the scenario's circle
    (the paper's simulations use 0.25 m). Outcome names follow the PyBullet runs': a set-point run
    is `reached`, `collided`, `stuck` (mean |v| and |omega| of the last 10 steps below the
    scenario's thresholds, away from the goal) or `timeout`; a tracking run is `tracking`,
    `collided` or `stuck`.
    """
    from dataclasses import replace

    import numpy as np

    from controllers import SetPoint
    from husky_sim.sim.kinematic import run_kinematic
    from husky_sim.sim.metrics import (
        NO_TRACKING_FIELDS,
        count_reversals,
        judge_tracking,
        solver_times,
        tracking_rmse,
    )
    from husky_sim.sim.outcomes import final_outcome, reference_reachable

    sc = resolved(scenario, horizon, gamma)
    entry = registry.entry(controller)
    if not entry.paper:
        paper = ", ".join(registry.paper_names())
        raise ValueError(f"controller: the kinematic loop runs the paper's ({paper}), got {controller!r}")
    config = sc.controller_config(controller)
    if robot_radius_m is not None:
        config = replace(config, robot_radius_m=robot_radius_m)
    problem = sc.kinematic_problem(config.robot_radius_m)
    obstacles, reference = problem.obstacles, problem.reference
    outcomes = sc.episode_config().outcomes
    ep = run_kinematic(
        entry.build(config),
        problem.start,
        reference,
        obstacles,
        sc.tau_s,
        problem.duration_s,
        problem.robot_radius_m,
        outcomes,
    )
    is_setpoint = isinstance(reference, SetPoint)
    refs = reference.states_at(ep.times_s)
    errors = np.hypot(*(ep.states[:, :2] - refs[:, :2]).T)
    rmse = None if is_setpoint else tracking_rmse(errors, ep.times_s, outcomes.tracking_settle_s)
    collided = ep.outcome == "collided"
    outcome = final_outcome(ep.outcome, collided=collided, is_setpoint=is_setpoint)
    judgement = None
    if not is_setpoint:
        # the robot here is the controller's circle (config.robot_radius_m), not the URDF footprint:
        # it is the body this model's clearance and collisions are measured on, so a reference point
        # is reachable exactly when that body could stand on it without collision
        centres = (
            np.stack([o.position_after(ep.times_s) for o in obstacles], axis=1)
            if obstacles
            else np.zeros((len(ep.times_s), 0, 2))
        )
        reachable = reference_reachable(
            refs[:, :2], centres, np.array([o.radius_m for o in obstacles]), config.robot_radius_m
        )
        judgement = judge_tracking(outcome, ep.times_s, errors, reachable, sc.tau_s, outcomes)
    converged = outcome == "reached" if is_setpoint else judgement.converged
    reversals, reverse_steps = count_reversals(ep.controls[:, 0])
    settings, _ = run_settings(sc, controller, model="kinematic")
    return RunSummary(
        settings,
        KinematicMetrics(
            outcome=outcome,
            collided=collided,
            converged=bool(converged),
            min_clearance_m=ep.min_clearance_m if obstacles else None,
            final_position_error_m=float(errors[-1]),
            tracking_rmse_m=rmse,
            **(NO_TRACKING_FIELDS if judgement is None else judgement.fields()),
            time_to_goal_s=ep.time_to_goal_s,
            reversals=reversals,
            reverse_steps=reverse_steps,
            max_abs_v_mps=float(np.max(np.abs(ep.controls[:, 0]))),
            max_abs_omega_radps=float(np.max(np.abs(ep.controls[:, 1]))),
            safety_active_steps=ep.safety_active_steps,
            fallbacks=ep.fallbacks,
            solve_ms_median=float(np.median(solver_times(1000.0 * ep.solve_time_s, ep.repeated))),
            repeated_steps=int(np.sum(ep.repeated)),
            robot_radius_m=config.robot_radius_m,
            steps=len(ep.controls),
            t_s=ep.times_s[:-1].tolist(),
            x_m=ep.states[:-1, 0].tolist(),
            y_m=ep.states[:-1, 1].tolist(),
            ref_x_m=refs[:-1, 0].tolist(),
            ref_y_m=refs[:-1, 1].tolist(),
            v_cmd_mps=ep.controls[:, 0].tolist(),
            omega_cmd_radps=ep.controls[:, 1].tolist(),
        ),
    )
