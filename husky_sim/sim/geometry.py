"""Robot geometry derived from the URDF itself (not from the published constants).

:func:`load_geometry` parses a URDF with ``yourdfpy`` and measures the quantities the
controllers and scenarios need: mass, wheel size, track, wheelbase, chassis footprint and
the radius of the smallest base-centred circle enclosing the robot's ground projection.
``husky_sim.sim.specs`` holds the published figures these are checked against.

Frames follow REP 103: x forward, y left, z up, all expressed in ``base_link`` with every
joint at zero.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yourdfpy

from husky_sim.paths import ASSETS_DIR

DEFAULT_URDF: Path = ASSETS_DIR / "husky_a200.urdf"
"""Path of the bundled Husky A200 description, independent of the working directory."""

_WHEEL_JOINT_TYPES = frozenset({"continuous", "revolute"})
_CYLINDER_RIM_SAMPLES = 720  # rim points per cylinder end; worst-case error r*(1-cos(pi/720))


@dataclass(frozen=True)
class WheelGeometry:
    """One wheel measured from its joint and collision cylinder.

    Attributes:
        joint_name: name of the wheel joint.
        link_name: name of the wheel link.
        centre_m: wheel centre in base_link (x, y, z), m.
        axis: unit joint axis in base_link (dimensionless).
        radius_m: collision cylinder radius, m.
        width_m: collision cylinder length, m.
    """

    joint_name: str
    link_name: str
    centre_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_m: float
    width_m: float

    @property
    def is_left(self) -> bool:
        """True for wheels on the +y (left) side."""
        return self.centre_m[1] > 0.0

    @property
    def is_front(self) -> bool:
        """True for wheels ahead of the base_link origin (+x)."""
        return self.centre_m[0] > 0.0


@dataclass(frozen=True)
class RobotGeometry:
    """Geometry and mass of a wheeled robot, derived from its URDF.

    Attributes:
        urdf_path: the parsed file.
        base_link: name of the root link.
        total_mass_kg: sum of all link masses, kg.
        wheel_radius_m: mean wheel collision radius, m.
        wheel_width_m: mean wheel collision width (cylinder length), m.
        track_width_m: lateral distance between left and right wheel centres, m.
        wheelbase_m: longitudinal distance between front and rear axles, m.
        chassis_half_extents_m: (half length along x, half width along y) of the base_link
            collision shapes projected on the ground, measured from the base_link origin
            (the larger of the +/- sides), m.
        footprint_radius_m: radius of the smallest circle centred at the base_link origin
            enclosing the ground projection of every collision shape, wheels included, m.
        footprint_half_extents_m: (half length along x, half width along y) of the ground
            projection of every collision shape, wheels included, about the base_link origin
            (the larger of the +/- sides), m: the rectangle husky-cbf covers with discs.
        base_height_m: height of the base_link origin above flat ground when all wheels
            touch it (wheel radius minus mean wheel-centre z), m.
        ground_clearance_m: height of the lowest base_link collision point above flat
            ground in that resting pose, m.
        wheels: per-wheel measurements, in URDF joint order.
    """

    urdf_path: Path
    base_link: str
    total_mass_kg: float
    wheel_radius_m: float
    wheel_width_m: float
    track_width_m: float
    wheelbase_m: float
    chassis_half_extents_m: tuple[float, float]
    footprint_radius_m: float
    footprint_half_extents_m: tuple[float, float]
    base_height_m: float
    ground_clearance_m: float
    wheels: tuple[WheelGeometry, ...]

    @property
    def wheel_joint_names(self) -> tuple[str, ...]:
        """Names of the wheel joints, in URDF order."""
        return tuple(w.joint_name for w in self.wheels)

    @property
    def left_wheel_joint_names(self) -> tuple[str, ...]:
        """Names of the left-side (+y) wheel joints."""
        return tuple(w.joint_name for w in self.wheels if w.is_left)

    @property
    def right_wheel_joint_names(self) -> tuple[str, ...]:
        """Names of the right-side (-y) wheel joints."""
        return tuple(w.joint_name for w in self.wheels if not w.is_left)


def _box_points(size: np.ndarray) -> np.ndarray:
    """The 8 corners of a box of full extents ``size`` centred at the origin, shape (8, 3)."""
    half = 0.5 * np.asarray(size, dtype=float)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return signs * half


def _cylinder_points(radius: float, length: float) -> np.ndarray:
    """Points on both rims of a z-axis cylinder centred at the origin, shape (2N, 3)."""
    theta = np.linspace(0.0, 2.0 * math.pi, _CYLINDER_RIM_SAMPLES, endpoint=False)
    ring = np.stack([radius * np.cos(theta), radius * np.sin(theta)], axis=1)
    top = np.column_stack([ring, np.full(len(ring), 0.5 * length)])
    bottom = np.column_stack([ring, np.full(len(ring), -0.5 * length)])
    return np.vstack([top, bottom])


def _sphere_points(radius: float) -> np.ndarray:
    """Extreme points of a sphere along +/-x, +/-y, +/-z (enough for axis-aligned bounds)."""
    return radius * np.vstack([np.eye(3), -np.eye(3)])


def _transform(points: np.ndarray, tf: np.ndarray) -> np.ndarray:
    """Apply the 4x4 homogeneous transform ``tf`` to an (N, 3) array of points."""
    return points @ tf[:3, :3].T + tf[:3, 3]


def _collision_points(urdf: yourdfpy.URDF, link_name: str, base_link: str) -> list[np.ndarray]:
    """Extreme points of each collision shape of ``link_name``, in base_link, metres.

    Boxes give their 8 corners and cylinders points sampled on both rims, so the convex hull
    of the points is the shape and maxima of convex functions (such as the planar distance
    from the origin) are attained on them. Spheres give their centre +/- radius along the
    base_link axes (exact for axis-aligned bounds; see :func:`_footprint_radius`).
    """
    link_tf = urdf.get_transform(frame_to=link_name, frame_from=base_link)
    shapes: list[np.ndarray] = []
    for collision in urdf.link_map[link_name].collisions:
        origin = collision.origin if collision.origin is not None else np.eye(4)
        tf = link_tf @ origin
        geometry = collision.geometry
        if geometry.box is not None:
            shapes.append(_transform(_box_points(np.asarray(geometry.box.size)), tf))
        elif geometry.cylinder is not None:
            cylinder = geometry.cylinder
            shapes.append(_transform(_cylinder_points(cylinder.radius, cylinder.length), tf))
        elif geometry.sphere is not None:
            shapes.append(_sphere_points(geometry.sphere.radius) + tf[:3, 3])
        else:
            raise ValueError(f"link {link_name!r}: only box, cylinder and sphere collisions are supported")
    return shapes


def _footprint_radius(urdf: yourdfpy.URDF, base_link: str) -> float:
    """Max planar (x, y) distance from the base origin over every collision shape, m."""
    radius = 0.0
    for link_name, link in urdf.link_map.items():
        link_tf = urdf.get_transform(frame_to=link_name, frame_from=base_link)
        for collision in link.collisions:
            if collision.geometry.sphere is not None:  # exact: |centre_xy| + r
                origin = collision.origin if collision.origin is not None else np.eye(4)
                centre = (link_tf @ origin)[:3, 3]
                planar = float(np.hypot(centre[0], centre[1]))
                radius = max(radius, planar + collision.geometry.sphere.radius)
        for points in _collision_points(urdf, link_name, base_link):
            radius = max(radius, float(np.max(np.hypot(points[:, 0], points[:, 1]))))
    return radius


def _footprint_half_extents(urdf: yourdfpy.URDF, base_link: str) -> tuple[float, float]:
    """Max |x| and max |y| (m) in base_link over every link's collision shapes."""
    points = [p for name in urdf.link_map for p in _collision_points(urdf, name, base_link)]
    stacked = np.vstack(points)
    return float(np.max(np.abs(stacked[:, 0]))), float(np.max(np.abs(stacked[:, 1])))


