"""What the node and the rehearsal robot need of a ROS 2 transport, and how to open one.

Two transports implement it: `cyclonedds` (husky_sim.ros2.cyclone_transport: Cyclone DDS from
Python, no ROS install) and `rclpy` (husky_sim.ros2.rclpy_transport: ROS 2's Python client
library, on whatever middleware the machine is configured for). A topic is named by its setting's
stem (`"odometry"` -> `settings.odometry_topic`, QoS `settings.odometry_qos`), so both ends of a
topic always take its name and QoS profile from the same place.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from husky_sim.ros2.messages import MessageKit
from husky_sim.ros2.settings import TRANSPORTS, Ros2Settings


@dataclass(frozen=True)
class Received:
    """A message as it arrived, with its source timestamp (ns since the epoch, the sender's clock)."""

    message: Any
    sent_ns: int


class Subscription(Protocol):
    def take(self) -> list[Received]:
        """Every message waiting, oldest first."""

    def publishers(self) -> int:
        """How many publishers are matched (DDS discovery)."""


class Publisher(Protocol):
    def write(self, message: Any) -> None: ...

    def subscribers(self) -> int:
        """How many subscriptions are matched (DDS discovery)."""

    def wait_for_acks(self, timeout_s: float) -> bool:
        """Block until reliable subscribers have acknowledged every message (or timeout_s)."""


class Transport(Protocol):
    settings: Ros2Settings  # as the transport resolved them (rclpy: from ROS parameters)
    messages: MessageKit  # builds this transport's messages

    def subscribe(self, topic: str, ros_type: str) -> Subscription:
        """A subscription to the topic of setting `{topic}_topic`, with QoS `{topic}_qos`."""

    def publish(self, topic: str, ros_type: str) -> Publisher:
        """A publisher on the topic of setting `{topic}_topic`, with QoS `{topic}_qos`."""

    def subscribe_topic(self, ros_topic: str, ros_type: str, qos: str) -> Subscription:
        """A subscription to any topic, with one of QOS_PROFILE_NAMES."""

    def publish_topic(self, ros_topic: str, ros_type: str, qos: str) -> Publisher:
        """A publisher on any topic, with one of QOS_PROFILE_NAMES."""

    def wait(self, timeout_s: float) -> None:
        """Block until a message arrives on a subscription, or timeout_s (s) has passed."""

    def close(self) -> None: ...


class TopicsBySetting:
    """`subscribe` and `publish` by a setting's stem, for a transport with `settings`,
    `subscribe_topic` and `publish_topic`."""

    settings: Ros2Settings

    def subscribe(self, topic: str, ros_type: str) -> Subscription:
        s = self.settings
        return self.subscribe_topic(getattr(s, f"{topic}_topic"), ros_type, getattr(s, f"{topic}_qos"))

    def publish(self, topic: str, ros_type: str) -> Publisher:
        s = self.settings
        return self.publish_topic(getattr(s, f"{topic}_topic"), ros_type, getattr(s, f"{topic}_qos"))


def latest(received: Sequence[Received]) -> Received | None:
    """The newest of some received messages, or None."""
    return received[-1] if received else None


def open_transport(
    settings: Ros2Settings, kind: str = "cyclonedds", ros_args: Sequence[str] = ()
) -> Transport:
    """A transport of `kind` (settings.TRANSPORTS); `ros_args` (rclpy only) are ROS 2's command-line
    arguments (`-p name:=value` sets a parameter, `-r __node:=name` renames the node)."""
    if kind == "cyclonedds":
        if ros_args:
            raise ValueError("--ros-args: only the rclpy transport takes ROS arguments")
        from husky_sim.ros2.cyclone_transport import CycloneTransport

        return CycloneTransport(settings)
    if kind == "rclpy":
        from husky_sim.ros2.rclpy_transport import RclpyTransport

        return RclpyTransport(settings, ros_args)
    raise ValueError(f"transport: expected one of {', '.join(TRANSPORTS)}, got {kind[:40]!r}")
