"""The lidar's visibility model (husky_sim.sim.sensing.visible_mask): range, field of view and
occlusion by static obstacles, against geometry worked out by hand and against a brute-force ray
cast; the sensor's filtered, delayed measurements; the log column and the Foxglove recording that
show it; the scenario schema and `husky-sim check`'s perturbation of it. Pure numpy tests, and one
real PyBullet episode in which a person walks behind a pillar."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from controllers import ControlResult, NMPCConfig, NMPCController, Obstacle, SetPoint
from husky_sim.realcheck.sweep import PerturbationRanges, apply_perturbation, sample_perturbations
from husky_sim.runs.scenario import ScenarioError, load_scenario, scenario_from_data
from husky_sim.sim.sensing import SensingConfig, Sensor, visible_mask
from husky_sim.sim.step_log import LOG_COLUMNS, format_visible, parse_visible

ORIGIN = np.array([0.0, 0.0, 0.0])


def mask(centres, radii, static=None, pose=ORIGIN, **model) -> list[bool]:  # noqa: ANN001
    centres = np.array(centres, dtype=float)
    static = np.ones(len(radii), dtype=bool) if static is None else np.array(static, dtype=bool)
    return visible_mask(pose, centres, np.array(radii, dtype=float), static, **model).tolist()


# -- range and field of view ---------------------------------------------------------------------
def test_a_circle_is_in_range_when_its_nearest_point_is() -> None:
    # surfaces at 4.7, 5.3 and 5.0 m; the last exactly at the range; the sensor inside the fourth
    centres, radii = [[5.0, 0.0], [0.0, 5.5], [-5.5, 0.0], [0.2, 0.0]], [0.3, 0.2, 0.5, 1.0]
    assert mask(centres, radii, range_m=5.0) == [True, False, True, True]
    assert mask(centres, radii) == [True] * 4  # unlimited: today's behaviour


def test_the_field_of_view_is_centred_on_the_heading_and_counts_a_circle_by_its_extent() -> None:
    # a 90 deg view: its edges at +-45 deg. The second circle's centre is at 50 deg, but its half
    # width asin(0.6 / 4) = 8.6 deg reaches into the view; the third's (asin(0.2 / 4) = 2.9 deg)
    # does not; the fourth is behind.
    at = [(4.0, 0.0), (4.0, math.radians(50)), (4.0, math.radians(50)), (4.0, math.pi)]
    centres = [[d * math.cos(a), d * math.sin(a)] for d, a in at]
    radii = [0.3, 0.6, 0.2, 0.3]
    assert mask(centres, radii, fov_deg=90.0) == [True, True, False, False]
    turned = np.array([0.0, 0.0, math.pi])  # facing the fourth: the rest is behind
    assert mask(centres, radii, pose=turned, fov_deg=90.0) == [False, False, False, True]
    assert mask(centres, radii, fov_deg=360.0) == [True] * 4


# -- occlusion -----------------------------------------------------------------------------------
PILLAR = ([3.0, 0.0], 0.3)  # half width asin(0.1) = 5.74 deg from the origin


def test_a_static_pillar_hides_a_circle_wholly_behind_it_and_not_one_partly_behind() -> None:
    # a 0.2 m circle at 5 m is 2.29 deg wide each side: hidden while its centre is within 3.45 deg
    # of the pillar's (0.30 m off the line); at 0.35 m it shows its edge
    behind, partly = [5.0, 0.0], [5.0, 0.35]
    assert mask([PILLAR[0], behind, partly], [0.3, 0.2, 0.2], [True, False, False], occlusion=True) == [
        True,
        False,
        True,
    ]
    # occlusion off: everything seen
    assert mask([PILLAR[0], behind], [0.3, 0.2], [True, False]) == [True, True]


def test_only_static_obstacles_occlude_and_only_from_in_front() -> None:
    # a mover in front of a pillar hides nothing; a pillar behind a mover hides nothing
    mover, pillar_behind = [3.0, 0.0], [5.0, 0.0]
    assert mask([mover, pillar_behind], [0.3, 0.2], [False, True], occlusion=True) == [True, True]
    # the same two as statics: the near one hides the far one
    assert mask([mover, pillar_behind], [0.3, 0.2], [True, True], occlusion=True) == [True, False]
    # a big static circle beside the sensor (r 7.5 m at 8 m: 0.5 m away at its nearest, its
    # interval 20 to 160 deg) whose nearest point is nearer than a small circle's farthest, but
    # which lies behind it along every ray to it (0.82 m at 40 deg against 0.42 m): not hidden
    small = [0.5 * math.cos(math.radians(40)), 0.5 * math.sin(math.radians(40))]
    assert mask([[0.0, 8.0], small], [7.5, 0.08], [True, False], occlusion=True) == [True, True]


def test_occluders_hide_together_but_not_through_a_gap() -> None:
    # a wide circle at 6 m (half width asin(0.9 / 6) = 8.6 deg) behind two pillars whose intervals
    # (3.8 to 18.8 deg and its mirror) leave a gap of +-3.8 deg about the line of sight, closed
    # by a third pillar nearer (+-6.9 deg): hidden; move the third aside: seen through the gap
    target = ([6.0, 0.0], 0.9)
    left, right, middle = [3.0, 0.6], [3.0, -0.6], [2.5, 0.0]
    radii = [0.4, 0.4, 0.3, target[1]]
    assert mask([left, right, middle, target[0]], radii, occlusion=True)[3] is False
    assert mask([left, right, [2.5, 3.0], target[0]], radii, occlusion=True)[3] is True


def test_occlusion_across_the_wrap_around_behind_the_sensor() -> None:
    # behind the robot (bearing +-180 deg) both intervals straddle the wrap-around
    assert mask([[-3.0, 0.0], [-5.0, 0.0]], [0.3, 0.2], [True, False], occlusion=True) == [True, False]
    # two pillars on either side of the wrap cover it together; the target straddles it too
    pillars = [[-3.0, 0.15], [-3.0, -0.15]]
    assert mask([*pillars, [-6.0, 0.0]], [0.2, 0.2, 0.35], [True, True, False], occlusion=True)[2] is False
    apart = [[-3.0, 0.5], [-3.0, -0.5]]  # a gap across 180 deg
    assert mask([*apart, [-6.0, 0.0]], [0.2, 0.2, 0.35], [True, True, False], occlusion=True)[2] is True


def test_the_edge_of_the_view_and_an_occluder_hide_together() -> None:
    # a 90 deg view (edges at +-45 deg); a circle centred on the edge, 5.7 deg wide each side; a
    # pillar covering its in-view half hides it, one covering its other half does not
    target = [5.0 * math.cos(math.radians(45)), 5.0 * math.sin(math.radians(45))]
    inside = [2.5 * math.cos(math.radians(41)), 2.5 * math.sin(math.radians(41))]
    outside = [2.5 * math.cos(math.radians(49)), 2.5 * math.sin(math.radians(49))]
    radii = [0.5, 0.3]
    assert mask([target], [0.5], fov_deg=90.0) == [True]  # half in view
    assert mask([target, inside], radii, [False, True], fov_deg=90.0, occlusion=True)[0] is False
    assert mask([target, outside], radii, [False, True], fov_deg=90.0, occlusion=True)[0] is True


def test_only_the_part_in_range_needs_to_be_hidden() -> None:
    # a big circle (r 3 m at 8 m) whose part within 5.5 m is a sliver about its centre line
    # (+-9.3 deg), behind a pillar at 2 m as wide (+-14.5 deg), while the whole circle (+-22 deg)
    # is wider than the pillar: hidden at that range, seen with an unlimited one
    centres, radii, static = [[2.0, 0.0], [8.0, 0.0]], [0.5, 3.0], [True, False]
    assert mask(centres, radii, static, range_m=5.5, occlusion=True) == [True, False]
    assert mask(centres, radii, static, occlusion=True) == [True, True]


def ray_cast(pose, centres, radii, static, range_m, fov_deg, which, rays=4001) -> list[bool]:  # noqa: ANN001
    """Brute force: circle i is seen when some ray in the view meets it within range before any
    static circle; its own interval swept with `rays` rays, for each i in `which` (against every
    circle whose interval reaches its own: no other can meet those rays)."""
    rel = centres - pose[:2]
    dist = np.hypot(rel[:, 0], rel[:, 1])
    bearing = np.arctan2(rel[:, 1], rel[:, 0])
    halves = np.arcsin(np.minimum(radii / dist, 1.0))
    seen = []
    for i in which:
        apart = np.abs((bearing - bearing[i] + math.pi) % (2 * math.pi) - math.pi)
        near = np.flatnonzero(apart <= halves + halves[i] + 1e-9)
        d, r, b = dist[near], radii[near], bearing[near]
        angles = bearing[i] + np.linspace(-halves[i], halves[i], rays)
        off = (angles - pose[2] + math.pi) % (2 * math.pi) - math.pi
        in_view = np.abs(off) <= math.radians(fov_deg) / 2 + 1e-12
        phi = angles[:, None] - b[None, :]
        across = d * np.sin(phi)
        hit = (np.abs(across) <= r) & (np.cos(phi) > 0)
        entry = np.where(hit, d * np.cos(phi) - np.sqrt(np.maximum(r**2 - across**2, 0.0)), np.inf)
        own = entry[:, near == i][:, 0]
        blocked = np.any((entry < own[:, None]) & (static[near] & (near != i))[None, :], axis=1)
        seen.append(bool(np.any(in_view & (own <= range_m) & ~blocked)))
    return seen


@pytest.mark.parametrize("seed", range(6))
def test_visibility_agrees_with_a_brute_force_ray_cast(seed: int) -> None:
    """Random non-overlapping circles round a sensor, some static, a range and a view that vary."""
    rng = np.random.default_rng(seed)
    centres, radii = [], []
    while len(radii) < 40:
        c, r = rng.uniform(-8, 8, 2), rng.uniform(0.1, 0.8)
        if np.hypot(*c) > r + 0.2 and all(
            np.hypot(*(c - d)) > r + s + 0.05 for d, s in zip(centres, radii, strict=True)
        ):
            centres.append(c)
            radii.append(r)
    centres, radii = np.array(centres), np.array(radii)
    static = rng.random(len(radii)) < 0.7
    pose = np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)])
    range_m, fov_deg = [(math.inf, 360.0), (6.0, 270.0), (4.0, 120.0)][seed % 3]
    ours = visible_mask(pose, centres, radii, static, range_m, fov_deg, occlusion=True)
    truth = ray_cast(pose, centres, radii, static, range_m, fov_deg, range(len(radii)))
    assert 0 < ours.sum() < len(radii)  # some hidden, some seen: the case is not trivial
    assert ours.tolist() == truth


def test_a_thousand_static_obstacles_agree_with_the_ray_cast() -> None:
    """A field of 1,000 static pillars, an unlimited range and a 270 deg view: every circle judged
    at once (the pairs swept are those whose intervals may overlap), checked against the ray cast
    on a sample of them, seen and hidden."""
    rng = np.random.default_rng(3)
    side = np.linspace(-38.0, 38.0, 32)
    grid = np.array([(x, y) for x in side for y in side if abs(x) > 2 or abs(y) > 2])[:1000]
    centres = grid + rng.uniform(-0.6, 0.6, grid.shape)
    radii = rng.uniform(0.2, 0.5, len(centres))
    static = np.ones(len(centres), dtype=bool)
    seen = visible_mask(ORIGIN, centres, radii, static, math.inf, 270.0, True)
    assert len(centres) == 1000 and 50 < seen.sum() < 500
    sample = [
        *rng.choice(np.flatnonzero(seen), 15, replace=False),
        *rng.choice(np.flatnonzero(~seen), 15, replace=False),
    ]
    assert ray_cast(ORIGIN, centres, radii, static, math.inf, 270.0, sample) == seen[sample].tolist()


# -- the sensor, the log and the recording -------------------------------------------------------
def test_the_sensor_tells_only_what_it_sees_in_order_delayed_with_the_same_noise() -> None:
    obstacles = [Obstacle(3.0, 0.0, 0.3), Obstacle(5.0, 0.0, 0.2, vy_mps=0.5), Obstacle(0.0, 4.0, 0.3)]
    noisy = dict(obstacle_xy_std_m=0.05, pose_xy_std_m=0.01, latency_steps=1)
    everything = Sensor(SensingConfig(**noisy), seed=4)
    lidar = Sensor(SensingConfig(**noisy, occlusion=True), seed=4, static=[True, False, True])
    aside = np.array([0.0, 1.0, 0.0])  # from here the mover is beside the pillar, not behind it
    told = [[s.measure(pose, obstacles) for s in (everything, lidar)] for pose in (ORIGIN, aside, aside)]
    assert [lidar_seen.visible for _, lidar_seen in told] == [(0, 2), (0, 2), (0, 1, 2)]  # a step late
    assert all(all_seen.visible == (0, 1, 2) for all_seen, _ in told)
    for all_seen, lidar_seen in told:  # the same noise on what both saw: it is drawn for every one
        assert lidar_seen.obstacles == [all_seen.obstacles[i] for i in lidar_seen.visible]
        assert np.array_equal(all_seen.pose, lidar_seen.pose)
    # a moving obstacle hides nothing: without a static mask, each is judged by its velocity
    assert Sensor(SensingConfig(occlusion=True), 0).visible(ORIGIN, obstacles) == (0, 2)
    swapped = [Obstacle(3.0, 0.0, 0.3, vx_mps=0.1), Obstacle(5.0, 0.0, 0.2)]  # the near one moves
    assert Sensor(SensingConfig(occlusion=True), 0).visible(ORIGIN, swapped) == (0, 1)


def test_sensing_config_rejects_a_bad_model_naming_the_field() -> None:
    assert SensingConfig().sees_everything and SensingConfig(range_m=None).range_m == math.inf
    for bad, field in (
        (dict(range_m=0.0), "range_m"),
        (dict(fov_deg=0.0), "fov_deg"),
        (dict(fov_deg=361.0), "fov_deg"),
    ):
        with pytest.raises(ValueError, match=f"sensing.{field}"):
            SensingConfig(**bad)


def test_the_scenario_schema_reads_the_model_and_names_the_field_and_range() -> None:
    data = load_scenario("head_on_moving_obstacle").model_dump()
    assert data["sensing"]["range_m"] is None  # unlimited by default
    data["sensing"].update(range_m=8.0, fov_deg=270.0, occlusion=True)
    sensing = scenario_from_data(data).episode_config().sensing
    assert (sensing.range_m, sensing.fov_deg, sensing.occlusion) == (8.0, 270.0, True)
    default = load_scenario("head_on_moving_obstacle").episode_config().sensing
    assert default.sees_everything and default.range_m == math.inf
    for field, value, allowed in (("range_m", 0.0, "(0, 1000] m"), ("fov_deg", 400.0, "(0, 360] deg")):
        data["sensing"][field] = value
        with pytest.raises(ScenarioError) as exc:
            scenario_from_data(data)
        message = str(exc.value)
        assert "\n" not in message and f"sensing.{field}" in message and allowed in message
        data["sensing"][field] = {"range_m": None, "fov_deg": 360.0}[field]
    data["sensing"]["occlusion"] = 1  # strict: a number is not a bool
    with pytest.raises(ScenarioError, match="sensing.occlusion"):
        scenario_from_data(data)


def test_the_log_column_lists_the_indices_and_reads_back() -> None:
    assert "visible_obstacles" in LOG_COLUMNS
    assert format_visible((0, 2, 5)) == "0;2;5" and format_visible(()) == ""
    for indices in ((0, 2, 5), (3,), ()):
        assert parse_visible(format_visible(indices)) == indices
    assert parse_visible(3.0) == (3,) and parse_visible(float("nan")) == ()  # as a CSV reader makes them


def test_foxglove_shows_hidden_obstacles_pale(tmp_path: Path) -> None:
    """run.mcap's /scene: the obstacles told to the controller red, the hidden ones pale grey."""
    pytest.importorskip("foxglove")
    pytest.importorskip("mcap_protobuf")
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    from husky_sim.runs.foxglove_record import MCAP_NAME, FoxgloveRecorder

    recorder = FoxgloveRecorder(
        tmp_path / MCAP_NAME, SetPoint(1.0, 0.0, 0.0), [0.3, 0.2, 0.3], [1.0] * 3, (0.49, 0.34), 0.1, 1.0
    )
    result = ControlResult.brake(5, 3, 0, 0.001, "test")
    for k, visible in enumerate(("0;1;2", "0;2")):
        row: dict[str, object] = {c: 0.0 for c in LOG_COLUMNS}
        row.update(
            step=k, t_s=0.1 * k, status="ok", solver="ipopt", fallback="none", visible_obstacles=visible
        )
        recorder.on_step(row, result, np.array([[3.0, 0.0], [5.0, 0.0], [0.0, 4.0]]))
    recorder.close("reached")
    with (tmp_path / MCAP_NAME).open("rb") as f:
        scenes = [
            m
            for *_, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/scene"]
            )
        ]
    alphas = [
        [round(c.color.a, 2) for e in scene.entities if e.id == "obstacles" for c in e.cylinders]
        for scene in scenes
    ]
    assert alphas == [[0.8, 0.8, 0.8], [0.8, 0.3, 0.8]]


