"""A problem posed again bit for bit is answered as before, not solved again
(controllers.backends.repeats): the answer must be exactly the one solving would give, and a step
that ran no solver must be marked, so that its lookup time never passes for a solve time."""

import numpy as np
import pytest

from controllers import NMPCController, Obstacle
from controllers.backends import FatropSolver
from controllers.backends.nlp import RawSolution
from controllers.backends.repeats import RepeatedProblems
from controllers.ocp import paper_nlp
from husky_sim.runs.scenario import load_scenario
from husky_sim.sim.kinematic import run_kinematic
from husky_sim.sim.metrics import solver_times


class Counting:
    """A pure stand-in solver that counts its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        self.calls += 1
        return RawSolution(parameters + guess, True, "Solve_Succeeded", 3, "fatrop")


def test_the_same_bytes_are_looked_up_for_one_step_more_and_then_forgotten() -> None:
    repeats, solve = RepeatedProblems(), Counting()
    p, guess = np.array([1.0, 2.0]), np.array([0.5, 0.5])
    first, looked_up = repeats.solve(solve, p, guess)
    assert not looked_up and solve.calls == 1
    first.decision[:] = -1.0  # what a caller does with its answer is its own
    repeats.next_step()
    again, looked_up = repeats.solve(solve, p.copy(), guess.copy())
    assert looked_up and solve.calls == 1 and np.array_equal(again.decision, [1.5, 2.5])
    _, looked_up = repeats.solve(solve, p, guess + np.array([0.0, 1e-15]))
    assert not looked_up and solve.calls == 2  # one bit off is another problem
    repeats.next_step()
    repeats.next_step()  # two steps without it
    _, looked_up = repeats.solve(solve, p, guess)
    assert not looked_up and solve.calls == 3


def _deadlock(monkeypatch: pytest.MonkeyPatch) -> tuple[NMPCController, dict]:
    """The paper's Relax-CBF, N = 5, started inside an obstacle's circle: every problem is
    infeasible, every retry fails, the robot brakes and stands still bit for bit. Reachability
    proves these problems infeasible before any solver is asked (controllers.reachability); the
    proof is switched off here, as for a problem it cannot decide, so that the solves are what
    is looked up."""
    monkeypatch.setattr("controllers.nmpc.proven_infeasible", lambda config, params: "")
    scenario = load_scenario("paper_point_stabilisation").with_overrides(horizon=5)
    config = scenario.controller_config("relax-cbf")
    problem = scenario.kinematic_problem()
    loop = dict(
        start=(0.0, 0.0, 0.0),
        reference=problem.reference,
        obstacles=[Obstacle(0.3, 0.0, 0.5)],
        tau_s=scenario.tau_s,
        duration_s=1.0,
        robot_radius_m=config.robot_radius_m,
    )
    return NMPCController(config), loop


def test_fatrop_answers_depend_on_the_problem_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    """What makes the lookup exact: the same (parameters, guess) solved again, after other problems
    in between, gives the same bits, for an infeasible problem (FATROP's failure and IPOPT's
    verdict) and a solvable one."""
    controller, loop = _deadlock(monkeypatch)
    recorded: list[tuple[np.ndarray, np.ndarray]] = []
    controller.on_solve = lambda p, guess: recorded.append((p.copy(), guess.copy()))
    run_kinematic(controller, **{**loop, "duration_s": 0.1})
    controller.reset()
    controller.solve(np.array([-2.0, 0.0, 0.0]), loop["reference"], loop["obstacles"], 0.0)
    (infeasible_p, infeasible_guess), (solvable_p, solvable_guess) = recorded
    solver = FatropSolver(paper_nlp(controller.config), controller.config.solver)
    first = [solver.solve(infeasible_p, infeasible_guess), solver.solve(solvable_p, solvable_guess)]
    again = [solver.solve(solvable_p, solvable_guess), solver.solve(infeasible_p, infeasible_guess)][::-1]
    assert not first[0].success and first[0].fallback_reason.startswith("fatrop: ") and first[1].success
    for a, b in zip(first, again, strict=True):
        assert a.decision.tobytes() == b.decision.tobytes()
        assert (a.success, a.status, a.iterations, a.solver, a.fallback_reason) == (
            b.success,
            b.status,
            b.iterations,
            b.solver,
            b.fallback_reason,
        )


def test_a_deadlocked_loop_runs_the_same_with_and_without_lookups(
    monkeypatch: pytest.MonkeyPatch, fatrop_solves: dict[str, int]
) -> None:
    controller, loop = _deadlock(monkeypatch)
    calls = fatrop_solves
    looked_up = run_kinematic(controller, **loop)
    with_lookups = calls["n"]
    monkeypatch.setattr(FatropSolver, "pure", False)  # the controller then solves every problem
    calls["n"] = 0
    solved = run_kinematic(NMPCController(controller.config), **loop)
    assert np.array_equal(solved.states, looked_up.states) and np.ptp(solved.states, axis=0).max() == 0.0
    assert np.array_equal(solved.controls, looked_up.controls)
    assert solved.statuses == looked_up.statuses and solved.fallbacks == looked_up.fallbacks == 10
    assert np.array_equal(solved.min_decay_slack, looked_up.min_decay_slack)
    # the first step solves its distinct problems (its brake retry is its first problem again);
    # every later step poses the same ones and runs no solver
    assert looked_up.repeated.tolist() == [0] + [1] * 9 and not solved.repeated.any()
    assert with_lookups == 3 and calls["n"] == 10 * 4
    # solve-time figures count the step that solved, not the lookups
    assert solver_times(looked_up.solve_time_s, looked_up.repeated).tolist() == [looked_up.solve_time_s[0]]
