"""`husky-sim serve`: one of our controllers as a ROS 2 node, on either transport
(husky_sim.ros2.transport: Cyclone DDS without a ROS install, or rclpy where ROS 2 is installed).

In: odometry (nav_msgs/Odometry, sensor-data QoS), a goal (geometry_msgs/PoseStamped on
/goal_pose; until one arrives the scenario's reference is tracked), obstacles
(visualization_msgs/MarkerArray of cylinders: centre, diameter = scale.x; velocities estimated
from successive markers of the same id) and, with use_sim_time, /clock. Goals and markers must
be in the odom frame (or have no frame): there is no tf here, so others are refused and counted.
Out: geometry_msgs/Twist (or TwistStamped with cmd_vel_stamped, stamped with the odometry it
answers) on /cmd_vel once per tau and the plan as nav_msgs/Path.

A control step runs on the first odometry sample at least tau (of odometry stamps) after the
previous step's. Safety, each event counted and logged as a row of `serve.csv`:
- `stale`: no odometry newer than 2 tau on the node's clock -> zero command, once per tau;
- `blind`: an obstacle publisher is matched and no MarkerArray has arrived yet -> zero
  command instead of a plan that ignores obstacles the robot reports (a reliable writer's first
  samples can reach a newly joined reader a heartbeat period late);
- `brake`: the controller fell back to braking (or raised: also counted as `error`) -> zero
  command;
- `overrun`: the solve took longer than tau (or a smaller budget; wall time: what the robot's
  computer takes) -> its result is dropped and a zero command sent, never the plan of an older
  step;
- `shutdown`: a zero command as the node stops (Ctrl-C, SIGTERM, end of --duration).
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from controllers import Controller, ControlResult, Obstacle, Reference, SetPoint
from husky_sim import interrupts
from husky_sim.ros2 import messages as msg
from husky_sim.ros2.settings import ROS_DISTRO_NAMES, Ros2Settings
from husky_sim.ros2.transport import latest, open_transport

#: How the node names the graph layout it is announced in (Humble's gids are 24 bytes, later ones' 16).
LAYOUT_NAMES = {
    name: "Humble's (24-byte gids)" if name == "humble" else "Iron's and later (16-byte gids)"
    for name in ROS_DISTRO_NAMES
}

#: Odometry older than this many control periods (on the node's clock) stops the robot.
STALE_ODOMETRY_PERIODS = 2.0

SERVE_LOG_COLUMNS = (
    "tick",
    "clock_s",
    "odom_stamp_s",
    "odom_age_s",
    "t_ref_s",
    "x_m",
    "y_m",
    "yaw_rad",
    "obstacles",
    "v_cmd_mps",
    "omega_cmd_radps",
    "event",
    "status",
    "fallback",
    "solver_fallback",
    "repeated",
    "recovered_by",
    "soft_constraint",
    "guided",
    "mode",
    "escape",
    "safety_active",
    "solve_ms",
    "odom_latency_ms",
)
EVENTS = ("command", "stale", "blind", "brake", "overrun", "shutdown")  # one per serve.csv row
#: Counted apart (the same step is also a `brake` row): the controller raised instead of returning.
ERROR = "error"
#: The controller's own counts, under the names of a run's summary (husky_sim.sim.metrics): only the
#: node knows them, so a rehearsal's summary takes them from the node's.
CONTROLLER_COUNTS = (
    "fallbacks",
    "solver_fallbacks",
    "recoveries",
    "soft_constraint_steps",
    "guided_steps",
    "escape_steps",
    "safety_active_steps",
    "repeated_steps",
)


class ObstacleTracker:
    """Obstacles from MarkerArrays of cylinders; velocity (m/s) from successive poses of each id."""

    def __init__(self) -> None:
        # (ns, id) -> [stamp s, x m, y m, radius m, vx m/s, vy m/s]
        self._tracks: dict[tuple[str, int], list[float]] = {}
        self.arrays_received = 0  # MarkerArrays taken, empty ones included

    def update(self, array: object, frame_id: str) -> int:
        """Take a MarkerArray; return how many markers were refused for another frame than
        frame_id (there is no tf here to move them into it)."""
        refused = 0
        self.arrays_received += 1
        for marker in array.markers:
            key = (marker.ns, marker.id)
            if marker.header.frame_id not in ("", frame_id):
                refused += 1
            elif marker.action == msg.MARKER_DELETEALL:
                self._tracks.clear()
            elif marker.action == 2:  # DELETE
                self._tracks.pop(key, None)
            elif marker.type == msg.MARKER_CYLINDER:
                stamp = msg.from_time(marker.header.stamp)
                x, y = marker.pose.position.x, marker.pose.position.y
                vx = vy = 0.0
                old = self._tracks.get(key)
                if old is not None:
                    dt = stamp - old[0]
                    vx, vy = ((x - old[1]) / dt, (y - old[2]) / dt) if dt > 1e-6 else (old[4], old[5])
                self._tracks[key] = [stamp, x, y, 0.5 * marker.scale.x, vx, vy]
        return refused

    def obstacles_at(self, t_s: float) -> list[Obstacle]:
        """Each obstacle predicted at constant velocity to time t_s (s, the odometry's stamp)."""
        out = []
        for stamp, x, y, r, vx, vy in self._tracks.values():
            dt = t_s - stamp
            out.append(Obstacle(x + vx * dt, y + vy * dt, r, vx, vy))
        return out


def timing_stats(values: Sequence[float]) -> dict[str, float | None]:
    """Median, p99 and max of times (ms); None for each when there are none."""
    if not values:
        return {"median": None, "p99": None, "max": None}
    a = np.asarray(values, dtype=float)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "max": float(a.max())}


