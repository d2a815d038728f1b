"""The node against the real ROS 2 client library: rclpy (the `ros-rclpy` wheels, a newer
distribution than Humble) on Fast DDS, ROS 2's default middleware. No mocks: real rclpy nodes,
real Fast DDS and Cyclone DDS between them, the real controller."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from husky_sim.ros2 import messages as msg
from husky_sim.ros2.cyclone_transport import CycloneTransport
from husky_sim.ros2.rclpy_transport import RclpyTransport, installed_distro, message_class
from husky_sim.ros2.settings import QOS_PROFILE_NAMES, TRANSPORTS, Ros2Settings, lease_domain_id
from husky_sim.runs.scenario import load_scenario
from husky_sim.sim.geometry import load_geometry
from tests.ros2.sample_messages import sample_messages

rclpy_serialization = pytest.importorskip("rclpy.serialization")  # `make test` installs rclpy

pytestmark = pytest.mark.physics

ROBOT = Path(__file__).with_name("rclpy_robot.py")


def _domain() -> int:
    return lease_domain_id(200, 232)


def _ours(message: object) -> bytes:
    """A message's CDR as our serializer writes it (padding zeroed)."""
    if not hasattr(message, "serialize"):  # rclpy's: read back with our type (CDR padding is unspecified)
        raw = bytes(rclpy_serialization.serialize_message(message))
        message = msg.message_type(_ros_type(message)).deserialize(raw)
    return bytes(message.serialize(use_version_2=False))


def _ros_type(rclpy_message: object) -> str:
    package = type(rclpy_message).__module__.split(".")[0]
    return f"{package}/msg/{type(rclpy_message).__name__}"


def _closure(store: object, ros_types: list[str]) -> list[str]:
    """The types and every type they contain, by Humble's definitions."""
    out: list[str] = []
    todo = list(ros_types)
    while todo:
        ros_type = todo.pop()
        if ros_type in out:
            continue
        out.append(ros_type)
        for _name, (node, arg) in store.fielddefs[ros_type][1]:
            if node.name == "NAME":
                todo.append(arg)
            elif node.name in ("ARRAY", "SEQUENCE") and arg[0][0].name == "NAME":
                todo.append(arg[0][1])
    return sorted(out)


def _wheel_definition(ros_type: str) -> tuple:
    """The installed .msg definition of a type, parsed by rosbags: (constants, fields). The wheels
    put them in the environment's share/ (a ROS 2 install, under AMENT_PREFIX_PATH)."""
    from rosbags.typesys import get_types_from_msg

    package, _kind, name = ros_type.split("/")
    prefixes = [*os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep), sys.prefix]
    path = next(
        p for p in (Path(x) / "share" / package / "msg" / f"{name}.msg" for x in prefixes if x) if p.exists()
    )
    return get_types_from_msg(path.read_text(), ros_type)[ros_type]


def test_the_wheels_definitions_equal_humbles_on_the_wire_but_for_the_graphs_gid() -> None:
    """Each message, serialised by us (Humble's definitions), is read by rclpy's own typesupport
    (the installed distribution's) and written back to the same message: the wire formats agree.
    Where the definitions differ, they differ as docs/on_the_robot.md says: Marker's ARROW_STRIP constant
    (not on the wire), and the graph's Gid (Humble 24 bytes, later 16)."""
    from rosbags.typesys import Stores, get_typestore

    for ros_type, message in sample_messages().items():
        wire = _ours(message)
        theirs = rclpy_serialization.deserialize_message(wire, message_class(ros_type))
        assert _ours(theirs) == wire, ros_type
    humble = get_typestore(Stores.ROS2_HUMBLE)
    differences = {}
    for ros_type in _closure(humble, [*sample_messages(), msg.PARTICIPANT_ENTITIES_INFO]):
        constants, fields = _wheel_definition(ros_type)
        humble_constants, humble_fields = humble.fielddefs[ros_type]
        if fields != humble_fields:
            differences[ros_type] = "fields"
        elif constants != humble_constants:
            differences[ros_type] = sorted({c[0] for c in constants} ^ {c[0] for c in humble_constants})
    assert differences == {
        "visualization_msgs/msg/Marker": ["ARROW_STRIP"],
        "rmw_dds_common/msg/Gid": "fields",
    }
    assert len(msg.make("rmw_dds_common/msg/Gid").data) == 24  # ours, Humble's
    assert len(message_class("rmw_dds_common/msg/Gid")().data) == 16 and installed_distro() == "kilted"
    assert len(msg.cyclone_kit("kilted").make("rmw_dds_common/msg/Gid").data) == 16


