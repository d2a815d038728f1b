"""husky-cbf's planner, behaviours and arbiter on their own (no PyBullet, no closed loop): the
planner's way round, the approaches, yielding to movers, and the arbiter's ordered policy."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pytest

from controllers import Obstacle
from controllers.husky_cbf import planner as planner_module
from controllers.husky_cbf.arbiter import Arbiter, Decision, Mode
from controllers.husky_cbf.behaviours.approach import (
    PIVOT_AIM_RAD,
    PointApproach,
    SetPointApproach,
    point_approach,
)
from controllers.husky_cbf.behaviours.base import ReferenceKind, Situation, Target
from controllers.husky_cbf.behaviours.yield_to_movers import RobotLimits, SideStep, StepAside
from controllers.husky_cbf.config import (
    ApproachConfig,
    MoverConfig,
    PlannerConfig,
    YieldConfig,
)
from controllers.husky_cbf.movers import PLANNER_SWEEP_FACTOR, MoverModel, free_run_m
from controllers.husky_cbf.planner import Planner, segment_blocked
from controllers.references import CircleTrajectory
from husky_sim.runs.scenario import load_scenario, shipped_scenarios

INFLATION = 0.48
#: a Husky's drive: 1 m/s, 3 m/s^2, 1.7 rad/s body yaw rate, 6 rad/s^2, 0.45 s delay and lag
ROBOT = RobotLimits(1.0, 3.0, 1.7, 6.0, 0.45)
SWEEP_S = MoverConfig().sweep_s
TAU = 0.1
NONE = np.zeros((0, 3))


def _movers(growth_s: float = 0.0, lead_s: float = 0.0, inflation_m: float = INFLATION) -> MoverModel:
    return MoverModel(SWEEP_S, inflation_m=inflation_m, growth_s=growth_s, lead_s=lead_s)


def _planner(config: PlannerConfig | None = None, **movers: float) -> Planner:
    return Planner(config or PlannerConfig(), _movers(**movers))


def _situation(
    pose: Sequence[float],
    goal: Sequence[float],
    obstacles: Sequence[Obstacle] = (),
    kind: ReferenceKind = ReferenceKind.SET_POINT,
    t: float = 0.0,
    speed_mps: float = 0.0,
    reference_state: Sequence[float] | None = None,
    reference_speed_mps: float = 0.0,
) -> Situation:
    pose_arr, goal_arr = np.asarray(pose, dtype=float), np.asarray(goal, dtype=float)
    return Situation(
        pose=pose_arr,
        estimate=pose_arr,
        speed_mps=speed_mps,
        kind=kind,
        goal=goal_arr,
        reference_state=goal_arr if reference_state is None else np.asarray(reference_state, dtype=float),
        reference_speed_mps=reference_speed_mps,
        obstacles=list(obstacles),
        circles=_movers().body_circles(obstacles, pose_arr[:2]),
        command=np.array([0.5, 0.0]),
        t=t,
    )


# -- the planner ----------------------------------------------------------------------------------
def test_the_planner_routes_round_a_blocking_obstacle_and_leaves_a_clear_line_alone() -> None:
    planner = _planner()
    goal = np.array([8.0, 0.0, 0.0])
    assert planner.waypoint(np.zeros(2), goal, [Obstacle(4.0, 3.0, 0.5)]) is None
    blocking = [Obstacle(4.0, 0.1, 0.6)]
    waypoint = planner.waypoint(np.zeros(2), goal, blocking)
    assert waypoint is not None
    circles = np.array([[4.0, 0.1, 1.08]])
    assert not segment_blocked(np.zeros(2), np.array([waypoint.x_m, waypoint.y_m]), circles)
    assert np.min(np.hypot(waypoint.path[:, 0] - 4.0, waypoint.path[:, 1] - 0.1)) > 1.08
    assert math.hypot(waypoint.path[-1, 0] - 8.0, waypoint.path[-1, 1]) < 0.1


def test_the_planner_follows_a_mover_through_a_gap_rather_than_turn_back_for_the_long_way() -> None:
    """A mover going the robot's way closes the gap north of a cylinder for a moment: the planner
    takes the gap when the robot, driving it, would meet the mover nowhere (it follows it), and
    the long way round when the mover all but stands in it."""
    planner = _planner(growth_s=0.93, inflation_m=0.49)
    robot, goal = np.array([4.0, 1.6]), np.array([0.5, 2.0, math.pi])  # the gap: north-west

    def way_round(speed_mps: float) -> float:
        cylinder, mover = Obstacle(2.0, 1.0, 0.4), Obstacle(2.6, 3.0, 0.3, vx_mps=-speed_mps)
        waypoint = planner.waypoint(robot, goal, [cylinder, mover])
        assert waypoint is not None and planner.guided
        return waypoint.y_m

    assert way_round(0.4) > 1.6  # north, through the gap behind the mover
    assert way_round(0.06) < 1.0  # south: a mover at 6 cm/s blocks the gap for a minute


def test_the_way_round_a_static_obstacle_dead_ahead_keeps_its_side_under_noise(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An obstacle dead ahead measured 3 cm to one side, then the other: without hysteresis the
    shortest way round changes sides; with it the robot keeps the side it took. Among movers there
    is no hysteresis (the way round changes for real)."""
    goal = np.array([7.0, 0.0, 0.0])

    def sides(vx_mps: float = 0.0) -> list[float]:
        planner = _planner()
        out = []
        for dy in (0.03, -0.03, 0.03, -0.03):
            waypoint = planner.waypoint(np.zeros(2), goal, [Obstacle(3.5, dy, 0.45, vx_mps=vx_mps)])
            assert waypoint is not None
            beside = waypoint.path[np.argmin(np.abs(waypoint.path[:, 0] - 3.5))]  # passing it
            out.append(math.copysign(1.0, beside[1]))
        return out

    assert len(set(sides())) == 1  # keeps its side
    assert len(set(sides(vx_mps=-0.3))) == 2  # a mover: no hysteresis
    monkeypatch.setattr(planner_module, "PATH_HYSTERESIS", 0.0)
    assert len(set(sides())) == 2  # flips with the noise


