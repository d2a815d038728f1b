"""Large worlds in the schema: a scenario of a thousand obstacles validates (quickly, with the same
random field as judging each candidate alone), the limit is a one-line error, and the paper's NLP
is given the nearest `controller.max_obstacle_slots` obstacles, not one slot per obstacle."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest

from controllers import SetPoint
from controllers.obstacles import select_nearest, surface_distance
from husky_sim.paths import SCENARIO_DIR
from husky_sim.runs.scenario import (
    MAX_OBSTACLE_SLOTS,
    MAX_OBSTACLES,
    RANDOM_GAP_M,
    RandomObstacles,
    ScenarioError,
    _farther,
    load_scenario,
    scenario_from_data,
    shipped_scenarios,
)
from husky_sim.sim.world import ObstacleSpec

LARGE_WORLD = SCENARIO_DIR / "large" / "large_world_1000.yaml"

#: A thousand seeded static posts over 140 m x 140 m round a start and a goal 30 m apart.
THOUSAND: dict[str, Any] = {
    "name": "thousand",
    "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_margin_m": 0.25},
    "reference": {"goal": {"x_m": 30.0, "y_m": 0.0}},
    "random_obstacles": {
        "count": 1000,
        "seed": 3,
        "x_range_m": [-70.0, 70.0],
        "y_range_m": [-70.0, 70.0],
    },
}


def _one_at_a_time(field: RandomObstacles, keep: list[tuple[float, float]]) -> list[ObstacleSpec]:
    """The random field's rule applied to one candidate at a time, as plainly as it reads."""
    rng = np.random.default_rng(field.seed)
    out: list[ObstacleSpec] = []
    for _ in range(1000 * field.count):
        if len(out) == field.count:
            break
        x, y = rng.uniform(*field.x_range_m), rng.uniform(*field.y_range_m)
        r = rng.uniform(*field.radius_range_m)
        if all(math.hypot(x - px, y - py) - r > field.keep_clear_m for px, py in keep) and all(
            math.hypot(x - o.x_m, y - o.y_m) > r + o.radius_m + RANDOM_GAP_M for o in out
        ):
            out.append(ObstacleSpec(float(x), float(y), float(r)))
    return out


def test_a_thousand_obstacles_validate_and_the_nlp_gets_its_slots() -> None:
    sc = scenario_from_data(THOUSAND)
    assert len(sc.obstacle_specs()) == 1000
    assert sc.controller_config("cbf").obstacle_slots == sc.controller.max_obstacle_slots == 16
    assert sc.controller_config("husky-cbf").slots == 6  # husky-cbf's own setting
    assert len(sc.episode_config().world.obstacles) == 1000  # the physics sees every one
    fewer = copy.deepcopy(THOUSAND)
    fewer["controller"] = {"max_obstacle_slots": 5}
    assert scenario_from_data(fewer).controller_config("relax-cbf").obstacle_slots == 5
    few = {**THOUSAND, "random_obstacles": {**THOUSAND["random_obstacles"], "count": 3}}
    assert scenario_from_data(few).controller_config("bt").obstacle_slots == 3  # one per obstacle


def test_the_large_world_is_shipped_apart_from_the_suites_scenarios() -> None:
    sc = load_scenario(str(LARGE_WORLD))
    assert sc.name == LARGE_WORLD.stem and len(sc.obstacle_specs()) == 1000
    assert not any(o.moving for o in sc.obstacle_specs())
    assert LARGE_WORLD not in shipped_scenarios()
    assert all(len(load_scenario(str(p)).obstacle_specs()) <= 16 for p in shipped_scenarios())


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"random_obstacles": {**THOUSAND["random_obstacles"], "count": MAX_OBSTACLES + 1}}, "count"),
        (
            {"obstacles": [{"x_m": 60.0, "y_m": 60.0, "radius_m": 0.2}] * (MAX_OBSTACLES + 1)},
            "obstacles",
        ),
        (
            {"obstacles": [{"x_m": -60.0, "y_m": 60.0, "radius_m": 0.2}] * (MAX_OBSTACLES - 999)},
            f"obstacles: {MAX_OBSTACLES + 1} in all",
        ),
        ({"controller": {"max_obstacle_slots": 0}}, "max_obstacle_slots"),
        ({"controller": {"max_obstacle_slots": MAX_OBSTACLE_SLOTS + 1}}, "max_obstacle_slots"),
    ],
)
def test_over_the_limits_is_one_line_naming_the_field(change: dict[str, Any], needle: str) -> None:
    with pytest.raises(ScenarioError) as exc:
        scenario_from_data({**THOUSAND, **change})
    message = str(exc.value)
    assert needle in message and "\n" not in message and len(message) < 400
    if "max_obstacle_slots" in needle:
        assert f"[1, {MAX_OBSTACLE_SLOTS}]" in message


