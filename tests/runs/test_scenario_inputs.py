"""Bad scenario files and command lines: always one line naming the file and the field, exit 2,
never a traceback, never a NaN or an infinity accepted (property-based, hypothesis)."""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
from pathlib import Path
from typing import Any, get_args, get_origin

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from controllers.husky_cbf import HuskyCBFConfig
from controllers.settings import nested_settings
from husky_sim.cli import main
from husky_sim.runs.run_folder import default_run_dir, run_dir_name
from husky_sim.runs.scenario import (
    MAX_OBSTACLES,
    Scenario,
    ScenarioError,
    load_scenario,
    scenario_from_data,
)
from husky_sim.scenario_file import MAX_DEPTH, read_scenario_data, scenario_yaml

BASE: dict[str, Any] = {
    "name": "t",
    "robot": {"start": {"x_m": 0.0, "y_m": 0.0}, "radius_margin_m": 0.1},
    "reference": {"goal": {"x_m": 5.0, "y_m": 0.0}},
    "obstacles": [{"x_m": 2.5, "y_m": 2.0, "radius_m": 0.3, "vx_mps": 0.1, "waypoints": []}],
    "random_obstacles": {"count": 2, "x_range_m": [1.0, 4.0], "y_range_m": [-3.0, -2.0]},
}
CIRCLE: dict[str, Any] = {
    **{k: v for k, v in BASE.items() if k != "random_obstacles"},
    "reference": {"circle": {"radius_m": 2.0, "angular_rate_radps": 0.2}},
}
SETTINGS = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _numeric_paths(model: type[BaseModel], prefix: tuple = ()) -> list[tuple[tuple, str]]:
    """(path, 'float' | 'int') of every number in the schema, descending into nested models,
    tuples (by index) and the first list entry."""
    out: list[tuple[tuple, str]] = []
    for name, info in model.model_fields.items():
        out += _paths_of(info.annotation, (*prefix, name))
    return out


def _paths_of(annotation: Any, path: tuple) -> list[tuple[tuple, str]]:
    origin, args = get_origin(annotation), get_args(annotation)
    if annotation is float:
        return [(path, "float")]
    if annotation is int:
        return [(path, "int")]
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return _numeric_paths(annotation, path)
    if origin is tuple:
        return [p for i, a in enumerate(args) for p in _paths_of(a, (*path, i))]
    if origin is list:
        return _paths_of(args[0], (*path, 0))
    if args:  # Annotated[...] or X | None
        return [p for a in args for p in _paths_of(a, path)]
    return []


def _base_for(path: tuple) -> dict[str, Any]:
    """A valid scenario with every field written out (defaults included), so that `path` exists."""
    data = copy.deepcopy(CIRCLE if path[:2] == ("reference", "circle") else BASE)
    if path[:2] == ("obstacles", 0) and path[2] in ("heading_rad", "speed_mps"):
        data["obstacles"][0].pop("vx_mps")
        data["obstacles"][0].update(heading_rad=0.5, speed_mps=0.1)
    if path[:2] == ("obstacles", 0) and path[2] == "waypoints":
        data["obstacles"][0].pop("vx_mps")
        data["obstacles"][0].update(speed_mps=0.2, waypoints=[[2.5, 2.0], [2.5, 3.0]])
    if path[:1] == ("robot",) and path[1] == "radius_m":
        data["robot"].pop("radius_margin_m")
        data["robot"]["radius_m"] = 0.8
    if path[:2] == ("robot", "yaw_response"):  # optional; when given, both of its numbers are required
        data["robot"]["yaw_response"] = {"gain": 0.5, "time_constant_s": 0.5}
    if path[:2] == ("controller", "husky_cbf"):  # optional, as are all of its settings
        data["controller"] = {"husky_cbf": {name: {} for name in nested_settings(HuskyCBFConfig)}}
        if isinstance(path[-1], int):  # an entry of a tuple setting: the whole tuple, as its default
            data["controller"]["husky_cbf"][path[2]] = list(getattr(HuskyCBFConfig, path[2]))
    return scenario_from_data(data).model_dump(mode="json")


def _set(data: dict[str, Any], path: tuple, value: Any) -> dict[str, Any]:
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return data


