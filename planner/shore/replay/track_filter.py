"""The track without its position noise, and the track simplified to a tolerance.

A navigation fix jitters by its noise (the simulator: 0.5 m per axis at about 2 Hz; a
GPS or a DVL-aided INS: metres, partly correlated over minutes). Summing great
circles between every fix adds that jitter to the distance: about 0.9 m a fix for
0.5 m of white noise, 4x the distance of a 15 km dive. ``filter_track`` takes the
median position of each fix within consecutive windows of vehicle time
(``WINDOW_S``, 30 s by default) and keeps the first and last fix: the path through
those points is the track the summary measures and the exports and the map draw.

Why medians over windows: the noise left in a median of n fixes is about
1.25 sigma / sqrt(n) (0.08 m for 60 fixes of 0.5 m), a spike the autopilot let through
moves it not at all, and it is a few numpy passes for any length of log (the 7-day
soak's 1.2 million fixes). What it costs: a corner is cut by at most a window's run
(30 m at 1 m/s; a chord for an arc), and noise correlated over longer than a window
passes through. docs/replay.md gives the errors measured.

``simplify`` is Douglas-Peucker in a local east/north/up plane (metres): every point
left out lies within the tolerance of the simplified line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.contract.geodesy import EARTH_RADIUS_M

__all__ = ["FilteredTrack", "WINDOW_S", "SIMPLIFY_M", "filter_track", "local_xyz_m", "path_length_m", "simplify"]

WINDOW_S = 30.0  # vehicle seconds a median position covers
SIMPLIFY_M = 2.0  # default tolerance of the simplified track exports, metres


@dataclass(frozen=True, eq=False, kw_only=True)
class FilteredTrack:
    """Positions without their noise: the first fix, a median per window, the last fix. NaN depth: unknown."""

    time_s: NDArray[np.float64]  # vehicle time (the running latest, so never decreasing)
    lat_deg: NDArray[np.float64]
    lon_deg: NDArray[np.float64]
    depth_m: NDArray[np.float64]
    window_s: float
    fixes: int  # distinct fixes it was made from

    def __len__(self) -> int:
        return int(self.time_s.size)

    def length_m(self) -> float:
        return path_length_m(self.lat_deg, self.lon_deg)


def path_length_m(lat_deg: NDArray[np.float64], lon_deg: NDArray[np.float64]) -> float:
    """Sum of haversine distances between consecutive finite points, in metres (spec section 1 radius)."""
    ok = np.isfinite(lat_deg) & np.isfinite(lon_deg)
    lat, lon = np.radians(lat_deg[ok]), np.radians(lon_deg[ok])
    if lat.size < 2:
        return 0.0
    a = np.sin(np.diff(lat) / 2) ** 2 + np.cos(lat[:-1]) * np.cos(lat[1:]) * np.sin(np.diff(lon) / 2) ** 2
    return float(np.sum(2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.minimum(a, 1.0)))))


def filter_track(time_s: NDArray[np.float64], lat_deg: NDArray[np.float64], lon_deg: NDArray[np.float64],
                 depth_m: NDArray[np.float64], *, window_s: float = WINDOW_S) -> FilteredTrack:
    """The first fix, the median fix of each ``window_s`` of vehicle time, and the last fix.

    Rows without a position are skipped; a row that repeats the previous position (a
    decision made on an attitude message holds the last fix) counts once. Time is the
    running latest, so that a reboot's step back does not reorder windows. A window
    of a gap (link lost) has no point: the path joins its neighbours straight.
    """
    if not (math.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window_s: expected seconds > 0; got {window_s}")
    t = np.asarray(time_s, np.float64)
    lat, lon, depth = (np.asarray(a, np.float64) for a in (lat_deg, lon_deg, depth_m))
    rows = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon) & np.isfinite(t))
    if rows.size:
        new = np.concatenate([[True], (lat[rows][1:] != lat[rows][:-1]) | (lon[rows][1:] != lon[rows][:-1])])
        rows = rows[new]
    if rows.size < 3:
        return FilteredTrack(time_s=np.maximum.accumulate(t[rows]) if rows.size else t[rows], lat_deg=lat[rows],
                             lon_deg=lon[rows], depth_m=depth[rows], window_s=window_s, fixes=int(rows.size))
    tt = np.maximum.accumulate(t[rows])
    group = np.floor((tt - tt[0]) / window_s).astype(np.int64)
    _, group = np.unique(group, return_inverse=True)  # 0, 1, 2, ... without the empty windows
    out_t = group_median(tt, group)
    out_lat, out_lon, out_depth = (group_median(a[rows], group) for a in (lat, lon, depth))
    cat = np.concatenate
    return FilteredTrack(time_s=cat([tt[:1], out_t, tt[-1:]]), lat_deg=cat([lat[rows[:1]], out_lat, lat[rows[-1:]]]),
                         lon_deg=cat([lon[rows[:1]], out_lon, lon[rows[-1:]]]),
                         depth_m=cat([depth[rows[:1]], out_depth, depth[rows[-1:]]]), window_s=window_s,
                         fixes=int(rows.size))


def group_median(values: NDArray[np.float64], group: NDArray[np.int64]) -> NDArray[np.float64]:
    """The median of the finite ``values`` of each group 0 .. group.max() (NaN for a group with none)."""
    n_groups = int(group.max()) + 1 if group.size else 0
    ok = np.isfinite(values)
    v, g = values[ok], group[ok]
    order = np.lexsort((v, g))
    v = v[order]
    counts = np.bincount(g, minlength=n_groups)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = np.full(n_groups, np.nan)
    has = counts > 0
    lo = (starts + (counts - 1) // 2)[has]
    hi = (starts + counts // 2)[has]
    out[has] = 0.5 * (v[lo] + v[hi])
    return out


def local_xyz_m(lat_deg: NDArray[np.float64], lon_deg: NDArray[np.float64], depth_m: NDArray[np.float64], *,
                lat0_deg: float | None = None) -> NDArray[np.float64]:
    """East, north, up (-depth; 0 where unknown) in metres, equirectangular about ``lat0_deg`` (default the mean).

    Within a dive's few tens of kilometres the plane differs from the sphere by well
    under a part in a thousand.
    """
    lat0 = math.radians(float(np.mean(lat_deg)) if lat0_deg is None else lat0_deg) if len(lat_deg) else 0.0
    k = math.radians(1.0) * EARTH_RADIUS_M
    up = np.where(np.isfinite(depth_m), -np.asarray(depth_m, np.float64), 0.0)
    return np.column_stack([np.asarray(lon_deg, np.float64) * k * math.cos(lat0), np.asarray(lat_deg, np.float64) * k,
                            up])


def simplify(points_m: NDArray[np.float64], tolerance_m: float) -> NDArray[np.int64]:
    """Douglas-Peucker: the indices of ``points_m`` (n, d) to keep, first and last always.

    Every point left out lies within ``tolerance_m`` of the segment between the kept
    points around it. A tolerance of 0 keeps every point not exactly on its segment.
    """
    n = len(points_m)
    if not (math.isfinite(tolerance_m) and tolerance_m >= 0):
        raise ValueError(f"tolerance_m: expected metres >= 0; got {tolerance_m}")
    if n <= 2:
        return np.arange(n, dtype=np.int64)
    keep = np.zeros(n, dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        d = distance_to_segment_m(points_m[a + 1:b], points_m[a], points_m[b])
        far = int(np.argmax(d))
        if d[far] > tolerance_m:
            m = a + 1 + far
            keep[m] = True
            stack += [(a, m), (m, b)]
    return np.flatnonzero(keep).astype(np.int64)


def distance_to_segment_m(points: NDArray[np.float64], a: NDArray[np.float64],
                          b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each point's distance to the segment ``a``-``b`` (same units as the points)."""
    ab = b - a
    length2 = float(np.dot(ab, ab))
    if length2 == 0.0:
        return np.linalg.norm(points - a, axis=-1)
    t = np.clip((points - a) @ ab / length2, 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=-1)
