"""The one mover model of husky-cbf: constant-velocity prediction and a swept footprint.

Every layer reads a mover from here: the NMPC's obstacle constraints (`MoverModel.nmpc_obstacles`),
the planner's circles (`MoverModel.swept_circles`) and the yielding behaviours (`MoverModel.growth_m`).

- A mover keeps its measured velocity (constant-velocity prediction).
- At a predicted instant it blocks its track over the next `sweep_s` (MoverConfig.sweep_s): a
  skid-steer needs time to turn away and brake, so a plan keeps clear of where the mover is about
  to be, not only of where it is. The NMPC's circle at step k is centred half a sweep along the
  track from the mover's predicted position and widened by half the sweep's length.
- Its circle grows with its predicted travel (`margin_per_m` per metre): its velocity is an
  estimate.
- The planner sees each mover as the NMPC's first circle: from `lead_s` along its track, as wide
  as the NMPC sees it at the horizon's middle (`growth_s`), and swept on over
  `PLANNER_SWEEP_FACTOR` times the NMPC's sweep, so that a path does not lead through a gap the
  NMPC holds closed, nor is kept from the track the mover has left behind it.

A mover's track ends where it meets the static layer (`free_run_m`): it turns before then, where
no constant-velocity prediction says.

An obstacle slower than STATIC_SPEED_MPS counts as static for the decisions that tell movers from
the static layer (the planner's hysteresis and waits, yielding); the circles sweep any obstacle
that moves at all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.config import ObstaclePrediction
from controllers.husky_cbf.config import MoverConfig
from controllers.obstacles import Obstacle, predict_obstacles

#: The planner sweeps a mover's track over this multiple of sweep_s: a path must stay clear of a
#: mover for longer than one NMPC plan does, since the robot drives the path for seconds
PLANNER_SWEEP_FACTOR = 4.0 / 3.0
#: An obstacle at most this fast (m/s) counts as static: the noise of a tracked velocity estimate
STATIC_SPEED_MPS = 0.05
#: A circle that holds the robot is shrunk to leave the robot this far outside it (m)
ROBOT_EXCLUSION_M = 1e-3
#: Below this speed (m/s) a mover's sweep is one circle: its track is shorter than any radius
SWEEP_SPEED_MPS = 1e-3


def is_static(obstacle: Obstacle) -> bool:
    """Whether an obstacle counts as static (at most STATIC_SPEED_MPS)."""
    return math.hypot(obstacle.vx_mps, obstacle.vy_mps) <= STATIC_SPEED_MPS


def inflated_circles(
    obstacles: Sequence[Obstacle],
    inflation_m: float,
    sweep_s: float,
    robot_xy: np.ndarray,
    mover_growth_s: float = 0.0,
    mover_lead_s: float = 0.0,
) -> np.ndarray:
    """(M, 3) circles [x, y, r] (m): obstacles inflated by `inflation_m` (a mover by its speed
    times mover_growth_s more), movers swept over sweep_s from where they will be mover_lead_s
    (s) from now; a circle that holds the robot is shrunk to just exclude it (the robot is where
    it is). An obstacle standing exactly still gets one circle, worked out for all of them at once
    with the same arithmetic as a mover's first (a world of a thousand posts costs no loop)."""
    if not obstacles:
        return np.zeros((0, 3))
    data = np.array([(o.x_m, o.y_m, o.radius_m, o.vx_mps, o.vy_mps) for o in obstacles])
    still = (data[:, 3] == 0.0) & (data[:, 4] == 0.0)
    blocks = {}  # each other obstacle's circles, in order along its track
    for i in np.flatnonzero(~still).tolist():
        ob = obstacles[i]
        speed = math.hypot(ob.vx_mps, ob.vy_mps)
        radius = ob.radius_m + inflation_m + mover_growth_s * speed
        # a circle every half radius along the track: neighbours overlap, the track is covered
        samples = (
            max(int(math.ceil(speed * sweep_s / (0.5 * radius))) + 1, 1) if speed > SWEEP_SPEED_MPS else 1
        )
        times = mover_lead_s + np.linspace(0.0, sweep_s if samples > 1 else 0.0, samples)
        blocks[i] = [(ob.x_m + ob.vx_mps * t, ob.y_m + ob.vy_mps * t, radius) for t in times]
    counts = np.ones(len(obstacles), dtype=int)
    counts[list(blocks)] = [len(rows) for rows in blocks.values()]
    starts = np.cumsum(counts) - counts
    out = np.empty((int(counts.sum()), 3))
    # a still obstacle's circle is a mover's first with v = 0: its centre (+ 0.0, as x + 0 t reads
    # a -0.0 coordinate as 0.0) and its radius inflated without growth
    out[starts[still]] = np.column_stack([data[still, 0:2] + 0.0, data[still, 2] + inflation_m])
    for i, rows in blocks.items():
        out[starts[i] : starts[i] + len(rows)] = rows
    dist = np.hypot(out[:, 0] - robot_xy[0], out[:, 1] - robot_xy[1])
    out[:, 2] = np.where(dist < out[:, 2], np.maximum(dist - ROBOT_EXCLUSION_M, 0.0), out[:, 2])
    return out


