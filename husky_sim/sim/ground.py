"""Grounds: named, fitted parameter sets of the tyre contact and of the drive's response, each a
folder grounds/NAME/ of a robot's folder (assets/husky_a200/grounds/wet_grass/) holding ground.yaml
and the calibration report it came with, both written by `husky-sim calibrate` from a real
recording.

A ground file holds `tyre` (husky_sim.sim.tyre.TyreContact) and `drive` (the dead time and lag of
the wheel speed loop: DriveResponse, which husky_sim.sim.drive.SkidSteerDrive applies), fitted
together on one recording. A scenario names its ground (`ground: wet_grass`, or a path to a file);
without one it gets its robot's default ground (robot.yaml; DEFAULT_GROUND for the Husky).
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.scenario_file import ScenarioFileError, read_scenario_data, scenario_yaml
from husky_sim.sim.robot_description import load_robot
from husky_sim.sim.tyre import TyreContact

#: The default robot's ground of every scenario that names none (its robot.yaml says why)
DEFAULT_GROUND = load_robot().default_ground
#: The plant before the calibration (PyBullet's Coulomb friction on the wheels), kept as a ground so
#: that what changed can be measured against it (`ground: pybullet_coulomb` in a scenario).
UNCALIBRATED_GROUND = "pybullet_coulomb"
GROUND_FILE = "ground.yaml"


class GroundError(ValueError):
    """A ground that cannot be loaded; the message is one line."""


#: Range of a drive's dead time and lag (s); a robot's declared dead time (scenario) too.
DRIVE_TIME_BOUNDS_S = (0.0, 2.0)


@dataclass(frozen=True)
class DriveResponse:
    """The wheel speed loop's dead time and first-order lag (s), fitted on the same recording."""

    command_delay_s: float = 0.0
    wheel_time_constant_s: float = 0.0

    def __post_init__(self) -> None:
        lo, hi = DRIVE_TIME_BOUNDS_S
        for name in ("command_delay_s", "wheel_time_constant_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (lo <= value <= hi):
                raise ValueError(f"ground.drive.{name}: must be in [{lo:g}, {hi:g}] s, got {value}")


@dataclass(frozen=True)
class Ground:
    """One ground: its name, the tyre contact on it and the drive response fitted with it."""

    name: str = "ideal"
    tyre: TyreContact = field(default_factory=TyreContact)
    drive: DriveResponse = field(default_factory=DriveResponse)
    #: "tyre": our slip-dependent tyre force (husky_sim.sim.tyre) and the motor model's torque
    #: limit; "coulomb": the uncalibrated plant (PyBullet's friction on the wheels, mu = the tyre's
    #: friction, and `wheel_torque_limit_nm` per wheel), kept only so that old verdicts reproduce
    contact: str = "tyre"
    wheel_torque_limit_nm: float | None = None

    def __post_init__(self) -> None:
        if self.contact not in ("tyre", "coulomb"):
            raise ValueError(f"ground.contact: must be 'tyre' or 'coulomb', got {self.contact!r}")
        if (self.contact == "coulomb") != (self.wheel_torque_limit_nm is not None):
            raise ValueError("ground.wheel_torque_limit_nm: give it with contact 'coulomb' and only then")
        limit = self.wheel_torque_limit_nm
        if limit is not None and not (
            isinstance(limit, int | float) and not isinstance(limit, bool) and 0.0 < limit <= 500.0
        ):
            raise ValueError(f"ground.wheel_torque_limit_nm: must be a number in (0, 500] N m, got {limit!r}")

    @property
    def calibrated(self) -> bool:
        return self.contact == "tyre"

    def to_dict(self) -> dict[str, object]:
        data: dict[str, object] = {"name": self.name, "tyre": asdict(self.tyre), "drive": asdict(self.drive)}
        if not self.calibrated:
            data.update(contact=self.contact, wheel_torque_limit_nm=self.wheel_torque_limit_nm)
        return data

    @classmethod
    def from_dict(cls, data: object, source: str) -> Ground:
        if not isinstance(data, dict):
            raise GroundError(f"{source}: a ground file is a mapping with name, tyre and drive")
        allowed = {"name", "tyre", "drive", "fit", "contact", "wheel_torque_limit_nm"}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise GroundError(f"{source}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")
        try:
            return cls(
                name=str(data.get("name", Path(source).stem)),
                tyre=TyreContact(**(data.get("tyre") or {})),
                drive=DriveResponse(**(data.get("drive") or {})),
                contact=str(data.get("contact", "tyre")),
                wheel_torque_limit_nm=data.get("wheel_torque_limit_nm"),
            )
        except (TypeError, ValueError) as exc:
            raise GroundError(f"{source}: {' '.join(str(exc).split())}") from None


def with_friction(ground: Ground, friction: float | None) -> Ground:
    """`ground` with its tyre friction coefficient replaced (None: unchanged)."""
    if friction is None:
        return ground
    return replace(ground, tyre=replace(ground.tyre, friction=friction))


def ground_names(robot: str = DEFAULT_ROBOT) -> list[str]:
    """The grounds shipped for `robot` (its folder's grounds/)."""
    return sorted(path.parent.name for path in load_robot(robot).grounds_dir.glob(f"*/{GROUND_FILE}"))


def load_ground(name_or_path: str | Path | None = None, robot: str = DEFAULT_ROBOT) -> Ground:
    """A ground shipped for `robot` by name (its default ground when None), or a ground file by
    path."""
    description = load_robot(robot)
    text = description.default_ground if name_or_path is None else str(name_or_path)
    path = Path(text)
    try:
        if path.suffix not in (".yaml", ".yml"):
            path = description.grounds_dir / text / GROUND_FILE
            if not path.exists():
                shipped = ", ".join(ground_names(robot))
                raise GroundError(f"ground: unknown ground {text!r} (shipped: {shipped}, or a .yaml file)")
        resolved = path.resolve()
        stamp = resolved.stat().st_mtime_ns
    except OSError as exc:
        raise GroundError(f"ground: cannot read {text!r} ({exc.strerror or exc})") from None
    return _load_ground(str(resolved), stamp)


@functools.lru_cache(maxsize=32)
def _load_ground(resolved: str, stamp_ns: int) -> Ground:
    """The ground file at `resolved`, read once per modification time (a file that `calibrate`
    rewrites in the same process is read again)."""
    path = Path(resolved)
    try:
        data = read_scenario_data(path)  # the project's one YAML reader
    except ScenarioFileError as exc:
        raise GroundError(f"{exc} (a ground file)") from None
    return Ground.from_dict(data, str(path))


def write_ground(ground: Ground, path: Path, header: str = "", fit: dict[str, object] | None = None) -> None:
    """Write `ground` as a ground file (with `fit`, the calibration's figures, kept for reading)."""
    data = ground.to_dict()
    if fit:
        data["fit"] = fit
    path.write_text(scenario_yaml(data, header))
