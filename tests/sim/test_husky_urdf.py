"""Checks of the Husky A200 URDF against the published figures and in PyBullet."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as p
import pybullet_data
import pytest
import yourdfpy

from husky_sim.sim import specs as specs
from husky_sim.sim.geometry import DEFAULT_URDF, RobotGeometry, load_geometry

WHEEL_JOINTS = ("front_left_wheel", "front_right_wheel", "rear_left_wheel", "rear_right_wheel")
REL_TOL = 0.02  # 2 % against published figures


@pytest.fixture(scope="module")
def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(DEFAULT_URDF), build_scene_graph=True, load_meshes=False)


@pytest.fixture(scope="module")
def geometry() -> RobotGeometry:
    return load_geometry()


@pytest.fixture()
def client() -> Iterator[int]:
    cid = p.connect(p.DIRECT)
    try:
        yield cid
    finally:
        p.disconnect(physicsClientId=cid)


# --------------------------------------------------------------------------- URDF structure


def test_default_urdf_exists_and_loads(urdf: yourdfpy.URDF) -> None:
    assert DEFAULT_URDF.is_file()
    assert urdf.validate()
    assert urdf.base_link == "base_link"
    assert set(urdf.link_map) == {"base_link", *(f"{j}_link" for j in WHEEL_JOINTS)}


def test_default_urdf_independent_of_cwd(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert load_geometry().total_mass_kg > 0.0


def test_wheel_joints_are_continuous_about_y(urdf: yourdfpy.URDF) -> None:
    for name in WHEEL_JOINTS:
        joint = urdf.joint_map[name]
        assert joint.type == "continuous"
        assert joint.parent == "base_link"
        np.testing.assert_allclose(joint.axis, [0.0, 1.0, 0.0])
        expected = specs.HUSKY_MODEL.wheel_positions_m[name]
        np.testing.assert_allclose(joint.origin[:3, 3], expected, atol=1e-9)


def test_every_link_has_valid_inertial(urdf: yourdfpy.URDF) -> None:
    for name, link in urdf.link_map.items():
        assert link.inertial is not None, name
        assert link.inertial.mass is not None and link.inertial.mass > 0.0, name
        inertia = np.asarray(link.inertial.inertia, dtype=float)
        np.testing.assert_allclose(inertia, inertia.T, err_msg=name)
        principal = np.sort(np.linalg.eigvalsh(inertia))
        assert principal[0] > 0.0, f"{name}: inertia not positive definite"
        assert principal[0] + principal[1] >= principal[2] - 1e-12, f"{name}: triangle"


def test_inertials_match_model_choices(urdf: yourdfpy.URDF) -> None:
    model = specs.HUSKY_MODEL
    base = urdf.link_map["base_link"].inertial
    assert base.mass == pytest.approx(model.chassis_mass_kg)
    np.testing.assert_allclose(base.origin[:3, 3], model.chassis_com_m)
    ixx, ixy, ixz, iyy, iyz, izz = model.chassis_inertia_kgm2
    expected = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    np.testing.assert_allclose(base.inertia, expected)
    for joint in WHEEL_JOINTS:
        wheel = urdf.link_map[f"{joint}_link"].inertial
        assert wheel.mass == pytest.approx(specs.HUSKY_DESCRIPTION.wheel_mass_kg)
        axle = wheel.inertia[1, 1]
        assert axle == pytest.approx(specs.HUSKY_DESCRIPTION.wheel_inertia_axle_kgm2)
        assert axle > wheel.inertia[0, 0]  # disc-like: largest moment about the axle


def test_collision_geometry_is_primitive(urdf: yourdfpy.URDF) -> None:
    for name, link in urdf.link_map.items():
        assert link.collisions, name
        for collision in link.collisions:
            geometry = collision.geometry
            assert geometry.mesh is None, name
            assert geometry.box is not None or geometry.cylinder is not None, name


def test_wheel_collision_cylinder_axis_is_the_axle(urdf: yourdfpy.URDF) -> None:
    for joint in WHEEL_JOINTS:
        (collision,) = urdf.link_map[f"{joint}_link"].collisions
        assert collision.geometry.cylinder is not None
        cylinder_axis = collision.origin[:3, :3] @ np.array([0.0, 0.0, 1.0])
        assert abs(cylinder_axis @ np.array([0.0, 1.0, 0.0])) == pytest.approx(1.0)


# ------------------------------------------------------------------ derived vs published


def test_derived_mass_matches_spec_sheet(geometry: RobotGeometry) -> None:
    assert geometry.total_mass_kg == pytest.approx(specs.TOTAL_MASS_KG, rel=REL_TOL)


def test_derived_wheel_size_matches_description(geometry: RobotGeometry) -> None:
    assert geometry.wheel_radius_m == pytest.approx(specs.WHEEL_RADIUS_M, rel=REL_TOL)
    assert 2 * geometry.wheel_radius_m == pytest.approx(specs.HUSKY_DESCRIPTION.wheel_diameter_m, rel=REL_TOL)
    assert geometry.wheel_width_m == pytest.approx(specs.WHEEL_WIDTH_M, rel=REL_TOL)


def test_derived_track_and_wheelbase_match_published(geometry: RobotGeometry) -> None:
    assert geometry.track_width_m == pytest.approx(specs.TRACK_WIDTH_M, rel=REL_TOL)
    assert geometry.wheelbase_m == pytest.approx(specs.WHEELBASE_M, rel=REL_TOL)
    assert geometry.wheelbase_m == pytest.approx(specs.HUSKY_SPEC_SHEET.wheelbase_m, rel=REL_TOL)


def test_wheel_sides(geometry: RobotGeometry) -> None:
    assert geometry.wheel_joint_names == WHEEL_JOINTS
    assert geometry.left_wheel_joint_names == ("front_left_wheel", "rear_left_wheel")
    assert geometry.right_wheel_joint_names == ("front_right_wheel", "rear_right_wheel")


def test_footprint(geometry: RobotGeometry) -> None:
    half_x, half_y = geometry.chassis_half_extents_m
    assert geometry.footprint_radius_m > 0.5  # bigger than a 0.25 m research robot
    assert geometry.footprint_radius_m >= math.hypot(half_x, half_y) - 1e-9
    # Every wheel's outer corner lies inside the footprint circle.
    for wheel in geometry.wheels:
        x, y, _ = wheel.centre_m
        corner = math.hypot(abs(x) + wheel.radius_m, abs(y) + wheel.width_m / 2)
        assert corner <= geometry.footprint_radius_m + 1e-9
    # The chassis box is the published 0.9874 x 0.5709 m.
    assert 2 * half_x == pytest.approx(specs.HUSKY_DESCRIPTION.base_x_size_m)
    assert 2 * half_y == pytest.approx(specs.HUSKY_DESCRIPTION.base_y_size_m)


def test_envelope_close_to_spec_sheet(geometry: RobotGeometry) -> None:
    sheet = specs.HUSKY_SPEC_SHEET
    half_x, _ = geometry.chassis_half_extents_m
    outer_width = geometry.track_width_m + geometry.wheel_width_m
    assert 2 * half_x == pytest.approx(sheet.length_m, rel=0.05)
    assert outer_width == pytest.approx(sheet.width_m, rel=0.05)
    assert geometry.ground_clearance_m == pytest.approx(sheet.ground_clearance_m, rel=0.05)


def test_chassis_clears_ground_when_resting(geometry: RobotGeometry) -> None:
    assert geometry.base_height_m == pytest.approx(specs.HUSKY_MODEL.base_link_height_m)
    assert geometry.ground_clearance_m > 0.1


def test_controller_figures() -> None:
    multiplier = specs.WHEEL_SEPARATION_MULTIPLIER
    assert multiplier == pytest.approx(1.875)  # [CONTROL] and [CONTROL2] agree
    assert specs.LINEAR_MAX_VELOCITY_MPS <= specs.MAX_SPEED_MPS
    assert specs.ROS1_DIFF_DRIVE.effective_wheel_separation_m(specs.TRACK_WIDTH_M) == (
        pytest.approx(0.5708 * 1.875)
    )


def test_the_specs_file_names_a_source_for_every_tag_and_rejects_a_missing_figure(tmp_path: Path) -> None:
    """Every [TAG] in the specs file is one of its sources; a figure left out (or one too many)
    is a one-line error naming the file, the section and the field."""
    text = specs.SPECS_FILE.read_text()
    tags = set(re.findall(r"\[([A-Z0-9]+)\]", text))
    assert tags and tags <= set(specs.HUSKY.sources), tags - set(specs.HUSKY.sources)
    broken = tmp_path / "specs.yaml"
    broken.write_text(text.replace("  wheel_mass_kg: 2.637", "  wheel_mass_kgs: 2.637"))
    with pytest.raises(ValueError, match=r"specs.yaml: description: .*check wheel_mass_kgs$"):
        specs.load_specs(broken)
    broken.write_text(text.replace("  gear_ratio: 78.71", ""))
    with pytest.raises(ValueError, match=r"specs.yaml: motor: .*check gear_ratio$"):
        specs.load_specs(broken)


# ----------------------------------------------------------------------------- PyBullet


def _load_robot(client: int, height: float) -> tuple[int, int]:
    p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=client)
    p.setGravity(0.0, 0.0, -9.81, physicsClientId=client)
    plane = p.loadURDF("plane.urdf", physicsClientId=client)
    robot = p.loadURDF(
        str(DEFAULT_URDF),
        basePosition=[0.0, 0.0, height],
        flags=p.URDF_USE_INERTIA_FROM_FILE,
        physicsClientId=client,
    )
    return plane, robot


def _base_link_pose(client: int, robot: int) -> tuple[np.ndarray, np.ndarray]:
    """base_link frame pose (PyBullet reports the base *inertial* frame)."""
    com_pos, com_orn = p.getBasePositionAndOrientation(robot, physicsClientId=client)
    local_pos, local_orn = p.getDynamicsInfo(robot, -1, physicsClientId=client)[3:5]
    inv_pos, inv_orn = p.invertTransform(local_pos, local_orn)
    pos, orn = p.multiplyTransforms(com_pos, com_orn, inv_pos, inv_orn)
    return np.asarray(pos), np.asarray(p.getEulerFromQuaternion(orn))


@pytest.mark.physics
def test_pybullet_masses_and_inertia(client: int, geometry: RobotGeometry) -> None:
    _, robot = _load_robot(client, geometry.base_height_m + 0.02)
    links = range(-1, p.getNumJoints(robot, physicsClientId=client))
    infos = [p.getDynamicsInfo(robot, i, physicsClientId=client) for i in links]
    assert sum(info[0] for info in infos) == pytest.approx(geometry.total_mass_kg)
    ixx, _, _, iyy, _, izz = specs.HUSKY_MODEL.chassis_inertia_kgm2
    np.testing.assert_allclose(infos[0][2], [ixx, iyy, izz], rtol=1e-6)
    # Inertial frame aligned with base_link, so the reported base orientation is base_link's.
    np.testing.assert_allclose(infos[0][4], [0.0, 0.0, 0.0, 1.0], atol=1e-9)
    names = [p.getJointInfo(robot, j, physicsClientId=client)[1].decode() for j in range(len(infos) - 1)]
    assert tuple(names) == WHEEL_JOINTS


@pytest.mark.physics
def test_pybullet_robot_rests_on_its_wheels(client: int, geometry: RobotGeometry) -> None:
    plane, robot = _load_robot(client, geometry.base_height_m + 0.02)
    steps = 240  # 1 s at the default 240 Hz
    heights = []
    for _ in range(steps):
        p.stepSimulation(physicsClientId=client)
        heights.append(_base_link_pose(client, robot)[0][2])
    pos, rpy = _base_link_pose(client, robot)

    assert pos[2] == pytest.approx(geometry.base_height_m, abs=3e-3)
    assert np.ptp(heights[-60:]) < 1e-4  # settled over the last 0.25 s
    assert abs(rpy[0]) < 0.01 and abs(rpy[1]) < 0.01  # level, rad
    assert np.hypot(pos[0], pos[1]) < 5e-3  # did not roll away, m

    link_of_joint = {
        p.getJointInfo(robot, j, physicsClientId=client)[1].decode(): j
        for j in range(p.getNumJoints(robot, physicsClientId=client))
    }
    for joint in WHEEL_JOINTS:
        contacts = p.getContactPoints(
            bodyA=robot, bodyB=plane, linkIndexA=link_of_joint[joint], physicsClientId=client
        )
        assert contacts, f"{joint} does not touch the ground"
    chassis = p.getContactPoints(bodyA=robot, bodyB=plane, linkIndexA=-1, physicsClientId=client)
    assert not chassis, "chassis touches the ground"