@pytest.mark.parametrize(
    ("count", "box_m", "radii_m", "keep"),
    [
        (12, (2.0, 10.0, -3.0, 3.0), (0.2, 0.45), [(0.0, 0.0), (12.0, 0.0)]),  # dense_random_field's
        (64, (0.0, 6.0, 0.0, 6.0), (0.3, 0.3), [(3.0, 3.0)]),  # full: fewer placed than asked
        (400, (-20.0, 20.0, -20.0, 20.0), (0.1, 0.6), [(0.0, 0.0), (5.0, 5.0)]),
        (60, (-2.5, 2.5, -2.5, 2.5), (0.2, 0.4), []),  # full, across many blocks of draws
    ],
)
def test_the_random_field_is_the_one_judged_a_candidate_at_a_time(
    count: int, box_m: tuple[float, ...], radii_m: tuple[float, float], keep: list[tuple[float, float]]
) -> None:
    for seed in (0, 2**31):
        field = RandomObstacles(
            count=count,
            seed=seed,
            x_range_m=box_m[:2],
            y_range_m=box_m[2:],
            radius_range_m=radii_m,
            keep_clear_m=1.5,
        )
        assert field.specs(keep) == _one_at_a_time(field, keep)


def test_a_gap_is_judged_as_math_hypot_judges_it() -> None:
    """Where numpy's hypot and math.hypot differ in the last bit, a threshold between them is
    decided by math.hypot (the random field's rule as written)."""
    rng = np.random.default_rng(0)
    dx, dy = rng.uniform(-100.0, 100.0, (2, 20_000))
    differ = np.flatnonzero(np.hypot(dx, dy) != [math.hypot(a, b) for a, b in zip(dx, dy, strict=True)])
    assert differ.size  # such pairs exist, so this test can see the difference
    for i in differ[:50].tolist():
        threshold = min(float(np.hypot(dx[i], dy[i])), math.hypot(dx[i], dy[i]))
        decided = _farther(dx[i : i + 1], dy[i : i + 1], 0.0, threshold)
        assert bool(decided[0]) == (math.hypot(dx[i], dy[i]) > threshold)


def test_the_nlp_gets_at_most_its_slots_and_they_are_the_nearest() -> None:
    """A paper controller of a 300-obstacle world (real CasADi solver) is built for
    max_obstacle_slots obstacles and given the nearest by surface distance."""
    data = {
        **THOUSAND,
        "random_obstacles": {**THOUSAND["random_obstacles"], "count": 300, "x_range_m": [-20.0, 20.0]},
        "controller": {"max_obstacle_slots": 4, "horizon": 5},
    }
    sc = scenario_from_data(data)
    controller = sc.make_controller("cbf")
    assert controller.config.obstacle_slots == 4
    obstacles = [spec.circle_at(0.0) for spec in sc.obstacle_specs()]
    state = np.array([0.0, 0.0, 0.0])
    result = controller.solve(state, SetPoint(30.0, 0.0, 0.0), obstacles, 0.0)
    assert (result.obstacles_considered, result.obstacles_ignored) == (4, 296)
    chosen = select_nearest(obstacles, state[:2], 4)
    farthest_chosen = max(surface_distance(state[:2], o) for o in chosen)
    assert sum(surface_distance(state[:2], o) < farthest_chosen for o in obstacles) <= 3
    # the NLP's four barriers at k = 0 are those of the chosen four: B = d^2 - (r_robot + r)^2
    r_robot = controller.config.robot_radius_m
    expected = [o.x_m**2 + o.y_m**2 - (r_robot + o.radius_m) ** 2 for o in chosen]
    assert result.predicted_barrier[:, 0] == pytest.approx(expected, abs=1e-9)
