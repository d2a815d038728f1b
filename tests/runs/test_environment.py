"""The gymnasium environment HuskyNav-v0 in real PyBullet: it passes gymnasium's checker, repeats
exactly under a seed, ends on collision and time out by the episode's rules, and it is the very
environment the NMPC rollout runs in (the same commands give the same poses)."""

import math

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import husky_sim  # noqa: F401 - registers HuskyNav-v0
from controllers import NMPCConfig, NMPCController, SetPoint
from husky_sim.runs.environment import OBSERVED_OBSTACLES, HuskyNavEnv
from husky_sim.sim.episode import EpisodeConfig, run_episode
from husky_sim.sim.sensing import SensingConfig
from husky_sim.sim.world import ObstacleSpec, WorldConfig

pytestmark = pytest.mark.physics

GOAL = SetPoint(8.0, 0.0, 0.0)
NOISY = SensingConfig(pose_xy_std_m=0.01, pose_yaw_std_rad=0.01, obstacle_xy_std_m=0.02, latency_steps=1)


def _config(**changes) -> EpisodeConfig:
    settings = dict(
        start=(0.0, 0.0, 0.0),
        tau_s=0.1,
        duration_s=3.0,
        world=WorldConfig(obstacles=(ObstacleSpec(3.0, 0.0, 0.3), ObstacleSpec(6.0, 2.0, 0.4, vx_mps=-0.4))),
    )
    return EpisodeConfig(**{**settings, **changes})


def _rollout(env: gymnasium.Env, seed: int, actions: list) -> tuple[list, list]:
    """The sensed poses after reset and after each action, and the rewards."""
    obs, _ = env.reset(seed=seed)
    poses, rewards = [obs["pose"]], []
    for action in actions:
        obs, reward, *_ = env.step(action)
        poses.append(obs["pose"])
        rewards.append(reward)
    return poses, rewards


# Physical units are the point (m/s and rad/s, m): the checker's advice for learning agents is not.
@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")
@pytest.mark.filterwarnings("ignore:.*Box observation space m")
def test_make_after_import_and_gymnasium_checker() -> None:
    env = gymnasium.make("HuskyNav-v0", scenario="husky_point_stabilisation")
    try:
        check_env(env.unwrapped)  # raises on any breach of the API (spaces, seeding, determinism)
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs) and info["outcome"] is None
        assert obs["obstacle_mask"].sum() == min(OBSERVED_OBSTACLES, 1)  # the scenario's one obstacle
        low, high = env.action_space.low, env.action_space.high
        assert high[0] == pytest.approx(1.0) and high[1] > 0 and np.all(low == -high)  # the drive's limits
    finally:
        env.close()


def test_seeded_resets_repeat_and_seeds_matter() -> None:
    env = HuskyNavEnv(_config(sensing=NOISY), GOAL)
    actions = [np.array([0.8, 0.3])] * 8
    try:
        a, b, c = _rollout(env, 5, actions), _rollout(env, 5, actions), _rollout(env, 6, actions)
    finally:
        env.close()
    assert all(np.array_equal(x, y) for x, y in zip(a[0], b[0], strict=True)) and a[1] == b[1]
    assert not np.array_equal(a[0][-1], c[0][-1])  # sensor noise follows the seed


def test_driving_into_an_obstacle_terminates_as_collided() -> None:
    env = HuskyNavEnv(_config(duration_s=20.0), GOAL)
    env.reset(seed=0)
    try:
        for _ in range(200):
            obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert terminated and not truncated and info["outcome"] == "collided"
    assert info["clearance_m"] <= 0.0 and reward <= -100.0
    # the body touched the cylinder at x = 3 - 0.3 m with its front bumper ahead of the base
    assert 1.5 < obs["pose"][0] < 2.7


def test_standing_still_truncates_at_the_scenario_duration() -> None:
    env = HuskyNavEnv(_config(duration_s=1.0), GOAL)
    env.reset(seed=0)
    try:
        results = [env.step(np.zeros(2)) for _ in range(10)]
    finally:
        env.close()
    assert [r[3] for r in results] == [False] * 9 + [True]  # 10 control steps of 0.1 s
    assert not any(r[2] for r in results) and results[-1][4]["outcome"] == "timeout"
    assert results[0][1] == pytest.approx(-8.0 * 0.1, abs=1e-3)  # 8 m from the goal for 0.1 s


def test_the_nmpc_rollout_runs_in_this_environment() -> None:
    """The NMPC's commands, logged by run_episode, replayed through HuskyNavEnv with the same seed
    give the same physics step by step: one environment, not a copy of it."""
    config = _config(sensing=NOISY, seed=11)
    nmpc = NMPCController(NMPCConfig(safety="cbf", horizon=7, gamma=0.2, robot_radius_m=0.65))
    rows = run_episode(nmpc, GOAL, config).rows
    env = HuskyNavEnv(config, GOAL)
    obs, _ = env.reset(seed=11)
    try:
        for row, following in zip(rows, rows[1:], strict=False):
            obs, _, terminated, truncated, info = env.step(
                np.array([row["v_cmd_mps"], row["omega_cmd_radps"]])
            )
            assert (
                info["applied"][0] == row["v_applied_mps"]
                and info["applied"][1] == row["omega_applied_radps"]
            )
            assert info["clearance_m"] == row["clearance_m"] or math.isinf(row["clearance_m"])
            true_pose = env.unwrapped._sim.robot.pose()
            assert (true_pose[0], true_pose[1], true_pose[2]) == (
                following["x_m"],
                following["y_m"],
                following["yaw_rad"],
            )
    finally:
        env.close()
    assert len(rows) == 30