# -- husky-sim check -----------------------------------------------------------------------------
def test_the_default_check_draws_exactly_what_it_drew_without_the_sensing_model() -> None:
    """The draws in their fixed order, by hand: the sensing model's default ranges draw nothing."""
    ranges = PerturbationRanges(payload_kg=(0.0, 50.0))
    samples = sample_perturbations(ranges, 4, seed=11)
    rng = np.random.default_rng(11)
    names = (
        "ground_friction", "payload_kg", "pose_xy_std_m", "pose_yaw_std_rad", "obstacle_xy_std_m",
        "obstacle_velocity_scale", "torque_scale",
    )  # fmt: skip
    for p in samples:
        assert p.episode_seed == int(rng.integers(0, 2**31 - 1))
        assert [getattr(p, n) for n in names] == [float(rng.uniform(*getattr(ranges, n))) for n in names]
        assert p.latency_steps == int(rng.integers(0, 3)) and p.yaw_ratio == float(rng.uniform(0.43, 0.54))
        assert p.sensing_range_m is None and p.occlusion is False
        assert "sensing" not in p.describe() and "occlusion" not in p.describe()


def test_a_sensing_perturbation_reaches_the_sample_scenario() -> None:
    ranges = PerturbationRanges(payload_kg=(0.0, 50.0), sensing_range_m=(3.0, 8.0), occlusion=(1, 1))
    samples = sample_perturbations(ranges, 6, seed=2)
    assert all(3.0 <= p.sensing_range_m <= 8.0 and p.occlusion for p in samples)
    sc = apply_perturbation(load_scenario("head_on_moving_obstacle"), samples[0])
    assert sc.sensing.range_m == samples[0].sensing_range_m and sc.sensing.occlusion
    assert f"sensing range {samples[0].sensing_range_m:.1f} m, occlusion on" in sc.description
    fixed = sample_perturbations(PerturbationRanges(payload_kg=(0.0, 50.0), sensing_range_m=(5.0, 5.0)), 2, 2)
    assert [p.sensing_range_m for p in fixed] == [5.0, 5.0]
    for bad in (dict(sensing_range_m=(0.0, 5.0)), dict(sensing_range_m=(6.0, 5.0)), dict(occlusion=(0, 2))):
        with pytest.raises(ValueError, match=next(iter(bad))):
            PerturbationRanges(**bad)