@dataclass(frozen=True)
class MoverModel:
    """How husky-cbf predicts and sweeps a mover. `sweep_s` and `margin_per_m` are the settings
    (MoverConfig); `inflation_m` the robot's body disc radius plus margin (what a planner circle
    adds to an obstacle's radius); `delay_s` how far ahead of the measurement the NMPC's first step
    is (the prediction's dead time); `lead_s` how far along its track (s) a mover's first NMPC
    circle is centred; `growth_s` how much (m per m/s of the mover's speed) the NMPC widens a mover
    at the horizon's middle, which the planner and the yielding behaviours add to its body."""

    sweep_s: float
    margin_per_m: float = 0.0
    inflation_m: float = 0.0
    delay_s: float = 0.0
    lead_s: float = 0.0
    growth_s: float = 0.0

    @classmethod
    def for_plan(cls, config: MoverConfig, inflation_m: float, delay_s: float, plan_s: float) -> MoverModel:
        """The model of a controller whose plan starts `delay_s` (s) after the measurement and whose
        horizon's middle is `plan_s` (s) after it."""
        half_sweep = 0.5 * config.sweep_s
        return cls(
            sweep_s=config.sweep_s,
            margin_per_m=config.margin_per_m,
            inflation_m=inflation_m,
            delay_s=delay_s,
            lead_s=delay_s + half_sweep,
            growth_s=half_sweep + config.margin_per_m * plan_s,
        )

    @property
    def planner_sweep_s(self) -> float:
        """How long a stretch of its track (s) a mover blocks for the planner."""
        return self.sweep_s * PLANNER_SWEEP_FACTOR

    def growth_m(self, speed_mps: float) -> float:
        """How much wider (m) than its body the NMPC sees a mover at `speed_mps` mid-horizon."""
        return self.growth_s * speed_mps

    def nmpc_obstacles(
        self,
        robot_xy: np.ndarray,
        obstacles: Sequence[Obstacle],
        slots: int,
        tau_s: float,
        horizon: int,
        mode: ObstaclePrediction,
        margin_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Centres (slots, N+1, 2) and inflated radii (slots, N+1) (m) of the `slots` obstacles
        nearest to the robot at the plan's steps, which start `delay_s` from the measurement: each
        circle covers the obstacle's track over [k tau, k tau + sweep_s], its radius inflated by
        `margin_m` and grown by margin_per_m per metre of predicted travel."""
        centres, radii = predict_obstacles(obstacles, robot_xy, slots, tau_s, horizon, mode)
        velocity = (centres[:, 1, :] - centres[:, 0, :]) / tau_s
        speed = np.hypot(velocity[:, 0], velocity[:, 1])
        half_sweep = 0.5 * self.sweep_s
        centres = centres + self.lead_s * velocity[:, None, :]
        travel = speed[:, None] * (self.delay_s + tau_s * np.arange(horizon + 1))
        inflated = radii[:, None] + margin_m + half_sweep * speed[:, None] + self.margin_per_m * travel
        return centres, inflated

    def body_circles(self, obstacles: Sequence[Obstacle], robot_xy: np.ndarray) -> np.ndarray:
        """(M, 3) circles [x, y, r] (m): each obstacle where it is now, inflated by inflation_m,
        not swept (inflated_circles)."""
        return inflated_circles(obstacles, self.inflation_m, 0.0, robot_xy)

    def swept_circles(self, obstacles: Sequence[Obstacle], robot_xy: np.ndarray) -> np.ndarray:
        """(M, 3) circles [x, y, r] (m) the planner avoids: obstacles inflated by inflation_m, a
        mover grown by growth_m and swept over planner_sweep_s from lead_s on, where the NMPC's
        first circle is (inflated_circles)."""
        return inflated_circles(
            obstacles, self.inflation_m, self.planner_sweep_s, robot_xy, self.growth_s, self.lead_s
        )


def free_run_m(data: np.ndarray) -> np.ndarray:
    """(M,) how far (m) each mover of `data` (rows [x, y, vx, vy, r, ...]) runs along its
    constant-velocity track before its disc meets a static obstacle's (inf: it meets none, or it
    stands): a walker does not walk through a wall, so it turns before it, and no
    constant-velocity prediction says where. An obstacle it already touches is not in its way (it
    passes beside it)."""
    speed = np.hypot(data[:, 2], data[:, 3])
    moving, still = speed > STATIC_SPEED_MPS, speed <= STATIC_SPEED_MPS
    out = np.full(len(data), np.inf)
    if not np.any(moving) or not np.any(still):
        return out
    movers, posts = data[moving], data[still]
    heading = movers[:, 2:4] / speed[moving, None]  # (A, 2)
    offset = movers[:, None, 0:2] - posts[None, :, 0:2]  # (A, B, 2)
    reach = movers[:, None, 4] + posts[None, :, 4]  # (A, B)
    along = np.einsum("abk,ak->ab", offset, heading)
    excess = np.einsum("abk,abk->ab", offset, offset) - reach**2
    disc = along**2 - excess
    hit = (excess > 0.0) & (along < 0.0) & (disc >= 0.0)
    out[moving] = np.min(np.where(hit, -along - np.sqrt(np.where(hit, disc, 0.0)), np.inf), axis=1)
    return out