def test_the_planner_sees_a_mover_as_the_nmpc_does_from_its_first_circle_on() -> None:
    """A mover 1 m past the reference, going away at 0.5 m/s: circles centred on the mover now,
    grown as wide as the NMPC sees it, would still cover the reference; the planner's start where
    the NMPC's first circle is (the mover model's lead), so the way back is clear. Coming the other
    way, the same mover holds the way closed."""
    planner = _planner(growth_s=0.96, lead_s=1.09)
    robot, reference = np.array([0.0, -2.0]), np.array([0.0, 0.0, math.pi / 2])
    going = Obstacle(1.0, 0.0, 0.3, vx_mps=0.5)
    assert _planner(growth_s=0.96).waypoint(robot, reference, [going]) is not None  # from now: closed
    assert planner.waypoint(robot, reference, [going]) is None  # straight back
    coming = Obstacle(1.0, 0.0, 0.3, vx_mps=-0.5)
    assert planner.waypoint(robot, reference, [coming]) is not None  # held closed: a detour


def test_the_planner_sweeps_a_mover_over_its_named_multiple_of_the_nmpc_sweep() -> None:
    """One sweep setting: the planner's sweep is the mover model's, times PLANNER_SWEEP_FACTOR."""
    movers = _movers()
    mover = Obstacle(0.0, 5.0, 0.3, vx_mps=1.0)
    circles = movers.swept_circles([mover], np.array([0.0, -10.0]))
    assert circles[-1, 0] - circles[0, 0] == pytest.approx(movers.planner_sweep_s)
    assert movers.planner_sweep_s == pytest.approx(PLANNER_SWEEP_FACTOR * SWEEP_S)


def test_a_mover_s_track_ends_where_its_disc_meets_a_static_one() -> None:
    """free_run_m: a walker heading at a post 3 m ahead runs 3 - 0.3 - 0.2 m; one walking past it,
    or away from it, or already touching it (passing beside it), and the post itself, run free."""
    post = (3.0, 0.0, 0.0, 0.0, 0.2)
    rows = np.array(
        [
            (0.0, 0.0, 1.0, 0.0, 0.3),  # at it
            (0.0, 1.0, 1.0, 0.0, 0.3),  # past it, 1 m beside
            (0.0, 0.0, -1.0, 0.0, 0.3),  # away from it
            (2.7, 0.3, 1.0, 0.0, 0.3),  # touching it
            post,
        ]
    )
    free = free_run_m(rows)
    assert free[0] == pytest.approx(2.5)
    assert np.all(np.isinf(free[1:]))


# -- approach -------------------------------------------------------------------------------------
def test_a_slow_trajectory_is_approached_along_the_bearing_and_tracked_when_near() -> None:
    goal = np.array([1.0, 0.0, math.pi / 2])  # the reference's heading: +y
    far = point_approach(np.array([-1.0, -2.0, 0.0]), goal, 0.1, 0.3)
    assert far is not None and (far.x_m, far.y_m) == (1.0, 0.0)
    assert far.heading_rad == pytest.approx(math.atan2(2.0, 2.0))  # at the point, not its tangent
    assert point_approach(np.array([1.05, 0.0, 0.0]), goal, 0.1, 0.3) is None  # near: the reference
    between = point_approach(np.array([0.8, 0.0, 0.0]), goal, 0.1, 0.3)  # 0.2 m: half way
    assert between is not None
    assert between.heading_rad == pytest.approx(0.5 * (0.0 + math.pi / 2))
    proposed = PointApproach().propose(_situation([0.8, 0.0, 0.0], goal, kind=ReferenceKind.SLOW_TRAJECTORY))
    assert proposed is not None and proposed.heading_rad == pytest.approx(between.heading_rad)


def _approach() -> SetPointApproach:
    approach = SetPointApproach(ApproachConfig(), PlannerConfig().grid_resolution_m)
    approach.pre_goal_done = True
    return approach


