"""The simulated Husky as a DDS "robot": the controller side of the episode loop, over DDS.

`DdsRobot` stands where a controller stands in `husky_sim.sim.episode.run_episode` (it implements
controllers.Controller), so the rehearsal runs the very loop, sensing, drive, collision checks
and judging of `husky-sim run`. At each control step it publishes the sensed obstacles (MarkerArray),
the sensed pose (Odometry, stamped with sim time) and /clock, in that order, then waits for the node's
next /cmd_vel (and takes the /plan stamped with this step). Sim time stands still while it waits,
so the loop is in lock-step with the node whatever the transport's latency, which is measured
(publication to reception, on this machine's clock) and reported.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import numpy as np

from controllers import ControlResult, Obstacle, Reference, SetPoint
from controllers.model import wrap_angle
from husky_sim import interrupts
from husky_sim.ros2 import messages as msg
from husky_sim.ros2.node import obstacles_to_markers
from husky_sim.ros2.settings import Ros2Settings
from husky_sim.ros2.transport import latest, open_transport

#: The rehearsal robot's name in the ROS graph.
ROBOT_NODE_NAME = "husky_sim_robot"


class NodeNotFound(ConnectionError):
    """The node did not appear on the DDS domain in time (an OSError: the command line reports
    it in one line, exit 1)."""


class DdsRobot:
    """controllers.Controller whose decisions come from a `husky-sim serve` node over DDS."""

    def __init__(
        self, settings: Ros2Settings, tau_s: float, horizon: int, reply_timeout_s: float = 10.0
    ) -> None:
        self.settings, self.tau_s, self.horizon, self.reply_timeout_s = (
            settings,
            tau_s,
            horizon,
            reply_timeout_s,
        )
        self._dds = t = open_transport(dataclasses.replace(settings, node_name=ROBOT_NODE_NAME))
        self.kit = t.messages
        self._odom = t.publish("odometry", msg.ODOMETRY)
        self._markers = t.publish("obstacles", msg.MARKER_ARRAY)
        self._clock = t.publish("clock", msg.CLOCK)
        self._goal = t.publish("goal", msg.POSE_STAMPED)
        self._cmd = t.subscribe("cmd_vel", msg.TWIST_STAMPED if settings.cmd_vel_stamped else msg.TWIST)
        self._plan = t.subscribe("plan", msg.PATH)
        self.cmd_latency_ms: list[float] = []
        self.reply_timeouts = 0
        self._previous: tuple[float, np.ndarray] | None = None
        self._goal_sent = False

    def wait_for_node(self, timeout_s: float) -> None:
        """Block until the node's readers and writers are matched with ours (DDS discovery)."""
        end = time.monotonic() + timeout_s
        entities = (self._odom, self._markers, self._goal, self._clock)
        while time.monotonic() < end:
            interrupts.check()
            writers_matched = all(w.subscribers() for w in entities)
            if writers_matched and all(r.publishers() for r in (self._cmd, self._plan)):
                return
            time.sleep(0.02)
        raise NodeNotFound(
            f"no husky-sim serve node answered on DDS domain {self.settings.resolved_domain_id()} "
            f"within {timeout_s:g} s"
        )

    def reset(self) -> None:
        self._previous = None
        self._goal_sent = False

    def solve(
        self, state: np.ndarray, reference: Reference, obstacles: Sequence[Obstacle], t: float
    ) -> ControlResult:
        start = time.perf_counter()
        frame, kit = self.settings.odom_frame, self.kit
        if isinstance(reference, SetPoint) and not self._goal_sent:  # as RViz's "2D Goal Pose" does
            goal = kit.make(
                msg.POSE_STAMPED,
                header=kit.header(t, frame),
                pose=kit.pose(reference.x_m, reference.y_m, reference.theta_rad),
            )
            self._goal.write(goal)
            self._goal.wait_for_acks(1.0)
            self._goal_sent = True
        self._cmd.take()  # nothing from before this step may pass for its answer
        # obstacles first, and acknowledged, so the node never plans step k with step k-1's
        # obstacles; the clock last, so the node never sees time t before the odometry stamped t
        self._markers.write(obstacles_to_markers(obstacles, t, frame, kit=kit))
        self._markers.wait_for_acks(self.reply_timeout_s)
        self._odom.write(self._odometry(state, t))
        self._clock.write(kit.make(msg.CLOCK, clock=kit.to_time(t)))
        twist = self._await_command()
        path = latest(self._plan.take())
        path = None if path is None else path.message
        plan = np.full((self.horizon + 1, 3), np.nan)
        plan_start_s = 0.0
        if path is not None and abs(msg.from_time(path.header.stamp) - t) < 1e-6:
            poses = [
                (p.pose.position.x, p.pose.position.y, msg.quaternion_yaw(p.pose.orientation))
                for p in path.poses
            ]
            plan[: min(len(poses), self.horizon + 1)] = poses[: self.horizon + 1]
            if path.poses:  # the first pose's stamp says when the plan starts (after a dead time)
                plan_start_s = msg.from_time(path.poses[0].header.stamp) - t
        replied = twist is not None
        control = np.array([twist.linear.x, twist.angular.z]) if replied else np.zeros(2)
        return ControlResult(
            control=control,
            predicted_states=plan,
            predicted_controls=np.zeros((self.horizon, 2)),
            clf_slack=np.zeros(self.horizon),
            decay_slack=np.ones(self.horizon),
            predicted_barrier=np.zeros((0, self.horizon + 1)),
            safety_active=0,
            status="dds" if replied else f"no /cmd_vel within {self.reply_timeout_s:g} s",
            success=replied,
            fallback="none" if replied else "brake",
            iterations=-1,
            solve_time_s=time.perf_counter() - start,
            obstacles_considered=len(obstacles),
            obstacles_ignored=0,
            plan_start_s=plan_start_s,
        )

    def _odometry(self, state: np.ndarray, t: float) -> object:
        """Odometry of the sensed pose; its twist is the body velocity between this pose and the
        previous one (what a state estimator would give without wheel data)."""
        kit = self.kit
        odom = kit.make(
            msg.ODOMETRY,
            header=kit.header(t, self.settings.odom_frame),
            child_frame_id=self.settings.base_frame,
            pose=kit.make("geometry_msgs/msg/PoseWithCovariance", pose=kit.pose(*state)),
        )
        if self._previous is not None and t > self._previous[0]:
            dt = t - self._previous[0]
            delta = state[:2] - self._previous[1][:2]
            odom.twist.twist.linear.x = float(np.dot(delta, [math.cos(state[2]), math.sin(state[2])]) / dt)
            odom.twist.twist.angular.z = float(wrap_angle(state[2] - self._previous[1][2]) / dt)
        self._previous = (t, np.array(state, dtype=float))
        return odom

    def _await_command(self) -> object | None:
        """The node's next command (its Twist, also when it sends TwistStamped), or None."""
        end = time.monotonic() + self.reply_timeout_s
        while time.monotonic() < end:
            interrupts.check()
            command = latest(self._cmd.take())
            if command is not None:
                self.cmd_latency_ms.append((time.time_ns() - command.sent_ns) / 1e6)
                return command.message.twist if self.settings.cmd_vel_stamped else command.message
            self._dds.wait(0.02)
        self.reply_timeouts += 1
        return None
