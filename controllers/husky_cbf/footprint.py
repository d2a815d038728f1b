"""Cover the body's rectangle with equal discs along its axis (for the obstacle constraint).

n discs centred at x_i = -L + (2i - 1) L / n (i = 1..n) with radius sqrt((L/n)^2 + W^2) cover a
rectangle of half length L and half width W: each disc's circle passes through the corners of its
slice. One circle about the base origin (n = 1 about the rectangle) blocks gaps a Husky fits
through; more discs hug the sides.
"""

from __future__ import annotations

import math

import numpy as np

from controllers.husky_cbf.config import Footprint

MAX_DISCS = 8


def disc_cover(footprint: Footprint, excess_m: float) -> tuple[np.ndarray, float]:
    """Disc centres along x (m, shape (n,)) and the common radius (m): the fewest discs whose
    radius exceeds the half width by at most `excess_m` (at most MAX_DISCS)."""
    half_l, half_w = footprint.half_length_m, footprint.half_width_m
    for n in range(1, MAX_DISCS + 1):
        radius = math.hypot(half_l / n, half_w)
        if radius - half_w <= excess_m or n == MAX_DISCS:
            centres = -half_l + (2 * np.arange(1, n + 1) - 1) * half_l / n
            return centres, radius
    raise AssertionError("unreachable")
