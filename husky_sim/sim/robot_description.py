"""A robot as data: everything that makes the simulated robot a Husky A200 (or another) lives in
its folder under assets/ (robot.yaml, the URDF, specs.yaml with its published figures and their
sources, grounds/ and yaw_response.yaml) and is loaded here into one RobotDescription, which the
simulator, the controllers' configuration, the check and the ROS 2 node are given."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

from husky_sim.paths import DEFAULT_ROBOT, ROBOTS_DIR
from husky_sim.scenario_file import ScenarioFileError, read_scenario_data
from husky_sim.sim.geometry import RobotGeometry, load_geometry
from husky_sim.sim.specs import RobotSpecs, load_specs

ROBOT_FILE = "robot.yaml"


@dataclass(frozen=True)
class RobotDescription:
    """One robot folder: its name (the folder's), title, files and published figures."""

    name: str  # the folder's name under assets/, what a scenario's `robot.model` names
    title: str  # e.g. "Clearpath Husky A200"
    folder: Path
    urdf: Path
    default_ground: str  # a ground of grounds/ that a scenario gets when it names none
    specs: RobotSpecs

    @property
    def grounds_dir(self) -> Path:
        return self.folder / "grounds"

    @property
    def yaw_response_file(self) -> Path:
        """The yaw-rate lag identified in PyBullet (`husky-sim identify --robot NAME`)."""
        return self.folder / "yaw_response.yaml"

    @property
    def geometry(self) -> RobotGeometry:
        """Geometry measured from its URDF (m, kg)."""
        return load_geometry(self.urdf)


def robot_names() -> list[str]:
    """The robots shipped under assets/: folders with a robot.yaml."""
    return sorted(path.parent.name for path in ROBOTS_DIR.glob(f"*/{ROBOT_FILE}"))


@functools.cache
def load_robot(name: str = DEFAULT_ROBOT) -> RobotDescription:
    """The robot folder `name`; a one-line ValueError naming the shipped ones if there is none."""
    folder = ROBOTS_DIR / name
    if name not in robot_names():
        raise ValueError(f"robot.model: no robot {name!r} (shipped: {', '.join(robot_names())})")
    try:
        data = read_scenario_data(folder / ROBOT_FILE)
    except ScenarioFileError as exc:
        raise ValueError(str(exc)) from None
    expected = {"name", "urdf", "default_ground"}
    if set(data) != expected:
        raise ValueError(f"{folder / ROBOT_FILE}: expected the keys {', '.join(sorted(expected))}")
    return RobotDescription(
        name=name,
        title=str(data["name"]),
        folder=folder,
        urdf=folder / str(data["urdf"]),
        default_ground=str(data["default_ground"]),
        specs=load_specs(folder / "specs.yaml"),
    )
