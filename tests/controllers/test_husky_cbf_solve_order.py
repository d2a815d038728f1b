"""husky-cbf's order of solves (controllers/husky_cbf/controller.py, step 5), with its real
solvers: the hard OCP first; after a plan that needed the penalised obstacle slack, the penalised
OCP first, its plan taken only if it needs the slack again; else the hard OCP, as usual."""

from __future__ import annotations

import numpy as np

from controllers import Obstacle
from controllers.backends import RawSolution
from controllers.references import SetPoint
from husky_sim.runs.scenario import load_scenario, shipped_scenarios


def test_after_a_plan_that_needed_slack_the_penalised_problem_goes_first() -> None:
    path = next(p for p in shipped_scenarios() if p.stem == "paper_dynamic_tracking")
    controller = load_scenario(path).make_controller("husky-cbf")
    calls: list[tuple[str, bool]] = []

    def record(name: str, solver: object) -> None:
        solve = solver.solve

        def recorded(parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
            raw = solve(parameters, guess)
            calls.append((name, raw.success))
            return raw

        solver.solve = recorded

    record("hard", controller._hard)
    record("soft", controller._soft)
    goal, pose = SetPoint(3.0, 0.0, 0.0), np.zeros(3)
    overlapping = [Obstacle(0.45, 0.0, 0.3)]  # over the robot's front disc: no hard plan exists
    clear = [Obstacle(0.45, 4.0, 0.3)]
    seen = []
    for k, obstacles in enumerate([overlapping, overlapping, clear, clear]):
        calls.clear()
        result = controller.solve(pose, goal, obstacles, 0.1 * k)
        seen.append((list(calls), result.recovered_by, result.soft_constraint))
    assert seen[0] == ([("hard", False), ("soft", True)], "penalty", True)  # the hard one fails first
    assert seen[1] == ([("soft", True)], "penalty", True)  # then the penalised one goes first
    assert seen[2] == ([("soft", True), ("hard", True)], "", False)  # no slack needed: the hard plan
    assert seen[3] == ([("hard", True)], "", False)  # and the hard one goes first again
