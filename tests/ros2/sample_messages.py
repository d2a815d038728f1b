"""One message of each type the node and its robot exchange, with values in every field group:
what the wire-format tests send (tests/ros2/test_ros2.py against rosbags, test_rclpy.py against
rclpy)."""

from __future__ import annotations

from controllers import Obstacle
from husky_sim.ros2 import messages as msg
from husky_sim.ros2.node import obstacles_to_markers


def sample_messages() -> dict[str, object]:
    """ROS 2 type name -> a message of it (our Cyclone DDS types, Humble's definitions)."""
    odom = msg.make(msg.ODOMETRY, header=msg.header(12.5, "odom"), child_frame_id="base_link")
    odom.pose.pose = msg.pose(1.0, -2.0, 0.7)
    odom.pose.covariance[0] = odom.twist.covariance[35] = 0.01
    odom.twist.twist.linear.x = 0.4
    twist = msg.make(msg.TWIST)
    twist.linear.x, twist.angular.z = 0.5, -0.25
    poses = [
        msg.make(msg.POSE_STAMPED, header=msg.header(3.0 + 0.1 * k, "odom"), pose=msg.pose(k, 0, 0.1 * k))
        for k in range(3)
    ]
    return {
        msg.ODOMETRY: odom,
        msg.TWIST: twist,
        msg.TWIST_STAMPED: msg.make(msg.TWIST_STAMPED, header=msg.header(4.0, "base_link"), twist=twist),
        msg.PATH: msg.make(msg.PATH, header=msg.header(3.0, "odom"), poses=poses),
        msg.POSE_STAMPED: msg.make(msg.POSE_STAMPED, header=msg.header(1.0, "map"), pose=msg.pose(3, 4, -1)),
        msg.MARKER_ARRAY: obstacles_to_markers(
            [Obstacle(2.0, 1.0, 0.45), Obstacle(-1.0, 0.5, 0.3)], 2.0, "odom"
        ),
        msg.CLOCK: msg.make(msg.CLOCK, clock=msg.to_time(7.25)),
    }
