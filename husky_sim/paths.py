"""Where the project's data lives, decided once: the robots' folders and the shipped scenarios sit
beside the package in the repository (the package is installed editable, from the checkout)."""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT: Path = Path(__file__).resolve().parent.parent
#: One folder per robot: its URDF, published specs, robot.yaml, grounds and yaw response
ROBOTS_DIR: Path = PROJECT_ROOT / "assets"
#: The robot a scenario drives unless it names another (`robot.model`)
DEFAULT_ROBOT = "husky_a200"
ASSETS_DIR: Path = ROBOTS_DIR / DEFAULT_ROBOT  # the default robot's folder (and its real recordings)
SCENARIO_DIR: Path = PROJECT_ROOT / "scenarios"  # the shipped scenario files
