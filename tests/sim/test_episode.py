"""Closed-loop episodes in real PyBullet with the real NMPC: collision checking that can fail,
avoidance of a moving obstacle, deterministic logs, and logs kept when a run fails."""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from controllers import NMPCConfig, NMPCController, Obstacle, SetPoint
from husky_sim.sim.collision import ClearanceMonitor
from husky_sim.sim.episode import EpisodeConfig, run_episode
from husky_sim.sim.robot import SkidSteerRobot
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.step_log import compare_logs
from husky_sim.sim.world import ObstacleSpec, World, WorldConfig

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)

GOAL = SetPoint(8.0, 0.0, 0.0)
#: A cylinder driving head-on at the Husky, 0.2 m off its straight path.
HEAD_ON = ObstacleSpec(6.0, 0.2, 0.3, vx_mps=-0.4)
#: Footprint radius 0.570 m (from the URDF) plus an 8 cm margin.
ROBOT_RADIUS_M = 0.65


def head_on_episode(**config_changes) -> EpisodeConfig:
    settings = dict(
        start=(0.0, 0.0, 0.0), tau_s=0.1, duration_s=25.0, world=WorldConfig(obstacles=(HEAD_ON,))
    )
    return EpisodeConfig(**{**settings, **config_changes})


def controller(safety: str) -> NMPCController:
    return NMPCController(NMPCConfig(safety=safety, horizon=7, gamma=0.2, robot_radius_m=ROBOT_RADIUS_M))


def test_clearance_monitor_measures_the_body() -> None:
    """Obstacle 2 m ahead: the nearest body point is the chassis front at x = 0.4937 m."""
    with World(WorldConfig(obstacles=(ObstacleSpec(2.0, 0.0, 0.3),))) as world:
        robot = SkidSteerRobot(world.client, (0.0, 0.0, 0.0))
        exact = ClearanceMonitor(
            world.client, robot.body, world.obstacle_ids, [0.3], 0.59, exact_within_m=5.0
        )
        filtered = ClearanceMonitor(world.client, robot.body, world.obstacle_ids, [0.3], 0.59)
        d_exact = exact.smallest(robot.position_xy(), np.array([[2.0, 0.0]]))
        d_filtered = filtered.smallest(robot.position_xy(), np.array([[2.0, 0.0]]))
    assert d_exact == pytest.approx(2.0 - 0.3 - 0.4937, abs=5e-3)
    assert d_filtered <= d_exact and filtered.queries == 0  # far: bound only, never above truth


def test_moving_obstacle_hits_unconstrained_husky() -> None:
    result = run_episode(controller("none"), GOAL, head_on_episode(), robot_radius_m=ROBOT_RADIUS_M)
    assert result.metrics.outcome == "collided"
    assert result.metrics.collided and result.metrics.min_clearance_m <= 0.0


def test_cbf_against_a_moving_obstacle_in_physics(tmp_path: Path) -> None:
    """The paper's CBF NMPC against a head-on mover, its episode logged. Measured on the calibrated
    plant: collided (first contact at 0.005 m, 16 active steps): the drive answers 0.34 s late,
    which the kinematic NMPC does not model, and its robot circle has 0.08 m to spare over the
    footprint; on the uncalibrated plant it reached the goal (clearance 0.052 m)."""
    log = tmp_path / "cbf.csv"
    result = run_episode(controller("cbf"), GOAL, head_on_episode(), log, robot_radius_m=ROBOT_RADIUS_M)
    m = result.metrics
    assert m.safety_active_steps > 0
    assert m.outcome == "collided" and m.collided and m.min_clearance_m <= 0.0
    assert m.max_abs_linear_accel_mps2 <= 3.0 + 1e-9 and m.max_abs_angular_accel_radps2 <= 6.0 + 1e-9
    assert not m.robot_radius_below_footprint
    with log.open() as f:
        assert sum(1 for _ in csv.DictReader(f)) == m.steps


def test_paper_radius_is_flagged() -> None:
    cfg = EpisodeConfig(start=(0.0, 0.0, 0.0), duration_s=0.3)
    result = run_episode(NMPCController(NMPCConfig(safety="cbf")), GOAL, cfg, robot_radius_m=0.25)
    assert result.metrics.robot_radius_below_footprint


