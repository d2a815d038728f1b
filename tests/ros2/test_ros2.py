"""The controller as a ROS 2 node over real DDS (Cyclone DDS between processes and threads on this
machine, traffic kept on 127.0.0.1), its safety behaviour, the rehearsal against the PyBullet
Husky, and run.mcap read back with the MCAP library. No mocks: real transport, real solver,
real physics."""

from __future__ import annotations

import base64
import csv
import json
import os
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from controllers import SetPoint
from husky_sim.cli import main
from husky_sim.ros2 import messages as msg
from husky_sim.ros2.cyclone_transport import DEFAULT_QOS, SENSOR_DATA_QOS, dds_topic_name, topic_qos
from husky_sim.ros2.node import ControllerNode
from husky_sim.ros2.rehearse import rehearse
from husky_sim.ros2.settings import TRANSPORTS, Ros2Settings, domain_id_from_env, lease_domain_id
from husky_sim.ros2.transport import open_transport
from husky_sim.runs.foxglove_record import MCAP_NAME, FoxgloveRecorder
from husky_sim.runs.run import run_scenario
from husky_sim.runs.scenario import load_scenario
from tests.ros2.sample_messages import sample_messages

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)

#: Per-step channels of run.mcap (one message per control step) and the one-off ones.
STEP_CHANNELS = {"/tf", "/robot/pose", "/scene", "/control", "/safety"}


def _domain() -> int:
    """A DDS domain no other process here uses (xdist workers and rehearsals run side by side)."""
    return lease_domain_id(200, 232)


# -- messages -------------------------------------------------------------------------------------
def _to_rosbags(value: object, ros_type: str, store: object) -> object:
    """The same message as a rosbags object (ROS 2's own CDR serializer, independent of ours)."""
    cls = store.types[ros_type]
    _consts, fields = store.fielddefs[ros_type]
    kwargs = {}
    for name, (node, arg) in fields:
        v = getattr(value, name)
        kind = node.name
        if kind == "NAME":
            kwargs[name] = _to_rosbags(v, arg, store)
        elif kind == "BASE":
            kwargs[name] = v
        else:
            (inner_node, inner_arg), _length = arg
            if inner_node.name == "BASE":
                kwargs[name] = np.array(v, dtype={"float64": np.float64, "uint8": np.uint8}[inner_arg[0]])
            else:
                kwargs[name] = [_to_rosbags(x, inner_arg, store) for x in v]
    return cls(**kwargs)


