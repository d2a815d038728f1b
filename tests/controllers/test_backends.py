"""Solver backends: the stage-wise transcription is the same OCP, FATROP's answers match IPOPT's,
its failures fall back to IPOPT and are reported, and compiled solvers are cached and reused."""

import fcntl
import math
import os
import re
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from controllers import NMPCConfig, NMPCController, Obstacle, SetPoint
from controllers.backends import FatropSolver, IpoptSolver
from controllers.backends import compiled as compiled_module
from controllers.backends.compiled import FATROP_RETURN_FLAGS, cache_dir, compiled
from controllers.backends.nlp import NLP, RawSolution
from controllers.backends.stagewise import NotStagewiseError, StageIndices, transcribe
from controllers.config import SolverOptions
from controllers.husky_cbf.ocp import build_problem
from controllers.model import step
from controllers.ocp import OCPParameters, Plan, layout_for, paper_nlp
from husky_sim.runs.scenario import load_scenario


def _feasible_point(config: NMPCConfig, rng: np.random.Generator) -> np.ndarray:
    """A decision vector with closed gaps (a rollout of random controls) and random slacks."""
    n = config.horizon
    controls = rng.uniform(-1, 1, size=(n, 2))
    states = [rng.uniform(-2, 2, size=3)]
    for u in controls:
        states.append(step(states[-1], u, config.tau_s))
    plan = Plan(np.array(states), controls, rng.uniform(0, 1, n), rng.uniform(0, 1, n))
    return plan.to_vector(layout_for(config))