NUMERIC_PATHS = _numeric_paths(Scenario)
BAD_NUMBERS = [math.nan, math.inf, -math.inf, 1e308, -1e308, True, False, "1.0", "on", "1:30", None, [1.0]]


def _write(tmp_path: Path, data: dict[str, Any], name: str = "bad.yaml") -> Path:
    path = tmp_path / name
    path.write_text(scenario_yaml(data))
    return path


def _run_cli(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code
    return int(code), out.getvalue(), err.getvalue()


def test_the_schema_walk_finds_every_number() -> None:
    """The property tests below cover every numeric field (a new field is covered automatically)."""
    assert len(NUMERIC_PATHS) > 60
    assert (("tau_s",), "float") in NUMERIC_PATHS and (("controller", "horizon"), "int") in NUMERIC_PATHS


def test_the_bases_load() -> None:
    assert load_scenario(str(_write(Path(os.environ.get("TMPDIR", "/tmp")), BASE, "hs_base_ok.yaml")))
    scenario_from_data(copy.deepcopy(CIRCLE))


@SETTINGS
@given(path_kind=st.sampled_from(NUMERIC_PATHS), bad=st.sampled_from(BAD_NUMBERS))
def test_every_number_rejects_non_finite_and_coerced_values(
    tmp_path: Path, path_kind: tuple[tuple, str], bad: Any
) -> None:
    path, kind = path_kind
    if bad is None and (
        path[0] in ("drive", "friction")
        or path[-1] in ("heading_rad", "speed_mps", "radius_margin_m", "radius_m")
        or path[:2] == ("controller", "husky_cbf")
    ):
        return  # None means "not given" for these optional fields (for friction: the ground's own)
    data = _set(_base_for(path), path, bad)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(str(_write(tmp_path, data)))
    message = str(exc.value)
    dotted = ".".join(str(p) for p in path)
    assert "\n" not in message and message.startswith(str(tmp_path / "bad.yaml"))
    assert dotted in message or path[0] in message, message
    assert len(message) < 400


@SETTINGS
@given(path_kind=st.sampled_from(NUMERIC_PATHS), value=st.floats(allow_nan=True, allow_infinity=True))
def test_any_number_anywhere_loads_finite_or_fails_in_one_line(
    tmp_path: Path, path_kind: tuple[tuple, str], value: float
) -> None:
    path, kind = path_kind
    data = _set(_base_for(path), path, int(value) if kind == "int" and math.isfinite(value) else value)
    try:
        sc = load_scenario(str(_write(tmp_path, data)))
    except ScenarioError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 400
        return
    numbers = _all_numbers(sc.model_dump())
    assert all(math.isfinite(x) for x in numbers)
    episode = sc.episode_config()  # what runs is built without surprises
    assert math.isfinite(episode.duration_s) and episode.tau_s > 0
    if path[:2] == ("controller", "husky_cbf"):  # the schema's ranges are the config's own
        sc.controller_config("husky-cbf")


def _all_numbers(node: Any) -> list[float]:
    if isinstance(node, dict):
        return [x for v in node.values() for x in _all_numbers(v)]
    if isinstance(node, list | tuple):
        return [x for v in node for x in _all_numbers(v)]
    return [float(node)] if isinstance(node, int | float) and not isinstance(node, bool) else []


@SETTINGS
@given(raw=st.binary(max_size=400))
def test_arbitrary_bytes_are_a_scenario_or_one_line(tmp_path: Path, raw: bytes) -> None:
    path = tmp_path / "fuzz.yaml"
    path.write_bytes(raw)
    try:
        load_scenario(str(path))
    except ScenarioError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(str(path))


@SETTINGS
@given(text=st.text(max_size=300))
def test_arbitrary_text_after_a_valid_scenario_is_a_scenario_or_one_line(tmp_path: Path, text: str) -> None:
    path = tmp_path / "fuzz.yaml"
    path.write_text(scenario_yaml(BASE) + text, encoding="utf-8")
    try:
        load_scenario(str(path))
    except ScenarioError as exc:
        assert "\n" not in str(exc)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("name: t\nname: u\n", 'duplicate key "name"'),
        ("a: " + "[" * 1000 + "]" * 1000 + "\n", f"deeper than {MAX_DEPTH}"),
        ("tau_s: on\n", "tau_s"),
        ("duration_s: 1:30\n", "duration_s"),
        ("controller: {horizon: true}\n", "controller.horizon"),
        ("seed: -1\n", "seed"),
        ("duration_s: 1.0e-12\n", "duration_s: must last at least one control step"),
        ("duration_s: 1.0e+300\n", "duration_s"),
        ("success: {goal_hold_s: .inf}\n", "success.goal_hold_s"),
        ("tau_s: 1.0e+6\n", "tau_s"),
        ("physics_hz: 245\n", "whole number of physics steps"),
        ("tau_s: 2020-01-01\n", "tau_s"),
        ("random_obstacles: {count: 12, x_range_m: [4, 1], y_range_m: [0, 1]}\n", "x_range_m: low"),
        ("random_obstacles: {count: 30, x_range_m: [2, 3], y_range_m: [2, 3]}\n", "placed only"),
        ("random_obstacles: {count: 2, x_range_m: [.nan, 1], y_range_m: [0, 1]}\n", "x_range_m.0"),
        ("drive: {max_linear_mps: .inf}\n", "drive.max_linear_mps"),
        ("drive: {colour: 1}\n", "drive.colour"),
        ("seed: " + "1" * 5000 + "\n", "a value YAML cannot read"),
        ("seed: 0x" + "f" * 5000 + "\n", "seed: an integer beyond"),
        ("tau_s: !!float abc\n", "a value YAML cannot read"),
        ("tau_s: 1e99999\n", "tau_s"),
    ],
)
def test_bad_files_name_the_problem(tmp_path: Path, text: str, needle: str) -> None:
    valid = "robot: {start: {x_m: 0, y_m: 0}, radius_margin_m: 0.1}\nreference: {goal: {x_m: 5, y_m: 0}}\n"
    path = tmp_path / "bad.yaml"
    path.write_text(("" if text.startswith("name") else "name: t\n") + valid + text)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(str(path))
    assert needle in str(exc.value) and "\n" not in str(exc.value) and str(path) in str(exc.value)


