"""Episode trace: what a renderer or a plot needs to redraw a run without re-solving it.

`log.csv` has one row per control step; the trace adds what does not fit a row: the full 3-D
base pose sampled at `TRACE_HZ` of sim time (for smooth video), the obstacles' true positions at
the same instants, the NMPC's predicted states at every control step, and the reference path.
It is written next to the log as `trace.npz` and only reads the simulation, so recording it never
changes the physics.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Sample rate (Hz of sim time) of the base pose and obstacle positions in the trace.
TRACE_HZ = 60.0


@dataclass
class EpisodeTrace:
    """Arrays of one episode. Units: m, rad, s; quaternions are (x, y, z, w) as PyBullet gives."""

    sample_t_s: np.ndarray  # (S,) sim time of each pose sample
    base_position_m: np.ndarray  # (S, 3)
    base_orientation_xyzw: np.ndarray  # (S, 4)
    obstacle_xy_m: np.ndarray  # (S, M, 2) true obstacle centres
    obstacle_radius_m: np.ndarray  # (M,)
    obstacle_height_m: np.ndarray  # (M,)
    control_t_s: np.ndarray  # (K,) time of each control step
    predicted_states: np.ndarray  # (K, N+1, 3) the plan returned at each control step
    reference_path: np.ndarray  # (P, 3) reference sampled over the episode (x m, y m, yaw rad)
    goal: np.ndarray  # (3,) goal pose, NaN for a tracking reference
    robot_radius_m: float  # the controller's robot circle
    footprint_radius_m: float  # the URDF footprint
    arena_half_size_m: float = float("nan")  # NaN: no walls

    def save(self, path: Path) -> None:
        np.savez_compressed(path, **{k: np.asarray(v) for k, v in self.__dict__.items()})

    @classmethod
    def load(cls, path: Path) -> EpisodeTrace:
        """Read a trace; raises ValueError naming the file when it is not one."""
        try:
            with np.load(path) as data:
                fields = {k: data[k] for k in data.files}
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{path}: not a readable episode trace ({exc})") from None
        names = list(cls.__dataclass_fields__)
        missing = [n for n in names if n not in fields]
        if missing:
            raise ValueError(f"{path}: not an episode trace (missing {', '.join(missing)})")
        scalars = {"robot_radius_m", "footprint_radius_m", "arena_half_size_m"}
        return cls(**{n: (float(fields[n]) if n in scalars else fields[n]) for n in names})

    def pose_index(self, t_s: float) -> int:
        """Index of the last pose sample at or before t_s (clamped)."""
        i = int(np.searchsorted(self.sample_t_s, t_s + 1e-9, side="right")) - 1
        return min(max(i, 0), len(self.sample_t_s) - 1)

    def control_index(self, t_s: float) -> int:
        """Index of the control step in force at t_s (clamped)."""
        i = int(np.searchsorted(self.control_t_s, t_s + 1e-9, side="right")) - 1
        return min(max(i, 0), len(self.control_t_s) - 1)
