"""The core runs without any optional extra: in a fresh interpreter that cannot import a module of
any extra, a PyBullet run writes its folder (no run.mcap, a one-line warning why), and a command
that needs an extra says in one line which to install (exit 1)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from husky_sim.extras import EXTRAS

#: Every top-level module the extras bring (pyproject's optional-dependencies).
EXTRA_MODULES = ("cyclonedds", "rosbags", "rclpy", "foxglove", "mcap", "gymnasium", "dask", "distributed")

BLOCKER = f"""
import importlib.abc, sys
class _NoExtras(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in {EXTRA_MODULES!r}:
            raise ImportError(f"No module named {{name!r}} (blocked: a core install)")
        return None
sys.meta_path.insert(0, _NoExtras())
"""


def _core(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", BLOCKER + code], capture_output=True, text=True, cwd=cwd, timeout=300
    )


def _cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return _core(f"import sys\nfrom husky_sim.cli import main\nsys.exit(main({args!r}))", cwd)


@pytest.mark.physics
def test_a_run_needs_no_extra(tmp_path: Path) -> None:
    out = tmp_path / "run"
    done = _cli(["run", "narrow_gap", "--controller", "cbf", "--horizon", "5", "--out", str(out)], tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "summary.json").read_text())["steps"] > 0
    assert (out / "log.csv").is_file() and not (out / "run.mcap").exists()
    warning = [line for line in done.stderr.splitlines() if "run.mcap" in line]
    assert warning == [
        "husky-sim: warning: no run.mcap: run.mcap and --live needs foxglove: "
        "pip install 'husky-nav-sim[foxglove]'"
    ]


@pytest.mark.parametrize(
    ("args", "extra"),
    [
        (["serve", "narrow_gap"], "ros2"),
        (["run", "narrow_gap", "--live", "8765"], "foxglove"),
        (["check", "narrow_gap", "--backend", "dask", "--samples", "1"], "cluster"),
    ],
)
def test_a_command_that_needs_an_extra_names_it_in_one_line(
    args: list[str], extra: str, tmp_path: Path
) -> None:
    done = _cli(args, tmp_path)
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].endswith(f"pip install 'husky-nav-sim[{extra}]'"), lines
    assert extra in EXTRAS


def test_the_package_imports_without_gymnasium_and_the_environment_names_its_extra(tmp_path: Path) -> None:
    done = _core(
        "import husky_sim\n"
        "try:\n    import husky_sim.runs.environment\n"
        "except ImportError as exc:\n    print(exc)\n",
        tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert (
        done.stdout.strip() == "the gymnasium environment needs gymnasium: pip install 'husky-nav-sim[gym]'"
    )