@pytest.mark.parametrize("ros_type", list(sample_messages()))
def test_messages_serialise_exactly_as_ros2_cdr(ros_type: str) -> None:
    """Our DDS types, built from ROS 2's definitions, put on the wire byte for byte what ROS 2's
    CDR serializer (rosbags, a separate implementation) writes for the same message."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    message = sample_messages()[ros_type]
    ours = message.serialize(use_version_2=False)
    theirs = bytes(store.serialize_cdr(_to_rosbags(message, ros_type, store), ros_type))
    assert ours == theirs
    assert type(message).__idl_typename__ == msg.dds_type_name(ros_type)
    assert type(message).__idl_annotations__["extensibility"] == "final"
    assert type(message).deserialize(ours).serialize(use_version_2=False) == ours  # and back


def test_names_and_settings() -> None:
    assert msg.dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"
    assert dds_topic_name("/cmd_vel") == "rt/cmd_vel"
    assert msg.quaternion_yaw(msg.yaw_quaternion(-2.5)) == pytest.approx(-2.5, abs=1e-12)
    assert msg.from_time(msg.to_time(12.3456789)) == pytest.approx(12.3456789, abs=1e-9)
    with pytest.raises(ValueError, match="cmd_vel_topic: expected an absolute ROS 2 topic name"):
        Ros2Settings(cmd_vel_topic="cmd_vel")
    with pytest.raises(ValueError, match="odometry_topic: expected an absolute ROS 2 topic name"):
        Ros2Settings(odometry_topic="/odometry//filtered")
    with pytest.raises(
        ValueError, match="odometry_qos: expected one of sensor_data, default, clock, got 'fast'"
    ):
        Ros2Settings(odometry_qos="fast")
    assert topic_qos(Ros2Settings(), "odometry") is SENSOR_DATA_QOS
    assert topic_qos(Ros2Settings(odometry_qos="default"), "odometry") is DEFAULT_QOS
    assert topic_qos(Ros2Settings(), "cmd_vel") is DEFAULT_QOS
    assert domain_id_from_env({}) == 0
    assert domain_id_from_env({"ROS_DOMAIN_ID": "42"}) == 42
    with pytest.raises(ValueError, match=r"ROS_DOMAIN_ID: expected an integer in \[0, 232\], got 300"):
        domain_id_from_env({"ROS_DOMAIN_ID": "300"})
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID: expected an integer"):
        domain_id_from_env({"ROS_DOMAIN_ID": "robot"})
    with pytest.raises(ValueError, match="message type: 'nav_msgs/msg/Nope' is not a ROS 2 message type"):
        msg.message_type("nav_msgs/msg/Nope")


def test_serve_rejects_bad_input_in_one_line(capsys: pytest.CaptureFixture[str], monkeypatch) -> None:
    assert main(["serve", "husky_point_stabilisation", "--domain-id", "500"]) == 2
    assert "--domain-id: expected an integer in [0, 232], got 500" in capsys.readouterr().err
    assert main(["serve", "husky_point_stabilisation", "--cmd-vel-topic", "cmd_vel"]) == 2
    err = capsys.readouterr().err.strip()
    assert "cmd_vel_topic: expected an absolute ROS 2 topic name" in err and len(err.splitlines()) == 1
    assert main(["serve", "husky_point_stabilisation", "--solve-budget", "0.5"]) == 2
    assert "--solve-budget: must be at most tau = 0.2 s, got 0.5" in capsys.readouterr().err
    assert main(["rehearse", "husky_point_stabilisation", "--reply-timeout", "0"]) == 2
    assert "--reply-timeout: expected a number in [0.01, 600], got 0" in capsys.readouterr().err
    assert main(["serve", "husky_point_stabilisation", "--ros-args", "-p", "plan_topic:=/p"]) == 2
    assert "--ros-args: only the rclpy transport takes ROS arguments" in capsys.readouterr().err
    assert main(["serve", "husky_point_stabilisation", "--node-name", "husky-cbf"]) == 2
    assert "node_name: expected a ROS 2 node name like husky_sim_controller, got 'husky-cbf'" in (
        capsys.readouterr().err
    )
    monkeypatch.setenv("ROS_DOMAIN_ID", "999")
    assert main(["serve", "husky_point_stabilisation"]) == 2
    assert "ROS_DOMAIN_ID: expected an integer in [0, 232], got 999" in capsys.readouterr().err


# -- the node's safety, over real DDS --------------------------------------------------------------
class _Robot:
    """The robot's side of the topics, in this process, on the node's (localhost) domain, over
    Cyclone DDS (a node on the rclpy transport talks to it through Fast DDS)."""

    def __init__(self, settings: Ros2Settings) -> None:
        self.dds = open_transport(settings)
        self.odom = self.dds.publish("odometry", msg.ODOMETRY)
        self.goal = self.dds.publish("goal", msg.POSE_STAMPED)
        self.cmd = self.dds.subscribe("cmd_vel", msg.TWIST)
        self.plan = self.dds.subscribe("plan", msg.PATH)

    def received(self, subscription) -> list[object]:
        return [r.message for r in subscription.take()]

    def send_odometry(self, x: float, y: float, yaw: float) -> None:
        odom = msg.make(msg.ODOMETRY, header=msg.header(time.time(), "odom"), child_frame_id="base_link")
        odom.pose.pose = msg.pose(x, y, yaw)
        self.odom.write(odom)

    def commands(self, seconds: float, odometry: tuple[float, float, float] | None = None) -> list[object]:
        """Twists received over `seconds` of wall time, sending odometry at 50 Hz if given."""
        got: list[object] = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if odometry is not None:
                self.send_odometry(*odometry)
            got.extend(self.received(self.cmd))
            time.sleep(0.02)
        return got + self.received(self.cmd)


def _wait_matched(robot: _Robot, node: ControllerNode) -> None:
    """Until both sides have matched the other (each middleware finishes discovery on its own)
    and the node's commands reach the robot (it sends zeros without odometry): from Fast DDS to
    Cyclone DDS the first samples come a second or two late, repaired by reliability."""
    end = time.monotonic() + 20
    while time.monotonic() < end:
        matched = robot.odom.subscribers() and robot.cmd.publishers() and node.connected()
        if matched and robot.received(robot.cmd):
            return
        time.sleep(0.02)
    raise AssertionError("the node never appeared on DDS")


@pytest.fixture(scope="module")
def husky_cbf():
    sc = load_scenario("husky_point_stabilisation")
    return sc, sc.with_overrides(horizon=5).make_controller("husky-cbf")


def _start_node(
    controller,
    reference,
    tau_s: float,
    settings: Ros2Settings,
    out: Path,
    budget_s=None,
    transport="cyclonedds",
):
    node = ControllerNode(controller, reference, tau_s, settings, out, budget_s, transport)
    stop = threading.Event()
    thread = threading.Thread(target=node.spin, kwargs={"stop": stop.is_set}, daemon=True)
    thread.start()
    return node, stop, thread


@pytest.mark.slow
@pytest.mark.parametrize("transport", TRANSPORTS)
def test_node_commands_on_fresh_odometry_and_stops_the_robot_otherwise(
    husky_cbf, tmp_path: Path, transport: str
) -> None:
    """Wall clock: no odometry -> zero commands every tau; fresh odometry -> the controller's
    commands and plans; a goal in another frame is refused, one in odom retargets the node;
    odometry gone for 2 tau -> zero again; on shutdown a last zero command. Every event counted
    and in serve.csv. The same on both transports (rclpy's: Fast DDS to our Cyclone DDS robot)."""
    sc, controller = husky_cbf
    settings = Ros2Settings(domain_id=_domain(), localhost_only=True)
    robot = _Robot(settings)
    node, stop, thread = _start_node(
        controller, sc.reference_object(), sc.tau_s, settings, tmp_path, transport=transport
    )
    _wait_matched(robot, node)
    silent = robot.commands(1.0)
    assert len(silent) >= 3 and all(t.linear.x == 0 and t.angular.z == 0 for t in silent)
    start = (sc.robot.start.x_m, sc.robot.start.y_m, sc.robot.start.yaw_rad)
    driven = robot.commands(1.5, odometry=start)
    assert any(t.linear.x > 0.1 for t in driven), "fresh odometry must give a driving command"
    plans = robot.received(robot.plan)
    assert plans and len(plans[-1].poses) == 6 and plans[-1].header.frame_id == "odom"
    # husky-cbf's plan starts where the drive acts on its first command: a dead time after the odometry
    stamps = [msg.from_time(p.header.stamp) - msg.from_time(plans[-1].header.stamp) for p in plans[-1].poses]
    assert stamps[0] == pytest.approx(0.34, abs=1e-5) and np.diff(stamps) == pytest.approx(0.2, abs=1e-5)
    elsewhere = msg.make(
        msg.POSE_STAMPED, header=msg.header(time.time(), "map"), pose=msg.pose(9.0, 9.0, 0.0)
    )
    robot.goal.write(elsewhere)  # no tf here: refused, never driven to in the wrong frame
    robot.commands(0.4, odometry=start)
    assert node.stats.rejected["goals"] == 1 and node.reference == sc.reference_object()
    goal = msg.make(msg.POSE_STAMPED, header=msg.header(time.time(), "odom"), pose=msg.pose(-5.0, 0.0, 0.0))
    robot.goal.write(goal)
    robot.commands(0.6, odometry=start)
    assert node.stats.goals_received == 1 and node.reference == SetPoint(-5.0, 0.0, pytest.approx(0.0))
    stale = robot.commands(1.5)[2:]  # the first may still answer the last odometry
    assert stale and all(t.linear.x == 0 and t.angular.z == 0 for t in stale)
    stop.set()
    thread.join(10)
    last = robot.commands(0.5)
    assert last and last[-1].linear.x == 0 and last[-1].angular.z == 0
    summary = json.loads((tmp_path / "serve_summary.json").read_text())
    assert summary["stale_events"] >= 6 and summary["command_events"] >= 5 and summary["shutdown_events"] == 1
    rows = list(csv.DictReader((tmp_path / "serve.csv").open()))
    assert {r["event"] for r in rows} >= {"stale", "command", "shutdown"}
    assert sum(r["event"] == "stale" for r in rows) == summary["stale_events"]


@pytest.mark.slow
def test_the_node_does_not_drive_blind_while_a_matched_obstacle_source_is_silent(
    husky_cbf, tmp_path: Path
) -> None:
    """An obstacle publisher is matched but has sent nothing (its first samples can come a
    heartbeat period late): fresh odometry gets zero commands and no plan, each a `blind` event;
    the first MarkerArray (an empty one counts) ends it and the controller drives."""
    sc, controller = husky_cbf
    settings = Ros2Settings(domain_id=_domain(), localhost_only=True)
    robot = _Robot(settings)
    markers = robot.dds.publish("obstacles", msg.MARKER_ARRAY)
    node, stop, thread = _start_node(controller, sc.reference_object(), sc.tau_s, settings, tmp_path)
    _wait_matched(robot, node)
    end = time.monotonic() + 20
    while not node._markers.publishers() and time.monotonic() < end:
        time.sleep(0.02)
    start = (sc.robot.start.x_m, sc.robot.start.y_m, sc.robot.start.yaw_rad)
    blind = robot.commands(1.0, odometry=start)
    assert len(blind) >= 3 and all(t.linear.x == 0 and t.angular.z == 0 for t in blind)
    assert robot.received(robot.plan) == [] and node.stats.events["blind"] >= 3
    assert node.stats.events["command"] == 0
    markers.write(msg.make(msg.MARKER_ARRAY))
    driven = robot.commands(1.5, odometry=start)
    stop.set()
    thread.join(10)
    assert any(t.linear.x > 0.1 for t in driven) and robot.received(robot.plan)
    rows = list(csv.DictReader((tmp_path / "serve.csv").open()))
    assert rows[0]["event"] in ("stale", "blind") and {"blind", "command"} <= {r["event"] for r in rows}
    first_command = next(i for i, r in enumerate(rows) if r["event"] == "command")
    assert all(r["event"] != "blind" for r in rows[first_command:])


@pytest.mark.slow
@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_solve_longer_than_tau_sends_zero_not_its_plan(husky_cbf, tmp_path: Path, transport: str) -> None:
    """With a solve budget shorter than any solve (1 us), every result is late: each is dropped,
    a zero command sent and no plan published."""
    sc, controller = husky_cbf
    settings = Ros2Settings(domain_id=_domain(), localhost_only=True)
    robot = _Robot(settings)
    node, stop, thread = _start_node(
        controller, sc.reference_object(), sc.tau_s, settings, tmp_path, 1e-6, transport
    )
    _wait_matched(robot, node)
    start = (sc.robot.start.x_m, sc.robot.start.y_m, sc.robot.start.yaw_rad)
    got = robot.commands(1.0, odometry=start)
    stop.set()
    thread.join(10)
    assert node.stats.events["overrun"] >= 3
    assert node.stats.events["command"] == 0
    assert got and all(t.linear.x == 0 and t.angular.z == 0 for t in got)
    assert robot.received(robot.plan) == []


@pytest.mark.slow
def test_serve_command_runs_and_stops_with_a_zero_command(tmp_path: Path, capsys) -> None:
    out = tmp_path / "node"
    args = ["serve", "husky_point_stabilisation", "--duration", "0.7", "--localhost-only"]
    assert main([*args, "--domain-id", str(_domain()), "--out", str(out)]) == 0
    summary = json.loads((out / "serve_summary.json").read_text())
    assert summary["shutdown_events"] == 1 and summary["stale_events"] >= 2  # nobody sent odometry
    assert summary["settings"]["cmd_vel_topic"] == "/cmd_vel" and summary["settings"]["localhost_only"]
    assert "node stopped after 0.7 s with a zero command" in capsys.readouterr().out


# -- rehearsal -------------------------------------------------------------------------------------
class _AsSeenOverRos2:
    """The same controller fed the pose, goal and time after ROS 2 message encoding (a pose's yaw
    travels as a quaternion, times as integer ns): what the node sees of an in-process state."""

    def __init__(self, inner) -> None:
        self.inner, self.config = inner, inner.config

    def reset(self) -> None:
        self.inner.reset()

    def solve(self, state, reference, obstacles, t):
        p = msg.pose(*state)
        seen = np.array([p.position.x, p.position.y, msg.quaternion_yaw(p.orientation)])
        g = msg.pose(reference.x_m, reference.y_m, reference.theta_rad)
        goal = SetPoint(g.position.x, g.position.y, msg.quaternion_yaw(g.orientation))
        return self.inner.solve(seen, goal, obstacles, msg.from_time(msg.to_time(t)))


#: log.csv columns the rehearsal robot measures itself (the rest are the controller's internals,
#: which only the node knows, or wall-clock times)
ROBOT_COLUMNS = (
    "step", "t_s", "x_m", "y_m", "yaw_rad", "ref_x_m", "ref_y_m", "v_cmd_mps", "omega_cmd_radps",
    "v_applied_mps", "omega_applied_radps", "v_body_mps", "omega_body_radps", "clearance_m",
)  # fmt: skip


def _mcap_messages(path: Path) -> tuple[dict[str, int], dict[str, list[bytes]]]:
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        counts = {c.topic: summary.statistics.channel_message_counts[i] for i, c in summary.channels.items()}
        f.seek(0)
        data: dict[str, list[bytes]] = {}
        for _schema, channel, message in make_reader(f).iter_messages():
            data.setdefault(channel.topic, []).append(message.data)
    return counts, data


@pytest.mark.slow
@pytest.mark.parametrize(("transport", "stamped"), [("cyclonedds", False), ("rclpy", True)])
def test_rehearsal_over_dds_reaches_the_in_process_outcome(
    tmp_path: Path, transport: str, stamped: bool
) -> None:
    """husky-cbf at N = 5 on husky_point_stabilisation (an obstacle beside the straight line, a
    goal 7 m away): the node in another process, every odometry, obstacle, goal, command and plan
    over DDS. The outcome is the in-process run's; and the robot's log equals, value for value,
    that of an in-process run whose controller sees the pose after the same message encoding,
    so the transport changes nothing but that rounding (about 1e-16 rad of yaw, which the closed
    loop amplifies: the plain in-process run differs from step 12 on). The same with the node on
    rclpy (Fast DDS) sending TwistStamped."""
    sc = load_scenario("husky_point_stabilisation").with_overrides(horizon=5)
    rehearsed = rehearse(
        sc, "husky-cbf", tmp_path / "rehearsal", _domain(), transport=transport, cmd_vel_stamped=stamped
    )
    direct = run_scenario(sc, "husky-cbf", out_dir=tmp_path / "direct").metrics
    transport = rehearsed["transport"]
    assert transport["node"]["overrun_events"] == 0, "machine too slow: a solve took longer than tau"
    assert rehearsed["outcome"] == direct.outcome == "reached"
    assert not rehearsed["collided"] and rehearsed["min_clearance_m"] > 0
    assert transport["reply_timeouts"] == 0 and transport["node_exit_code"] == 0
    assert transport["node"]["goals_received"] == 1 and transport["node"]["stale_events"] == 0
    assert transport["node"]["command_events"] == rehearsed["steps"]
    assert transport["cmd_vel_latency_ms"]["median"] > 0 and transport["odometry_latency_ms"]["median"] > 0
    assert rehearsed["guided_steps"] > 0  # the controller's own counts come from the node

    encoded = run_scenario(
        sc,
        "husky-cbf",
        out_dir=tmp_path / "encoded",
        implementation=_AsSeenOverRos2(sc.make_controller("husky-cbf")),
    ).metrics
    assert encoded.steps == rehearsed["steps"]
    over_dds = list(csv.DictReader((tmp_path / "rehearsal" / "log.csv").open()))
    in_process = list(csv.DictReader((tmp_path / "encoded" / "log.csv").open()))
    assert [[r[c] for c in ROBOT_COLUMNS] for r in over_dds] == [
        [r[c] for c in ROBOT_COLUMNS] for r in in_process
    ]
    plans = np.load(tmp_path / "rehearsal" / "trace.npz")["predicted_states"]
    assert plans.shape == (rehearsed["steps"], 6, 3) and np.isfinite(plans).all()  # every /plan arrived

    # run.mcap: the rehearsal's and the in-process run's show the same robot
    counts, data = _mcap_messages(tmp_path / "rehearsal" / MCAP_NAME)
    assert set(counts) == STEP_CHANNELS | {"/outcome"}
    assert all(counts[c] == rehearsed["steps"] for c in STEP_CHANNELS) and counts["/outcome"] == 1
    assert data["/tf"] == _mcap_messages(tmp_path / "encoded" / MCAP_NAME)[1]["/tf"]


# -- run.mcap --------------------------------------------------------------------------------------
@pytest.mark.slow
def test_run_mcap_has_foxglove_channels_and_one_message_per_step(tmp_path: Path) -> None:
    """A moving-obstacle run read back with the MCAP library: Foxglove schemas, one message per
    control step on each step channel, the obstacles as cylinders, the plan, the outcome; and the
    same run again gives the same messages (solve times aside)."""
    from mcap_protobuf.decoder import DecoderFactory

    summaries = [
        run_scenario("head_on_moving_obstacle", "husky-cbf", horizon=5, out_dir=tmp_path / name).metrics
        for name in "ab"
    ]
    steps = summaries[0].steps
    path = tmp_path / "a" / MCAP_NAME
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas == {
        "/tf": "foxglove.FrameTransform",
        "/robot/pose": "foxglove.PoseInFrame",
        "/scene": "foxglove.SceneUpdate",
        "/control": "husky_sim.Control",
        "/safety": "husky_sim.Safety",
        "/outcome": "foxglove.Log",
    }
    counts, data = _mcap_messages(path)
    assert all(counts[c] == steps for c in STEP_CHANNELS)
    assert summaries[0].outcome.encode() in data["/outcome"][0]
    with path.open("rb") as f:  # decoded with the schema the file carries, as Foxglove does
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        scenes = [m for _s, _c, _m, m in reader.iter_decoded_messages(topics=["/scene"])]
    entities = {e.id: e for e in scenes[steps // 2].entities}
    sc = load_scenario("head_on_moving_obstacle")
    assert len(entities["obstacles"].cylinders) == len(sc.obstacle_specs())
    assert len(entities["robot"].cubes) == 1 and len(entities["plan"].lines[0].points) == 6
    safety = [json.loads(d) for d in data["/safety"]]
    log = list(csv.DictReader((tmp_path / "a" / "log.csv").open()))
    assert [s["clearance_m"] for s in safety] == pytest.approx([float(r["clearance_m"]) for r in log])
    _, again = _mcap_messages(tmp_path / "b" / MCAP_NAME)
    for channel in STEP_CHANNELS - {"/safety"}:
        assert again[channel] == data[channel], channel
    strip = [{k: v for k, v in json.loads(d).items() if k != "solve_ms"} for d in again["/safety"]]
    assert strip == [{k: v for k, v in s.items() if k != "solve_ms"} for s in safety]


def test_live_server_advertises_the_run_channels(tmp_path: Path) -> None:
    """--live: Foxglove's WebSocket server accepts a client and advertises the recording's channels."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    recorder = FoxgloveRecorder(
        tmp_path / MCAP_NAME, SetPoint(1.0, 1.0, 0.0), [0.5], [1.0], (0.494, 0.343), 0.1, 5.0, live_port=port
    )
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as client:
            key = base64.b64encode(os.urandom(16)).decode()
            client.sendall(
                (
                    f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                    "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                    f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                    "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
                ).encode()
            )
            received = b""
            end = time.monotonic() + 5
            while b'"/safety"' not in received and time.monotonic() < end:
                received += client.recv(65536)
    finally:
        recorder.close("reached")
    assert received.startswith(b"HTTP/1.1 101")
    for channel in STEP_CHANNELS | {"/outcome"}:
        assert f'"{channel}"'.encode() in received


def test_live_on_a_port_in_use_is_a_one_line_error(tmp_path: Path, capsys) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code = main(["run", "husky_point_stabilisation", "--live", str(port), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert f"--live: cannot serve Foxglove on 127.0.0.1:{port}" in err
    assert not (tmp_path / "run" / MCAP_NAME).exists()