def test_too_many_obstacles_through_aliases_is_refused_before_validation(tmp_path: Path) -> None:
    ob = "o: &o {x_m: 3, y_m: 3, radius_m: 0.2}\nl: &l [" + ", ".join(["*o"] * 100) + "]\n"
    big = "obstacles: &b [" + ", ".join(["*o"] * 100) + "]\nmore: [" + ", ".join(["*l"] * 1000) + "]\n"
    path = tmp_path / "alias.yaml"
    path.write_text("name: t\n" + ob + big)
    with pytest.raises(ScenarioError, match="after expanding anchors"):
        load_scenario(str(path))
    many = {
        **BASE,
        "obstacles": [{"x_m": 3.0 + i, "y_m": 3.0, "radius_m": 0.2} for i in range(MAX_OBSTACLES + 1)],
    }
    with pytest.raises(ScenarioError, match="obstacles"):
        scenario_from_data(many)


def test_special_files_are_refused_without_blocking(tmp_path: Path) -> None:
    (tmp_path / "dir.yaml").mkdir()
    os.mkfifo(tmp_path / "fifo.yaml")  # opening it would block until a writer came
    (tmp_path / "latin1.yaml").write_bytes("name: caf\xe9\n".encode("latin-1"))
    for name, needle in [
        ("dir.yaml", "directory"),
        ("fifo.yaml", "not a regular file"),
        ("latin1.yaml", "UTF-8"),
    ]:
        with pytest.raises(ScenarioError, match=needle):
            load_scenario(str(tmp_path / name))


def test_a_huge_value_is_quoted_short(tmp_path: Path) -> None:
    path = _write(tmp_path, {**BASE, "tau_s": "x" * 1_000_000})
    with pytest.raises(ScenarioError) as exc:
        load_scenario(str(path))
    assert len(str(exc.value)) < 300 and "1000002 characters" in str(exc.value)


