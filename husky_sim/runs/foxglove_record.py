"""A run as Foxglove sees it: `run.mcap` written while the episode runs, optionally streamed live.

Written with Foxglove's SDK (its MCAP writer and WebSocket server, its message schemas); every
message is stamped with sim time (s since the episode's start, as ns), so the file is the same for
the same scenario, seed and code. Channels:
- `/tf` (FrameTransform odom -> base_link) and `/robot/pose` (PoseInFrame): the true base pose;
- `/scene` (SceneUpdate): the robot's footprint box with its heading, the obstacles' cylinders
  (red where the controller was told of them this step, pale grey where the sensing model hid
  them: the log's `visible_obstacles`), the plan, the trail (one persistent line per second of
  travel) and the goal or the reference path with the reference point;
- `/control` (JSON): commanded, drive-limited and measured body velocities (m/s, rad/s);
- `/safety` (JSON): clearance (m), Relax-CBF and CLF slacks, active obstacle constraints, solve
  time (ms), and the step's solver status, fallback and guidance flags;
- `/outcome` (Log): the episode's outcome at its end.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from controllers import ControlResult, Reference, SetPoint
from husky_sim.extras import missing

try:
    import foxglove
    from foxglove import messages as fm
except ImportError:  # the core install has no Foxglove SDK
    raise missing("foxglove", "foxglove", "run.mcap and --live") from None
from husky_sim.sim.step_log import LOG_COLUMNS, parse_visible

#: The file a run folder's recording is written to.
MCAP_NAME = "run.mcap"

_ODOM, _BASE = "odom", "base_link"
#: the log's velocity columns: commanded, drive-limited and measured v (m/s) and omega (rad/s)
_CONTROL_FIELDS = tuple(c for c in LOG_COLUMNS if c.startswith(("v_", "omega_")))
_SAFETY_FIELDS = ("clearance_m", "s_h_min", "s_v_max", "safety_active", "solve_ms")
#: the log's per-step verdict columns, from the solver's status to a missed deadline
_SAFETY_TEXT = LOG_COLUMNS[LOG_COLUMNS.index("status") : LOG_COLUMNS.index("deadline_miss") + 1]


def _json_schema(name: str, numbers: Sequence[str], texts: Sequence[str] = ()) -> foxglove.Schema:
    """A named JSON schema (Foxglove plots any numeric field of a JSON channel)."""
    props: dict[str, object] = {"t_s": {"type": "number"}}
    props.update({k: {"type": ["number", "null"]} for k in numbers})
    props.update({k: {"type": ["string", "number"]} for k in texts})
    schema = {"title": name, "type": "object", "properties": props}
    return foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())


def _stamp(t_s: float) -> fm.Timestamp:
    sec = math.floor(t_s)
    return fm.Timestamp(sec=int(sec), nsec=int(round((t_s - sec) * 1e9)) % 1_000_000_000)


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def _yaw(yaw_rad: float) -> fm.Quaternion:
    return fm.Quaternion(x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2))


def _pose(x: float, y: float, z: float = 0.0, yaw: float = 0.0) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=float(x), y=float(y), z=float(z)), orientation=_yaw(float(yaw)))


def _line(points: np.ndarray, color: fm.Color, thickness: float = 0.05, z: float = 0.05) -> fm.LinePrimitive:
    return fm.LinePrimitive(
        type=fm.LinePrimitiveLineType.LineStrip,
        pose=_pose(0.0, 0.0),
        thickness=thickness,
        scale_invariant=False,
        points=[fm.Point3(x=float(p[0]), y=float(p[1]), z=z) for p in points],
        color=color,
    )


_ROBOT = fm.Color(r=1.0, g=0.8, b=0.1, a=0.9)
_OBSTACLE = fm.Color(r=0.85, g=0.2, b=0.2, a=0.8)
_HIDDEN_OBSTACLE = fm.Color(r=0.6, g=0.6, b=0.6, a=0.3)  # not told to the controller this step
_PLAN = fm.Color(r=0.1, g=0.5, b=1.0, a=1.0)
_TRAIL = fm.Color(r=0.3, g=0.3, b=0.3, a=1.0)
_REFERENCE = fm.Color(r=0.2, g=0.75, b=0.3, a=1.0)


class FoxgloveRecorder:
    """Writes one episode to `run.mcap` (and to a live Foxglove WebSocket server when asked);
    `on_step` is called by the episode loop after each control step and only reads."""

    def __init__(
        self,
        path: Path | None,
        reference: Reference,
        obstacle_radii_m: Sequence[float],
        obstacle_heights_m: Sequence[float],
        footprint_half_extents_m: tuple[float, float],
        tau_s: float,
        duration_s: float,
        live_port: int | None = None,
    ) -> None:
        self._context = foxglove.Context()
        self._server = None
        if live_port is not None:  # first: a port in use is the user's to change, before any file
            try:
                self._server = foxglove.start_server(name="husky-sim", port=live_port, context=self._context)
            except RuntimeError as exc:
                raise ValueError(f"--live: cannot serve Foxglove on 127.0.0.1:{live_port} ({exc})") from None
        # no path: live only (a run that writes no folder)
        self._writer = (
            None if path is None else foxglove.open_mcap(path, allow_overwrite=True, context=self._context)
        )
        ctx = self._context
        self._tf = foxglove.channels.FrameTransformChannel("/tf", context=ctx)
        self._pose = foxglove.channels.PoseInFrameChannel("/robot/pose", context=ctx)
        self._scene = foxglove.channels.SceneUpdateChannel("/scene", context=ctx)
        self._control = foxglove.Channel(
            "/control",
            schema=_json_schema("husky_sim.Control", _CONTROL_FIELDS),
            message_encoding="json",
            context=ctx,
        )
        self._safety = foxglove.Channel(
            "/safety",
            schema=_json_schema("husky_sim.Safety", _SAFETY_FIELDS, _SAFETY_TEXT),
            message_encoding="json",
            context=ctx,
        )
        self._outcome = foxglove.channels.LogChannel("/outcome", context=ctx)
        self._reference = reference
        self._radii = np.asarray(obstacle_radii_m, dtype=float)
        self._heights = np.asarray(obstacle_heights_m, dtype=float)
        self._half = footprint_half_extents_m
        self._trail: list[tuple[float, float]] = []
        self._trail_second = 0
        self._last_t = 0.0
        self._closed = False
        if not isinstance(reference, SetPoint):  # the whole reference path, once
            t = np.arange(0.0, duration_s + 1e-9, min(tau_s, 0.05))
            path = reference.states_at(t)
            self._scene.log(
                fm.SceneUpdate(
                    entities=[self._entity(0.0, "reference-path", lines=[_line(path, _REFERENCE, 0.03)])]
                ),
                log_time=0,
            )

    @staticmethod
    def _entity(t_s: float, entity_id: str, **primitives: object) -> fm.SceneEntity:
        return fm.SceneEntity(
            timestamp=_stamp(t_s),
            frame_id=_ODOM,
            id=entity_id,
            lifetime=fm.Duration(sec=0, nsec=0),
            **primitives,
        )

    def on_step(self, row: dict[str, object], result: ControlResult, obstacle_xy: np.ndarray) -> None:
        """Record one control step: the row of log.csv, the solve's result, obstacle centres (m)."""
        t = float(row["t_s"])
        ns = _ns(t)
        x, y, yaw = float(row["x_m"]), float(row["y_m"]), float(row["yaw_rad"])
        self._last_t = t
        self._tf.log(
            fm.FrameTransform(
                timestamp=_stamp(t),
                parent_frame_id=_ODOM,
                child_frame_id=_BASE,
                translation=fm.Vector3(x=x, y=y, z=0.0),
                rotation=_yaw(yaw),
            ),
            log_time=ns,
        )
        self._pose.log(
            fm.PoseInFrame(timestamp=_stamp(t), frame_id=_ODOM, pose=_pose(x, y, 0.0, yaw)), log_time=ns
        )
        self._control.log({"t_s": t, **{k: _number(row[k]) for k in _CONTROL_FIELDS}}, log_time=ns)
        self._safety.log(
            {"t_s": t, **{k: _number(row[k]) for k in _SAFETY_FIELDS}, **{k: row[k] for k in _SAFETY_TEXT}},
            log_time=ns,
        )
        self._scene.log(
            fm.SceneUpdate(entities=self._entities(t, x, y, yaw, row, result, obstacle_xy)), log_time=ns
        )

    def _entities(
        self,
        t: float,
        x: float,
        y: float,
        yaw: float,
        row: dict[str, object],
        result: ControlResult,
        obstacle_xy: np.ndarray,
    ) -> list[fm.SceneEntity]:
        half_l, half_w = self._half
        body = fm.Vector3(x=2 * half_l, y=2 * half_w, z=0.4)
        visible = set(parse_visible(row["visible_obstacles"]))
        robot = self._entity(
            t,
            "robot",
            cubes=[fm.CubePrimitive(pose=_pose(x, y, 0.2, yaw), size=body, color=_ROBOT)],
            arrows=[fm.ArrowPrimitive(pose=_pose(x, y, 0.45, yaw), shaft_length=0.6, shaft_diameter=0.05,
                                      head_length=0.2, head_diameter=0.12, color=_ROBOT)],
        )  # fmt: skip
        cylinders = [
            fm.CylinderPrimitive(
                pose=_pose(cx, cy, 0.5 * h),
                size=fm.Vector3(x=2 * r, y=2 * r, z=h),
                bottom_scale=1.0,
                top_scale=1.0,
                color=_OBSTACLE if i in visible else _HIDDEN_OBSTACLE,
            )
            for i, ((cx, cy), r, h) in enumerate(zip(obstacle_xy, self._radii, self._heights, strict=True))
        ]
        entities = [robot, self._entity(t, "obstacles", cylinders=cylinders)]
        plan = result.predicted_states
        finite = plan[np.all(np.isfinite(plan), axis=1)] if plan.size else plan
        entities.append(self._entity(t, "plan", lines=[_line(finite, _PLAN)] if len(finite) > 1 else []))
        second = int(t)
        if second != self._trail_second:  # close this second's line; the next starts where it ended
            self._trail = self._trail[-1:]
            self._trail_second = second
        self._trail.append((x, y))
        if len(self._trail) > 1:
            entities.append(
                self._entity(t, f"trail-{second}", lines=[_line(np.array(self._trail), _TRAIL, 0.03)])
            )
        rx, ry, ryaw = float(row["ref_x_m"]), float(row["ref_y_m"]), float(row["ref_yaw_rad"])
        kind = "goal" if isinstance(self._reference, SetPoint) else "reference"
        entities.append(
            self._entity(
                t,
                kind,
                arrows=[
                    fm.ArrowPrimitive(
                        pose=_pose(rx, ry, 0.05, ryaw),
                        shaft_length=0.5,
                        shaft_diameter=0.06,
                        head_length=0.2,
                        head_diameter=0.15,
                        color=_REFERENCE,
                    )
                ],
            )  # fmt: skip
        )
        return entities

    def close(self, outcome: str | None = None, detail: str = "") -> None:
        """Write the outcome and finish the file (a valid MCAP even after an interrupt); a second
        call does nothing."""
        if self._closed:
            return
        self._closed = True
        if outcome is not None:
            level = fm.LogLevel.Info if outcome in ("reached", "tracking") else fm.LogLevel.Warning
            self._outcome.log(
                fm.Log(timestamp=_stamp(self._last_t), level=level, message=f"{outcome} {detail}".strip(),
                       name="husky-sim", file="", line=0),
                log_time=_ns(self._last_t),
            )  # fmt: skip
        if self._writer is not None:
            self._writer.close()
        if self._server is not None:
            self._server.stop()


def _number(value: object) -> float | None:
    """A JSON number (None for NaN or infinity, which JSON has not)."""
    v = float(value)
    return v if math.isfinite(v) else None