def test_every_message_both_ways_with_every_qos_profile() -> None:
    """Cyclone DDS (ours) to rclpy on Fast DDS and back, each of the seven message types on each
    QoS profile: every message arrives and is what was sent."""
    domain = _domain()
    cyclone = CycloneTransport(Ros2Settings(domain_id=domain, localhost_only=True))
    ros = RclpyTransport(Ros2Settings(domain_id=domain, localhost_only=True, node_name="probe"))
    links = []  # (name, publisher, subscription, message to send, its wire bytes)
    for i, (ros_type, message) in enumerate(sample_messages().items()):
        wire = _ours(message)
        as_rclpy = rclpy_serialization.deserialize_message(wire, message_class(ros_type))
        for qos in QOS_PROFILE_NAMES:
            for source, sink, sent, to in (
                (cyclone, ros, message, "rclpy"),
                (ros, cyclone, as_rclpy, "cyclone"),
            ):
                topic = f"/probe/to_{to}_{i}_{qos}"
                publisher = source.publish_topic(topic, ros_type, qos)
                subscription = sink.subscribe_topic(topic, ros_type, qos)
                links.append((f"{ros_type} {qos} to {to}", publisher, subscription, sent, wire))
    got: dict[str, bytes] = {}
    end = time.monotonic() + 30
    try:
        while len(got) < len(links) and time.monotonic() < end:
            for name, publisher, _s, message, _w in links:
                if name not in got:
                    publisher.write(message)
            ros.wait(0.05)
            for name, _p, subscription, _m, _w in links:
                for received in subscription.take():
                    got[name] = _ours(received.message)
    finally:
        ros.close()
    assert sorted(name for name, *_ in links if name not in got) == []
    for name, _p, _s, _m, wire in links:
        assert got[name] == wire, name


def test_the_graph_follows_the_peers_layout(capsys) -> None:
    """No distribution given: our node announces itself in the graph layout of the first ROS 2
    peer it discovers. A Humble-layout peer (endpoints without `typehash=`) keeps Humble's 24-byte
    gids; an rclpy peer (the Kilted wheels, Fast DDS) joining later is named in a one-line notice
    of mixed layouts, not followed. With
    rclpy first, the node switches to 16-byte gids and rclpy's graph lists it with its topic."""
    domain = _domain()
    humble = CycloneTransport(
        Ros2Settings(domain_id=domain, localhost_only=True, node_name="old", ros_distro="humble")
    )
    first = CycloneTransport(Ros2Settings(domain_id=domain, localhost_only=True, node_name="first"))
    end = time.monotonic() + 20
    while first.graph_distro is None and time.monotonic() < end:
        first.wait(0.05)
    assert first.graph_distro == "humble" and humble.graph_distro == "humble"

    domain = _domain()
    ours = CycloneTransport(Ros2Settings(domain_id=domain, localhost_only=True, node_name="follower"))
    ours.publish("cmd_vel", "geometry_msgs/msg/Twist")
    assert ours.graph_distro is None
    ros = RclpyTransport(Ros2Settings(domain_id=domain, localhost_only=True, node_name="probe"))
    try:
        listed: list = []
        end = time.monotonic() + 30
        while not listed and time.monotonic() < end:
            ours.wait(0.05)
            ros.wait(0.05)
            if ("follower", "/") in ros.node.get_node_names_and_namespaces():
                listed = ros.node.get_publisher_names_and_types_by_node("follower", "/")
        assert ours.graph_distro == "kilted" == installed_distro()
        assert ("/cmd_vel", ["geometry_msgs/msg/Twist"]) in listed
        # the Humble-layout domain meets a later peer: named, not followed
        late = RclpyTransport(
            Ros2Settings(domain_id=first.settings.domain_id, localhost_only=True, node_name="late")
        )
        try:
            end = time.monotonic() + 20
            while "peers of both layouts" not in capsys.readouterr().err and time.monotonic() < end:
                first.wait(0.05)
                late.wait(0.0)
            assert first.graph_distro == "humble" and time.monotonic() < end
        finally:
            late.close()
    finally:
        ros.close()


