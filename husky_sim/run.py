"""Run one scenario with one controller in PyBullet and write `summary.json` and `log.csv`."""

from __future__ import annotations

import json
from pathlib import Path

from controllers import NMPCController, SafetyConstraint
from husky_sim.episode import run_episode
from husky_sim.scenario import Scenario, load_scenario


def run_dir_name(scenario: str, controller: str, horizon: int, gamma: float, seed: int) -> str:
    return f"{scenario}__{controller}__N{horizon}__g{gamma:g}__s{seed}"


def run_scenario(
    scenario: Scenario | str,
    controller: SafetyConstraint,
    horizon: int | None = None,
    gamma: float | None = None,
    seed: int | None = None,
    out_dir: Path | None = None,
) -> dict[str, object]:
    """Run a scenario; return the summary (also written to out_dir/summary.json, with the log)."""
    sc = load_scenario(scenario) if isinstance(scenario, str) else scenario
    nmpc_config = sc.controller_config(controller, horizon, gamma)
    episode_config = sc.episode_config(seed)
    log_path = out_dir / "log.csv" if out_dir is not None else None
    result = run_episode(
        NMPCController(nmpc_config),
        sc.reference_object(),
        episode_config,
        log_path,
        robot_radius_m=nmpc_config.robot_radius_m,
    )
    summary: dict[str, object] = {
        "scenario": sc.name,
        "controller": controller,
        "horizon": nmpc_config.horizon,
        "gamma": nmpc_config.gamma,
        "seed": episode_config.seed,
        "tau_s": nmpc_config.tau_s,
        "prediction_time_s": nmpc_config.horizon * nmpc_config.tau_s,
        "v_min_mps": nmpc_config.v_min_mps,
        "v_max_mps": nmpc_config.v_max_mps,
        "omega_max_radps": nmpc_config.omega_max_radps,
        **result.metrics.as_dict(),
    }
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        result.trace.save(out_dir / "trace.npz")
        (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
