"""The eight grid directions and compass headings (spec section 2).

Numpy only: the executive imports this module through ``planner.contract.table``.
"""

from __future__ import annotations

from enum import IntEnum, unique

import numpy as np
from numpy.typing import NDArray

from planner.contract.geodesy import EARTH_RADIUS_M


@unique
class Direction(IntEnum):
    """Grid direction ``k``, counter-clockwise from east (spec section 2)."""

    E = 0
    NE = 1
    N = 2
    NW = 3
    W = 4
    SW = 5
    S = 6
    SE = 7


N_HEADINGS = 8
# (di, dj) per direction k, spec section 2.
DI = np.array([1, 1, 0, -1, -1, -1, 0, 1], dtype=np.int64)
DJ = np.array([0, 1, 1, 1, 0, -1, -1, -1], dtype=np.int64)


def cell_size_m(lat_deg: NDArray[np.float64], dlon_deg: float, dlat_deg: float) -> tuple[NDArray[np.float64], float]:
    """Return ``(dx_m per row, dy_m)`` for rows at ``lat_deg`` (spec section 1)."""
    dy_m = EARTH_RADIUS_M * np.radians(dlat_deg)
    dx_m = EARTH_RADIUS_M * np.cos(np.radians(np.asarray(lat_deg, dtype=np.float64))) * np.radians(dlon_deg)
    return dx_m, float(dy_m)


def bearings_deg(dx_m: NDArray[np.float64], dy_m: float) -> NDArray[np.float64]:
    """True compass bearing of each grid direction per row, shape ``(ny, 8)``.

    ``bearing_k(j) = atan2(di * dx(j), dj * dy)``, clockwise from north, in [0, 360).
    """
    dx = np.asarray(dx_m, dtype=np.float64)[:, None]
    b = np.degrees(np.arctan2(DI[None, :] * dx, DJ[None, :] * dy_m))
    return np.mod(b, 360.0)


# FORWARD_LEFT/RIGHT steer this fraction of the way to the neighbouring heading's bearing: the 24
# courses are then evenly spaced (a third of each gap between bearings), and each stays inside
# heading k's sector (which ends half-way), so the vehicle's heading still reads as k
# (docs/physical-model.md, "Courses").
COURSE_FRACTION = 1.0 / 3.0


def courses_deg(bearings: NDArray[np.float64]) -> NDArray[np.float64]:
    """Compass courses ``(ny, 8, 3)`` of FORWARD, FORWARD_LEFT and FORWARD_RIGHT per row and heading.

    Left is towards ``bearing_{k+1}`` (counter-clockwise, ROTATE_LEFT's heading), right towards
    ``bearing_{k-1}``; each ``COURSE_FRACTION`` of the angle between the two bearings.
    """
    b = np.asarray(bearings, dtype=np.float64)
    to_left = np.mod(b - np.roll(b, -1, axis=1), 360.0)  # clockwise angle from bearing_{k+1} up to bearing_k
    to_right = np.mod(np.roll(b, 1, axis=1) - b, 360.0)  # from bearing_k up to bearing_{k-1}
    return np.mod(np.stack([b, b - COURSE_FRACTION * to_left, b + COURSE_FRACTION * to_right], axis=2), 360.0)


def heading_index(heading_deg: float, row_bearings_deg: NDArray[np.float64]) -> int:
    """The ``k`` whose bearing in this row is nearest to ``heading_deg``; ties go to the lower ``k``."""
    diff = np.abs(np.mod(float(heading_deg) - row_bearings_deg + 180.0, 360.0) - 180.0)
    return int(np.argmin(diff))  # argmin returns the first (lowest k) of equal minima
