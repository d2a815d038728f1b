"""The solved OCP satisfies its own constraints (checked in numpy, independently of the CasADi
formulation), obstacle slots and prediction behave as documented, and failures fall back."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controllers import CircleTrajectory, NMPCConfig, NMPCController, Obstacle, SetPoint
from controllers.config import SOLVER_BACKENDS, SolverOptions
from controllers.model import step, wrap_angle

TOL = 1e-6
VARIANTS = ("none", "bt", "cbf", "relax-cbf")


def clf_values(states: np.ndarray, ref: np.ndarray, w_v: np.ndarray) -> np.ndarray:
    err = states - ref
    err[:, 2] = wrap_angle(err[:, 2])
    return np.einsum("ki,ij,kj->k", err, w_v, err)


def random_case(rng: np.random.Generator) -> tuple[np.ndarray, Obstacle, SetPoint]:
    """A robot 0.05-1.2 m from an obstacle's surface, the goal on the far side."""
    obstacle = Obstacle(0.0, 0.0, float(rng.uniform(0.3, 0.7)), *rng.uniform(-0.3, 0.3, size=2))
    bearing = rng.uniform(-math.pi, math.pi)
    dist = 0.25 + obstacle.radius_m + rng.uniform(0.05, 1.2)
    pos = dist * np.array([math.cos(bearing), math.sin(bearing)])
    heading = bearing + math.pi + rng.uniform(-0.8, 0.8)  # roughly facing the obstacle
    goal = SetPoint(*(-3.0 * pos / np.linalg.norm(pos)), float(rng.uniform(-math.pi, math.pi)))
    return np.array([*pos, heading]), obstacle, goal