def _find_wheels(urdf: yourdfpy.URDF, base_link: str) -> tuple[WheelGeometry, ...]:
    """Wheels: children of continuous/revolute joints with a cylinder collision."""
    wheels: list[WheelGeometry] = []
    for joint_name in urdf.joint_names:
        joint = urdf.joint_map[joint_name]
        if joint.type not in _WHEEL_JOINT_TYPES:
            continue
        link = urdf.link_map[joint.child]
        cylinders = [c for c in link.collisions if c.geometry.cylinder is not None]
        if not cylinders:
            continue
        tf = urdf.get_transform(frame_to=joint.child, frame_from=base_link)
        cylinder = cylinders[0].geometry.cylinder
        axis_local = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0))
        axis = tf[:3, :3] @ (axis_local / np.linalg.norm(axis_local))
        wheels.append(
            WheelGeometry(
                joint_name=joint_name,
                link_name=joint.child,
                centre_m=(float(tf[0, 3]), float(tf[1, 3]), float(tf[2, 3])),
                axis=(float(axis[0]), float(axis[1]), float(axis[2])),
                radius_m=float(cylinder.radius),
                width_m=float(cylinder.length),
            )
        )
    return tuple(wheels)


def load_geometry(urdf_path: Path | None = None) -> RobotGeometry:
    """Parse ``urdf_path`` (default :data:`DEFAULT_URDF`) and derive its geometry.

    Args:
        urdf_path: URDF file; primitive collision shapes only (box, cylinder, sphere).

    Returns:
        The measured :class:`RobotGeometry` (SI units: m, kg).

    Raises:
        ValueError: if the robot does not have wheels on both sides and both ends, or a
            collision shape is a mesh.
    """
    path = Path(urdf_path) if urdf_path is not None else DEFAULT_URDF
    stamp = path.stat()
    return _measured(path, stamp.st_mtime_ns, stamp.st_size)