def test_a_robot_beside_its_set_point_pivots_turns_drives_and_settles() -> None:
    """Beside the goal and off its line, the approach turns where the robot stands to face the
    goal, then drives at it, then leaves the goal's heading to the NMPC; past the goal it backs
    onto it instead of turning round; far off the line it does not pivot."""
    approach = _approach()
    goal = np.array([7.0, 0.0, 0.0])
    pose = np.array([6.7, 0.25, 0.0])  # 0.3 m short, 0.25 m beside
    turn = approach.waypoint(pose, goal, NONE)
    bearing = math.atan2(-0.25, 0.3)
    assert turn is not None and (turn.x_m, turn.y_m) == (6.7, 0.25)  # turn where it stands
    assert turn.heading_rad == pytest.approx(bearing) and approach.pivot == "turn"
    assert not approach.reversing
    aimed = np.array([6.7, 0.25, bearing + 0.5 * PIVOT_AIM_RAD])
    drive = approach.waypoint(aimed, goal, NONE)
    assert drive is not None and (drive.x_m, drive.y_m) == (7.0, 0.0) and approach.pivot == "drive"
    assert approach.waypoint(np.array([6.98, 0.02, bearing]), goal, NONE) is None  # arrived
    assert approach.pivot == "settle" and approach.settling
    assert approach.waypoint(np.array([7.03, 0.05, -0.4]), goal, NONE) is None  # settling
    approach.waypoint(np.array([7.0, 0.15, 0.0]), goal, NONE)  # drifted 0.15 m aside: pivots again
    assert approach.pivot == "turn"
    approach.waypoint(np.array([5.5, 0.5, 0.0]), goal, NONE)  # taken 1.6 m away mid-pivot
    assert approach.pivot == ""

    past = _approach()
    back = past.waypoint(np.array([7.3, 0.25, 0.0]), goal, NONE)  # past the goal, facing on
    assert back is not None and past.reversing  # backs onto the goal: less turning in all
    assert math.cos(back.heading_rad) > 0.5
    beside = _approach()
    beside.waypoint(np.array([7.0, 1.5, 0.0]), goal, NONE)  # beyond pivot_radius_m: docks
    assert beside.pivot == "" and beside.docking


def test_docking_gives_way_to_a_pivot_where_an_obstacle_takes_the_room_behind_the_goal() -> None:
    """Beside a goal and past it, the approach backs up along the goal's line to drive in; with an
    obstacle on that line behind the goal it pivots instead."""
    goal = np.array([0.0, 0.0, 0.0])
    pose = np.array([0.3, 1.5, 0.0])  # beyond pivot_radius_m, past the goal: docking
    free = _approach()
    free.waypoint(pose, goal, NONE)
    assert free.docking and free.pivot == ""
    blocked = _approach()
    circles = _planner().circles(pose[:2], [Obstacle(-1.5, 0.0, 0.4)])
    blocked.waypoint(pose, goal, circles)
    assert not blocked.docking and blocked.pivot == "turn"


def test_a_robot_that_slides_off_the_line_while_settling_pivots_again() -> None:
    """Turning in place to the goal's heading, a skid-steer scrubs sideways: 8 cm off the line
    (beyond ENTER_M, within PIVOT_RESTART_M of the goal) it pivots again, 5 cm it settles."""
    goal = np.array([9.0, 0.0, 0.0])
    for lateral, phase in ((0.05, "settle"), (0.08, "turn")):
        approach = _approach()
        approach.pivot = "settle"
        approach.waypoint(np.array([9.02, lateral, -0.14]), goal, NONE)
        assert approach.pivot == phase


def test_a_settle_still_turning_to_the_goal_heading_is_not_restarted_by_its_own_scrub() -> None:
    """Mid-turn, 8 cm off the line is the turn's own slip: the settle goes on; drifted beyond
    PIVOT_RESTART_M it pivots again whatever its heading."""
    goal = np.array([9.0, 0.0, 0.0])
    for pose, phase in (
        ((9.02, 0.08, -1.0), "settle"),
        ((9.02, 0.08, -0.14), "turn"),
        ((9.0, 0.12, -1.0), "turn"),
    ):
        approach = _approach()
        approach.pivot = "settle"
        approach.waypoint(np.array(pose), goal, NONE)
        assert approach.pivot == phase, pose


# -- yielding to movers ---------------------------------------------------------------------------
def test_stepping_aside_judges_a_mover_against_the_robot_where_it_means_to_be() -> None:
    """A robot reversing ahead of a mover at the mover's speed sees no closing track relative to its
    own velocity (it is chased); judged standing, the mover is on course and the step is to the
    side of the mover's own line, not along it."""
    judge = SideStep(YieldConfig(), _movers())
    pose = np.array([0.0, 0.0, math.pi])  # facing -x, reversing moves it along +x
    mover = [Obstacle(-1.5, 0.0, 0.3, vx_mps=0.6)]  # 1.5 m behind the robot's path, coming on at 0.6 m/s
    assert judge.step(pose[:2], pose[2], np.array([0.6, 0.0]), mover) is None  # fleeing: never closer
    step = judge.step(pose[:2], pose[2], np.zeros(2), mover)
    assert step is not None and judge.active
    assert abs(step.x_m) < 1e-9 and abs(step.y_m) >= 0.3 + INFLATION + YieldConfig().margin_m - 1e-9