@pytest.mark.parametrize("backend", SOLVER_BACKENDS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_solved_plans_satisfy_their_constraints(variant: str, backend: str) -> None:
    rng = np.random.default_rng(7)
    cfg = NMPCConfig(safety=variant, gamma=0.1, horizon=6, solver=SolverOptions(backend=backend))
    n, gamma = cfg.horizon, cfg.gamma
    w_v = np.array(cfg.clf_weight)
    for _ in range(12):
        state, obstacle, goal = random_case(rng)
        controller = NMPCController(cfg)
        res = controller.solve(state, goal, [obstacle], 0.0)
        assert res.success, res.status
        assert res.solver == backend or res.solver_fallback.startswith("fatrop:"), res.solver
        x, u = res.predicted_states, res.predicted_controls
        assert np.allclose(x[0], state, atol=TOL)
        for k in range(n):
            assert np.allclose(x[k + 1], step(x[k], u[k], cfg.tau_s), atol=TOL)
        assert np.all(u[:, 0] >= cfg.v_min_mps - TOL) and np.all(u[:, 0] <= cfg.v_max_mps + TOL)
        assert np.all(np.abs(u[:, 1]) <= cfg.omega_max_radps + TOL)
        assert np.all(res.clf_slack >= -TOL)
        v = clf_values(x, goal.sample(0.0, cfg.tau_s, n)[0], w_v)
        assert np.all((1 - cfg.alpha) * v[:-1] + res.clf_slack - v[1:] >= -TOL)
        centres = obstacle.position_after(cfg.tau_s * np.arange(n + 1))
        dist = np.linalg.norm(x[:, :2] - centres, axis=1)
        r_sum = cfg.robot_radius_m + obstacle.radius_m
        b = dist**2 - r_sum**2
        assert np.allclose(res.predicted_barrier[0], b, atol=1e-9)
        if variant == "bt":
            assert np.all(dist[1:] - r_sum >= -TOL)
        elif variant == "cbf":
            assert np.all(b[1:] - (1 - gamma) * b[:-1] >= -TOL)
            assert np.all(res.decay_slack == 1.0)
        elif variant == "relax-cbf":
            s_h = res.decay_slack
            assert np.all(s_h >= -TOL) and np.all(s_h <= 1 + TOL)
            assert np.all(b[1:] - s_h * (1 - gamma) * b[:-1] >= -TOL)
            # the point of bounding s_h below by 0: every predicted state stays safe
            assert np.all(b >= -TOL)


@pytest.mark.parametrize("backend", SOLVER_BACKENDS)
def test_relax_cbf_inside_the_set_recovers_at_least_at_the_cbf_rate(backend: str) -> None:
    """A measured state a hair inside the obstacle circle (B < 0) must not let s_h > 1 loosen
    the constraint: predicted B may not sink below (1 - gamma) times its previous value."""
    cfg = NMPCConfig(safety="relax-cbf", gamma=0.1, horizon=7, solver=SolverOptions(backend=backend))
    obstacle = Obstacle(0.0, 0.0, 0.6)
    state = np.array([0.0, -0.84, math.pi / 2])  # 0.01 m inside r_sum = 0.85, facing the obstacle
    goal = SetPoint(0.0, 3.0, math.pi / 2)  # straight through the obstacle
    res = NMPCController(cfg).solve(state, goal, [obstacle], 0.0)
    assert res.success, res.status
    b = res.predicted_barrier[0]
    assert b[0] < 0
    assert np.all(b[1:] >= (1 - cfg.gamma) * b[:-1] - TOL)


def test_unused_slots_are_parked_and_change_nothing() -> None:
    state, goal, obstacle = (
        np.array([0.0, 0.0, math.pi / 2]),
        SetPoint(0.0, 10.0, math.pi / 2),
        Obstacle(0.1, 1.2, 0.4),
    )
    one = NMPCController(NMPCConfig(safety="cbf", obstacle_slots=1)).solve(state, goal, [obstacle], 0.0)
    three = NMPCController(NMPCConfig(safety="cbf", obstacle_slots=3)).solve(state, goal, [obstacle], 0.0)
    assert one.success and three.success
    assert three.obstacles_considered == 1 and three.predicted_barrier.shape[0] == 1
    assert np.allclose(one.control, three.control, atol=1e-5)


def test_no_obstacle_slots() -> None:
    res = NMPCController(NMPCConfig(safety="cbf", obstacle_slots=0)).solve(
        np.array([0.0, 0.0, 0.0]), SetPoint(1.0, 0.0, 0.0), [Obstacle(0.5, 0.0, 0.1)], 0.0
    )
    assert res.success and res.obstacles_considered == 0 and res.obstacles_ignored == 1
    assert res.control[0] > 0  # drives straight through: the obstacle was not considered


def test_more_obstacles_than_slots_keeps_the_nearest() -> None:
    state, goal = np.array([0.0, 0.0, math.pi / 2]), SetPoint(0.0, 10.0, math.pi / 2)
    far, near = Obstacle(5.0, 5.0, 0.3), Obstacle(0.0, 1.3, 0.5)
    res = NMPCController(NMPCConfig(safety="cbf", obstacle_slots=1)).solve(state, goal, [far, near], 0.0)
    assert res.obstacles_considered == 1 and res.obstacles_ignored == 1
    expected_b0 = 1.3**2 - (0.25 + 0.5) ** 2
    assert res.predicted_barrier[0, 0] == pytest.approx(expected_b0, abs=1e-9)


@pytest.mark.parametrize("mode", ["constant-velocity", "frozen"])
def test_obstacle_prediction_modes(mode: str) -> None:
    cfg = NMPCConfig(safety="cbf", horizon=8, obstacle_prediction=mode)
    obstacle = Obstacle(1.5, 2.0, 0.3, vx_mps=-0.5, vy_mps=0.0)  # crossing the robot's path
    state, goal = np.array([0.0, 0.0, math.pi / 2]), SetPoint(0.0, 10.0, math.pi / 2)
    res = NMPCController(cfg).solve(state, goal, [obstacle], 0.0)
    assert res.success
    dt = cfg.tau_s * np.arange(cfg.horizon + 1)
    centres = obstacle.position_after(dt if mode == "constant-velocity" else 0.0 * dt)
    b = np.sum((res.predicted_states[:, :2] - centres) ** 2, axis=1) - (0.25 + 0.3) ** 2
    assert np.allclose(res.predicted_barrier[0], b, atol=1e-9)
    assert np.all(b[1:] - (1 - cfg.gamma) * b[:-1] >= -TOL)


def test_circle_reference_feed_forward() -> None:
    circle = CircleTrajectory(radius_m=2.5, angular_rate_radps=0.16)
    states, controls = circle.sample(3.0, 0.2, 7)
    t = 3.0 + 0.2 * np.arange(8)
    assert np.allclose(states[:, 0], 2.5 * np.cos(0.16 * t)) and np.allclose(
        states[:, 1], 2.5 * np.sin(0.16 * t)
    )
    assert np.allclose(wrap_angle(states[:, 2] - (0.16 * t + math.pi / 2)), 0.0, atol=1e-12)
    assert np.allclose(controls[:, 0], 2.5 * 0.16) and np.allclose(controls[:, 1], 0.16)


@given(
    radius=st.floats(0.1, 20.0),
    rate=st.floats(-2.0, 2.0).filter(lambda w: abs(w) > 1e-3),
    centre=st.tuples(st.floats(-50.0, 50.0), st.floats(-50.0, 50.0)),
    phase=st.floats(-math.pi, math.pi),
    times=st.lists(st.floats(0.0, 3600.0), min_size=1, max_size=40),
)
@settings(max_examples=60, deadline=None)
def test_a_path_sampled_at_once_is_every_sample_first_state(
    radius: float, rate: float, centre: tuple[float, float], phase: float, times: list[float]
) -> None:
    """`states_at` (traces and recordings draw a whole path with it) gives, bit for bit, the state
    a controller's `sample` starts from, at every time."""
    circle = CircleTrajectory(radius, rate, *centre, phase)
    one_by_one = np.array([circle.sample(t, 0.1, 3)[0][0] for t in times])
    assert np.array_equal(circle.states_at(np.array(times)), one_by_one)
    assert all(np.array_equal(circle.state_at(t), row) for t, row in zip(times, one_by_one, strict=True))
    goal = SetPoint(1.0, -2.0, 0.5)
    assert np.array_equal(goal.states_at(np.array(times)), np.tile([1.0, -2.0, 0.5], (len(times), 1)))


def test_heading_is_wrapped_in_cost_and_clf() -> None:
    """The same pose with theta + 2 pi k must give the same decision (k up to 5 laps)."""
    cfg = NMPCConfig(safety="cbf", horizon=5)
    circle = CircleTrajectory(radius_m=1.0, angular_rate_radps=0.5)
    base = np.array([1.2, 0.1, 1.4])
    controls = []
    for laps in (0, 1, 5, -3):
        state = base + [0.0, 0.0, 2 * math.pi * laps]
        res = NMPCController(cfg).solve(state, circle, [Obstacle(3.0, 3.0, 0.2)], 0.0)
        assert res.success
        controls.append(res.control)
    assert np.allclose(controls, controls[0], atol=1e-5)


@pytest.mark.physics
def test_tracking_many_laps_keeps_converging() -> None:
    """Circle tracking where theta grows without bound (3 laps) keeps the error small."""
    from husky_sim.sim.kinematic import run_kinematic

    circle = CircleTrajectory(radius_m=1.0, angular_rate_radps=0.6)
    cfg = NMPCConfig(safety="none", horizon=5)
    ep = run_kinematic(NMPCController(cfg), (1.0, 0.0, math.pi / 2), circle, [], cfg.tau_s, 32.0, 0.25)
    refs = np.array([circle.state_at(t)[:2] for t in ep.times_s])
    err = np.linalg.norm(ep.states[:, :2] - refs, axis=1)
    assert ep.states[-1, 2] > 2 * math.pi * 3  # the heading really wound up
    assert np.max(err[len(err) // 2 :]) < 0.05


def test_failures_fall_back_and_never_raise() -> None:
    cfg = NMPCConfig(safety="cbf", horizon=6)
    controller = NMPCController(cfg)
    state, goal = np.array([0.0, 0.0, math.pi / 2]), SetPoint(0.0, 10.0, math.pi / 2)
    obstacle = Obstacle(2.0, 2.0, 0.3)
    first = controller.solve(state, goal, [obstacle], 0.0)
    assert first.success and first.fallback == "none"
    broken = SetPoint(float("nan"), 10.0, math.pi / 2)  # IPOPT: invalid number
    moved = step(state, first.control, cfg.tau_s)
    second = controller.solve(moved, broken, [obstacle], 0.1)
    assert not second.success and second.fallback == "previous-plan"
    assert np.allclose(second.control, first.predicted_controls[1])
    assert np.allclose(second.predicted_states[0], first.predicted_states[1])  # the plan followed
    # an obstacle now sits on the old plan: the previous plan is unsafe -> brake
    blocking = Obstacle(*first.predicted_states[3, :2], 0.3)
    third = controller.solve(moved, broken, [blocking], 0.2)
    assert third.fallback == "brake" and np.all(third.control == 0.0)
    assert np.all(third.predicted_states == moved) and np.all(np.isfinite(third.predicted_barrier))
    # braking drops the old plan: a further failure may not replay it out of time
    again = controller.solve(moved, broken, [obstacle], 0.25)
    assert again.fallback == "brake"
    nan_state = controller.solve(np.array([np.nan, 0.0, 0.0]), goal, [obstacle], 0.3)
    assert nan_state.fallback == "brake" and nan_state.status == "invalid state"
    # after a failure the next good solve succeeds again (cold start)
    fourth = controller.solve(moved, goal, [obstacle], 0.3)
    assert fourth.success and fourth.fallback == "none"
