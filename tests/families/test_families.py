"""Scenario families: listed, seeded byte for byte, valid, feasible, and refused clearly when asked
for something outside their ranges. Pure tests (no physics)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from husky_sim.cli import main
from husky_sim.families.feasibility import check_layout
from husky_sim.families.generate import draw_layout, generate, header_fields
from husky_sim.families.registry import family, family_names
from husky_sim.runs.scenario import load_scenario, scenario_from_data


def test_at_least_eight_families_are_listed_a_line_each(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["families"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(family_names()) >= 8
    assert [line.split()[0] for line in lines] == family_names()


@pytest.mark.parametrize("name", family_names())
def test_a_family_generated_twice_with_one_seed_is_byte_identical(name: str, tmp_path: Path) -> None:
    for out in ("a", "b"):
        assert main(["generate", name, "--count", "3", "--seed", "11", "--out", str(tmp_path / out)]) == 0
    files_a = sorted((tmp_path / "a").glob("*.yaml"))
    assert len(files_a) == 3
    for path in files_a:
        assert path.read_bytes() == (tmp_path / "b" / path.name).read_bytes()
    other = generate(name, 1, 12)[0].text
    assert other != files_a[0].read_text(), "another seed gives another layout"


@pytest.mark.parametrize("name", family_names())
def test_fifty_layouts_of_each_family_load_and_pass_the_feasibility_check(name: str, tmp_path: Path) -> None:
    for layout in generate(name, 50, 1000):
        path = layout.write(tmp_path)
        scenario = load_scenario(str(path))  # the file as `husky-sim run` reads it
        verdict = check_layout(scenario)
        assert verdict.feasible, f"{layout.name}: {verdict.reason}"
        assert verdict.path_length_m is not None and math.isfinite(verdict.path_length_m)
        header = header_fields(path.read_text())
        assert header["family"] == name and header["seed"] == "1000" and header["index"] == str(layout.index)
        for p in family(name).params:
            assert f"{p.name}=" in header["params"]
            assert p.low <= layout.params[p.name] <= p.high


def test_a_fixed_parameter_keeps_its_value_and_leaves_the_others_draws_alone() -> None:
    free = draw_layout("crossing_walkers", 5, 0)
    fixed = draw_layout("crossing_walkers", 5, 0, {"speed_mps": 0.4})
    assert fixed.params["speed_mps"] == 0.4
    others = [k for k in free.params if k != "speed_mps"]
    assert [free.params[k] for k in others] == [fixed.params[k] for k in others]
    speeds = {o.speed_mps for o in fixed.scenario.obstacle_specs() if o.moving}
    assert speeds and all(0.8 * 0.4 - 1e-3 <= v <= 0.4 + 1e-3 for v in speeds)


def test_a_parameter_out_of_its_range_or_unknown_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(tmp_path / "x")
    assert main(["generate", "doorways", "--param", "door_margin_m=5", "--out", out]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "door_margin_m" in err and "[0.15, 1]" in err
    assert main(["generate", "doorways", "--param", "width=1", "--out", out]) == 2
    assert "no such parameter" in capsys.readouterr().err
    assert main(["generate", "no_such_family", "--out", out]) == 2
    assert not (tmp_path / "x").exists(), "nothing is written before the input is known good"


def test_the_feasibility_check_refuses_a_goal_walled_in_and_a_mover_on_the_start() -> None:
    posts = [
        {
            "x_m": 6.0 + 1.2 * math.cos(a / 20 * 2 * math.pi),
            "y_m": 1.2 * math.sin(a / 20 * 2 * math.pi),
            "radius_m": 0.2,
        }
        for a in range(20)
    ]
    walled = {
        "name": "walled",
        "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_margin_m": 0.25},
        "reference": {"goal": {"x_m": 6.0, "y_m": 0.0}},
        "obstacles": posts[:0],
    }
    assert check_layout(scenario_from_data(walled)).feasible
    # a ring of posts 1.2 m round the goal: the body's circle (0.57 m) fits inside but cannot get in
    ring = {**walled, "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_m": 0.3}}
    verdict = check_layout(scenario_from_data({**ring, "obstacles": posts}))
    assert not verdict.feasible and "no way" in verdict.reason
    mover = {"x_m": 2.0, "y_m": 0.0, "radius_m": 0.3, "vx_mps": -1.0}
    verdict = check_layout(scenario_from_data({**walled, "obstacles": [mover]}))
    assert not verdict.feasible and "mover 0" in verdict.reason


def test_the_feasibility_check_refuses_a_walker_that_walks_through_a_post_not_one_that_passes_it() -> None:
    post = {"x_m": 3.0, "y_m": 3.0, "radius_m": 0.4}
    layout = {
        "name": "past_a_post",
        "duration_s": 20.0,
        "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_margin_m": 0.25},
        "reference": {"goal": {"x_m": 6.0, "y_m": 0.0}},
    }

    def walker(y_m: float) -> dict[str, object]:  # walks along x at y_m, from x = 0 to 6 at 1 m/s
        return {"x_m": 0.0, "y_m": y_m, "radius_m": 0.3, "speed_mps": 1.0, "waypoints": [[6.0, y_m]]}

    # surfaces 0.01 m apart: it passes; 0.69 m between centres overlaps by 0.01 m: it walks through
    assert check_layout(scenario_from_data({**layout, "obstacles": [post, walker(3.71)]})).feasible
    verdict = check_layout(scenario_from_data({**layout, "obstacles": [post, walker(3.69)]}))
    assert not verdict.feasible and verdict.reason == "mover 1 walks through a static obstacle at 2.9 s"
    # the same walker, started after the run ends: never within the run
    late = {**walker(3.69), "x_m": 25.0, "waypoints": [[30.0, 3.69]]}
    assert check_layout(scenario_from_data({**layout, "obstacles": [post, late]})).feasible


def test_a_campaign_with_a_parameter_out_of_range_is_refused_before_any_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "campaign"
    assert main(["campaign", "--families", "crowd", "--param", "walkers=40", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "walkers" in err and "[4, 12]" in err
    assert not out.exists()