@dataclass
class ServeStats:
    """Counts and timings of a serve session (written as serve_summary.json)."""

    ticks: int = 0
    events: dict[str, int] = field(default_factory=lambda: dict.fromkeys((*EVENTS, ERROR), 0))
    goals_received: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: {"goals": 0, "markers": 0})  # other frames
    controller_counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(CONTROLLER_COUNTS, 0))
    solve_ms: list[float] = field(default_factory=list)
    odom_latency_ms: list[float] = field(default_factory=list)

    def as_dict(self) -> dict[str, object]:
        return {
            "ticks": self.ticks,
            **{f"{k}_events": v for k, v in self.events.items()},
            "goals_received": self.goals_received,
            **{f"{k}_rejected_other_frame": v for k, v in self.rejected.items()},
            **self.controller_counts,
            "solve_ms": timing_stats(self.solve_ms),
            "odometry_latency_ms": timing_stats(self.odom_latency_ms),
        }


class ControllerNode:
    """A controller (controllers.Controller) behind ROS 2 topics."""

    def __init__(
        self,
        controller: Controller,
        reference: Reference,
        tau_s: float,
        settings: Ros2Settings,
        out_dir: Path | None = None,
        solve_budget_s: float | None = None,
        transport: str = "cyclonedds",
        ros_args: Sequence[str] = (),
    ) -> None:
        """`solve_budget_s` (s, default tau): a solve that takes longer is an overrun; less than
        tau leaves time for the transport and the drive. `transport` and `ros_args`: see
        husky_sim.ros2.transport.open_transport (with rclpy, `settings` become the node's ROS
        parameters' defaults, and `self.settings` what the parameters say)."""
        self.controller, self.reference, self.tau_s = controller, reference, tau_s
        self.solve_budget_s = tau_s if solve_budget_s is None else solve_budget_s
        if not 0.0 < self.solve_budget_s <= tau_s:
            raise ValueError(
                f"solve_budget_s: must be in (0, tau = {tau_s:g}] s, got {self.solve_budget_s:g}"
            )
        self.stats = ServeStats()
        self.transport = open_transport(settings, transport, ros_args)
        self.settings = s = self.transport.settings
        self.msg = self.transport.messages
        t = self.transport
        self._odom = t.subscribe("odometry", msg.ODOMETRY)
        self._goal = t.subscribe("goal", msg.POSE_STAMPED)
        self._markers = t.subscribe("obstacles", msg.MARKER_ARRAY)
        self._clock = t.subscribe("clock", msg.CLOCK) if s.use_sim_time else None
        self.cmd_vel = t.publish("cmd_vel", msg.TWIST_STAMPED if s.cmd_vel_stamped else msg.TWIST)
        self._plan = t.publish("plan", msg.PATH)
        self._tracker = ObstacleTracker()
        self._sim_now: float | None = None
        self._last_odom_stamp: float | None = None
        self._t0: float | None = 0.0 if s.use_sim_time else None
        self._next_step_stamp = -math.inf
        self._next_stale_at = -math.inf
        self.out_dir = out_dir
        self._log_file = self._writer = None
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            self._log_file = (out_dir / "serve.csv").open("w", newline="")
            self._writer = csv.DictWriter(self._log_file, fieldnames=SERVE_LOG_COLUMNS)
            self._writer.writeheader()
            self._log_file.flush()
        controller.reset()

    def connected(self) -> bool:
        """Whether the node has matched an odometry publisher and a cmd_vel subscriber (from its
        side: with two middlewares, each side's discovery finishes at its own time)."""
        return bool(self._odom.publishers() and self.cmd_vel.subscribers())

    # -- clock ---------------------------------------------------------------------------------
    def now(self) -> float | None:
        """The node's clock (s): /clock with use_sim_time, else ROS time (the system clock)."""
        return self._sim_now if self.settings.use_sim_time else time.time()

    # -- loop ----------------------------------------------------------------------------------
    def spin(self, stop: Callable[[], bool] = lambda: False, duration_s: float | None = None) -> None:
        """Serve until `stop()` is true, duration_s of wall time has passed, or a signal arrives;
        then send a zero command. Never raises for a solver failure."""
        end = math.inf if duration_s is None else time.monotonic() + duration_s
        try:
            layout = getattr(self.transport, "graph_distro", None)
            while not stop() and time.monotonic() < end:
                interrupts.check()
                self.transport.wait(0.25 * self.tau_s)
                self.poll()
                if layout is None and getattr(self.transport, "graph_distro", None) is not None:
                    layout = self.transport.graph_distro
                    print(f"ROS graph: announced in the peers' layout, {LAYOUT_NAMES[layout]}", flush=True)
        finally:
            with interrupts.deferred():
                self._publish_twist(np.zeros(2), self.now())
                self._log_row("shutdown", "shutdown", np.zeros(2))
                self._flush_acks()
                self.close()

    def poll(self) -> None:
        """Read everything waiting and act on it once."""
        goal = latest(self._goal.take())
        if goal is not None:
            goal = goal.message
            if goal.header.frame_id in ("", self.settings.odom_frame):
                p = goal.pose
                self.reference = SetPoint(p.position.x, p.position.y, msg.quaternion_yaw(p.orientation))
                self.stats.goals_received += 1
            else:  # no tf here: a goal in another frame would be driven to in the wrong place
                self.stats.rejected["goals"] += 1
        for array in self._markers.take():
            self.stats.rejected["markers"] += self._tracker.update(array.message, self.settings.odom_frame)
        if self._clock is not None:
            clock = latest(self._clock.take())
            if clock is not None:
                self._sim_now = msg.from_time(clock.message.clock)
        odom = latest(self._odom.take())
        if odom is not None:
            stamp = msg.from_time(odom.message.header.stamp)
            self._last_odom_stamp = stamp
            latency_ms = (time.time_ns() - odom.sent_ns) / 1e6
            self.stats.odom_latency_ms.append(latency_ms)
            if stamp >= self._next_step_stamp - 1e-3 * self.tau_s:
                self._next_step_stamp = stamp + self.tau_s
                self._control_step(odom.message, stamp, latency_ms)
        self._watchdog()

    def _watchdog(self) -> None:
        now = self.now()
        if now is None:
            return
        age = math.inf if self._last_odom_stamp is None else now - self._last_odom_stamp
        if age > STALE_ODOMETRY_PERIODS * self.tau_s and now >= self._next_stale_at:
            self._next_stale_at = now + self.tau_s
            self._publish_twist(np.zeros(2), now)
            self._log_row("stale", f"odometry age {age:.3g} s", np.zeros(2), odom_age_s=age)

    def _control_step(self, odom: object, stamp: float, latency_ms: float) -> None:
        now = self.now()
        if now is not None and now - stamp > STALE_ODOMETRY_PERIODS * self.tau_s:
            return  # arrived too late to act on: the watchdog stops the robot
        p = odom.pose.pose
        state = np.array([p.position.x, p.position.y, msg.quaternion_yaw(p.orientation)])
        if not self._tracker.arrays_received and self._markers.publishers():
            self._publish_twist(np.zeros(2), stamp)
            self._log_row(
                "blind",
                f"{self.settings.obstacles_topic}: a publisher is matched, no obstacles from it yet",
                np.zeros(2),
                odom_stamp_s=stamp,
                x_m=float(state[0]),
                y_m=float(state[1]),
                yaw_rad=float(state[2]),
                odom_latency_ms=latency_ms,
            )
            return
        if self._t0 is None:
            self._t0 = stamp  # wall clock: the reference starts with the first odometry
        t_ref = stamp - self._t0
        obstacles = self._tracker.obstacles_at(stamp)
        start = time.perf_counter()
        try:
            result = self.controller.solve(state, self.reference, obstacles, t_ref)
        except Exception as exc:  # noqa: BLE001 - a node must stop the robot, not die, on any failure
            result = ControlResult.brake(1, 0, 0, time.perf_counter() - start, f"error: {exc}"[:200])
            self.stats.events[ERROR] += 1
        solve_s = time.perf_counter() - start
        if not result.repeated:  # a step answered by lookup is not a solve time (metrics.solver_times)
            self.stats.solve_ms.append(1000.0 * solve_s)
        if solve_s > self.solve_budget_s:
            event, command = "overrun", np.zeros(2)
        elif result.fallback == "brake":
            event, command = "brake", np.zeros(2)
        else:
            event, command = "command", np.asarray(result.control, dtype=float)
            self._publish_plan(result, stamp)
        self._publish_twist(command, stamp)
        counts = self.stats.controller_counts
        counts["fallbacks"] += result.is_fallback
        counts["solver_fallbacks"] += bool(result.solver_fallback)
        counts["recoveries"] += bool(result.recovered_by)
        counts["soft_constraint_steps"] += result.soft_constraint
        counts["guided_steps"] += result.guided
        counts["escape_steps"] += bool(result.escape)
        counts["safety_active_steps"] += result.safety_active > 0
        counts["repeated_steps"] += result.repeated
        self._log_row(
            event,
            result.status,
            command,
            odom_stamp_s=stamp,
            odom_age_s=math.nan if now is None else now - stamp,
            t_ref_s=t_ref,
            x_m=float(state[0]),
            y_m=float(state[1]),
            yaw_rad=float(state[2]),
            obstacles=len(obstacles),
            fallback=result.fallback,
            solver_fallback=result.solver_fallback,
            repeated=int(result.repeated),
            recovered_by=result.recovered_by,
            soft_constraint=int(result.soft_constraint),
            guided=int(result.guided),
            mode=result.mode,
            escape=result.escape,
            safety_active=int(result.safety_active),
            solve_ms=1000.0 * solve_s,
            odom_latency_ms=latency_ms,
        )

    # -- output --------------------------------------------------------------------------------
    def _publish_twist(self, command: np.ndarray, stamp: float | None) -> None:
        """A command; stamped (cmd_vel_stamped) with the odometry it answers, else the node's clock."""
        twist = self.msg.make(msg.TWIST)
        twist.linear.x, twist.angular.z = float(command[0]), float(command[1])
        if self.settings.cmd_vel_stamped:
            t_s = time.time() if stamp is None else stamp
            twist = self.msg.make(
                msg.TWIST_STAMPED, header=self.msg.header(t_s, self.settings.base_frame), twist=twist
            )
        self.cmd_vel.write(twist)

    def _publish_plan(self, result: ControlResult, stamp: float) -> None:
        frame, kit = self.settings.odom_frame, self.msg
        poses = [
            kit.make(
                msg.POSE_STAMPED,
                header=kit.header(stamp + result.plan_start_s + k * self.tau_s, frame),
                pose=kit.pose(*xs),
            )
            for k, xs in enumerate(result.predicted_states)
            if np.all(np.isfinite(xs))
        ]
        self._plan.write(kit.make(msg.PATH, header=kit.header(stamp, frame), poses=poses))

    def _log_row(self, event: str, status: str, command: np.ndarray, **fields: object) -> None:
        """Count an event and write its row of serve.csv (columns not given are left empty)."""
        self.stats.ticks += 1
        self.stats.events[event] += 1  # ERROR is counted where it happens
        if self._writer is None:
            return
        row = {k: "" for k in SERVE_LOG_COLUMNS}
        row.update(tick=self.stats.ticks - 1, clock_s=self.now(), event=event, status=status)
        row.update(v_cmd_mps=float(command[0]), omega_cmd_radps=float(command[1]), **fields)
        with interrupts.deferred():
            self._writer.writerow({k: (f"{v:.9g}" if isinstance(v, float) else v) for k, v in row.items()})
            self._log_file.flush()

    def _flush_acks(self) -> None:
        """Give the last (zero) command time to reach reliable subscribers before leaving."""
        with contextlib.suppress(Exception):  # best effort: a vanished subscriber is not an error here
            self.cmd_vel.wait_for_acks(0.5)

    def close(self) -> None:
        self.transport.close()
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None
        if self.out_dir is not None:
            summary = {"settings": self.settings.__dict__, "tau_s": self.tau_s, **self.stats.as_dict()}
            tmp = self.out_dir / "serve_summary.json.tmp"
            tmp.write_text(json.dumps(summary, indent=2, default=str) + "\n")
            tmp.replace(self.out_dir / "serve_summary.json")


