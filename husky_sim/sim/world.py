"""The PyBullet world: ground plane, cylinder obstacles (static or kinematic movers), optional
arena walls, and the physics clock.

Moving obstacles are kinematic: zero-mass bodies whose pose is set before every physics step from
their motion (constant velocity, or waypoints followed at a constant speed), so the Husky cannot
push them and their motion is exactly reproducible.

In a large world (more than RIGID_STATICS_ABOVE obstacles) the static ones are asleep static rigid
bodies, sharing one collision and one visual shape per size; see RIGID_STATICS_ABOVE.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from controllers import Obstacle
from husky_sim.sim.bullet import pybullet as p

#: Worlds with more obstacles than this make their static ones static rigid bodies (PyBullet's
#: maximal coordinates), asleep, with one collision and one visual shape per (radius, height).
#: The engine visits every fixed-base multibody at every step, asleep or not, so a world of a
#: thousand posts costs several times the Husky alone; it skips sleeping static bodies
#: (`husky-sim bench-sim --world large` prints the physics step's cost). An immovable cylinder
#: is the same obstacle either way: the Husky driving into one moves and clears bit for bit alike
#: (tests/sim/test_large_world.py). Worlds up to this many, every shipped scenario's among them,
#: keep the multibodies their logs were made with.
RIGID_STATICS_ABOVE = 64


@dataclass(frozen=True)
class ObstacleSpec:
    """A cylinder obstacle: centre at t = 0 (m), radius and height (m), and its motion.

    Motion: constant velocity (vx, vy) in m/s, or `waypoints` [(x, y), ...] visited in order at
    `speed_mps` after the start position, stopping at the last one.
    """

    x_m: float
    y_m: float
    radius_m: float
    height_m: float = 1.0
    vx_mps: float = 0.0
    vy_mps: float = 0.0
    waypoints: tuple[tuple[float, float], ...] = ()
    speed_mps: float = 0.0

    def __post_init__(self) -> None:
        if not self.radius_m > 0:
            raise ValueError(f"obstacle.radius_m: must be > 0 m, got {self.radius_m}")
        if not self.height_m > 0:
            raise ValueError(f"obstacle.height_m: must be > 0 m, got {self.height_m}")
        if self.waypoints and not self.speed_mps > 0:
            raise ValueError(f"obstacle.speed_mps: must be > 0 m/s with waypoints, got {self.speed_mps}")

    @property
    def moving(self) -> bool:
        return bool(self.waypoints) or self.vx_mps != 0.0 or self.vy_mps != 0.0

    @cached_property
    def _legs(self) -> tuple[tuple[tuple[float, float], tuple[float, float], float], ...]:
        """The waypoint path's legs as (start (m), unit direction, length m), worked out once."""
        points = [np.array([self.x_m, self.y_m]), *(np.asarray(w, dtype=float) for w in self.waypoints)]
        legs = []
        for a, b in zip(points[:-1], points[1:], strict=True):
            length = float(np.linalg.norm(b - a))
            unit = (b - a) / length if length > 0 else np.zeros(2)
            legs.append(((float(a[0]), float(a[1])), (float(unit[0]), float(unit[1])), length))
        return tuple(legs)

    def motion_at(self, t_s: float) -> tuple[float, float, float, float]:
        """Centre (m) and velocity (m/s) at time t_s as plain floats (x, y, vx, vy): the one
        place motion is worked out, called every physics step for each mover."""
        if not self.waypoints:
            return self.x_m + self.vx_mps * t_s, self.y_m + self.vy_mps * t_s, self.vx_mps, self.vy_mps
        travelled = self.speed_mps * t_s
        for (ax, ay), (ux, uy), length in self._legs:
            if travelled <= length and length > 0:
                return ax + ux * travelled, ay + uy * travelled, ux * self.speed_mps, uy * self.speed_mps
            travelled -= length
        x, y = self.waypoints[-1]
        return float(x), float(y), 0.0, 0.0

    def state_at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Centre (m) and velocity (m/s) at time t_s."""
        x, y, vx, vy = self.motion_at(t_s)
        return np.array([x, y]), np.array([vx, vy])

    def circle_at(self, t_s: float) -> Obstacle:
        """The controller's view of this obstacle at time t_s: its circle and its velocity then."""
        centre, vel = self.state_at(t_s)
        return Obstacle(float(centre[0]), float(centre[1]), self.radius_m, float(vel[0]), float(vel[1]))


@dataclass(frozen=True)
class WorldConfig:
    """Physics rate, ground friction, obstacles and optional square arena (half-size, m)."""

    physics_hz: float = 240.0
    ground_friction: float = 1.0  # ground plane lateral friction coefficient
    obstacles: tuple[ObstacleSpec, ...] = ()
    arena_half_size_m: float | None = None
    solver_iterations: int = 50

    def __post_init__(self) -> None:
        if not (self.physics_hz >= 60 and math.isfinite(self.physics_hz)):
            raise ValueError(f"physics_hz: must be >= 60 Hz, got {self.physics_hz}")
        if not self.ground_friction > 0:
            raise ValueError(f"ground_friction: must be > 0, got {self.ground_friction}")


