"""Controllers built for the same problem in one process share one FATROP solver
(controllers.backends.shared): each must then run exactly as it would on a solver of its own,
whatever the other asked the solver in between."""

import numpy as np
import pytest

from controllers import NMPCConfig, NMPCController, Obstacle, SetPoint
from controllers.backends import IpoptSolver
from controllers.backends.shared import SHARED_SOLVERS, forget_shared_solvers
from controllers.config import SolverOptions
from controllers.model import step
from husky_sim.runs.scenario import load_scenario

CONFIG = NMPCConfig(safety="relax-cbf", horizon=5, gamma=0.1, obstacle_slots=2)
GOAL = SetPoint(3.0, 0.0, 0.0)
OBSTACLES = [Obstacle(1.5, 0.1, 0.4), Obstacle(2.2, -1.0, 0.3, 0.0, 0.4)]


def _lockstep(controllers: list[NMPCController], starts: list[np.ndarray], steps: int) -> list[list]:
    """Each controller drives its own unicycle from its start, one step each in turn; per
    controller, the (control, status, fallback, solver) of every step."""
    states = [s.copy() for s in starts]
    records: list[list] = [[] for _ in controllers]
    for k in range(steps):
        for i, controller in enumerate(controllers):
            result = controller.solve(states[i], GOAL, OBSTACLES, k * CONFIG.tau_s)
            records[i].append((result.control.tobytes(), result.status, result.fallback, result.solver))
            states[i] = step(states[i], result.control, CONFIG.tau_s)
    return records


def test_one_solver_per_problem_and_the_most_recent_ones_kept() -> None:
    forget_shared_solvers()
    first, again = NMPCController(CONFIG), NMPCController(CONFIG)
    other = NMPCController(CONFIG.with_(gamma=0.2))
    assert first._backend is again._backend and other._backend is not first._backend
    for gamma in np.linspace(0.3, 0.9, SHARED_SOLVERS):  # as many other problems as are kept
        NMPCController(CONFIG.with_(gamma=float(gamma)))
    assert NMPCController(CONFIG)._backend is not first._backend  # the oldest was dropped
    ipopt = CONFIG.with_(solver=SolverOptions(backend="ipopt"))
    one, two = NMPCController(ipopt), NMPCController(ipopt)
    assert isinstance(one._backend, IpoptSolver) and one._backend is not two._backend  # warm-started


def test_controllers_sharing_a_solver_run_as_they_would_alone() -> None:
    starts = [np.array([0.0, 0.0, 0.0]), np.array([0.2, -0.6, 0.3])]
    alone = []
    for start in starts:
        forget_shared_solvers()
        alone += _lockstep([NMPCController(CONFIG)], [start], 25)
    forget_shared_solvers()
    pair = [NMPCController(CONFIG), NMPCController(CONFIG)]
    assert pair[0]._backend is pair[1]._backend
    together = _lockstep(pair, starts, 25)
    assert together == alone
    assert {solver for run in alone for *_, solver in run} >= {"fatrop"}


@pytest.mark.parametrize("scenario", ["head_on_moving_obstacle"])
def test_a_sweep_builds_husky_cbf_once_per_problem(scenario: str) -> None:
    """Samples of a check with one payload differ in the robot and the world, not in the NLPs (the
    pose filter's noise is no part of them): a second controller reuses the first's solvers. The
    payload is: husky-cbf plans with the yaw lag of the payload it is told, so another payload
    is another problem."""
    from dataclasses import replace

    from husky_sim.realcheck.check import CheckOptions
    from husky_sim.realcheck.sweep import apply_perturbation, sample_perturbations

    forget_shared_solvers()
    base = load_scenario(scenario)
    ranges = replace(CheckOptions().ranges, payload_kg=(10.0, 10.0)).for_robot(base.robot.description())
    samples = [apply_perturbation(base, p) for p in sample_perturbations(ranges, 2, 0)]
    first, second = (s.make_controller("husky-cbf") for s in samples)
    assert samples[0].controller_config("husky-cbf") != samples[1].controller_config("husky-cbf")
    assert first._hard is second._hard and first._soft is second._soft
    heavier = replace(ranges, payload_kg=(40.0, 40.0))
    loaded = apply_perturbation(base, sample_perturbations(heavier, 1, 0)[0]).make_controller("husky-cbf")
    assert loaded._hard is not first._hard