def test_written_scenarios_read_back_equal() -> None:
    for name in ("dense_random_field", "paper_dynamic_tracking"):
        sc = load_scenario(name)
        text = scenario_yaml(sc.model_dump(mode="json", exclude_none=True), "header\nline two")
        path = Path(os.environ.get("TMPDIR", "/tmp")) / f"hs_roundtrip_{name}.yaml"
        path.write_text(text)
        assert load_scenario(str(path)) == sc
        assert read_scenario_data(path)["name"] == name


@given(name=st.text(min_size=1, max_size=300))
@settings(max_examples=200, deadline=None)
def test_run_folders_never_leave_results(name: str) -> None:
    folder = default_run_dir(name, "relax-cbf", 5, 0.1, 0)
    assert folder.parent.name == "results" and len(folder.name) <= 80
    assert folder.name not in (".", "..") and "/" not in folder.name and "\n" not in folder.name
    assert run_dir_name(name, "cbf", 5, 0.1, 0) == default_run_dir(name, "cbf", 5, 0.1, 0).name


# -- the command line ---------------------------------------------------------------------------


@SETTINGS
@given(path_kind=st.sampled_from(NUMERIC_PATHS), bad=st.sampled_from([math.nan, math.inf, True, "on"]))
def test_cli_run_with_a_bad_number_exits_2_in_one_line(tmp_path: Path, path_kind: tuple, bad: Any) -> None:
    path, _ = path_kind
    scenario = _write(tmp_path, _set(_base_for(path), path, bad))
    out = tmp_path / "out"
    code, _, err = _run_cli(["run", str(scenario), "--out", str(out)])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "husky-sim: error:" in err
    assert not out.exists()  # checked before anything was created or built


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["run", "narrow_gap", "--horizon", "500"], "[1, 50]"),
        (["suite", "--jobs", "100000"], "--jobs"),
        (["check", "narrow_gap", "--samples", "1000000000"], "--samples"),
        (["run", "narrow_gap", "--gamma", "nan"], "gamma"),
        (["run", "narrow_gap", "--seed", "-1"], "seed"),
        (["run", "narrow_gap", "--seed", str(2**40)], "seed"),
        (["check", "narrow_gap", "--horizon", "500"], "[1, 50]"),
        (["bench-sim", "--duration", "inf"], "duration"),
        (["run", "a/../../x.yaml"], "scenario"),
        (["run", "narrow_gap", "--out", ""], "--out"),
        (["suite", "--out", " "], "--out"),
        (["run", "x" * 300], "scenario"),
    ],
)
def test_cli_bad_options_exit_2_in_one_line(argv: list[str], needle: str) -> None:
    code, _, err = _run_cli(argv)
    assert code == 2 and len(err.strip().splitlines()) == 1 and needle in err


def test_cli_out_must_be_a_creatable_directory(tmp_path: Path) -> None:
    existing = tmp_path / "a_file"
    existing.write_text("keep me")
    code, _, err = _run_cli(["run", "narrow_gap", "--out", str(existing)])
    assert code == 2 and "--out" in err and "not a directory" in err and existing.read_text() == "keep me"
    code, _, err = _run_cli(["run", "narrow_gap", "--out", str(tmp_path / ("n" * 300))])
    assert code == 2 and "--out" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run_cli(["suite", "--scenarios", "narrow_gap", "--out", str(existing)])
    assert code == 2 and "--out" in err


def test_cli_choices_are_the_controllers_packages() -> None:
    """The CLI names them without importing CasADi before its signal handlers; they must not drift."""
    from controllers.config import SOLVER_BACKENDS
    from husky_sim.cli import SOLVER_CHOICES
    from husky_sim.cli.common import MAX_HORIZON, MAX_PAYLOAD_KG, PARALLEL_BACKENDS, RUN_SOLVER_CHOICES
    from husky_sim.runs import parallel, scenario

    assert SOLVER_CHOICES == SOLVER_BACKENDS
    literal, _ = get_args(scenario.ControllerSpec.model_fields["solver"].annotation)  # Literal | None
    assert set(RUN_SOLVER_CHOICES) == set(get_args(literal))
    assert MAX_HORIZON == scenario.MAX_HORIZON
    assert MAX_PAYLOAD_KG == scenario.MAX_PAYLOAD_KG
    assert PARALLEL_BACKENDS == parallel.BACKENDS
