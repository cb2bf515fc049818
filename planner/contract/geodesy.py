"""The Earth as the spec models it: a sphere of one radius, flat within a cell (spec section 1).

Standard library and numpy only: shore, vehicle and simulator share these figures.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.contract.errors import GridError

EARTH_RADIUS_M = 6_371_000.0  # spec section 1
M_PER_DEG_LAT = EARTH_RADIUS_M * math.pi / 180.0  # metres per degree of latitude on that sphere


@dataclass(frozen=True, eq=False, kw_only=True)
class BBox:
    """A box in degrees, GIS order; cell centres lie on its edges (spec section 1)."""

    west_deg: float
    south_deg: float
    east_deg: float
    north_deg: float

    def __post_init__(self) -> None:
        values = (self.west_deg, self.south_deg, self.east_deg, self.north_deg)
        if not all(np.isfinite(values)):
            raise GridError(f"bbox: expected four finite numbers WEST,SOUTH,EAST,NORTH; got {values}")
        if not (self.west_deg < self.east_deg and self.south_deg < self.north_deg):
            raise GridError(
                f"bbox: expected WEST < EAST and SOUTH < NORTH; got west={self.west_deg}, "
                f"south={self.south_deg}, east={self.east_deg}, north={self.north_deg}"
            )
        if not (-90.0 <= self.south_deg and self.north_deg <= 90.0):
            raise GridError(f"bbox: latitudes must lie in [-90, 90]; got {self.south_deg}..{self.north_deg}")



def swap_hint(lon_deg: float, lat_deg: float, *, fits: Callable[[float, float], bool] | None = None) -> str:
    """``"; did you mean LAT,LON (lon,lat)?"`` when the pair reads better swapped, else ``""``.

    Better swapped: out of range as given ([-180, 180], [-90, 90]) but in range the other way round,
    or, with ``fits(lon, lat)`` (inside a grid, say), not fitting as given but fitting swapped.
    """
    def in_range(lon: float, lat: float) -> bool:
        return math.isfinite(lon) and math.isfinite(lat) and -180 <= lon <= 180 and -90 <= lat <= 90

    if not in_range(lat_deg, lon_deg):
        return ""
    if in_range(lon_deg, lat_deg) and (fits is None or fits(lon_deg, lat_deg) or not fits(lat_deg, lon_deg)):
        return ""
    return f"; did you mean {lat_deg:g},{lon_deg:g} (lon,lat)?"