def test_the_check_command_line_sets_the_sensing_ranges() -> None:
    from husky_sim.cli import check
    from husky_sim.runs import scenario

    assert check.MAX_SENSING_RANGE_M == scenario.MAX_SENSING_RANGE_M
    parser = argparse.ArgumentParser()
    check._add_check_options(parser)
    args = parser.parse_args(["--sensing-range-m", "4", "9", "--occlusion"])
    ranges = check._options(args, None).ranges
    assert ranges.sensing_range_m == (4.0, 9.0) and ranges.occlusion == (1, 1)
    plain = check._options(parser.parse_args([]), None).ranges
    assert plain == PerturbationRanges()


# -- a real episode --------------------------------------------------------------------------------
class Recording:
    """A real controller whose every call's obstacles are kept (it only reads them)."""

    def __init__(self, controller: NMPCController) -> None:
        self.controller, self.given = controller, []
        self.config = controller.config

    def reset(self) -> None:
        self.controller.reset()

    def solve(self, state, reference, obstacles, t):  # noqa: ANN001, ANN201
        self.given.append(list(obstacles))
        return self.controller.solve(state, reference, obstacles, t)


@pytest.mark.physics
def test_a_person_behind_a_pillar_is_absent_until_it_emerges(tmp_path: Path) -> None:
    """The Husky holds its start facing a pillar 3 m ahead (r 0.3 m); a person (r 0.2 m) walks
    across 5 m ahead at 0.5 m/s. With occlusion the controller (the real CBF NMPC) is not told of
    the person while it is wholly behind the pillar (|y| < 0.30 m, about 1.2 s), and is again once
    it emerges; the log's column says the same."""
    from husky_sim.sim.episode import EpisodeConfig, run_episode
    from husky_sim.sim.outcomes import Outcomes
    from husky_sim.sim.world import ObstacleSpec, WorldConfig

    pillar = ObstacleSpec(3.0, 0.0, 0.3)
    person = ObstacleSpec(5.0, -2.5, 0.2, vy_mps=0.5)

    def episode(occlusion: bool) -> tuple[list, list[dict]]:
        controller = Recording(NMPCController(NMPCConfig(safety="cbf", horizon=5, robot_radius_m=0.65)))
        config = EpisodeConfig(
            start=(0.0, 0.0, 0.0),
            duration_s=9.0,
            world=WorldConfig(obstacles=(pillar, person)),
            sensing=SensingConfig(occlusion=occlusion),
            outcomes=Outcomes(stop_early=False),
        )
        result = run_episode(controller, SetPoint(0.0, 0.0, 0.0), config, tmp_path / f"{occlusion}.csv", 0.65)
        assert result.metrics.outcome == "reached" and not result.metrics.collided
        return controller.given, result.rows

    given, rows = episode(occlusion=True)
    told = [len(obstacles) == 2 for obstacles in given]
    hidden = [k for k, seen in enumerate(told) if not seen]
    assert [r["visible_obstacles"] for r in rows] == ["0;1" if seen else "0" for seen in told]
    assert all(obstacles[0].x_m == 3.0 for obstacles in given)  # the pillar, always, first
    # one stretch, in the middle: seen before, hidden behind the pillar, seen again after
    assert hidden == list(range(hidden[0], hidden[-1] + 1)) and hidden[0] > 0 and hidden[-1] < len(told) - 1
    y_person = [-2.5 + 0.5 * float(r["t_s"]) for r in rows]
    assert all(abs(y_person[k]) < 0.31 for k in hidden)
    assert all(abs(y_person[k]) > 0.29 for k, seen in enumerate(told) if seen)
    assert 10 <= len(hidden) <= 14  # |y| < 0.30 m at 0.5 m/s: 1.2 s of 0.1 s steps
    # the person is still told of where seen, at its true place (no noise here)
    k = hidden[-1] + 1
    assert given[k][1].y_m == pytest.approx(y_person[k]) and given[k][1].vy_mps == 0.5

    given, rows = episode(occlusion=False)
    assert all(len(obstacles) == 2 for obstacles in given)
    assert {r["visible_obstacles"] for r in rows} == {"0;1"}
