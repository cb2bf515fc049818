"""The mission's geofence: a lon/lat polygon the vehicle must stay inside (docs/missions.md, ``safety.geofence``)."""

from __future__ import annotations

from collections.abc import Sequence


def inside(lon_deg: float, lat_deg: float, polygon: Sequence[tuple[float, float]]) -> bool:
    """True when the point is inside the polygon of ``(lon_deg, lat_deg)`` vertices (even-odd rule).

    Planar in degrees, which is exact enough for fences of tens of kilometres away from
    the poles and the antimeridian; a point on an edge may fall either side.
    """
    hit = False
    n = len(polygon)
    for a in range(n):
        x1, y1 = polygon[a]
        x2, y2 = polygon[(a + 1) % n]
        if (y1 > lat_deg) != (y2 > lat_deg):  # the edge straddles the point's latitude
            x_cross = x1 + (lat_deg - y1) * (x2 - x1) / (y2 - y1)
            if lon_deg < x_cross:
                hit = not hit
    return hit
