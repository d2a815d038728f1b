"""How late the first samples after discovery are, from an rclpy robot on Fast DDS to our Cyclone DDS
node, when the node joins a robot that is already publishing (the usual order on a robot).

    python tests/ros2/first_samples.py [--runs 5] [--fastdds-profile FILE]

Each run: an rclpy process publishes obstacles (visualization_msgs/MarkerArray, reliable, 10 Hz)
and odometry (nav_msgs/Odometry, best effort, 50 Hz) on a leased domain, loopback only; 3 s later a
Cyclone DDS transport (ours) subscribes to both and records each sample's latency (reception
minus source timestamp). Prints the median, p99 and max of the first 20 samples of each topic, pooled
over the runs. `--fastdds-profile` hands the robot a Fast DDS XML profile (for instance one with
a shorter writer heartbeat period) through FASTDDS_DEFAULT_PROFILES_FILE.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import numpy as np

FIRST = 20
TOPICS = {  # name: (ROS type, QoS profile, period s)
    "/obstacles": ("visualization_msgs/msg/MarkerArray", "default", 0.1),
    "/odometry/filtered": ("nav_msgs/msg/Odometry", "sensor_data", 0.02),
}


def publish(domain: int, duration_s: float) -> None:
    """The robot: rclpy on Fast DDS, publishing every topic at its period."""
    from husky_sim.ros2.rclpy_transport import RclpyTransport
    from husky_sim.ros2.settings import Ros2Settings

    ros = RclpyTransport(Ros2Settings(domain_id=domain, localhost_only=True, node_name="robot"))
    publishers = {t: ros.publish_topic(t, ros_type, qos) for t, (ros_type, qos, _p) in TOPICS.items()}
    classes = {t: ros.messages.make(ros_type) for t, (ros_type, _q, _p) in TOPICS.items()}
    start = time.monotonic()
    due = dict.fromkeys(TOPICS, start)
    while time.monotonic() - start < duration_s:
        now = time.monotonic()
        for topic, (_t, _q, period_s) in TOPICS.items():
            if now >= due[topic]:
                publishers[topic].write(classes[topic])
                due[topic] += period_s
        time.sleep(0.002)
    ros.close()


def measure(domain: int, profile: str | None) -> dict[str, list[float]]:
    """One run: the robot first, our node 3 s later; latencies (ms) of each topic's first samples."""
    from husky_sim.ros2.cyclone_transport import CycloneTransport
    from husky_sim.ros2.settings import Ros2Settings

    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    if profile:
        env["FASTDDS_DEFAULT_PROFILES_FILE"] = profile
    robot = subprocess.Popen([sys.executable, __file__, "--publisher", str(domain)], env=env)
    try:
        time.sleep(3.0)
        node = CycloneTransport(Ros2Settings(domain_id=domain, localhost_only=True, node_name="node"))
        readers = {t: node.subscribe_topic(t, ros_type, qos) for t, (ros_type, qos, _p) in TOPICS.items()}
        latency: dict[str, list[float]] = {t: [] for t in TOPICS}
        end = time.monotonic() + 8.0
        while time.monotonic() < end and any(len(v) < FIRST for v in latency.values()):
            node.wait(0.005)
            for topic, reader in readers.items():
                latency[topic] += [(time.time_ns() - r.sent_ns) / 1e6 for r in reader.take()]
    finally:
        robot.kill()
        robot.wait()
    return {t: v[:FIRST] for t, v in latency.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--fastdds-profile", default=None, help="a Fast DDS XML profile for the robot")
    p.add_argument("--publisher", type=int, default=None, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.publisher is not None:
        publish(a.publisher, 15.0)
        return
    from husky_sim.ros2.settings import lease_domain_id

    pooled: dict[str, list[float]] = {t: [] for t in TOPICS}
    for _ in range(a.runs):
        for topic, values in measure(lease_domain_id(200, 232), a.fastdds_profile).items():
            pooled[topic] += values
    profile = a.fastdds_profile or "default"
    print(f"first {FIRST} samples after discovery, {a.runs} runs, robot profile: {profile}")
    for topic, values in pooled.items():
        v = np.asarray(values)
        print(
            f"  {topic:20s} {TOPICS[topic][1]:12s} n={len(v):3d}  median {np.median(v):7.1f} ms  "
            f"p99 {np.percentile(v, 99):7.1f} ms  max {v.max():7.1f} ms"
        )


if __name__ == "__main__":
    main()
