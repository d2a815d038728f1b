"""A robot played by a real rclpy node (ROS 2's Python client library on its default middleware,
Fast DDS), run as its own process by tests/ros2/test_rclpy.py.

A unicycle integrated at 50 Hz from the latest /cmd_vel (Twist or TwistStamped), publishing
nav_msgs/Odometry on /odometry/filtered, a geometry_msgs/PoseStamped goal on /goal_pose (once a
second) and the obstacles as a visualization_msgs/MarkerArray of cylinders on /obstacles (10 Hz);
subscribed to /cmd_vel and /plan. It can go silent (no odometry) for a while, to see the node's
stale-odometry stop. It writes what it saw, as the robot saw it, to a JSON file.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import rclpy
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Twist, TwistStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray


def _stamp(t: float):
    from builtin_interfaces.msg import Time

    sec, nsec = divmod(round(t * 1e9), 1_000_000_000)
    return Time(sec=int(sec), nanosec=int(nsec))


def _pose(x: float, y: float, yaw: float) -> Pose:
    return Pose(
        position=Point(x=float(x), y=float(y), z=0.0),
        orientation=Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
    )


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, required=True)
    p.add_argument("--duration", type=float, required=True)
    p.add_argument("--start", type=float, nargs=3, default=(0.0, 0.0, 0.0))
    p.add_argument("--goal", type=float, nargs=3, required=True)
    p.add_argument("--obstacle", type=float, nargs=3, action="append", default=[])
    p.add_argument("--robot-radius", type=float, default=0.0)
    p.add_argument("--odometry-qos", choices=("sensor_data", "default"), default="sensor_data")
    p.add_argument("--stamped", action="store_true")
    p.add_argument("--silent-from", type=float, default=math.inf, help="s: stop sending odometry then")
    p.add_argument("--silent-for", type=float, default=0.0)
    p.add_argument("--graph-at", type=float, default=6.0, help="s: when to ask rclpy for the graph")
    p.add_argument("--wait-for-node", type=float, default=60.0, help="s to wait for /cmd_vel's publisher")
    p.add_argument("--out", required=True)
    a = p.parse_args()

    rclpy.init(domain_id=a.domain, signal_handler_options=SignalHandlerOptions.NO)
    node = Node("husky_robot")
    odom_qos = qos_profile_sensor_data if a.odometry_qos == "sensor_data" else QoSProfile(depth=10)
    odom_pub = node.create_publisher(Odometry, "/odometry/filtered", odom_qos)
    goal_pub = node.create_publisher(PoseStamped, "/goal_pose", 10)
    markers_pub = node.create_publisher(MarkerArray, "/obstacles", 10)
    x, y, yaw = a.start
    command = [0.0, 0.0]
    seen: dict[str, list] = {"commands": [], "plans": []}

    def on_cmd(message, info) -> None:
        twist = message.twist if a.stamped else message
        command[:] = [twist.linear.x, twist.angular.z]
        seen["commands"].append(
            {
                "t": time.time(),
                "v": twist.linear.x,
                "omega": twist.angular.z,
                "latency_ms": (time.time_ns() - info["source_timestamp"]) / 1e6,
                "stamp": (message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec)
                if a.stamped
                else None,
                "frame": message.header.frame_id if a.stamped else None,
            }
        )

    def on_plan(message, info) -> None:
        seen["plans"].append(
            {
                "t": time.time(),
                "poses": len(message.poses),
                "frame": message.header.frame_id,
                "latency_ms": (time.time_ns() - info["source_timestamp"]) / 1e6,
            }
        )

    node.create_subscription(TwistStamped if a.stamped else Twist, "/cmd_vel", on_cmd, 10)
    node.create_subscription(Path, "/plan", on_plan, 10)
    end_wait = time.monotonic() + a.wait_for_node
    while node.count_publishers("/cmd_vel") == 0 and time.monotonic() < end_wait:
        rclpy.spin_once(node, timeout_sec=0.02)
    seen["commands"].clear()  # from here on the robot drives

    t0 = last = time.time()
    next_goal = next_markers = t0
    trajectory, min_clearance, reached_at = [], math.inf, None
    graph: dict[str, object] = {}
    while time.time() - t0 < a.duration:
        now = time.time()
        dt, last = now - last, now
        x += command[0] * math.cos(yaw) * dt
        y += command[0] * math.sin(yaw) * dt
        yaw = math.atan2(math.sin(yaw + command[1] * dt), math.cos(yaw + command[1] * dt))
        for ox, oy, r in a.obstacle:
            min_clearance = min(min_clearance, math.hypot(x - ox, y - oy) - r - a.robot_radius)
        distance = math.hypot(x - a.goal[0], y - a.goal[1])
        if reached_at is None and distance < 0.1:
            reached_at = now - t0
        trajectory.append((now - t0, x, y, yaw))
        if not a.silent_from <= now - t0 < a.silent_from + a.silent_for:
            odom = Odometry(header=Header(stamp=_stamp(now), frame_id="odom"), child_frame_id="base_link")
            odom.pose.pose = _pose(x, y, yaw)
            odom.twist.twist.linear.x, odom.twist.twist.angular.z = command
            odom_pub.publish(odom)
        if now >= next_goal:
            next_goal = now + 1.0
            goal_pub.publish(
                PoseStamped(header=Header(stamp=_stamp(now), frame_id="odom"), pose=_pose(*a.goal))
            )
        if now >= next_markers:
            next_markers = now + 0.1
            markers = []
            for i, (ox, oy, r) in enumerate(a.obstacle):
                m = Marker(header=Header(stamp=_stamp(now), frame_id="odom"), ns="obstacles", id=i)
                m.type, m.action, m.pose = Marker.CYLINDER, Marker.ADD, _pose(ox, oy, 0.0)
                m.scale.x = m.scale.y = 2.0 * r
                m.scale.z = 1.0
                markers.append(m)
            markers_pub.publish(MarkerArray(markers=markers))
        if not graph and now - t0 >= a.graph_at:
            graph = _graph(node)
        deadline = now + 0.02
        while time.time() < deadline:
            rclpy.spin_once(node, timeout_sec=max(0.0, deadline - time.time()))
    result = {
        **seen,
        "t0": t0,
        "final": [x, y, yaw],
        "reached_at_s": reached_at,
        "min_clearance_m": min_clearance,
        "graph": graph,
        "trajectory": trajectory[:: max(1, len(trajectory) // 200)],
    }
    node.destroy_node()
    rclpy.try_shutdown()
    with open(a.out, "w") as f:
        json.dump(result, f)


def _graph(node: Node) -> dict[str, object]:
    """What rclpy's graph queries say of the other nodes: names, and each one's topics."""
    out = {}
    for name, namespace in node.get_node_names_and_namespaces():
        if name == node.get_name():
            continue
        out[f"{namespace.rstrip('/')}/{name}"] = {
            "publishers": sorted(
                (t, ts[0]) for t, ts in node.get_publisher_names_and_types_by_node(name, namespace)
            ),
            "subscriptions": sorted(
                (t, ts[0]) for t, ts in node.get_subscriber_names_and_types_by_node(name, namespace)
            ),
        }
    return out


if __name__ == "__main__":
    main()
