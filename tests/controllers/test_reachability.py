"""The reachability proof (controllers.reachability) may only call a problem infeasible when it is:
never where a trajectory satisfies every row, even one that touches its bound; and where it does
speak, the real solvers agree from every recovery guess, and the closed loop does what it did
when they were asked."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from controllers import NMPCConfig, NMPCController, Obstacle, SetPoint
from controllers.model import step
from controllers.nmpc import PROVEN_INFEASIBLE
from controllers.ocp import OCPParameters
from controllers.reachability import proven_infeasible


def _parameters(state: np.ndarray, centres: np.ndarray, radius_m: float) -> OCPParameters:
    n = centres.shape[0] - 1
    return OCPParameters(state, np.zeros((n + 1, 3)), np.zeros((n, 2)), centres[None], np.array([radius_m]))


@given(
    safety=st.sampled_from(["bt", "cbf", "relax-cbf"]),
    horizon=st.integers(1, 10),
    tau_s=st.floats(0.05, 0.3),
    v_min=st.floats(-1.5, 0.0),
    v_max=st.floats(0.1, 1.5),
    omega_max=st.floats(0.1, 2.0),
    gamma=st.floats(0.01, 1.0),
    seed=st.integers(0, 2**32 - 1),
)
@settings(max_examples=150, deadline=None)
def test_a_trajectory_that_meets_every_row_is_never_proven_infeasible(
    safety: str,
    horizon: int,
    tau_s: float,
    v_min: float,
    v_max: float,
    omega_max: float,
    gamma: float,
    seed: int,
) -> None:
    """A random control sequence (often on its bounds) driven through the model's own RK4, and two
    obstacles (one behind the trajectory or anywhere, one beside it; moving at constant velocity)
    each sized so that the trajectory meets its safety rows with equality somewhere: a solution
    exists, at the edge of the feasible set."""
    rng = np.random.default_rng(seed)
    state = np.array([*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi)])
    controls = np.column_stack(
        [rng.uniform(v_min, v_max, horizon), rng.uniform(-omega_max, omega_max, horizon)]
    )
    adversarial = rng.random() < 0.5
    if adversarial:  # full speed, full turn: the trajectory runs along the edge of the reachable set
        controls[:] = [v_min if rng.random() < 0.5 else v_max, omega_max * rng.choice([-1.0, 1.0])]
    else:
        extreme = rng.random((horizon, 2)) < 0.5
        controls[:, 0] = np.where(
            extreme[:, 0], np.where(rng.random(horizon) < 0.5, v_min, v_max), controls[:, 0]
        )
        controls[:, 1] = np.where(extreme[:, 1], np.sign(controls[:, 1]) * omega_max, controls[:, 1])
    states = [state]
    for u in controls:
        states.append(step(states[-1], u, tau_s))
    positions = np.array(states)[:, :2]
    if adversarial:  # a static obstacle right behind where the trajectory ends up at some step
        end = positions[rng.integers(1, horizon + 1)]
        away = math.atan2(*(end - positions[0])[::-1]) + rng.uniform(-0.3, 0.3)
        behind = end - rng.uniform(0.3, 3.0) * np.array([math.cos(away), math.sin(away)])
        first = np.tile(behind, (horizon + 1, 1))
    else:
        first = rng.uniform(-2, 2, 2) + rng.uniform(-1, 1, 2) * tau_s * np.arange(horizon + 1)[:, None]
    # a second obstacle beside the trajectory at some step, moving: the two may squeeze it
    k = rng.integers(0, horizon + 1)
    side = rng.uniform(-math.pi, math.pi)
    second = positions[k] + rng.uniform(0.3, 1.5) * np.array([math.cos(side), math.sin(side)])
    second = second + rng.uniform(-1, 1, 2) * tau_s * (np.arange(horizon + 1) - k)[:, None]
    centres = np.stack([first, second])
    r_sum = np.array([_touching(positions, c, safety, gamma) for c in centres])
    assume(np.all(r_sum > 1e-2))
    robot_radius = 0.5 * float(np.min(r_sum))
    config = NMPCConfig(
        safety=safety,
        horizon=horizon,
        tau_s=tau_s,
        v_min_mps=v_min,
        v_max_mps=v_max,
        omega_max_radps=omega_max,
        gamma=gamma,
        robot_radius_m=robot_radius,
        obstacle_slots=2,
    )
    params = OCPParameters(
        state, np.zeros((horizon + 1, 3)), np.zeros((horizon, 2)), centres, r_sum - robot_radius
    )
    assert proven_infeasible(config, params) == ""


def _touching(positions: np.ndarray, centres: np.ndarray, safety: str, gamma: float) -> float:
    """The radii sum (m) at which the trajectory meets the obstacle's rows with equality somewhere
    (0 where no positive one lets it meet them)."""
    distances = np.hypot(*(positions - centres).T)
    if safety == "bt":
        return float(np.min(distances[1:]))
    # B(k+1) - (1 - gamma) B(k) = d(k+1)^2 - (1 - gamma) d(k)^2 - gamma r^2 >= 0 (s_h = 1)
    r_sq = float(np.min(distances[1:] ** 2 - (1 - gamma) * distances[:-1] ** 2)) / gamma
    return math.sqrt(r_sq) if r_sq > 0 else 0.0


@pytest.mark.parametrize(
    ("case", "safety", "obstacles", "proof"),
    [
        # 0.14 m inside a static obstacle's BT circle, facing it: 0.1 m of travel per step
        ("deadlock", "bt", [Obstacle(0.61, 0.0, 0.5)], "bt row of obstacle slot 0 at step 1 out of reach"),
        # facing along y, 0.05 m inside a circle on its left: the way out is sideways, which the
        # unicycle cannot take in one step (a disc of reach 0.1 m would not prove it)
        ("sideways", "bt", [Obstacle(-0.95, 0.0, 0.75)], "bt row of obstacle slot 0 at step 1 out of reach"),
        # a mover closing at 3 m/s, faster than the robot can reverse (1 m/s): B must fall by more
        # than the CBF's 10 % per step
        (
            "overrun",
            "cbf",
            [Obstacle(1.2, 0.0, 0.3, -3.0, 0.0)],
            "cbf row of obstacle slot 0 at step 1 out of reach",
        ),
        # 0.02 m inside two circles, one ahead and one behind: either alone is left by driving
        # away from it, but leaving one means going deeper into the other
        (
            "squeeze",
            "bt",
            [Obstacle(0.73, 0.0, 0.5), Obstacle(-0.73, 0.0, 0.5)],
            "bt rows of obstacle slots 0, 1 at step 1 out of reach together",
        ),
    ],
)
def test_where_the_proof_speaks_every_solver_fails_and_the_loop_does_the_same(
    case: str,
    safety: str,
    obstacles: list[Obstacle],
    proof: str,
    monkeypatch: pytest.MonkeyPatch,
    fatrop_solves: dict[str, int],
) -> None:
    config = NMPCConfig(safety=safety, horizon=5, gamma=0.1, obstacle_slots=len(obstacles))
    heading = math.pi / 2 if case == "sideways" else 0.0
    state = np.array([0.0, 0.0, heading])
    goal = SetPoint(3.0, 0.0, 0.0)
    proven = NMPCController(config)
    calls = fatrop_solves
    answer = proven.solve(state, goal, obstacles, 0.0)
    assert answer.status == f"{PROVEN_INFEASIBLE} ({proof})"
    assert calls["n"] == 0 and answer.iterations == -1 and not answer.success and answer.fallback == "brake"
    # the same problem put to FATROP, IPOPT and every recovery guess: all of them fail
    monkeypatch.setattr("controllers.nmpc.proven_infeasible", lambda config, params: "")
    asked = NMPCController(config)
    solved = asked.solve(state, goal, obstacles, 0.0)
    # the first guess, then the reverse and straight ones (the brake guess is the first again)
    assert calls["n"] == 3 and not solved.success and solved.recovered_by == ""
    assert "fatrop: " in solved.solver_fallback  # IPOPT was asked too, and failed
    assert np.array_equal(solved.control, answer.control) and solved.fallback == answer.fallback
    assert np.array_equal(solved.predicted_states, answer.predicted_states)


@pytest.mark.parametrize("safety", ["bt", "cbf", "relax-cbf"])
@pytest.mark.parametrize("broken_step", [None, 1, 5])
def test_the_proof_is_tight_where_the_robot_flees_at_full_speed(safety: str, broken_step: int | None) -> None:
    """A robot that cannot reverse flees straight ahead from an obstacle behind it, whose predicted
    centres are placed so that full speed meets every row with 0.02 to spare (m or m^2), or misses
    one step's row by 0.02: nothing reaches farther, so the first is feasible and the second is
    not, and the proof must tell them apart at that step (the CBF chain, B(k) >= (1 - gamma)^k
    B(0), included)."""
    n, tau, r_sum, margin = 5, 0.1, 0.75, 0.02
    config = NMPCConfig(safety=safety, horizon=n, tau_s=tau, v_min_mps=0.0, gamma=0.2, robot_radius_m=0.25)
    start = -0.7 if safety == "relax-cbf" else -1.0  # Relax-CBF is judged with B(0) <= 0 only
    b0 = start**2 - r_sum**2
    centres = [[start, 0.0]]
    for k in range(1, n + 1):
        spare = -margin if k == broken_step else margin
        ahead = k * config.v_max_mps * tau  # where full speed takes the robot along +x
        if safety == "bt":
            gap = r_sum + spare
        else:  # B(k) = (1 - gamma)^k B(0) + spare
            gap = math.sqrt(r_sum**2 + (1 - config.gamma) ** k * b0 + spare)
        centres.append([ahead - gap, 0.0])
    params = _parameters(np.zeros(3), np.array(centres), r_sum - config.robot_radius_m)
    proof = proven_infeasible(config, params)
    if broken_step is None:
        assert proof == ""
    else:
        assert proof == f"{safety} row of obstacle slot 0 at step {broken_step} out of reach"