def _parameters(config: NMPCConfig, state: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    n, slots = config.horizon, config.obstacle_slots
    return OCPParameters(
        state,
        rng.uniform(-3, 3, size=(n + 1, 3)),
        rng.uniform(-1, 1, size=(n, 2)),
        rng.uniform(-3, 3, size=(slots, n + 1, 2)),
        rng.uniform(0.2, 0.6, size=slots),
    ).to_vector()


@pytest.mark.parametrize("variant", ["bt", "cbf", "relax-cbf"])
def test_stagewise_rows_equal_the_declared_rows_on_the_feasible_set(variant: str) -> None:
    config = NMPCConfig(safety=variant, horizon=4, obstacle_slots=2)
    nlp = paper_nlp(config)
    lbx, ubx, lbg, ubg = nlp.bounds
    stagewise = transcribe(nlp.problem, lbg, ubg, nlp.stages)
    declared = ca.Function("g", [nlp.problem["x"], nlp.problem["p"]], [nlp.problem["g"]])
    reordered = ca.Function("g_s", [stagewise.nlp["x"], stagewise.nlp["p"]], [stagewise.nlp["g"]])
    rng = np.random.default_rng(3)
    for _ in range(5):
        w = _feasible_point(config, rng)
        p = _parameters(config, w[:3], rng)
        g = np.asarray(declared(w, p)).ravel()
        g_s = np.asarray(reordered(stagewise.to_stage_order(w), p)).ravel()
        assert np.allclose(g_s, g[stagewise.rows], atol=1e-9, rtol=1e-12)
    assert sorted(stagewise.rows.tolist()) == list(range(g.size))


def test_stagewise_rows_read_only_their_stage() -> None:
    """Every row of stage k reads only x_k, u_k (and x_(k+1) in the dynamics gaps)."""
    config = NMPCConfig(safety="relax-cbf", horizon=3, obstacle_slots=1)
    nlp = paper_nlp(config)
    stagewise = transcribe(nlp.problem, *nlp.bounds[2:], nlp.stages)
    stage_of = np.empty(stagewise.order.size, dtype=int)
    for k, (x, u) in enumerate(zip(nlp.stages.states, [*nlp.stages.controls, ()], strict=True)):
        for i in (*x, *u):
            stage_of[np.flatnonzero(stagewise.order == i)[0]] = k
    rows, cols = ca.jacobian_sparsity(stagewise.nlp["g"], stagewise.nlp["x"]).get_triplet()
    for r in set(rows):
        stages = {int(stage_of[c]) for rr, c in zip(rows, cols, strict=True) if rr == r}
        assert max(stages) - min(stages) <= 1, (r, stages)


def test_a_row_across_two_stages_is_refused() -> None:
    x = ca.SX.sym("x", 3)  # x_0, x_1, x_2 (scalar states), no controls' effect on x_2 - x_0
    u = ca.SX.sym("u", 2)
    w = ca.vertcat(x[0], u[0], x[1], u[1], x[2])
    g = ca.vertcat(x[1] - (x[0] + u[0]), x[2] - (x[1] + u[1]), x[2] - x[0])
    stages = StageIndices(((0,), (2,), (4,)), ((1,), (3,)))
    with pytest.raises(NotStagewiseError, match="constraint row 2"):
        transcribe({"x": w, "p": ca.SX.sym("p", 0), "f": ca.sumsqr(u), "g": g}, [0, 0, 0], [0, 0, 1], stages)


def test_husky_cbf_problems_are_stagewise() -> None:
    config = load_scenario("head_on_moving_obstacle").with_overrides(horizon=5).controller_config("husky-cbf")
    for soft in (False, True):
        problem = build_problem(config, 5, config.slots, soft)
        stagewise = transcribe(problem.nlp.problem, *problem.nlp.bounds[2:], problem.nlp.stages)
        assert stagewise.nlp["g"].numel() == problem.nlp.problem["g"].numel()


def _one_problem() -> tuple[NMPCConfig, np.ndarray, np.ndarray]:
    """A relax-cbf problem with an obstacle on the way, as the closed loop poses it."""
    config = NMPCConfig(safety="relax-cbf", horizon=5, solver=SolverOptions(backend="ipopt"))
    controller = NMPCController(config)
    recorded: list[tuple[np.ndarray, np.ndarray]] = []
    controller.on_solve = lambda p, guess: recorded.append((p, guess))
    start, goal = np.array([0.0, 0.0, math.pi / 2]), SetPoint(0.0, 4.0, math.pi / 2)
    controller.solve(start, goal, [Obstacle(0.1, 2.0, 0.5)], 0.0)
    return config, *recorded[0]


def test_fatrop_answers_like_ipopt() -> None:
    config, p, guess = _one_problem()
    reference = IpoptSolver(paper_nlp(config), SolverOptions()).solve(p, guess)
    raw = FatropSolver(paper_nlp(config), SolverOptions()).solve(p, guess)
    assert raw.success and raw.solver == "fatrop" and not raw.fallback_reason
    assert np.max(np.abs(raw.decision - reference.decision)) < 1e-4


class StandIn:
    """In place of the compiled FATROP function (called as `call([x0, p, bounds...])`): raises
    `error`, or returns `answer` ([x, g] in stage order) whatever it is asked."""

    def __init__(self, error: Exception | None = None, answer: list[ca.DM] | None = None) -> None:
        self.error, self.answer = error, answer

    def call(self, _args: list[object]) -> list[ca.DM]:
        if self.error is not None:
            raise self.error
        assert self.answer is not None
        return self.answer


def test_fatrop_failures_fall_back_to_ipopt_and_say_why() -> None:
    """A real FATROP exit that is not accepted (its iteration cap, read through the status shim),
    a solver error and an answer that violates the constraints are all handed to IPOPT, which
    answers the same problem, and the fallback names FATROP's exit."""
    config, p, guess = _one_problem()
    reference = IpoptSolver(paper_nlp(config), SolverOptions()).solve(p, guess)

    capped = FatropSolver(paper_nlp(config), SolverOptions(max_iter=2)).solve(p, guess)
    assert capped.solver == "ipopt"  # IPOPT runs under the same cap, so it need not converge
    assert capped.fallback_reason.startswith("fatrop: MaxIterExceeded after ")
    # without its fallback the same exit comes back as FATROP's failure, and IPOPT is never built
    solver = FatropSolver(paper_nlp(config), SolverOptions(max_iter=2))
    alone = solver.solve_without_fallback(p, guess)
    assert not alone.success and alone.solver == "fatrop"
    assert alone.status.startswith("MaxIterExceeded after ")
    assert np.array_equal(alone.decision, guess) and solver._reference is None

    solver = FatropSolver(paper_nlp(config), SolverOptions())
    solver._function = StandIn(error=RuntimeError("Evaluation failed"))
    raw = solver.solve(p, guess)
    assert raw.success and raw.solver == "ipopt" and raw.fallback_reason == "fatrop: solver error"
    assert np.max(np.abs(raw.decision - reference.decision)) < 1e-6

    solver = FatropSolver(paper_nlp(config), SolverOptions())
    stagewise = solver._stagewise
    infeasible = stagewise.to_stage_order(guess)
    g = ca.Function("g", [stagewise.nlp["x"], stagewise.nlp["p"]], [stagewise.nlp["g"]])
    # the status shim reports the library's last real exit: a real solve makes it an accepted one
    assert solver.solve(p, guess).solver == "fatrop"
    solver._function = StandIn(answer=[ca.DM(infeasible), g(infeasible, p)])
    raw = solver.solve(p, guess)
    assert raw.solver == "ipopt" and raw.fallback_reason.startswith("fatrop: constraint check")


def test_a_failed_step_asks_ipopt_once_and_retries_on_fatrop_alone(
    monkeypatch: pytest.MonkeyPatch, fatrop_solves: dict[str, int]
) -> None:
    """A paper controller's failed step: its own problem falls back to IPOPT, its retries from the
    recovery guesses are FATROP's alone (controllers.nmpc), and the brake guess, the first one
    again, is not solved twice. The robot is 0.02 m inside two circles, ahead and behind (the
    squeeze of test_reachability, its proof switched off so that the solvers are asked)."""
    monkeypatch.setattr("controllers.nmpc.proven_infeasible", lambda config, params: "")
    ipopt_solves = {"n": 0}
    solve = IpoptSolver.solve

    def counted(self: IpoptSolver, parameters: np.ndarray, guess: np.ndarray) -> RawSolution:
        ipopt_solves["n"] += 1
        return solve(self, parameters, guess)

    monkeypatch.setattr(IpoptSolver, "solve", counted)
    config = NMPCConfig(safety="bt", horizon=5, gamma=0.1, obstacle_slots=2)
    obstacles = [Obstacle(0.73, 0.0, 0.5), Obstacle(-0.73, 0.0, 0.5)]
    result = NMPCController(config).solve(np.zeros(3), SetPoint(3.0, 0.0, 0.0), obstacles, 0.0)
    assert not result.success and result.fallback == "brake" and result.recovered_by == ""
    assert result.solver == "ipopt" and result.solver_fallback.startswith("fatrop: ")
    # FATROP from the first guess, the reverse and the straight ones; IPOPT from the first only
    assert fatrop_solves["n"] == 3 and ipopt_solves["n"] == 1


def test_fatrop_never_sees_non_finite_data() -> None:
    """FATROP does not check its inputs (a NaN made it spin without end): a NaN parameter goes
    straight to IPOPT, which reports the invalid number as a failed solve."""
    config, p, guess = _one_problem()
    broken = p.copy()
    broken[0] = np.nan
    raw = FatropSolver(paper_nlp(config), SolverOptions()).solve(broken, guess)
    assert raw.fallback_reason == "fatrop: non-finite parameters or guess" and not raw.success


def test_fatrop_reports_its_exit_and_iterations() -> None:
    """The compiled solver's status shim gives FATROP's own exit flag and iteration count."""
    config, p, guess = _one_problem()
    raw = FatropSolver(paper_nlp(config), SolverOptions()).solve(p, guess)
    assert raw.solver == "fatrop" and raw.status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    assert 1 <= raw.iterations < SolverOptions().max_iter


def test_fatrop_exit_names_match_the_shipped_header() -> None:
    """The shim reports FATROP's enum by position: its names must be the header's, in order."""
    header = Path(ca.__file__).parent / "include" / "fatrop" / "ip_algorithm" / "ip_algorithm.hpp"
    body = re.search(r"enum class IpSolverReturnFlag\s*\{(.*?)\}", header.read_text(), re.S)
    assert body is not None, f"no IpSolverReturnFlag in {header}"
    names = re.findall(r"^\s*(\w+)\s*,?", re.sub(r"//[^\n]*", "", body.group(1)), re.M)
    assert tuple(names) == FATROP_RETURN_FLAGS


def test_fatrop_is_the_default_backend() -> None:
    assert SolverOptions().backend == "fatrop"
    assert NMPCController(NMPCConfig()).backend_name == "fatrop"


def test_compiled_solver_is_cached_and_reused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HUSKY_SIM_SOLVER_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 2)
    function = ca.Function("cache_probe", [x], [ca.sumsqr(x) + ca.sin(x[0])])
    first = compiled(function)
    assert cache_dir() == tmp_path and len(list(tmp_path.glob("cache_probe_*.so"))) == 1
    monkeypatch.setenv("CC", "no-such-compiler")  # a cache hit needs no compiler
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = compiled(function)
    assert float(again([0.3, -0.2])) == pytest.approx(float(function([0.3, -0.2])), abs=1e-15)
    assert float(first([1.0, 2.0])) == pytest.approx(float(function([1.0, 2.0])), abs=1e-15)


