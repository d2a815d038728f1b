"""The paper's three controllers in kinematic closed loops whose outputs are pinned bit for bit
(tests/controllers/test_paper_unchanged.py); `python -m tests.controllers.paper_kinematic_runs`
rewrites the reference file, which is only right when a change to those controllers is intended
and explained."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controllers import NMPCConfig, NMPCController
from controllers.config import SolverOptions
from husky_sim.runs.paper_problems import CLUTTERED_POINT_STABILISATION, PAPER_POINT_STABILISATION
from husky_sim.sim.kinematic import run_kinematic

REFERENCE_FILE = Path(__file__).parent / "data" / "paper_kinematic_outputs.npz"
PROBLEMS = {p.name: p for p in (PAPER_POINT_STABILISATION, CLUTTERED_POINT_STABILISATION)}
CASES = [(p, v, n) for p in PROBLEMS for v in ("bt", "cbf", "relax-cbf") for n in (5, 12)]
DURATION_S = 20.0  # long enough to pass (or stall at) the obstacle


def case_key(problem: str, variant: str, horizon: int) -> str:
    return f"{problem}__{variant}__N{horizon}"


def run_case(problem: str, variant: str, horizon: int) -> dict[str, np.ndarray]:
    """States, controls, s_h minima and fallback count of one kinematic closed loop."""
    p = PROBLEMS[problem]
    cfg = NMPCConfig(
        safety=variant,
        horizon=horizon,
        robot_radius_m=p.robot_radius_m,
        obstacle_slots=len(p.obstacles),
        solver=SolverOptions(backend="ipopt"),  # the reference backend the outputs were pinned with
    )
    ep = run_kinematic(
        NMPCController(cfg), p.start, p.reference, p.obstacles, cfg.tau_s, DURATION_S, p.robot_radius_m
    )
    return {
        "states": ep.states,
        "controls": ep.controls,
        "min_decay_slack": ep.min_decay_slack,
        "fallbacks": np.array(ep.fallbacks),
    }


if __name__ == "__main__":
    arrays = {}
    for case in CASES:
        out = run_case(*case)
        print(case, "fallbacks", int(out["fallbacks"]), "steps", len(out["controls"]))
        arrays.update({f"{case_key(*case)}__{k}": v for k, v in out.items()})
    REFERENCE_FILE.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCE_FILE, **arrays)
