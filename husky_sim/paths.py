"""Where the project's data lives, decided once: the Husky's assets and the shipped scenarios sit
beside the package in the repository (the package is installed editable, from the checkout)."""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT: Path = Path(__file__).resolve().parent.parent
ASSETS_DIR: Path = PROJECT_ROOT / "assets" / "husky_a200"  # URDF, meshes, identified yaw lag
SCENARIO_DIR: Path = PROJECT_ROOT / "scenarios"  # the shipped scenario files