def test_stepping_aside_on_a_trajectory_does_not_switch_with_the_robot_s_own_speed() -> None:
    """A robot standing behind its reference (0.23 m/s north) with a mover crossing from the
    north-west: judged at its own speed, the mover is off course while the robot stands and on
    course once it drives off, so the verdict would switch as it stops and starts. Judged at the
    reference, at the reference's velocity, the step aside is the same at either speed; a
    set-point is judged at the robot's own speed, a slow trajectory standing."""
    pose = np.array([2.35, -0.84, 1.58])
    mover = [Obstacle(0.52, 1.44, 0.3, vx_mps=0.4 * math.cos(-1.0), vy_mps=0.4 * math.sin(-1.0))]
    reference_state = np.array([2.30, 0.08, math.pi / 2 + 0.035])
    heading = np.array([math.cos(pose[2]), math.sin(pose[2])])
    assert SideStep(YieldConfig(), _movers()).step(pose[:2], pose[2], 0.0 * heading, mover) is None
    assert SideStep(YieldConfig(), _movers()).step(pose[:2], pose[2], 0.3 * heading, mover) is not None

    def situation(kind: ReferenceKind, speed_mps: float) -> Situation:
        return _situation(pose, reference_state, mover, kind, speed_mps=speed_mps, reference_speed_mps=0.23)

    steps = []
    for speed in (0.0, 0.3):
        step = StepAside(YieldConfig(), _movers(), ROBOT).propose(situation(ReferenceKind.TRAJECTORY, speed))
        assert step is not None
        steps.append((step.x_m, step.y_m))
    assert steps[0] == steps[1]
    meant = StepAside.meant_velocity
    assert np.allclose(meant(situation(ReferenceKind.SET_POINT, 0.3)), 0.3 * heading)
    assert np.allclose(meant(situation(ReferenceKind.SLOW_TRAJECTORY, 0.3)), 0.0)


def test_on_a_trajectory_the_robot_steps_aside_only_when_it_must_leave_and_behind_the_mover() -> None:
    """A reference heading east at 0.4 m/s with a walker crossing it from the south at 1 m/s, due
    to meet it: the robot keeps to the reference while the walker is farther off than the robot
    needs to leave (RobotLimits.leave_s), and then steps aside from the reference point, to the
    side away from the walker's track ahead (west of it: behind it), not the side the walker is
    heading for."""
    reference = np.array([0.0, 0.0, 0.0])
    velocity = np.array([0.4, 0.0])

    def propose(t_meet_s: float, behaviour: StepAside) -> Target | None:
        # the walker reaches the reference's point at t_meet_s, where the reference is then
        meet = velocity * t_meet_s
        walker = [Obstacle(float(meet[0]), float(meet[1] - t_meet_s), 0.3, vx_mps=0.0, vy_mps=1.0)]
        s = _situation(reference, reference, walker, ReferenceKind.TRAJECTORY, reference_speed_mps=0.4)
        return behaviour.propose(replace(s, pose=np.array([0.0, -0.2, 0.0])))

    needed = 0.3 + INFLATION + YieldConfig().margin_m
    assert 1.5 < ROBOT.leave_s(needed) < 5.9 < YieldConfig().horizon_s
    assert propose(5.9, StepAside(YieldConfig(), _movers(), ROBOT)) is None  # on course, time to spare
    behaviour = StepAside(YieldConfig(), _movers(), ROBOT)
    step = propose(1.5, behaviour)
    assert step is not None and behaviour.active
    assert step.path[0] == pytest.approx(reference[:2])  # from the reference point, not the robot
    assert step.x_m < 0.0  # behind the walker (its track runs north at x = 0.6)
    relative = np.array([-0.4, 1.0]) / math.hypot(0.4, 1.0)  # its track seen from the point
    clearance = abs(relative[0] * step.y_m - relative[1] * step.x_m)  # from that track, through the point
    assert clearance == pytest.approx(needed, abs=1e-6)


def test_the_time_to_leave_a_mover_s_track_grows_with_the_distance_and_the_delay() -> None:
    """RobotLimits.leave_s: a quarter turn and a drive from rest after the delay, in sequence."""
    slow = RobotLimits(0.5, 1.0, 1.0, 2.0, 0.0)
    assert slow.leave_s(1.0) == pytest.approx(math.pi / 2 + 0.5 + 2.0 + 0.5)
    assert replace(slow, delay_s=0.3).leave_s(1.0) == pytest.approx(slow.leave_s(1.0) + 0.3)
    assert slow.leave_s(2.0) - slow.leave_s(1.0) == pytest.approx(2.0)


def test_a_step_aside_goes_to_the_side_of_the_mover_s_line_a_given_point_is_on() -> None:
    """A mover heading north-east through (0.6, 0.8): the step aside from that point goes to the
    side of the mover's line that `side_of` is on, whichever that is, to the same distance."""
    point = np.array([0.6, 0.8])
    mover = [Obstacle(-0.9, -0.7, 0.3, vx_mps=0.45 / math.sqrt(2), vy_mps=0.45 / math.sqrt(2))]
    needed = 0.3 + INFLATION + YieldConfig().margin_m
    for side_of, sign in ((np.array([2.4, 0.1]), 1.0), (np.array([-0.5, 2.0]), -1.0)):
        step = SideStep(YieldConfig(), _movers()).step(point, 0.0, np.zeros(2), mover, side_of=side_of)
        assert step is not None
        across = (step.x_m - step.y_m) - (point[0] - point[1])  # > 0: south-east of the line
        assert across * sign > 0 and abs(across) / math.sqrt(2) == pytest.approx(needed)