def test_identical_runs_give_identical_logs() -> None:
    noisy = SensingConfig(pose_xy_std_m=0.01, pose_yaw_std_rad=0.01, obstacle_xy_std_m=0.02, latency_steps=1)
    runs = [
        run_episode(controller("cbf"), GOAL, head_on_episode(duration_s=4.0, sensing=noisy, seed=seed))
        for seed in (3, 3, 4)
    ]
    assert compare_logs(runs[0].rows, runs[1].rows) == []
    assert compare_logs(runs[0].rows, runs[2].rows) != []  # the seed does matter


class _FailsAtStep:
    """A real NMPC whose host process dies at a given control step (e.g. a crashed node)."""

    def __init__(self, inner: NMPCController, fail_at: int) -> None:
        self.inner, self.fail_at, self.calls = inner, fail_at, 0

    def reset(self) -> None:
        self.inner.reset()

    def solve(self, state, reference, obstacles: list[Obstacle], t: float):
        self.calls += 1
        if self.calls > self.fail_at:
            raise RuntimeError("controller process died")
        return self.inner.solve(state, reference, obstacles, t)


def test_log_is_kept_when_the_run_fails(tmp_path: Path) -> None:
    log = tmp_path / "partial.csv"
    with pytest.raises(RuntimeError, match="died"):
        run_episode(_FailsAtStep(controller("cbf"), 5), GOAL, head_on_episode(), log)
    rows = list(csv.DictReader(log.open()))
    assert len(rows) == 5 and rows[-1]["step"] == "4"
    assert math.isclose(float(rows[0]["x_m"]), 0.0, abs_tol=1e-3)


def test_husky_circle_tracking_oscillates_on_the_calibrated_drive() -> None:
    """The paper's Husky circle (2.5 m, 0.16 rad/s) with its weights (W_u = 0.01), no obstacle. On
    the calibrated plant the NMPC falls into a limit cycle (v swinging between -1 and 1 m/s, omega
    between the bounds) against the drive's 0.34 s dead time, which its model leaves out: measured
    RMSE 0.41 m, where it was 0.027 m on the uncalibrated plant. The bound 0.1 m is the tracking
    accuracy a Husky team expects; 0.2 m is twice it, far from the measured figure either way."""
    import math

    from controllers import HUSKY_EXPERIMENT, CircleTrajectory

    cfg = NMPCConfig(**HUSKY_EXPERIMENT, safety="none", robot_radius_m=ROBOT_RADIUS_M)
    episode = EpisodeConfig(start=(2.5, 0.0, math.pi / 2), tau_s=0.2, duration_s=40.0)
    m = run_episode(NMPCController(cfg), CircleTrajectory(2.5, 0.16), episode).metrics
    assert m.outcome == "tracking" and not m.converged
    assert m.tracking_rmse_m is not None and m.tracking_rmse_m > 0.2
    assert m.min_clearance_m is None  # no obstacles, no clearance


def test_arena_wall_contact_is_a_collision() -> None:
    cfg = EpisodeConfig(start=(0.0, 0.0, 0.0), duration_s=10.0, world=WorldConfig(arena_half_size_m=3.0))
    m = run_episode(controller("none"), GOAL, cfg).metrics  # the goal lies outside the arena
    assert m.outcome == "collided" and m.collided and m.min_clearance_m <= 0.0


def test_episode_and_controller_periods_must_match() -> None:
    with pytest.raises(ValueError, match="tau_s"):
        run_episode(controller("cbf"), GOAL, head_on_episode(tau_s=0.2))


def test_reversal_counting() -> None:
    from husky_sim.sim.metrics import count_reversals

    assert count_reversals(np.array([0.5, -0.2, -0.3, 0.1, -0.5, 0.0])) == (2, 3)
    assert count_reversals(np.array([-0.5, 0.2])) == (1, 1)
    assert count_reversals(np.array([0.0, -0.005])) == (0, 0)  # within the dead band