@functools.lru_cache(maxsize=16)
def _measured(path: Path, mtime_ns: int, size: int) -> RobotGeometry:
    """load_geometry's work, once per file version: every episode builds a robot, and parsing the
    URDF cost 8 ms each time."""
    urdf = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)
    base_link = urdf.base_link

    total_mass = sum(
        float(link.inertial.mass)
        for link in urdf.link_map.values()
        if link.inertial is not None and link.inertial.mass is not None
    )

    wheels = _find_wheels(urdf, base_link)
    left = [w for w in wheels if w.is_left]
    right = [w for w in wheels if not w.is_left]
    front = [w for w in wheels if w.is_front]
    rear = [w for w in wheels if not w.is_front]
    if not (left and right and front and rear):
        raise ValueError(f"{path}: expected wheels on both sides and at both ends")

    def mean(values: list[float]) -> float:
        return float(np.mean(values))

    wheel_radius = mean([w.radius_m for w in wheels])
    track = mean([w.centre_m[1] for w in left]) - mean([w.centre_m[1] for w in right])
    wheelbase = mean([w.centre_m[0] for w in front]) - mean([w.centre_m[0] for w in rear])
    base_height = wheel_radius - mean([w.centre_m[2] for w in wheels])

    chassis = _collision_points(urdf, base_link, base_link)
    if chassis:
        pts = np.vstack(chassis)
        half_extents = (float(np.max(np.abs(pts[:, 0]))), float(np.max(np.abs(pts[:, 1]))))
        clearance = base_height + float(np.min(pts[:, 2]))
    else:
        half_extents = (0.0, 0.0)
        clearance = math.inf

    return RobotGeometry(
        urdf_path=path,
        base_link=base_link,
        total_mass_kg=total_mass,
        wheel_radius_m=wheel_radius,
        wheel_width_m=mean([w.width_m for w in wheels]),
        track_width_m=track,
        wheelbase_m=wheelbase,
        chassis_half_extents_m=half_extents,
        footprint_radius_m=_footprint_radius(urdf, base_link),
        footprint_half_extents_m=_footprint_half_extents(urdf, base_link),
        base_height_m=base_height,
        ground_clearance_m=clearance,
        wheels=wheels,
    )