def test_stepping_aside_from_a_fast_mover_clears_it_as_wide_as_the_nmpc_sees_it() -> None:
    """A fast mover's track passing beside the robot beyond the yielding margin but inside the
    NMPC's sweep of that mover would hold the robot, which then backs away along the track,
    chased. The robot steps aside from such a mover (to beyond the NMPC's sweep), and still not
    from a slow one passing as far off."""
    path = next(p for p in shipped_scenarios() if p.stem == "paper_dynamic_tracking")
    controller = load_scenario(path).make_controller("husky-cbf")
    config, movers = controller.config, controller.movers
    judge = controller.arbiter.step_aside.judge
    pose = np.array([0.0, 0.0, math.pi / 2])

    def passing(speed_mps: float, beside_m: float) -> list[Obstacle]:  # heading east, 4 s away
        return [Obstacle(-4.0 * speed_mps, beside_m, 0.25, vx_mps=speed_mps)]

    # as wide as the NMPC sees the mover at the horizon's middle (disc + inflated radius there)
    fast = passing(0.7, 0.0)
    base = config.nmpc
    _, radii = movers.nmpc_obstacles(
        pose[:2], fast, config.slots, base.tau_s, base.horizon, base.obstacle_prediction, config.margin_m
    )
    swept_m = controller.disc_radius_m + float(radii[0, base.horizon // 2])
    body_m = 0.25 + movers.inflation_m + config.yielding.margin_m
    assert swept_m > body_m + 0.05  # the NMPC's sweep of a 0.7 m/s mover: wider than the body's
    beside_m = 0.5 * (body_m + swept_m)
    step = judge.step(pose[:2], pose[2], np.zeros(2), passing(0.7, beside_m))
    assert step is not None and abs(step.y_m - beside_m) >= swept_m - 1e-9  # beyond the sweep
    judge.reset()
    assert judge.step(pose[:2], pose[2], np.zeros(2), passing(0.3, beside_m)) is None  # slow: clear
    assert judge.step(pose[:2], pose[2], np.zeros(2), passing(0.3, body_m - 0.05)) is not None


def _slow_circle_controller():  # noqa: ANN202 - the scenario's husky-cbf controller
    path = next(p for p in shipped_scenarios() if p.stem == "slow_circle_among_movers")
    scenario = load_scenario(path)
    return scenario, scenario.make_controller("husky-cbf")


def test_a_robot_on_its_way_back_to_a_slow_reference_waits_beside_it_for_a_mover() -> None:
    """1.9 m from its reference's point, with a mover headed for the point, the robot goes where
    it would step aside to from the point, on its own side of the mover's line; not if the mover
    passes the point before the robot could get there (it follows behind), and not once it is at
    the point (stepping aside proper)."""
    _, controller = _slow_circle_controller()
    wait = controller.arbiter.wait_beside
    goal = np.array([0.6, 0.8, 2.6])
    pose = np.array([2.38, 0.07, 2.4])  # south-east of the mover's line, 1.9 m from the point
    diagonal = np.array([1.0, 1.0]) / math.sqrt(2)

    def mover(seconds_to_point: float) -> list[Obstacle]:
        x, y = goal[:2] - 0.45 * seconds_to_point * diagonal
        return [Obstacle(x, y, 0.3, vx_mps=0.45 * diagonal[0], vy_mps=0.45 * diagonal[1])]

    def spot(at: np.ndarray, obstacles: list[Obstacle]) -> Target | None:
        return wait.propose(_situation(at, goal, obstacles, ReferenceKind.SLOW_TRAJECTORY))

    waiting = spot(pose, mover(5.0))  # 1.9 m at 0.6 m/s: 3.2 s
    assert waiting is not None and (waiting.x_m - waiting.y_m) > (goal[0] - goal[1]) + 1.0
    assert waiting.heading_rad == pose[2]  # waits as it faces
    assert spot(pose, mover(2.0)) is None  # gone by the time it arrives
    assert spot(np.array([0.75, 0.8, 2.6]), mover(5.0)) is None  # at the point


def test_a_robot_at_a_slow_reference_turns_across_an_oncoming_mover_s_track() -> None:
    """At its point, facing along a mover's track, a robot could only back away along it; with a
    mover on course to the point within the bracing horizon it turns its axis across the mover's
    track (the way that turns less); not for a mover farther off in time, nor away from the
    point. In the loop, the arbiter keeps the robot at its point, turned across the track, while
    the mover is still beyond the yielding horizon."""
    scenario, controller = _slow_circle_controller()
    brace = controller.arbiter.brace_across
    horizon_s = brace.horizon_s
    assert horizon_s > controller.config.yielding.horizon_s
    goal = np.array([0.9, 0.45, 2.1])

    def mover(seconds_to_point: float) -> list[Obstacle]:  # walking south at 0.35 m/s
        return [Obstacle(1.0, goal[1] + 0.35 * seconds_to_point, 0.35, vx_mps=0.0, vy_mps=-0.35)]

    def across(pose: np.ndarray, seconds_to_point: float) -> float | None:
        target = brace.propose(_situation(pose, goal, mover(seconds_to_point), ReferenceKind.SLOW_TRAJECTORY))
        return None if target is None else target.heading_rad

    facing_north_west = np.array([0.88, 0.48, 2.16])
    heading = across(facing_north_west, 0.8 * horizon_s)
    assert heading is not None and abs(math.cos(heading)) == pytest.approx(1.0)  # east-west axis
    assert math.cos(heading - facing_north_west[2]) > 0.0  # the nearer way: west, forwards
    heading = across(np.array([0.88, 0.48, -0.9]), 0.8 * horizon_s)
    assert heading is not None and math.cos(heading) == pytest.approx(1.0)  # east
    controller.reset()
    assert across(facing_north_west, 1.2 * horizon_s) is None
    assert across(np.array([2.0, 0.45, 2.16]), 0.8 * horizon_s) is None  # 1.1 m from the point
    # in the loop: the reference's point with the mover still beyond the yielding horizon
    controller.reset()
    reference, n = scenario.reference_object(), controller.config.nmpc.horizon
    t = 18.0
    sampled = controller._feed_forward(reference.sample(t, controller.tau_s, n))
    at_point = np.array([*sampled[0][0][:2], 2.16])
    yield_s = controller.config.yielding.horizon_s
    obstacles = [Obstacle(at_point[0] + 0.1, at_point[1] + 0.35 * (yield_s + 1.0), 0.35, vy_mps=-0.35)]
    situation = controller._situation(at_point, at_point, 0.0, reference, sampled, obstacles, t)
    assert situation.kind is ReferenceKind.SLOW_TRAJECTORY
    decision = controller.arbiter.decide(situation)
    assert decision.mode is Mode.YIELD and not decision.stepping_aside
    target = decision.target
    assert target is not None
    assert (target.x_m, target.y_m) == pytest.approx(sampled[0][0][:2], abs=0.05)  # stays at its point
    assert math.cos(target.heading_rad) == pytest.approx(-1.0)  # facing west, across the track


def test_a_robot_stepping_aside_round_an_obstacle_backs_along_the_way_round_if_that_turns_less() -> None:
    """Braced facing east, the robot steps west out of a mover's way; the planner's way round (here
    round a post west of the robot) points north-west, and turning to it would turn the robot to
    face the mover. Stepping aside, the way round is taken backwards when that turns less."""
    scenario, controller = _slow_circle_controller()
    reference, n = scenario.reference_object(), controller.config.nmpc.horizon
    t = 18.8
    pose = np.array([0.92, 0.40, 0.0])  # at its point, facing east
    post = Obstacle(0.0, 0.40, 0.15)
    obstacles = [Obstacle(2.0, -1.0, 0.4), post, Obstacle(1.0, 2.3, 0.35, vx_mps=0.0, vy_mps=-0.37)]
    sampled = controller._feed_forward(reference.sample(t, controller.tau_s, n))
    decision = controller.arbiter.decide(
        controller._situation(pose, pose, 0.0, reference, sampled, obstacles, t)
    )
    assert decision.mode is Mode.DETOUR and decision.stepping_aside and controller.arbiter.planner.guided
    target = decision.target
    assert target is not None
    assert target.x_m < pose[0] - 0.3 and abs(target.y_m - post.y_m) > 0.1  # west, round the post
    assert math.cos(target.heading_rad - pose[2]) > 0.0  # facing east still: backing, not turning


def test_a_tracking_robot_that_cannot_swing_round_beside_a_cylinder_first_drives_to_room() -> None:
    """A robot beside a cylinder, facing west-south-west, its reference moving off south: turning
    in place towards it swings the rear into the cylinder, and a short horizon sees no way out.
    Stalled while it tracks its reference, it recovers as on a set-point, first forwards along its
    axis to room to swing round; with the cylinder a metre farther off it turns where it stands.
    Stalled on the planner's way round an obstacle, it recovers too: a detour it does not follow is
    no progress."""
    path = next(p for p in shipped_scenarios() if p.stem == "paper_dynamic_tracking_crossing")
    scenario = load_scenario(path)
    reference = scenario.reference_object()
    pose = np.array([-2.1, 0.63, -2.8])
    axis = np.array([math.cos(pose[2]), math.sin(pose[2])])

    def stalled(cylinder: Obstacle, at: np.ndarray = pose) -> tuple[str, np.ndarray, bool]:
        controller = scenario.make_controller("husky-cbf")
        window_s = controller.config.recovery.progress_window_s
        for k in range(round(2 * window_s / controller.tau_s)):  # the robot does not move
            result = controller.solve(at, reference, [cylinder], 27.0 + k * controller.tau_s)
            if result.escape:
                break
        return result.escape, result.predicted_states, controller.arbiter.planner.guided

    phase, plan, _ = stalled(Obstacle(-2.3, 1.5, 0.4))
    assert phase == "room"
    assert (plan[-1, :2] - pose[:2]) @ axis > 0.05  # forwards, away from the cylinder
    assert stalled(Obstacle(-2.3, 2.5, 0.4))[0] == "turn"
    # 1.7 m east of its goal (the reference 1 s ahead, near (-2.2, 0.8)), a cylinder between: the
    # planner detours, and the robot that does not move along the detour recovers all the same
    phase, _, guided = stalled(Obstacle(-1.3, 1.0, 0.4), np.array([-0.5, 1.2, math.pi]))
    assert guided and phase != ""


# -- the arbiter's policy -------------------------------------------------------------------------
class _Fixed:
    """A behaviour that proposes a fixed target (or None) and records what it was asked."""

    def __init__(self, target: Target | None = None) -> None:
        self.target = target
        self.proposed = 0
        self.resets = 0
        self.pauses = 0
        self.active = False
        self.enabled = True
        self.reversing = False
        self.settling = False

    def propose(self, situation: Situation) -> Target | None:
        self.proposed += 1
        self.active = self.target is not None
        return self.target

    def reset(self) -> None:
        self.resets += 1

    def pause(self) -> None:
        self.pauses += 1

    def tabu_circles(self, t: float) -> np.ndarray:
        return NONE


def _target(x_m: float, y_m: float, heading_rad: float = 0.0) -> Target:
    return Target(x_m, y_m, heading_rad, np.array([[x_m, y_m]]))


def _arbiter(**behaviours: object) -> Arbiter:
    parts: dict[str, object] = {
        "planner": _planner(),
        "step_aside": _Fixed(),
        "wait_beside": _Fixed(),
        "brace_across": _Fixed(),
        "set_point_approach": _Fixed(),
        "point_approach": _Fixed(),
        "recovery": _Fixed(),
    }
    parts.update(behaviours)
    return Arbiter(**parts)  # type: ignore[arg-type]


BLOCKED = [Obstacle(4.0, 0.1, 0.6)]  # on the straight way from the origin to (8, 0)
GOAL = (8.0, 0.0, 0.0)


def test_recovery_beats_the_planner_s_detour() -> None:
    out = _target(-0.5, 0.0, math.pi)
    detour = _arbiter().decide(_situation((0.0, 0.0, 0.0), GOAL, BLOCKED))
    assert detour.mode is Mode.DETOUR and detour.target is not None
    decision = _arbiter(recovery=_Fixed(out)).decide(_situation((0.0, 0.0, 0.0), GOAL, BLOCKED))
    assert decision.mode is Mode.RECOVER and decision.target is out and decision.guided


def test_stepping_aside_beats_recovery_and_the_approach_and_pauses_recovery() -> None:
    aside, out, line = _target(0.0, 1.0), _target(-0.5, 0.0), _target(2.0, 0.0)
    recovery, approach = _Fixed(out), _Fixed(line)
    arbiter = _arbiter(step_aside=_Fixed(aside), recovery=recovery, set_point_approach=approach)
    decision = arbiter.decide(_situation((0.0, 0.0, 0.0), GOAL))
    assert decision.mode is Mode.YIELD and decision.target is aside and decision.stepping_aside
    assert recovery.pauses == 1 and recovery.proposed == 0 and approach.proposed == 0


def test_yielding_beats_the_approach_on_a_set_point_and_the_approach_beats_tracking() -> None:
    line = _target(2.0, 0.0)
    alone = _arbiter(set_point_approach=_Fixed(line)).decide(_situation((0.0, 0.0, 0.0), GOAL))
    assert alone.mode is Mode.APPROACH and alone.target is line
    aside = _target(0.0, 1.0)
    arbiter = _arbiter(step_aside=_Fixed(aside), set_point_approach=_Fixed(line))
    decision = arbiter.decide(_situation((0.0, 0.0, 0.0), GOAL))
    assert decision.mode is Mode.YIELD and decision.target is aside
    nothing = _arbiter().decide(_situation((0.0, 0.0, 0.0), GOAL))
    assert nothing.mode is Mode.TRACK and nothing.target is None and not nothing.guided


def test_the_planner_detours_towards_the_behaviour_s_target_backwards_while_stepping_aside() -> None:
    """A blocked way to a step aside is a detour; stepping aside, its heading is the nearer way."""
    aside = _target(8.0, 0.0)  # the step aside lies beyond the obstacle
    facing_back = (0.0, 0.0, math.pi)
    plain = _arbiter().decide(_situation(facing_back, GOAL, BLOCKED))
    decision = _arbiter(step_aside=_Fixed(aside)).decide(_situation(facing_back, GOAL, BLOCKED))
    assert plain.mode is decision.mode is Mode.DETOUR
    assert plain.target is not None and decision.target is not None
    assert math.cos(plain.target.heading_rad - math.pi) < 0.0  # forwards: turned away from its heading
    assert math.cos(decision.target.heading_rad - math.pi) > 0.0  # the same axis, backwards


def test_recovery_never_acts_on_a_slow_trajectory_and_acts_on_any_other_detouring_or_not() -> None:
    out = _target(-0.5, 0.0)
    recovery = _Fixed(out)
    slow = _arbiter(recovery=recovery).decide(
        _situation((0.0, 0.0, 0.0), GOAL, kind=ReferenceKind.SLOW_TRAJECTORY)
    )
    assert slow.mode is not Mode.RECOVER and recovery.proposed == 0 and recovery.pauses == 0
    planner = _planner()
    planner.guided = True  # detoured last step: a detour does not hold recovery back
    for kind in (ReferenceKind.TRAJECTORY, ReferenceKind.SET_POINT):
        recovery = _Fixed(out)
        decision = _arbiter(recovery=recovery, planner=planner).decide(
            _situation((0.0, 0.0, 0.0), GOAL, kind=kind)
        )
        assert decision.mode is Mode.RECOVER and decision.target is out and recovery.pauses == 0


def test_at_a_slow_point_bracing_beats_the_approach_and_waiting_leads_the_approach_to_its_spot() -> None:
    goal = (3.0, 0.0, math.pi / 2)
    slow = ReferenceKind.SLOW_TRAJECTORY
    approach = _arbiter(point_approach=PointApproach()).decide(_situation((0.0, 0.0, 0.0), goal, kind=slow))
    assert approach.mode is Mode.APPROACH and approach.target is not None
    brace = _target(3.0, 0.0, 0.0)
    braced = _arbiter(point_approach=PointApproach(), brace_across=_Fixed(brace)).decide(
        _situation((0.0, 0.0, 0.0), goal, kind=slow)
    )
    assert braced.mode is Mode.YIELD and braced.target is brace
    spot = _target(1.0, 2.0, 0.3)
    bracing = _Fixed(brace)
    waiting = _arbiter(point_approach=PointApproach(), wait_beside=_Fixed(spot), brace_across=bracing).decide(
        _situation((0.0, 0.0, 0.0), goal, kind=slow)
    )
    assert waiting.mode is Mode.YIELD and bracing.proposed == 0  # waiting: no bracing
    assert waiting.target is not None and (waiting.target.x_m, waiting.target.y_m) == (1.0, 2.0)
    assert waiting.target.heading_rad == pytest.approx(math.atan2(2.0, 1.0))  # driving at the spot


def test_the_arbiter_built_for_husky_cbf_shares_one_mover_model() -> None:
    config = load_scenario("slow_circle_among_movers").controller_config("husky-cbf")
    movers = MoverModel.for_plan(config.movers, INFLATION, 0.34, 1.0)
    arbiter = Arbiter.build(config, movers, TAU, 0.2)
    assert arbiter.planner.movers is movers
    judges = (arbiter.step_aside.judge, arbiter.wait_beside.judge, arbiter.brace_across.judge)
    assert all(judge.movers is movers for judge in judges)
    assert arbiter.recovery.planner is arbiter.planner
    assert movers.lead_s == pytest.approx(0.34 + 0.5 * config.movers.sweep_s)


def test_the_tracking_goal_lies_beyond_an_obstacle_on_the_reference_never_inside_it() -> None:
    """A slow circle (0.15 m/s) with a 0.5 m cylinder on it just ahead of the reference: the tracking
    goal is the first reference point clear of every inflated obstacle, past the cylinder along
    the reference (its inflated circle spans more of the circle than a few seconds cover), so the
    planner has a free goal to route round it to. A walker there is soon gone: the goal is not
    searched that far past it."""
    path = next(p for p in shipped_scenarios() if p.stem == "paper_dynamic_tracking")
    controller = load_scenario(path).make_controller("husky-cbf")
    reference = CircleTrajectory(radius_m=3.0, angular_rate_radps=0.05)
    ahead = reference.state_at(2.0)
    cylinder = [Obstacle(float(ahead[0]), float(ahead[1]), 0.5)]
    pose = reference.state_at(-10.0)  # 1.5 m behind the reference, well clear of the cylinder
    circles = controller.movers.body_circles(cylinder, pose[:2])
    goal = controller._tracking_goal(reference, circles, np.array([True]), 0.0)
    assert math.hypot(goal[0] - ahead[0], goal[1] - ahead[1]) > circles[0, 2]
    assert math.atan2(goal[1], goal[0]) > math.atan2(ahead[1], ahead[0])  # past it along the circle
    walker = controller._tracking_goal(reference, circles, np.array([False]), 0.0)
    assert walker == pytest.approx(reference.state_at(1.0))  # the preview point, inside it for now


def test_a_step_aside_from_a_trajectory_moves_on_with_it_and_any_other_target_is_held_at_rest() -> None:
    """What the NMPC tracks: the reference itself (TRACK); stepping aside from a moving reference's
    point, the reference shifted by the step, at its pace (the target moves on with the
    reference); any other target (here the planner's waypoint) held over the horizon at rest."""
    path = next(p for p in shipped_scenarios() if p.stem == "paper_dynamic_tracking")
    controller = load_scenario(path).make_controller("husky-cbf")
    n = controller.config.nmpc.horizon
    reference = CircleTrajectory(radius_m=3.0, angular_rate_radps=0.1)
    sampled = reference.sample(0.0, controller.tau_s, n)
    states, controls = sampled
    trajectory = ReferenceKind.TRAJECTORY
    assert (
        controller._tracked(Decision(Mode.TRACK, None, False, False, False), sampled, trajectory) is sampled
    )
    step = Target(float(states[0, 0]) + 1.0, float(states[0, 1]) - 0.5, 0.3, None)
    shifted, pace = controller._tracked(Decision(Mode.YIELD, step, True, False, False), sampled, trajectory)
    assert shifted[:, :2] == pytest.approx(states[:, :2] + np.array([1.0, -0.5]))
    assert shifted[:, 2] == pytest.approx(states[:, 2]) and pace == pytest.approx(controls)
    waypoint = Target(1.0, 2.0, 0.5, None)
    held, rest = controller._tracked(Decision(Mode.DETOUR, waypoint, True, False, False), sampled, trajectory)
    assert held == pytest.approx(np.tile([1.0, 2.0, 0.5], (n + 1, 1))) and not rest.any()
