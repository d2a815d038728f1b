"""The tracking success definition (husky_sim.sim.metrics.judge_tracking) on synthetic series."""

from __future__ import annotations

import numpy as np
import pytest

from husky_sim.runs.scenario import SuccessSpec
from husky_sim.sim.metrics import judge_tracking, tracking_rmse
from husky_sim.sim.outcomes import Outcomes, reference_reachable

TAU_S = 0.1
OUTCOMES = Outcomes(tracking_settle_s=10.0, tracking_rmse_m=0.3, rejoin_s=5.0)


def _series(duration_s: float = 60.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (s), errors of 0.1 m and an always-reachable reference."""
    t = TAU_S * np.arange(round(duration_s / TAU_S))
    return t, np.full(t.shape, 0.1), np.ones(t.shape, dtype=bool)


def _between(t: np.ndarray, lo_s: float, hi_s: float) -> np.ndarray:
    return (t >= lo_s - 1e-9) & (t < hi_s - 1e-9)


def test_always_reachable_is_the_old_rmse_rule() -> None:
    t, _, reachable = _series()
    rng = np.random.default_rng(3)
    for scale in (0.1, 0.25, 0.3, 0.35, 0.6):
        err = np.abs(rng.normal(0.0, scale, t.shape))
        old = tracking_rmse(err, t, OUTCOMES.tracking_settle_s)
        judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
        assert judged.rmse_reachable_m == pytest.approx(old)
        assert judged.converged == (old <= OUTCOMES.tracking_rmse_m)
        assert judged.blocked_s == 0.0 and judged.rejoin_times_s == ()


def test_blocked_interval_is_excluded() -> None:
    t, err, reachable = _series()
    blocked = _between(t, 20.0, 30.0)
    reachable[blocked] = False
    err[blocked] = 2.0  # the robot goes round the obstacle sitting on the reference
    assert tracking_rmse(err, t, OUTCOMES.tracking_settle_s) > OUTCOMES.tracking_rmse_m  # old rule: fails
    judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
    assert judged.converged
    assert judged.rmse_reachable_m == pytest.approx(0.1)
    assert judged.blocked_s == pytest.approx(10.0)
    assert judged.rejoin_times_s == (0.0,)  # back on the reference the instant it is reachable


@pytest.mark.parametrize(("lag_s", "converged"), [(3.0, True), (4.9, True), (7.0, False)])
def test_rejoin_must_be_within_rejoin_s(lag_s: float, converged: bool) -> None:
    t, err, reachable = _series()
    reachable[_between(t, 20.0, 30.0)] = False
    err[_between(t, 20.0, 30.0 + lag_s)] = 1.0  # still away from the reference after it cleared
    judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
    assert judged.rejoin_times_s == (pytest.approx(lag_s),)
    assert judged.rmse_reachable_m == pytest.approx(0.1)  # the window is judged by the rejoin rule only
    assert judged.converged == converged


def test_window_open_at_the_end_is_not_judged_unless_already_overdue() -> None:
    t, err, reachable = _series()
    reachable[_between(t, 50.0, 58.0)] = False
    err[t >= 50.0] = 1.0  # never back on the reference before the run ends at 60 s
    judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
    assert judged.converged and judged.rejoin_times_s == ()  # 2 s open: cannot tell yet
    reachable[:] = True
    reachable[_between(t, 50.0, 52.0)] = False  # open for 8 s at the end: a rejoin already failed
    judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
    assert not judged.converged and judged.rejoin_times_s == (pytest.approx(8.0),)


def test_window_cut_by_a_new_blockage_is_judged_only_when_overdue() -> None:
    t, err, reachable = _series()
    reachable[_between(t, 20.0, 25.0) | _between(t, 28.0, 33.0)] = False
    err[_between(t, 20.0, 33.0)] = 1.0  # 3 s open between two blockages: not judged
    assert judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES).converged
    reachable[_between(t, 28.0, 33.0)] = True
    reachable[_between(t, 34.0, 37.0)] = False  # 9 s open, 7 s of it before the leave window: failed
    err[_between(t, 20.0, 37.0)] = 1.0
    assert not judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES).converged


@pytest.mark.parametrize(("left_s", "converged"), [(1.5, True), (2.0, True), (5.0, False)])
def test_leaving_before_a_blockage_is_judged_only_beyond_leave_s(left_s: float, converged: bool) -> None:
    """A robot standing on the reference must be gone when an obstacle arrives: the `leave_s`
    (2 s) before a blockage are not judged; a robot that left earlier than that is."""
    t, err, reachable = _series()
    reachable[_between(t, 30.0, 35.0)] = False
    err[_between(t, 30.0 - left_s, 35.0)] = 2.0  # aside from left_s before the blockage to its end
    judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
    assert OUTCOMES.leave_s == 2.0
    assert judged.blocked_s == pytest.approx(5.0)  # the blockage itself, not the leave window
    assert judged.converged == converged
    if converged:
        assert judged.rmse_reachable_m == pytest.approx(0.1)
    no_leave = judge_tracking("tracking", t, err, reachable, TAU_S, Outcomes(leave_s=0.0))
    assert no_leave.rmse_reachable_m > judged.rmse_reachable_m  # those instants were excluded


def test_rejoin_clock_starts_at_settle_and_other_outcomes_never_converge() -> None:
    t, err, reachable = _series()
    reachable[_between(t, 2.0, 6.0)] = False
    err[t < 14.0] = 1.0  # rejoins at 14 s: 8 s after the way cleared, but only 4 s after settling
    judged = judge_tracking("tracking", t, err, reachable, TAU_S, OUTCOMES)
    assert judged.converged and judged.rejoin_times_s == (pytest.approx(4.0),)
    assert not judge_tracking("stuck", *_series(), TAU_S, OUTCOMES).converged
    t, err, _ = _series()
    assert not judge_tracking("tracking", t, err, np.zeros(t.shape, bool), TAU_S, OUTCOMES).converged


def test_reference_reachable_is_outside_every_inflated_circle() -> None:
    radii, robot = np.array([0.5, 0.3]), 0.57
    centres = np.array([[0.0, 0.0], [5.0, 0.0]])
    assert reference_reachable(np.array([1.08, 0.0]), centres, radii, robot)
    assert not reference_reachable(np.array([1.06, 0.0]), centres, radii, robot)
    assert not reference_reachable(np.array([5.0, 0.8]), centres, radii, robot)
    moving = np.array([[[0.0, 0.0], [5.0, 0.0]], [[0.0, 0.0], [2.0, 0.0]]])  # (steps, obstacles, 2)
    ref = np.array([[2.5, 0.0], [2.5, 0.0]])
    assert reference_reachable(ref, moving, radii, robot).tolist() == [True, False]
    assert reference_reachable(ref, np.zeros((2, 0, 2)), np.zeros(0), robot).tolist() == [True, True]


def test_success_spec_and_outcomes_share_rejoin_s() -> None:
    assert SuccessSpec().rejoin_s == Outcomes().rejoin_s == 5.0
