"""The rclpy transport: the node as an rclpy node, on whatever middleware ROS 2 is configured for.

This is what a team starts on the Husky's computer where ROS 2 is installed: the node appears in
the ROS graph as any rclpy node does, uses RMW_IMPLEMENTATION's middleware (Fast DDS by
default), and takes its settings as ROS parameters: every topic, QoS profile and frame of
Ros2Settings, `cmd_vel_stamped` and ROS 2's own `use_sim_time`, each defaulting to what the command
line gave, overridden by `--ros-args -p name:=value` or a parameter file. Messages are rclpy's
own classes (the installed distribution's definitions).

ROS 2's signal handlers are not installed: husky_sim.interrupts handles SIGINT and SIGTERM, so
the node still sends its zero command before it stops.
"""

from __future__ import annotations

import importlib
import os
from collections import deque
from collections.abc import Sequence
from dataclasses import fields, replace
from typing import Any

from husky_sim.extras import MissingExtra
from husky_sim.ros2.messages import MessageKit
from husky_sim.ros2.settings import QOS_PROFILE_NAMES, Ros2Settings
from husky_sim.ros2.transport import Received, TopicsBySetting

#: Ros2Settings that are ROS parameters of the node (the others are needed before it exists).
PARAMETERS = tuple(
    f.name for f in fields(Ros2Settings) if f.name.endswith(("_topic", "_qos", "_frame")) or f.name in (
        "use_sim_time", "cmd_vel_stamped",
    )
)  # fmt: skip
#: Messages kept per subscription between two reads (a node reads every few ms).
_QUEUE = 256


def installed_distro() -> str:
    """The ROS 2 distribution rclpy's messages here are from, as far as the wire tells them apart:
    ROS_DISTRO where ROS 2 is sourced, else by the graph's gid (24 bytes: Humble; 16: later)."""
    from husky_sim.ros2.settings import ROS_DISTRO_NAMES

    named = os.environ.get("ROS_DISTRO", "")
    if named in ROS_DISTRO_NAMES:
        return named
    return "humble" if len(message_class("rmw_dds_common/msg/Gid")().data) == 24 else "kilted"


def message_class(ros_type: str) -> type:
    """rclpy's class of a ROS 2 message type: `nav_msgs/msg/Odometry` -> nav_msgs.msg.Odometry."""
    package, kind, name = ros_type.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), name)
    except (ImportError, AttributeError):
        raise ValueError(f"message type: {ros_type!r} is not installed for rclpy") from None


def qos_profile(name: str) -> Any:
    """rclpy's QoS of one of QOS_PROFILE_NAMES (the same profiles as the Cyclone transport's)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

    profiles = {
        "sensor_data": qos_profile_sensor_data,
        "default": QoSProfile(depth=10),
        "clock": QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
    }
    assert set(profiles) == set(QOS_PROFILE_NAMES)
    return profiles[name]


class _Subscription:
    def __init__(self, transport: RclpyTransport, topic: str, ros_type: str, qos: Any) -> None:
        self._queue: deque[Received] = deque(maxlen=_QUEUE)
        self._transport = transport
        self.handle = transport.node.create_subscription(message_class(ros_type), topic, self._on, qos)

    def _on(self, message: Any, info: dict) -> None:
        self._queue.append(Received(message, int(info["source_timestamp"])))
        self._transport.arrivals += 1

    def take(self) -> list[Received]:
        out = list(self._queue)
        self._queue.clear()
        return out

    def publishers(self) -> int:
        return self.handle.get_publisher_count()


class _Publisher:
    def __init__(self, handle: Any) -> None:
        self.handle = handle

    def write(self, message: Any) -> None:
        self.handle.publish(message)

    def subscribers(self) -> int:
        return self.handle.get_subscription_count()

    def wait_for_acks(self, timeout_s: float) -> bool:
        from rclpy.duration import Duration

        return bool(self.handle.wait_for_all_acked(Duration(nanoseconds=round(timeout_s * 1e9))))


class RclpyTransport(TopicsBySetting):
    """An rclpy node in a context of its own (several can live in one process)."""

    def __init__(self, settings: Ros2Settings, ros_args: Sequence[str] = ()) -> None:
        try:
            import rclpy
            from rclpy.context import Context
            from rclpy.executors import SingleThreadedExecutor
            from rclpy.node import Node
            from rclpy.parameter import Parameter
            from rclpy.signals import SignalHandlerOptions
        except ImportError as exc:
            raise MissingExtra(
                f"--transport rclpy: ROS 2's rclpy is not importable here ({exc}); source a ROS 2 "
                "install, or pip install 'husky-nav-sim[rclpy]'"
            ) from None
        if settings.localhost_only:  # ROS 2's own switch (Jazzy on): discovery on this machine only
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self._context = Context()
        try:
            rclpy.init(
                args=["husky-sim", "--ros-args", *ros_args] if ros_args else None,
                context=self._context,
                domain_id=settings.resolved_domain_id(),
                signal_handler_options=SignalHandlerOptions.NO,
            )
        except Exception as exc:  # rcl's argument parser: a malformed rule or an unknown argument
            first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ValueError(f"--ros-args: {first.split(', at /')[0][:160]}") from None
        try:
            overrides = [Parameter("use_sim_time", value=True)] if settings.use_sim_time else []
            self.node = Node(settings.node_name, context=self._context, parameter_overrides=overrides)
            values = {}
            for name in PARAMETERS:
                try:
                    if name == "use_sim_time":  # rclpy declares it
                        values[name] = self.node.get_parameter(name).value
                    else:
                        values[name] = self.node.declare_parameter(name, getattr(settings, name)).value
                except Exception as exc:  # rclpy's parameter exceptions: a wrong type from --ros-args
                    first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                    raise ValueError(f"{name} (ROS parameter): {first[:160]}") from None
            self.settings = replace(
                settings, node_name=self.node.get_name(), ros_distro=installed_distro(), **values
            )
        except Exception:
            self._context.try_shutdown()
            raise
        self.messages = MessageKit(message_class)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self.arrivals = 0

    def subscribe_topic(self, ros_topic: str, ros_type: str, qos: str) -> _Subscription:
        return _Subscription(self, ros_topic, ros_type, qos_profile(qos))

    def publish_topic(self, ros_topic: str, ros_type: str, qos: str) -> _Publisher:
        return _Publisher(self.node.create_publisher(message_class(ros_type), ros_topic, qos_profile(qos)))

    def wait(self, timeout_s: float) -> None:
        """Run callbacks: wait up to timeout_s for the first, then take all that are ready."""
        before = self.arrivals
        self._executor.spin_once(timeout_sec=timeout_s)
        while self.arrivals != before:  # spin_once runs at most one callback
            before = self.arrivals
            self._executor.spin_once(timeout_sec=0.0)

    def close(self) -> None:
        self._executor.shutdown()
        self.node.destroy_node()
        self._context.try_shutdown()