class World:
    """A headless PyBullet world (DIRECT connection; never a GUI)."""

    def __init__(self, config: WorldConfig) -> None:
        self.config = config
        self.client = p.connect(p.DIRECT)
        self.dt_s = 1.0 / config.physics_hz
        self.time_s = 0.0
        cid = self.client
        p.resetSimulation(physicsClientId=cid)
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=self.dt_s,
            numSolverIterations=config.solver_iterations,
            deterministicOverlappingPairs=1,
            physicsClientId=cid,
        )
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        self.ground = p.createMultiBody(0, plane, physicsClientId=cid)
        p.changeDynamics(self.ground, -1, lateralFriction=config.ground_friction, physicsClientId=cid)
        rigid = len(config.obstacles) > RIGID_STATICS_ABOVE
        self._shapes: dict[tuple[float, float], tuple[int, int]] = {}  # (radius, height): shapes
        self.obstacle_ids: list[int] = [
            self._add_rigid_cylinder(o) if rigid and not o.moving else self._add_cylinder(o)
            for o in config.obstacles
        ]
        self._static_centres = np.array([[o.x_m, o.y_m] for o in config.obstacles]).reshape(-1, 2)
        self._moving = [i for i, o in enumerate(config.obstacles) if o.moving]
        self._centres = self.obstacle_centres(0.0)
        # a static obstacle's circle is the same at every time (circle_at: x + 0 t is x)
        self._circles = [None if o.moving else o.circle_at(0.0) for o in config.obstacles]
        self.wall_ids: list[int] = self._add_arena(config.arena_half_size_m)

    def _cylinder_shapes(self, spec: ObstacleSpec) -> tuple[int, int]:
        """A cylinder's collision and visual shapes (movers drawn red, static obstacles grey)."""
        cid = self.client
        shape = p.createCollisionShape(
            p.GEOM_CYLINDER, radius=spec.radius_m, height=spec.height_m, physicsClientId=cid
        )
        visual = p.createVisualShape(
            p.GEOM_CYLINDER,
            radius=spec.radius_m,
            length=spec.height_m,
            rgbaColor=[0.8, 0.3, 0.2, 1] if spec.moving else [0.25, 0.25, 0.25, 1],
            physicsClientId=cid,
        )
        return shape, visual

    def _add_cylinder(self, spec: ObstacleSpec) -> int:
        cid = self.client
        shape, visual = self._cylinder_shapes(spec)
        return p.createMultiBody(
            0, shape, visual, basePosition=[spec.x_m, spec.y_m, 0.5 * spec.height_m], physicsClientId=cid
        )

    def _add_rigid_cylinder(self, spec: ObstacleSpec) -> int:
        """A static obstacle of a large world (RIGID_STATICS_ABOVE): an asleep static rigid body
        whose shapes are shared with every other of its radius and height."""
        cid = self.client
        key = (spec.radius_m, spec.height_m)
        if key not in self._shapes:
            self._shapes[key] = self._cylinder_shapes(spec)
        shape, visual = self._shapes[key]
        body = p.createMultiBody(
            0,
            shape,
            visual,
            basePosition=[spec.x_m, spec.y_m, 0.5 * spec.height_m],
            useMaximalCoordinates=True,
            physicsClientId=cid,
        )
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_SLEEP, physicsClientId=cid)
        return body

    def _add_arena(self, half: float | None) -> list[int]:
        """Four box walls whose inner faces are `half` - 0.1 m from the origin; their half-planes
        (inward normal n, offset d: inside where n . p <= d) go to `wall_planes`."""
        self.wall_planes: list[tuple[np.ndarray, float]] = []
        if half is None:
            return []
        cid, thick, height = self.client, 0.1, 0.5
        ids = []
        for nx, ny in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            extents = [thick, half + thick, height / 2] if nx else [half + thick, thick, height / 2]
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=extents, physicsClientId=cid)
            centre = [nx * half, ny * half, height / 2]
            ids.append(p.createMultiBody(0, shape, basePosition=centre, physicsClientId=cid))
            self.wall_planes.append((np.array([nx, ny]), half - thick))
        return ids

    def _place_obstacles(self, t_s: float) -> None:
        """Move the kinematic obstacles to their pose at t_s and remember their centres."""
        for i in self._moving:
            spec = self.config.obstacles[i]
            x, y, _, _ = spec.motion_at(t_s)
            self._centres[i] = x, y
            p.resetBasePositionAndOrientation(
                self.obstacle_ids[i], [x, y, 0.5 * spec.height_m], [0, 0, 0, 1], physicsClientId=self.client
            )

    def step(self) -> None:
        """Advance one physics step, moving kinematic obstacles to their pose at the new time."""
        self._place_obstacles(self.time_s + self.dt_s)
        p.stepSimulation(physicsClientId=self.client)
        self.time_s += self.dt_s

    def obstacle_centres(self, t_s: float | None = None) -> np.ndarray:
        """True obstacle centres (m), shape (n, 2), at time t_s (default: now, as placed by the
        last step: the hot path of per-physics-step collision checks)."""
        if t_s is None:
            return self._centres.copy()
        centres = self._static_centres.copy()
        for i in self._moving:
            centres[i] = self.config.obstacles[i].state_at(t_s)[0]
        return centres

    def obstacle_states(self, t_s: float | None = None) -> list[Obstacle]:
        """True obstacle circles (centre, radius, velocity) at time t_s (default: now)."""
        t = self.time_s if t_s is None else t_s
        return [
            spec.circle_at(t) if circle is None else circle
            for spec, circle in zip(self.config.obstacles, self._circles, strict=True)
        ]

    def close(self) -> None:
        if p.isConnected(self.client):
            p.disconnect(self.client)

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def obstacle_specs_from(obstacles: Sequence[Obstacle], height_m: float = 1.0) -> tuple[ObstacleSpec, ...]:
    """Constant-velocity obstacle specs from controller-side circles."""
    return tuple(ObstacleSpec(o.x_m, o.y_m, o.radius_m, height_m, o.vx_mps, o.vy_mps) for o in obstacles)