def test_the_cache_forgets_libraries_unused_for_a_month(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """After a compile, libraries unused for CACHE_MAX_AGE_DAYS go with their locks; a lookup
    marks a library used, so a library in use is never pruned, and a locked one is left."""
    monkeypatch.setenv("HUSKY_SIM_SOLVER_CACHE", str(tmp_path))
    x = ca.SX.sym("x")
    old, kept = ca.Function("prune_old", [x], [x + 1]), ca.Function("prune_kept", [x], [x + 2])
    compiled(old), compiled(kept)
    month_ago = time.time() - (compiled_module.CACHE_MAX_AGE_DAYS + 1) * 86400
    for library in tmp_path.glob("*.so"):
        os.utime(library, (month_ago, month_ago))
    compiled(kept)  # a cache hit: marked used now
    busy = tmp_path / "prune_busy_0.so"
    busy.write_bytes(b"")
    os.utime(busy, (month_ago, month_ago))
    with open(busy.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process compiling it now
        compiled(ca.Function("prune_new", [x], [x + 3]))  # a compile prunes
    names = sorted(p.name.split("_")[1] + p.suffix for p in tmp_path.iterdir())
    assert names == ["busy.lock", "busy.so", "kept.lock", "kept.so", "new.lock", "new.so"]
    assert float(compiled(old)(1.0)) == 2.0  # compiled again when needed


def test_without_a_compiler_the_function_runs_uncompiled(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HUSKY_SIM_SOLVER_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setattr(compiled_module, "_warned", set())
    x = ca.SX.sym("x")
    function = ca.Function("no_compiler_probe", [x], [2 * x])
    with pytest.warns(RuntimeWarning, match="no C compiler"):
        result = compiled(function)
    assert result is function and not list(tmp_path.glob("*.so"))


def test_fatrop_without_a_compiler_still_answers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Uncompiled, FATROP's exit flag is not visible: a converged solve is used, anything else
    goes to IPOPT; either way the answer is the problem's."""
    monkeypatch.setenv("HUSKY_SIM_SOLVER_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setattr(compiled_module, "_warned", set())
    config, p, guess = _one_problem()
    reference = IpoptSolver(paper_nlp(config), SolverOptions()).solve(p, guess)
    with pytest.warns(RuntimeWarning, match="no C compiler"):
        solver = FatropSolver(paper_nlp(config), SolverOptions())
    raw = solver.solve(p, guess)
    assert raw.success and raw.solver in ("fatrop", "ipopt") and not list(tmp_path.glob("*.so"))
    assert raw.solver == "fatrop" or raw.fallback_reason == "fatrop: did not converge (uncompiled)"
    assert np.max(np.abs(raw.decision - reference.decision)) < 1e-4


def test_nlp_names_its_solver_problem() -> None:
    nlp = paper_nlp(NMPCConfig())
    assert isinstance(nlp, NLP) and nlp.name == "nmpc"


def test_a_scenario_file_chooses_the_solver() -> None:
    """`controller.solver` in a scenario picks the backend for the paper's controllers and husky-cbf."""
    from husky_sim.runs.scenario import scenario_from_data

    data = load_scenario("head_on_moving_obstacle").model_dump(mode="json")
    assert load_scenario("head_on_moving_obstacle").controller_config("cbf").solver.backend == "fatrop"
    data["controller"]["solver"] = "ipopt"
    scenario = scenario_from_data(data)
    assert scenario.controller_config("cbf").solver.backend == "ipopt"
    assert scenario.with_overrides(horizon=5).controller_config("husky-cbf").nmpc.solver.backend == "ipopt"
    data["controller"]["solver"] = "hpipm"
    with pytest.raises(ValueError, match="solver"):
        scenario_from_data(data)


def test_dynamics_with_a_parameter_on_the_next_state_are_refused_not_crashed() -> None:
    """x_(k+1) must have a unit coefficient in its dynamics row; p x_1 = x_0 + u_0 is no gap."""
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p")
    w = ca.vertcat(x[0], u, x[1])
    stages = StageIndices(((0,), (2,)), ((1,),))
    problem = {"x": w, "p": p, "f": ca.sumsqr(w), "g": p * x[1] - (x[0] + u)}
    with pytest.raises(NotStagewiseError, match="stage 0: found gap rows"):
        transcribe(problem, [0], [0], stages)


#: Problems recorded in PyBullet closed loops (Relax-CBF, scenario files' settings) on which FATROP
#: ran into its iteration cap while the slacks' bounds were in force: s_h(k) sits on s_h <= 1 with
#: a zero multiplier wherever the obstacle constraint is slack, and FATROP's dual infeasibility
#: stalled near 3e-4 once its barrier parameter reached its floor (IPOPT: 14 to 21 iterations).
DEGENERATE_BOUND_PROBLEMS = {
    "husky_point_stabilisation_N12_step110": ("husky_point_stabilisation", 12),
    "husky_circle_tracking_N7_step240": ("husky_circle_tracking", 7),
}


def _holds(nlp: NLP, p: np.ndarray) -> dict[str, float]:
    """Each redundant bound's condition at p, by side."""
    return {e.side: float(ca.Function("holds", [nlp.problem["p"]], [e.holds])(p)) for e in nlp.redundant}


@pytest.mark.parametrize("key", sorted(DEGENERATE_BOUND_PROBLEMS))
def test_fatrop_converges_where_a_slack_sits_on_its_bound(key: str) -> None:
    """With the redundant bounds loosened for FATROP (every B(0) > 0 here), FATROP answers
    itself, with the first control of converged IPOPT and the slacks back within their bounds."""
    scenario, horizon = DEGENERATE_BOUND_PROBLEMS[key]
    config = load_scenario(scenario).with_overrides(horizon=horizon).controller_config("relax-cbf")
    data = np.load(Path(__file__).parent / "data" / "fatrop_degenerate_bound.npz")
    p, guess = data[f"{key}_p"], data[f"{key}_guess"]
    nlp = paper_nlp(config)
    assert _holds(nlp, p)["upper"] > 0
    raw = FatropSolver(nlp, SolverOptions()).solve(p, guess)
    assert raw.solver == "fatrop" and not raw.fallback_reason, raw.fallback_reason
    converged = IpoptSolver(nlp, SolverOptions(tol=1e-10, acceptable_tol=1e-10, max_iter=3000)).solve(
        p, guess
    )
    assert converged.success
    layout = layout_for(config)
    plan, reference = Plan.from_vector(raw.decision, layout), Plan.from_vector(converged.decision, layout)
    assert np.max(np.abs(plan.controls[0] - reference.controls[0])) < 1e-4
    assert np.all(plan.decay_slack <= 1.0) and np.all(plan.decay_slack >= 0.0)
    assert np.all(plan.clf_slack >= 0.0)


def test_the_slacks_bounds_are_declared_redundant_only_where_they_are() -> None:
    """s_v >= 0 is always redundant; Relax-CBF's s_h <= 1 only while min over obstacles of B(0)
    at the measured state is positive (then no feasible B(k) is negative)."""
    config = NMPCConfig(safety="relax-cbf", horizon=4, obstacle_slots=2, robot_radius_m=0.3)
    nlp = paper_nlp(config)
    lbx, ubx = nlp.bounds[:2]
    layout = layout_for(config)
    n = layout.n_decision
    sides = {e.side: e.indices for e in nlp.redundant}
    assert sides == {"lower": tuple(range(n - 8, n - 4)), "upper": tuple(range(n - 4, n))}
    assert np.all(lbx[list(sides["lower"])] == 0.0) and np.all(ubx[list(sides["upper"])] == 1.0)

    def params(state: np.ndarray) -> np.ndarray:
        centres = np.stack([np.tile([2.0, 0.0], (5, 1)), np.tile([0.0, 3.0], (5, 1))])
        return OCPParameters(
            state, np.zeros((5, 3)), np.zeros((4, 2)), centres, np.array([0.5, 0.2])
        ).to_vector()

    # B(0) of the first obstacle: 1.0^2 - 0.8^2 = 0.36; of the second: 3^2 - 0.5^2 = 8.75
    assert _holds(nlp, params(np.array([1.0, 0.0, 0.0])))["upper"] == pytest.approx(0.36)
    inside = _holds(nlp, params(np.array([1.5, 0.0, 0.0])))
    assert inside["upper"] < 0 < inside["lower"]  # inside an obstacle's set s_h <= 1 stays
    for variant in ("bt", "cbf"):
        assert [e.side for e in paper_nlp(NMPCConfig(safety=variant, horizon=4)).redundant] == ["lower"]


def test_fatrop_fallback_can_be_capped() -> None:
    """A capped IPOPT fallback stops at its cap; uncapped, the same fallback converges; a cap of 0
    (husky-cbf's hard problem: its penalised re-solve follows) leaves FATROP's failure as it is."""
    config, p, guess = _one_problem()

    answers = {}
    for cap in (None, 2, 0):
        solver = FatropSolver(paper_nlp(config), SolverOptions(), fallback_max_iter=cap)
        solver._function = StandIn(error=RuntimeError("Evaluation failed"))
        answers[cap] = solver.solve(p, guess)
    assert answers[None].success and answers[None].iterations > 2
    assert not answers[2].success and answers[2].iterations == 2
    assert answers[2].fallback_reason == "fatrop: solver error"
    assert not answers[0].success and answers[0].solver == "fatrop" and answers[0].status == "solver error"
