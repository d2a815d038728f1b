"""husky-cbf's safety filter (controllers.husky_cbf.safety_filter): the backup manoeuvre, and when
the filter keeps the NMPC's command or brakes instead. Pure tests: no physics, no solver."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.husky_cbf.config import RobotResponse
from controllers.husky_cbf.safety_filter import SafetyFilter
from controllers.husky_cbf.safety_filter import _obstacle_rows as sf_rows
from controllers.obstacles import Obstacle

RESPONSE = RobotResponse(
    max_linear_accel_mps2=1.0,
    max_angular_accel_radps2=2.0,
    yaw_gain=1.0,
    yaw_time_constant_s=0.1,
    half_separation_m=0.3,
    max_linear_mps=1.0,
)
DISCS = np.array([-0.33, 0.0, 0.33])


def _filter(
    accel_bound: float = 0.5, lead_s: float = 0.0, threat_s: float = 0.0, trap_s: float = 0.0
) -> SafetyFilter:
    """A filter for the test robot; threat_s 0: standing is always a refuge; trap_s 0: a plan that
    passes is never traded for an evasive backup."""
    return SafetyFilter(RESPONSE, 0.1, DISCS, 0.38, accel_bound, lead_s, threat_s, 2.0, trap_s)


def _moving_at(v_mps: float) -> np.ndarray:
    """The extended state [x, y, theta, v, omega_cmd, omega] of a robot at the origin facing +x."""
    return np.array([0.0, 0.0, 0.0, v_mps, 0.0, 0.0])


def test_the_backup_holds_the_command_one_period_then_brakes_to_a_stand_at_the_drive_s_limit() -> None:
    times, poses = _filter().manoeuvre(_moving_at(1.0), np.array([[1.0, 0.0]]))
    assert np.all(np.diff(times) > 0)
    # 0.1 s at 1 m/s, then v^2 / (2 a) = 0.5 m of braking at 1 m/s^2
    assert 0.55 <= poses[-1, 0] <= 0.65 and abs(poses[-1, 1]) < 1e-12
    assert 1.0 <= times[-1] <= 1.2
    _, braking = _filter().manoeuvre(_moving_at(1.0), None)
    assert 0.45 <= braking[-1, 0] <= 0.55


def test_a_clear_way_keeps_the_command_and_a_post_within_the_stopping_distance_brakes() -> None:
    command = np.array([1.0, 0.0])
    far = [Obstacle(3.0, 0.0, 0.3)]
    kept = _filter().filter(_moving_at(1.0), command, far)
    assert not kept.intervened and np.array_equal(kept.command, command) and kept.clearance_m > 1.0
    # the front disc reaches 0.33 + 0.6 + 0.38 = 1.31 m on the command's backup, 1.21 m braking now
    near = [Obstacle(1.55, 0.0, 0.3)]
    verdict = _filter().filter(_moving_at(1.0), command, near)
    assert verdict.intervened and np.array_equal(verdict.command, np.zeros(2))
    assert (
        verdict.clearance_m
        > 0
        > _filter().clearance(*_filter().manoeuvre(_moving_at(1.0), command[None]), near)
    )


def test_a_mover_on_course_to_the_way_is_braked_for_and_one_walking_away_is_not() -> None:
    command = np.array([0.5, 0.0])
    assert (
        not _filter(accel_bound=0.0)
        .filter(_moving_at(0.5), command, [Obstacle(0.6, 1.2, 0.3, 0, 1.0)])
        .intervened
    )
    assert (
        _filter(accel_bound=0.0)
        .filter(_moving_at(0.5), command, [Obstacle(0.6, 1.2, 0.3, 0, -1.0)])
        .intervened
    )


def test_a_mover_s_circle_grows_with_the_bound_on_its_change_of_velocity() -> None:
    command = np.array([0.5, 0.0])
    beside = [Obstacle(1.0, 1.5, 0.3, 0.0, 1e-3)]  # a walker standing beside the way
    assert not _filter(accel_bound=0.0).filter(_moving_at(0.5), command, beside).intervened
    assert _filter(accel_bound=10.0).filter(_moving_at(0.5), command, beside).intervened
    static = [Obstacle(1.0, 1.5, 0.3)]  # a static obstacle does not move whatever the bound
    assert not _filter(accel_bound=10.0).filter(_moving_at(0.5), command, static).intervened


def test_the_time_since_the_measurement_counts_for_the_mover() -> None:
    walker = [Obstacle(0.6, 1.4, 0.3, 0.0, -1.0)]
    command = np.array([0.5, 0.0])
    assert not _filter(accel_bound=0.0).filter(_moving_at(0.5), command, walker).intervened
    assert _filter(accel_bound=0.0, lead_s=0.8).filter(_moving_at(0.5), command, walker).intervened


def test_when_no_backup_clears_the_one_that_keeps_more_clearance_is_sent() -> None:
    post = [Obstacle(1.5, 0.0, 0.3)]  # within reach of both the command's backup and braking now
    command = np.array([1.0, 0.0])
    f = _filter()
    kept = f.clearance(*f.manoeuvre(_moving_at(1.0), command[None]), post)
    braking = f.clearance(*f.manoeuvre(_moving_at(1.0), None), post)
    verdict = f.filter(_moving_at(1.0), command, post)
    assert kept < 0 and verdict.clearance_m == max(kept, braking) and verdict.intervened
    assert math.isinf(f.clearance(*f.manoeuvre(_moving_at(1.0), command[None]), []))


def test_the_committed_trajectory_carries_the_robot_when_no_cut_of_a_new_plan_clears() -> None:
    f = _filter()
    cruise, reverse = np.tile([0.5, 0.0], (5, 1)), np.tile([-1.0, 0.0], (5, 1))
    standing = np.zeros(6)
    first = f.filter(standing, cruise, [])
    assert not first.intervened and np.array_equal(first.command, cruise[0])
    # a post 5 mm behind the rear disc: every cut of the reversing plan touches it, the committed
    # forward run does not, so its next command is sent instead of the plan's
    behind = [Obstacle(-(0.33 + 0.38 + 0.3 + 0.005), 0.0, 0.3)]
    assert f.clearance(*f.manoeuvre(standing, reverse[:1]), behind) < 0
    second = f.filter(standing, reverse, behind)
    assert second.intervened and np.array_equal(second.command, cruise[1]) and second.clearance_m >= 0
    f.reset()  # a reset commits braking now: standing still
    third = f.filter(standing, reverse, behind)
    assert third.intervened and np.array_equal(third.command, np.zeros(2))


def test_a_longer_cut_passes_only_if_its_whole_manoeuvre_clears() -> None:
    f = _filter()
    straight = np.tile([1.0, 0.0], (10, 1))
    post = [Obstacle(2.3, 0.0, 0.3)]  # braking after one period clears it, after ten it does not
    assert f.clearance(*f.manoeuvre(_moving_at(1.0), straight[:1]), post) >= 0
    assert f.clearance(*f.manoeuvre(_moving_at(1.0), straight), post) < 0
    verdict = f.filter(_moving_at(1.0), straight, post)
    assert not verdict.intervened and verdict.clearance_m >= 0
    # the longest cut that passes was committed: more than the first command, less than all ten
    k = next(
        k for k in range(10, 0, -1) if f.clearance(*f.manoeuvre(_moving_at(1.0), straight[:k]), post) >= 0
    )
    assert 1 < k < 10 and len(f._committed) == k - 1


def test_where_standing_is_no_refuge_a_checked_way_out_is_taken_and_else_the_robot_brakes() -> None:
    """A standing robot with a post behind it, so that no cut of its reversing plan passes, and a
    walker coming down on it from the north: braking stands in the walker's way. A dash forwards
    out of the way is taken where it passes the full check; where no moving manoeuvre passes (a
    bound so large that every mover's circle swallows it), the robot brakes all the same, even
    against a plan that clears the walker's track as measured: an unchecked command is never sent."""
    standing = np.zeros(6)
    reverse = np.tile([-1.0, 0.0], (5, 1))
    post = Obstacle(-(0.33 + 0.38 + 0.3 + 0.005), 0.0, 0.3)
    walker = Obstacle(-0.2, 3.0, 0.3, 0.0, -1.0)
    f = _filter(accel_bound=0.0, threat_s=6.0)
    evading = f.filter(standing, reverse, [post, walker])
    assert evading.intervened and evading.clearance_m >= 0.0 and evading.command[0] > 0.0
    times, poses = f.manoeuvre(standing, np.vstack([evading.command, f._committed]))
    assert f.clearance(times, poses, [post, walker]) >= 0.0
    assert not f._hit_standing(times[-1], poses[-1], sf_rows([post, walker]), 6.0)
    # nearer, with that bound: no cut of a creeping plan clears the walker's grown circle, though
    # every cut clears its track as measured; the plan is not sent
    creeping, nearer = np.tile([0.3, 0.0], (5, 1)), Obstacle(-0.2, 1.6, 0.3, 0.0, -1.0)
    strict = _filter(accel_bound=50.0, threat_s=6.0)
    cut = strict.manoeuvre(standing, creeping[:1])
    assert strict.clearance(*cut, [post, nearer]) < 0.0 <= strict.clearance(*cut, [post, nearer], 0.0)
    braking = strict.filter(standing, creeping, [post, nearer])
    assert braking.intervened and np.array_equal(braking.command, np.zeros(2))
    # a walker whose track passes beside the standing robot is no threat: no dash, the robot brakes
    passing = Obstacle(1.2, 1.2, 0.3, -0.6, 0.0)
    stays = _filter(accel_bound=0.0, threat_s=6.0).filter(standing, reverse, [post, passing])
    assert stays.intervened and np.array_equal(stays.command, np.zeros(2))


def test_what_cannot_be_checked_does_not_pass() -> None:
    f = _filter()
    nan_plan = np.full((5, 2), np.nan)
    verdict = f.filter(_moving_at(0.5), nan_plan, [Obstacle(5.0, 0.0, 0.3)])
    assert verdict.intervened and np.all(np.isfinite(verdict.command))
    unmeasured = [Obstacle(float("nan"), 0.0, 0.3)]
    assert f.clearance(*f.manoeuvre(_moving_at(0.5), None), unmeasured) == -math.inf
    empty = f.filter(_moving_at(0.5), np.zeros((0, 2)), [])
    assert empty.intervened and np.array_equal(empty.command, np.zeros(2))


def test_a_plan_that_would_stand_in_a_walker_s_way_gives_way_to_a_checked_evasive_backup() -> None:
    """A robot creeping east towards a post, with a walker coming at it from the north: the plan is
    cut short of the post (its longest passing cut ends before its last command), and that cut
    ends standing where the walker arrives within the trap horizon. With a trap horizon the filter
    commits an evasive backup that passes the same full check and ends out of the walker's way;
    without one the plan is kept. A plan that passes whole but stands in the walker's way gives way
    too, unless the walker's track meets a static obstacle within the threat horizon: it turns
    before then, and its track does not say where it will go."""
    creeping = np.tile([0.2, 0.0], (30, 1))
    post = Obstacle(1.5, 0.0, 0.3)
    walker = Obstacle(0.6, 3.5, 0.3, 0.0, -1.0)  # crosses the way just after the cut's stand
    kept = _filter(accel_bound=0.0).filter(_moving_at(0.2), creeping, [post, walker])
    assert not kept.intervened and np.array_equal(kept.command, creeping[0])
    f = _filter(accel_bound=0.0, trap_s=3.0)
    evading = f.filter(_moving_at(0.2), creeping, [post, walker])
    assert evading.intervened and evading.clearance_m >= 0.0
    assert abs(evading.command[0]) == RESPONSE.max_linear_mps  # a dash at the drive's full speed
    times, poses = f.manoeuvre(_moving_at(0.2), np.vstack([evading.command, f._committed]))
    assert f.clearance(times, poses, [post, walker], 0.0) >= 0.0
    assert not f._hit_standing(times[-1], poses[-1], sf_rows([post, walker]), 3.0)
    # the whole plan passes, and ends standing in the walker's way
    whole = _filter(accel_bound=0.0, threat_s=6.0, trap_s=3.0)
    assert whole.filter(_moving_at(0.2), creeping[:5], [post, walker]).intervened
    # ... where a wall stands across the walker's track, 1.1 m on, it will turn: the plan goes on
    wall = Obstacle(0.6, 1.8, 0.3)
    assert not whole.filter(_moving_at(0.2), creeping[:5], [post, walker, wall]).intervened


def test_a_remembered_mover_s_circle_grows_over_its_age() -> None:
    """A walker measured a while ago (obstacle_memory.py) is as uncertain as its age: beside the
    way, it passes the check measured now and not measured two seconds ago."""
    command = np.array([0.5, 0.0])
    beside = [Obstacle(1.0, 1.6, 0.3, 0.0, 1e-3)]
    assert not _filter(accel_bound=0.5).filter(_moving_at(0.5), command, beside, [0.0]).intervened
    assert _filter(accel_bound=0.5).filter(_moving_at(0.5), command, beside, [2.0]).intervened


def test_with_no_way_out_of_a_walker_s_way_the_robot_stands_where_it_is_reached_last() -> None:
    """A standing robot, a walker coming down just behind it, and no evasive backups: every cut of
    a plan that reverses towards the walker's track stands in its way, sooner the further it goes,
    and no way out exists. The robot brakes where it stands, where the walker reaches it last,
    rather than back into its way; a plan that drives away from the track goes on."""
    no_evasions = 0.0
    f = SafetyFilter(RESPONSE, 0.1, DISCS, 0.38, 0.0, 0.0, 6.0, no_evasions, 3.0)
    standing = np.zeros(6)
    walker = Obstacle(-0.8, 2.5, 0.3, 0.0, -1.0)
    rows = sf_rows([walker])
    reverse = np.tile([-0.5, 0.0], (5, 1))
    times, poses = f.manoeuvre(standing, reverse)
    braking_times, braking = f.manoeuvre(standing, None)
    reversed_s = times[-1] + f._reached_s(times[-1], poses[-1], rows, 3.0)
    assert reversed_s < braking_times[-1] + f._reached_s(braking_times[-1], braking[-1], rows, 3.0)
    verdict = f.filter(standing, reverse, [walker])
    assert verdict.intervened and np.array_equal(verdict.command, np.zeros(2))
    forward = np.tile([0.5, 0.0], (5, 1))
    assert not f.filter(standing, forward, [walker]).intervened


def test_a_robot_standing_closer_to_a_post_than_its_discs_allow_may_leave_but_not_go_deeper() -> None:
    """The front disc (0.33 m ahead, radius 0.38 m) overlaps a post 0.1 m: no candidate from there
    clears it as measured, so the robot could never move again. It may back away from the post,
    and may not drive on into it."""
    standing = _moving_at(0.0)
    post = [Obstacle(0.33 + 0.38 + 0.3 - 0.1, 0.0, 0.3)]
    backing = _filter().filter(standing, np.array([[-0.5, 0.0]] * 5), post)
    assert not backing.intervened and backing.command[0] == -0.5
    assert backing.clearance_m == pytest.approx(0.0, abs=1e-9)  # shrunk by the overlap: no deeper
    onwards = _filter().filter(standing, np.array([[0.5, 0.0]] * 5), post)
    assert onwards.intervened and np.array_equal(onwards.command, np.zeros(2))


def test_a_disc_deeper_in_a_thin_post_than_its_radius_may_still_leave() -> None:
    """A post of 0.05 m radius with the front disc's centre 0.35 m from it: the disc is deeper in
    it than the post is wide. Backing away is still allowed, driving on is not."""
    standing = _moving_at(0.0)
    post = [Obstacle(0.33 + 0.35, 0.0, 0.05)]
    assert not _filter().filter(standing, np.array([[-0.5, 0.0]] * 5), post).intervened
    assert _filter().filter(standing, np.array([[0.5, 0.0]] * 5), post).intervened