def serve(
    controller: Controller,
    reference: Reference,
    tau_s: float,
    settings: Ros2Settings,
    out_dir: Path | None = None,
    duration_s: float | None = None,
    solve_budget_s: float | None = None,
    transport: str = "cyclonedds",
    ros_args: Sequence[str] = (),
) -> ServeStats:
    """Run a node until interrupted or duration_s (wall) has passed; return its counts."""
    node = ControllerNode(
        controller, reference, tau_s, settings, out_dir, solve_budget_s, transport, ros_args
    )
    node.spin(duration_s=duration_s)
    return node.stats


def obstacles_to_markers(
    obstacles: Sequence[Obstacle],
    stamp_s: float,
    frame_id: str,
    height_m: float = 1.0,
    kit: msg.MessageKit | None = None,
) -> object:
    """A MarkerArray of cylinders (one per obstacle, id = index, action ADD, which replaces the
    marker of the same id) that RViz and Foxglove draw and ObstacleTracker reads back; built with
    `kit` (default: our Cyclone DDS types)."""
    kit = kit or msg.DEFAULT_KIT
    markers = []
    for i, o in enumerate(obstacles):
        m = kit.make(
            msg.MARKER,
            header=kit.header(stamp_s, frame_id),
            ns="obstacles",
            id=i,
            type=msg.MARKER_CYLINDER,
            action=msg.MARKER_ADD,
            pose=kit.pose(o.x_m, o.y_m, 0.0),
        )
        m.pose.position.z = 0.5 * height_m
        m.scale.x = m.scale.y = 2.0 * o.radius_m
        m.scale.z = height_m
        m.color.r, m.color.g, m.color.b, m.color.a = 0.8, 0.2, 0.2, 0.8
        markers.append(m)
    return kit.make(msg.MARKER_ARRAY, markers=markers)
