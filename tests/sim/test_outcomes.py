"""The outcome monitor alone (no physics): the episode's rules, step by step."""

import math

import numpy as np

from controllers import CircleTrajectory, SetPoint
from husky_sim.sim.outcomes import OutcomeMonitor, Outcomes, mover_within_reach

GOAL = SetPoint(1.0, 0.0, 0.0)


def _row(v: float = 0.0, w: float = 0.0) -> dict[str, object]:
    return {"v_body_mps": v, "omega_body_radps": w, "v_cmd_mps": v, "omega_cmd_radps": w, "fallback": "none"}


def test_reached_needs_the_tolerance_held_and_names_its_entry() -> None:
    monitor = OutcomeMonitor(GOAL, Outcomes(goal_hold_s=0.3), tau_s=0.1)
    at_goal, off = np.array([1.05, 0.0, 0.05]), np.array([0.5, 0.0, 0.0])
    stops = [
        monitor.update(t, pose, math.inf, []) for t, pose in [(0.1, off), (0.2, at_goal), (0.3, at_goal)]
    ]
    assert stops == [False, False, False] and monitor.outcome is None  # held 2 of 3 steps
    assert monitor.update(0.4, at_goal, math.inf, []) and monitor.outcome == "reached"
    assert monitor.reached_at == 0.2


def test_a_collision_names_the_episode_even_after_reaching() -> None:
    monitor = OutcomeMonitor(GOAL, Outcomes(goal_hold_s=0.1, stop_early=False), tau_s=0.1)
    assert not monitor.update(0.1, np.array([1.0, 0.0, 0.0]), 1.0, []) and monitor.outcome == "reached"
    assert monitor.update(0.2, np.array([1.0, 0.0, 0.0]), 0.0, []) and monitor.outcome == "collided"


def test_stuck_only_after_the_grace_time_and_away_from_the_reference() -> None:
    outcomes = Outcomes(stuck_window_steps=3, stuck_grace_s=0.5)
    idle, far = [_row()] * 3, np.array([0.0, 0.0, 0.0])
    early = OutcomeMonitor(GOAL, outcomes, tau_s=0.1)
    assert not early.update(0.3, far, math.inf, idle) and early.outcome is None
    late = OutcomeMonitor(GOAL, outcomes, tau_s=0.1)
    assert late.update(0.6, far, math.inf, idle) and late.outcome == "stuck"
    turning = OutcomeMonitor(GOAL, outcomes, tau_s=0.1)
    assert not turning.update(0.6, far, math.inf, [_row(w=0.5)] * 3)  # turning in place is progress


def test_a_trajectory_is_never_reached() -> None:
    circle = CircleTrajectory(2.0, 0.2, 0.0, 0.0, 0.0)
    monitor = OutcomeMonitor(circle, Outcomes(goal_hold_s=0.1), tau_s=0.1)
    on_it = np.asarray(circle.state_at(0.1), dtype=float)
    assert not monitor.update(0.1, on_it, math.inf, []) and monitor.outcome is None


def test_a_held_goal_ends_the_episode_after_a_collision_that_still_names_it() -> None:
    monitor = OutcomeMonitor(GOAL, Outcomes(goal_hold_s=0.2, stop_on_collision=False), tau_s=0.1)
    at_goal = np.array([1.0, 0.0, 0.0])
    assert not monitor.update(0.1, at_goal, -0.5, []) and monitor.outcome == "collided"
    assert monitor.update(0.2, at_goal, 1.0, []) and monitor.goal_held and monitor.reached_at == 0.1
    assert monitor.outcome == "collided"


def test_a_contact_tolerance_and_the_stuck_rule_judged_at_the_end() -> None:
    outcomes = Outcomes(stuck_window_steps=3, stuck_grace_s=0.0)
    monitor = OutcomeMonitor(GOAL, outcomes, tau_s=0.1, contact_tolerance_m=1e-6, stuck_at_end=True)
    far = np.array([0.0, 0.0, 0.0])
    assert not monitor.update(0.1, far, -1e-7, [_row()] * 3) and monitor.outcome is None  # contact
    monitor.finish([_row(v=1.0)] + [_row()] * 2)
    assert monitor.outcome is None  # the last window was not idle
    monitor.finish([_row()] * 3)
    assert monitor.outcome == "stuck"
    assert monitor.update(0.2, far, -2e-6, []) and monitor.outcome == "collided"  # beyond it


def test_a_mover_within_reach_is_one_whose_speed_closes_the_gap_in_time() -> None:
    # a walker 2 m off at 0.5 m/s (gap 1.2 m to a 0.5 m robot circle) and a post touching the robot
    def centres(t_s: float) -> np.ndarray:
        return np.array([[2.0 - 0.5 * t_s, 0.0], [0.6, 0.0]])

    radii, robot = np.array([0.3, 0.2]), np.zeros(2)
    assert not mover_within_reach(robot, centres, radii, 0.5, 0.0, 0.1, ahead_s=2.0)  # 1.0 m < 1.2 m
    assert mover_within_reach(robot, centres, radii, 0.5, 0.0, 0.1, ahead_s=2.5)  # 1.25 m >= 1.2 m
    # the post alone never counts, however close: a robot stopped at a wall is not giving way
    assert not mover_within_reach(robot, lambda t: centres(t)[1:], radii[1:], 0.5, 0.0, 0.1, ahead_s=2.5)
