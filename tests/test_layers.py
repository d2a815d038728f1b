"""The package layout is the architecture: each layer of husky_sim imports only the layers below
it (docs/layout.md), and `controllers` never imports the simulator. Read from the source with
`ast`, lazy imports inside functions included, so a shortcut across layers fails here."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: What each sub-package may import from husky_sim besides itself and the shared top-level modules.
ALLOWED = {
    "sim": set(),
    "runs": {"sim"},
    "viz": {"sim", "runs"},
    "study": {"sim", "runs", "viz"},
    "realcheck": {"sim", "runs", "calibration"},  # a sample's steerability: drive-response's probe
    "bench": {"sim", "runs"},
    "ros2": {"sim", "runs"},
    "calibration": {"sim"},
    "families": {"sim", "runs"},
    "campaign": {"sim", "runs", "viz", "families"},
    "cli": {
        "sim",
        "runs",
        "viz",
        "study",
        "realcheck",
        "bench",
        "ros2",
        "calibration",
        "families",
        "campaign",
    },
}
SHARED = {"extras", "interrupts", "paths", "scenario_file"}  # the top-level modules every layer may use


def _imported_modules(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            if node.module == "husky_sim":  # `from husky_sim import interrupts`
                names |= {f"husky_sim.{alias.name}" for alias in node.names}
    return names


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_layer_imports_only_the_layers_below_it(package: str) -> None:
    crossings = []
    for path in sorted((ROOT / "husky_sim" / package).rglob("*.py")):
        for name in _imported_modules(path):
            parts = name.split(".")
            if parts[0] != "husky_sim" or len(parts) < 2:
                continue
            target = parts[1]
            if target not in ALLOWED[package] | SHARED | {package}:
                crossings.append(f"{path.relative_to(ROOT)} imports {name}")
    assert not crossings, crossings


def test_the_top_level_holds_at_most_six_modules() -> None:
    modules = sorted(p.name for p in (ROOT / "husky_sim").glob("*.py"))
    assert len(modules) <= 6, modules
    assert {p.stem for p in (ROOT / "husky_sim").glob("*.py")} - {"__init__"} == SHARED


def test_controllers_never_import_the_simulator() -> None:
    crossings = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in sorted((ROOT / "controllers").rglob("*.py"))
        for name in _imported_modules(path)
        if name.split(".")[0] == "husky_sim"
    ]
    assert not crossings, crossings


def _controller_solve_calls(path: Path) -> int:
    """Calls `x.solve(state, reference, obstacles, t)`: a closed loop asking a Controller for its
    command (controllers.interface; the solver benchmark's two-argument `solver.solve` replays
    recorded problems, not a loop)."""
    return sum(
        isinstance(node, ast.Call)
        and isinstance(node.func, ast.Attribute)
        and node.func.attr == "solve"
        and len(node.args) + len(node.keywords) == 4
        for node in ast.walk(ast.parse(path.read_text()))
    )


def test_one_closed_loop_drives_every_simulated_plant() -> None:
    """The PyBullet Husky and the kinematic unicycle both run through sim/rollout.py; the only
    other caller is the ROS 2 node, which answers a robot's odometry instead of simulating."""
    callers = {
        str(path.relative_to(ROOT)): n
        for path in sorted((ROOT / "husky_sim").rglob("*.py"))
        if (n := _controller_solve_calls(path))
    }
    assert callers == {"husky_sim/sim/rollout.py": 1, "husky_sim/ros2/node.py": 1}