def _serve(tmp_path: Path, domain: int, transport: str, duration_s: float, *extra: str) -> subprocess.Popen:
    command = [
        sys.executable, "-m", "husky_sim.cli", "serve", "husky_point_stabilisation",
        "--controller", "husky-cbf", "--horizon", "5", "--domain-id", str(domain), "--localhost-only",
        "--duration", str(duration_s),
        "--transport", transport, "--out", str(tmp_path / "node"), *extra,
    ]  # fmt: skip
    return subprocess.Popen(command, stdout=(tmp_path / "serve.out").open("wb"), stderr=subprocess.STDOUT)


def _robot(tmp_path: Path, domain: int, duration_s: float, *extra: str) -> dict:
    sc = load_scenario("husky_point_stabilisation")
    goal = sc.reference_object()
    command = [
        sys.executable, str(ROBOT), "--domain", str(domain), "--duration", str(duration_s),
        "--goal", str(goal.x_m), str(goal.y_m), str(goal.theta_rad),
        "--robot-radius", str(load_geometry().footprint_radius_m),
        "--out", str(tmp_path / "robot.json"), *extra,
    ]  # fmt: skip
    for o in sc.obstacle_specs():
        command += ["--obstacle", str(o.x_m), str(o.y_m), str(o.radius_m)]
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}  # as serve --localhost-only
    subprocess.run(command, check=True, timeout=duration_s + 120, env=env)
    return json.loads((tmp_path / "robot.json").read_text())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("transport", "stamped"), [("cyclonedds", False), ("rclpy", False), ("cyclonedds", True)]
)
def test_an_rclpy_robot_is_driven_to_the_goal_and_sees_the_nodes_safety(
    tmp_path: Path, transport: str, stamped: bool
) -> None:
    """A real rclpy robot node (a unicycle on Fast DDS, odometry at 50 Hz with sensor-data QoS,
    goal, obstacle markers) and `husky-sim serve husky_point_stabilisation --controller
    husky-cbf` (an obstacle on the straight line to a goal 7 m away): /cmd_vel at 1/tau, a /plan
    for each, the goal reached without touching the obstacle; the odometry withheld for 2 s gives
    zero commands (the node ends at 20 s of its own, the robot at 24 s: plenty of slack for start-up
    and discovery); the node's end, a last zero. rclpy's graph lists the node and its topics."""
    domain = _domain()
    # no --ros-distro: the graph follows the robot's; the stamped run gives it as an override
    flags = ["--cmd-vel-stamped", "--ros-distro", installed_distro()] if stamped else []
    node = _serve(tmp_path, domain, transport, 20.0, *flags)
    try:
        silence = ["--silent-from", "14", "--silent-for", "2"]
        seen = _robot(tmp_path, domain, 24.0, *silence, *(["--stamped"] if stamped else []))
    finally:
        node.wait(timeout=60)
    output = (tmp_path / "serve.out").read_text()
    assert node.returncode == 0, output
    if transport == "cyclonedds" and not stamped:  # no --ros-distro: the robot's layout, found
        assert "ROS graph: announced in the peers' layout, Iron's and later (16-byte gids)" in output
    commands, plans = seen["commands"], seen["plans"]
    t = np.array([c["t"] for c in commands]) - seen["t0"]
    driving = (t > 1.0) & (t < 12.0)
    assert np.median(np.diff(t[driving])) == pytest.approx(0.2, abs=0.02)  # 1/tau
    assert len(plans) >= driving.sum() - 2 and all(p["poses"] == 6 and p["frame"] == "odom" for p in plans)
    assert seen["reached_at_s"] is not None
    assert np.hypot(seen["final"][0] - 7.0, seen["final"][1]) < 0.1
    assert seen["min_clearance_m"] > 0.0
    silent = [c for c, ti in zip(commands, t, strict=True) if 14.0 + 0.5 < ti < 16.0]  # after 2 tau
    assert len(silent) >= 3 and all(c["v"] == 0 and c["omega"] == 0 for c in silent)
    last = commands[-1]
    assert last["v"] == 0 and last["omega"] == 0 and t[-1] < 23.0  # the node's end, then nothing
    if stamped:
        assert all(c["frame"] == "base_link" for c in commands)
    graph = seen["graph"]["/husky_sim_controller"]
    cmd_type = "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist"
    assert {("/cmd_vel", cmd_type), ("/plan", "nav_msgs/msg/Path")} <= {tuple(p) for p in graph["publishers"]}
    assert {
        ("/odometry/filtered", "nav_msgs/msg/Odometry"),
        ("/goal_pose", "geometry_msgs/msg/PoseStamped"),
        ("/obstacles", "visualization_msgs/msg/MarkerArray"),
    } <= {tuple(s) for s in graph["subscriptions"]}
    summary = json.loads((tmp_path / "node" / "serve_summary.json").read_text())
    assert summary["stale_events"] >= 5 and summary["shutdown_events"] == 1 and summary["overrun_events"] == 0
    assert summary["goals_received"] >= 10 and summary["odometry_latency_ms"]["median"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("transport", TRANSPORTS)
def test_an_rclpy_robot_sees_an_overrunning_node_send_zero_and_no_plan(
    tmp_path: Path, transport: str
) -> None:
    """Solve budget 1 us: every solve overruns; the rclpy robot gets zero commands at 1/tau and
    no plan, and stays where it is."""
    domain = _domain()
    node = _serve(tmp_path, domain, transport, 6.0, "--solve-budget", "0.000001")
    try:
        seen = _robot(tmp_path, domain, 7.0)
    finally:
        node.wait(timeout=60)
    assert node.returncode == 0, (tmp_path / "serve.out").read_text()
    assert len(seen["commands"]) >= 15 and all(c["v"] == 0 and c["omega"] == 0 for c in seen["commands"])
    assert seen["plans"] == [] and seen["final"] == [0.0, 0.0, 0.0]
    summary = json.loads((tmp_path / "node" / "serve_summary.json").read_text())
    assert summary["overrun_events"] >= 15 and summary["command_events"] == 0


@pytest.mark.parametrize(
    ("ros_args", "message"),
    [
        (
            ["-p", "odometry_qos:=fast"],
            "odometry_qos: expected one of sensor_data, default, clock, got 'fast'",
        ),
        (
            ["-p", "odometry_qos:=5"],
            "odometry_qos (ROS parameter): Trying to set parameter 'odometry_qos' to '5'",
        ),
        (["-p"], "--ros-args: failed to initialize rcl: Couldn't parse trailing -p flag"),
        (["--bogus"], "--ros-args: ['--bogus']"),
    ],
)
def test_a_bad_ros_argument_is_a_one_line_error(
    capsys, tmp_path: Path, ros_args: list[str], message: str
) -> None:
    from husky_sim.cli import main

    args = ["serve", "husky_point_stabilisation", "--transport", "rclpy", "--localhost-only"]
    args += ["--domain-id", str(_domain()), "--out", str(tmp_path / "node"), "--ros-args", *ros_args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_ros_parameters_set_the_nodes_settings() -> None:
    """With rclpy the node's settings are ROS parameters: --ros-args override the defaults the
    command line gave, and the node takes the name it is remapped to."""
    transport = RclpyTransport(
        Ros2Settings(domain_id=_domain(), localhost_only=True, cmd_vel_topic="/husky/cmd_vel"),
        ["-p", "odometry_topic:=/odom", "-p", "cmd_vel_stamped:=true", "-p", "use_sim_time:=true",
         "-r", "__node:=husky_controller"],
    )  # fmt: skip
    try:
        s = transport.settings
        assert (s.odometry_topic, s.cmd_vel_topic, s.cmd_vel_stamped, s.use_sim_time) == (
            "/odom",
            "/husky/cmd_vel",
            True,
            True,
        )
        assert s.node_name == "husky_controller" and s.ros_distro == installed_distro()
        assert transport.node.get_parameter("plan_topic").value == "/plan"
    finally:
        transport.close()
