"""The simulated ocean: true currents from a forecast file, looked up fast, one point at a time.

A ``World`` holds the currents on a regular lon/lat grid, ``(T, Z, Y, X)`` float64 with NaN
for land, read with ``planner.forecast.open_forecast``. Curvilinear forecasts and forecasts
with per-column (terrain-following) depths are put onto a regular grid once, at load, with
``planner.forecast.resample.resample`` (the planner's own spec section 1 rules), at about their native
resolution.

``current_at`` is called once per physics step, so it is plain Python: ``bisect`` on the
axes, then quadrilinear interpolation (time, depth, lat, lon) of the 16 surrounding nodes,
which are copied out of the numpy arrays into Python floats once per grid cell and cached.
Coverage rules follow the planner (spec section 1): a point that gives non-zero weight to a
land (NaN) node is land; shallower than the first level takes the first level; deeper than
the last level, or outside the lon/lat box, is not covered. Where there is no water the
current is 0 and ``is_water`` says False. Times before the first or after the last forecast
time take the first or last field.

A ``TruthSequence`` strings several dated Worlds together in order of their first times
(e.g. successive forecast issues, a later issue serving as truth): at time ``t`` the current
comes from the latest member whose first time is <= ``t`` (the first member before any).
``load_truth`` reads one file (a plain ``World``), several files, or a directory of ``*.nc``.
"""

from __future__ import annotations

import math
import os
import warnings
from bisect import bisect_right
from collections.abc import Iterable
from dataclasses import dataclass, field
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import LrauvError, SimulatorError
from planner.grid import Grid
from planner.contract.geodesy import BBox

if TYPE_CHECKING:
    from planner.forecast import Forecast

_CACHE_MAX_CELLS = 65_536  # cached 16-node blocks (a few MB); cleared when full
_MAX_RESAMPLED_POINTS = 2_000_000  # per level: caps the regular grid made for a curvilinear forecast


class WorldError(SimulatorError):
    """A truth forecast the simulator cannot use; the message names the file."""


# (u nodes, v nodes, True when no node is NaN) of one cell; nodes in [t][z][y][x] order, 2 each.
_Block = tuple[tuple[float, ...], tuple[float, ...], bool]


@dataclass(frozen=True, eq=False, kw_only=True)
class World:
    """True currents, east/north m/s, on a regular grid (T, Z, Y, X); NaN = land.

    Every axis has at least two nodes (a single time or level is repeated), so each
    lookup interpolates between exactly two nodes per axis. ``time_s`` counts from the
    forecast's first time. ``depth_covered_m`` is the deepest covered depth (inf when the
    forecast has no depth axis and its field applies at every depth).
    """

    source: str
    time_s: tuple[float, ...]
    depth_m: tuple[float, ...]
    lat_deg: tuple[float, ...]
    lon_deg: tuple[float, ...]
    u_east_m_s: NDArray[np.float64]
    v_north_m_s: NDArray[np.float64]
    start_unix_s: float = 0.0  # unix time of time_s = 0; 0 when the forecast has no reference date
    dated: bool = False  # True when the forecast's times have a reference date
    duration_s: float = math.inf  # last forecast time; 0 for a single step, inf for a uniform world
    depth_covered_m: float = math.inf
    # Nodes of the cells looked up so far, as Python floats (the only mutable part).
    _cache: dict[tuple[int, int, int, int], _Block] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        shape = (len(self.time_s), len(self.depth_m), len(self.lat_deg), len(self.lon_deg))
        if self.u_east_m_s.shape != shape or self.v_north_m_s.shape != shape:
            raise WorldError(f"{self.source}: currents: expected shape {shape}; got {self.u_east_m_s.shape}")
        for name in ("time_s", "depth_m", "lat_deg", "lon_deg"):
            axis = getattr(self, name)
            if len(axis) < 2 or any(b <= a for a, b in pairwise(axis)):
                raise WorldError(f"{self.source}: {name}: expected at least 2 strictly increasing values")
        for arr in (self.u_east_m_s, self.v_north_m_s):
            arr.setflags(write=False)

    # -- construction -------------------------------------------------------------------

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> World:
        """Read a forecast file (any layout ``open_forecast`` reads) as the truth."""
        from planner.forecast import open_forecast

        try:
            forecast = open_forecast(path)
        except LrauvError as exc:
            raise WorldError(str(exc)) from exc
        return cls.from_forecast(forecast)

    @classmethod
    def from_forecast(cls, forecast: Forecast) -> World:
        """A world from a ``planner.forecast.Forecast``; resampled once when not regular."""
        src = forecast.source
        if forecast.is_regular and not forecast.has_per_column_depth:
            lon, lat = forecast.lon_deg, forecast.lat_deg
            depth = forecast.depth_m
            u, v = forecast.u_east_m_s, forecast.v_north_m_s
        else:
            lon, lat, depth, u, v = _regularize(forecast)
        if lon.size < 2 or lat.size < 2:
            raise WorldError(f"{src}: expected at least 2 longitudes and 2 latitudes; got {lon.size} x {lat.size}")
        times = forecast.times
        start_unix_s = 0.0 if times is None else float(times[0].astype("datetime64[ms]").astype(np.int64)) / 1000.0
        time_s = np.asarray(forecast.time_s, dtype=np.float64) - float(forecast.time_s[0])
        if depth is None:  # the field applies at every depth
            depth_axis, covered = np.array([0.0]), math.inf
        else:
            depth_axis, covered = np.asarray(depth, dtype=np.float64), float(depth[-1])
        duration_s = float(time_s[-1])
        time_s, u, v = _at_least_two(time_s, u, v, dim=0, step=3600.0)
        depth_axis, u, v = _at_least_two(depth_axis, u, v, dim=1, step=1.0)
        return cls(
            source=src, time_s=tuple(time_s.tolist()), depth_m=tuple(depth_axis.tolist()),
            lat_deg=tuple(np.asarray(lat, dtype=np.float64).tolist()),
            lon_deg=tuple(np.asarray(lon, dtype=np.float64).tolist()),
            u_east_m_s=np.array(u, dtype=np.float64), v_north_m_s=np.array(v, dtype=np.float64),
            start_unix_s=start_unix_s, dated=times is not None, duration_s=duration_s, depth_covered_m=covered,
        )

    @classmethod
    def uniform(cls, u_east_m_s: float = 0.0, v_north_m_s: float = 0.0, *, start_unix_s: float = 0.0) -> World:
        """The same current everywhere, at every depth and time: the whole globe is water."""
        shape = (2, 2, 2, 2)
        return cls(
            source=f"uniform current ({u_east_m_s:g}, {v_north_m_s:g}) m/s", time_s=(0.0, 1.0), depth_m=(0.0, 1.0),
            lat_deg=(-90.0, 90.0), lon_deg=(-180.0, 180.0),
            u_east_m_s=np.full(shape, float(u_east_m_s)), v_north_m_s=np.full(shape, float(v_north_m_s)),
            start_unix_s=start_unix_s, dated=True,
        )

    @classmethod
    def calm(cls, *, start_unix_s: float = 0.0) -> World:
        """Still water everywhere (tests, bench runs)."""
        return cls.uniform(0.0, 0.0, start_unix_s=start_unix_s)

    # -- what the simulator asks ----------------------------------------------------------

    @property
    def bbox(self) -> BBox:
        return BBox(west_deg=self.lon_deg[0], south_deg=self.lat_deg[0], east_deg=self.lon_deg[-1],
                    north_deg=self.lat_deg[-1])

    @property
    def max_depth_m(self) -> float:
        """Deepest depth with currents (inf when the forecast has no depth axis)."""
        return self.depth_covered_m

    def source_at(self, t_s: float) -> str:
        """The file that gives the current at ``t_s``."""
        return self.source

    def current_at(self, t_s: float, lat_deg: float, lon_deg: float, depth_m: float) -> tuple[float, float]:
        """(east, north) current in m/s at a point; (0, 0) where there is no water."""
        at = self._locate(t_s, lat_deg, lon_deg, depth_m)
        if at is None:
            return 0.0, 0.0
        key, wt, wz, wy, wx = at
        block = self._cache.get(key)
        if block is None:
            block = self._load_block(key)
        u, v, clean = block
        if clean:
            return _interp16(u, wt, wz, wy, wx), _interp16(v, wt, wz, wy, wx)
        return _interp16_masked(u, v, wt, wz, wy, wx)

    def is_water(self, lat_deg: float, lon_deg: float, depth_m: float, t_s: float = 0.0) -> bool:
        """True inside the covered box and depth range where no land node carries weight."""
        at = self._locate(t_s, lat_deg, lon_deg, depth_m)
        if at is None:
            return False
        key, wt, wz, wy, wx = at
        block = self._cache.get(key) or self._load_block(key)
        if block[2]:
            return True
        return not math.isnan(_interp16_masked(block[0], block[1], wt, wz, wy, wx, land=math.nan)[0])

    # -- internals ---------------------------------------------------------------------------

    def _locate(
        self, t_s: float, lat_deg: float, lon_deg: float, depth_m: float
    ) -> tuple[tuple[int, int, int, int], float, float, float, float] | None:
        lat, lon = self.lat_deg, self.lon_deg
        if not (lat[0] <= lat_deg <= lat[-1]):
            return None
        if not (lon[0] <= lon_deg <= lon[-1]):
            lon_deg = lon[0] + (lon_deg - lon[0]) % 360.0  # a 0..360 forecast asked in -180..180, or back
            if not (lon[0] <= lon_deg <= lon[-1]):
                return None
        times, depths = self.time_s, self.depth_m
        t = min(max(t_s, times[0]), times[-1])  # clamp beyond the forecast's ends
        if depth_m > self.depth_covered_m:
            return None
        d = min(max(depth_m, depths[0]), depths[-1])  # above the first level: the first level's value
        it, wt = _bracket(times, t)
        iz, wz = _bracket(depths, d)
        iy, wy = _bracket(lat, lat_deg)
        ix, wx = _bracket(lon, lon_deg)
        return (it, iz, iy, ix), wt, wz, wy, wx

    def _load_block(self, key: tuple[int, int, int, int]) -> _Block:
        it, iz, iy, ix = key
        sl = (slice(it, it + 2), slice(iz, iz + 2), slice(iy, iy + 2), slice(ix, ix + 2))
        u = self.u_east_m_s[sl].ravel()
        v = self.v_north_m_s[sl].ravel()
        clean = bool(np.all(np.isfinite(u)) and np.all(np.isfinite(v)))
        block: _Block = (tuple(u.tolist()), tuple(v.tolist()), clean)
        if len(self._cache) >= _CACHE_MAX_CELLS:
            self._cache.clear()
        self._cache[key] = block
        return block


@dataclass(frozen=True, eq=False)
class TruthSequence:
    """Dated Worlds one after another: each is the truth from its own first time until the next one's.

    ``members`` are sorted by ``start_unix_s`` at construction; ``t_s`` counts from the first
    member's start. At ``t_s`` the latest member with ``start <= t_s`` answers, at its own
    time ``t_s - offset`` (so past its last time it holds its last field until the next
    member takes over); before the first start the first member answers. Members may
    overlap in time and need not share a grid; ``bbox`` and ``max_depth_m`` are what every
    member covers. Two members with the same start, or an undated member among several,
    raise ``WorldError``.
    """

    members: tuple[World, ...]
    offsets_s: tuple[float, ...] = field(init=False)  # member i's start, seconds after the first's
    bbox: BBox = field(init=False)  # the lon/lat box every member covers (the first member's longitudes)

    def __post_init__(self) -> None:
        ordered = _ordered_members(tuple(self.members))
        object.__setattr__(self, "members", ordered)
        object.__setattr__(self, "offsets_s", tuple(w.start_unix_s - ordered[0].start_unix_s for w in ordered))
        object.__setattr__(self, "bbox", _common_box(ordered))  # raises when the members share no area

    @property
    def source(self) -> str:
        return " + ".join(w.source for w in self.members)

    @property
    def start_unix_s(self) -> float:
        return self.members[0].start_unix_s

    @property
    def dated(self) -> bool:
        return all(w.dated for w in self.members)

    @property
    def duration_s(self) -> float:
        """Last time any member covers, seconds after the first start."""
        return max(off + w.duration_s for off, w in zip(self.offsets_s, self.members, strict=True))

    @property
    def max_depth_m(self) -> float:
        """Deepest depth every member covers."""
        return min(w.max_depth_m for w in self.members)

    def source_at(self, t_s: float) -> str:
        return self._member(t_s)[0].source

    def current_at(self, t_s: float, lat_deg: float, lon_deg: float, depth_m: float) -> tuple[float, float]:
        """(east, north) current in m/s from the member in charge at ``t_s``; (0, 0) where there is no water."""
        world, local_s = self._member(t_s)
        return world.current_at(local_s, lat_deg, lon_deg, depth_m)

    def is_water(self, lat_deg: float, lon_deg: float, depth_m: float, t_s: float = 0.0) -> bool:
        world, local_s = self._member(t_s)
        return world.is_water(lat_deg, lon_deg, depth_m, local_s)

    def _member(self, t_s: float) -> tuple[World, float]:
        """The member in charge at ``t_s`` and the time in its own terms."""
        i = max(bisect_right(self.offsets_s, t_s) - 1, 0)
        return self.members[i], t_s - self.offsets_s[i]


Truth = World | TruthSequence  # what the simulator's ocean can be


def load_truth(paths: Iterable[str | os.PathLike[str]]) -> World | TruthSequence:
    """The truth from forecast files: one file is a plain ``World``, several a ``TruthSequence``.

    A directory stands for every ``*.nc`` directly in it. Errors name the file.
    """
    files = [f for p in paths for f in forecast_files(p)]
    if not files:
        raise WorldError("no forecast given; expected one or more netCDF files or a directory of them")
    worlds = [World.load(f) for f in files]
    return worlds[0] if len(worlds) == 1 else TruthSequence(tuple(worlds))


def forecast_files(path: str | os.PathLike[str]) -> list[str]:
    """``[path]`` for a file (checked on load), or the ``*.nc`` files of a directory, sorted by name."""
    if not os.path.isdir(path):
        return [os.fspath(path)]
    found = sorted(e.path for e in os.scandir(path) if e.name.endswith(".nc") and e.is_file())
    if not found:
        raise WorldError(f"{os.fspath(path)}: no *.nc files in this directory; expected netCDF forecasts")
    return found


def _ordered_members(members: tuple[World, ...]) -> tuple[World, ...]:
    """``members`` sorted by start time; checks there is one, all are dated (when several), starts differ."""
    if not members:
        raise WorldError("truth sequence: expected at least one forecast")
    if len(members) > 1:
        for w in members:
            if not w.dated:
                raise WorldError(f"{w.source}: its times have no reference date; every forecast of a truth "
                                 "sequence needs one (time units like 'hours since 2026-01-15 00:00:00')")
    ordered = tuple(sorted(members, key=lambda w: w.start_unix_s))
    for a, b in pairwise(ordered):
        if b.start_unix_s == a.start_unix_s:
            raise WorldError(f"{b.source}: starts at the same time as {a.source}; expected one forecast per "
                             "start time in a truth sequence")
    return ordered


def _common_box(members: tuple[World, ...]) -> BBox:
    """Intersection of the members' lon/lat boxes, longitudes shifted by 360 to the first's convention."""
    first = members[0].bbox
    west, south, east, north = first.west_deg, first.south_deg, first.east_deg, first.north_deg
    mid = 0.5 * (west + east)
    for w in members[1:]:
        box = w.bbox
        shift = 360.0 * round((mid - 0.5 * (box.west_deg + box.east_deg)) / 360.0)
        west, east = max(west, box.west_deg + shift), min(east, box.east_deg + shift)
        south, north = max(south, box.south_deg), min(north, box.north_deg)
        if not (west < east and south < north):
            raise WorldError(f"{w.source}: shares no lon/lat area with the other forecasts of the truth sequence; "
                             "expected forecasts of one region")
    return BBox(west_deg=west, south_deg=south, east_deg=east, north_deg=north)


def _bracket(axis: tuple[float, ...], x: float) -> tuple[int, float]:
    """Lower node index i (axis[i] <= x <= axis[i + 1]) and the weight of node i + 1."""
    i = bisect_right(axis, x) - 1
    last = len(axis) - 2
    if i > last:
        i = last
    elif i < 0:
        i = 0
    a = axis[i]
    return i, (x - a) / (axis[i + 1] - a)


def _interp16(c: tuple[float, ...], wt: float, wz: float, wy: float, wx: float) -> float:
    """Quadrilinear interpolation of 16 nodes in [t][z][y][x] order."""
    ax = 1.0 - wx
    x0 = c[0] * ax + c[1] * wx
    x1 = c[2] * ax + c[3] * wx
    x2 = c[4] * ax + c[5] * wx
    x3 = c[6] * ax + c[7] * wx
    x4 = c[8] * ax + c[9] * wx
    x5 = c[10] * ax + c[11] * wx
    x6 = c[12] * ax + c[13] * wx
    x7 = c[14] * ax + c[15] * wx
    ay = 1.0 - wy
    y0 = x0 * ay + x1 * wy
    y1 = x2 * ay + x3 * wy
    y2 = x4 * ay + x5 * wy
    y3 = x6 * ay + x7 * wy
    az = 1.0 - wz
    z0 = y0 * az + y1 * wz
    z1 = y2 * az + y3 * wz
    return z0 * (1.0 - wt) + z1 * wt


def _interp16_masked(
    u: tuple[float, ...], v: tuple[float, ...], wt: float, wz: float, wy: float, wx: float, *, land: float = 0.0
) -> tuple[float, float]:
    """Like ``_interp16`` for both components, but any NaN node with non-zero weight makes it land."""
    su = sv = 0.0
    n = 0
    for a in (1.0 - wt, wt):
        for b in (1.0 - wz, wz):
            for c in (1.0 - wy, wy):
                for d in (1.0 - wx, wx):
                    w = a * b * c * d
                    if w > 0.0:
                        if math.isnan(u[n]) or math.isnan(v[n]):
                            return land, land
                        su += w * u[n]
                        sv += w * v[n]
                    n += 1
    return su, sv


def _at_least_two(
    values: NDArray[np.float64], u: NDArray[np.float64], v: NDArray[np.float64], *, dim: int, step: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Repeat a single time step or level once (``step`` later/deeper), so every axis has two nodes."""
    if values.size >= 2:
        return values, u, v
    return np.array([values[0], values[0] + step]), np.repeat(u, 2, axis=dim), np.repeat(v, 2, axis=dim)


def _regularize(
    forecast: Forecast,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64],
           NDArray[np.float64]]:
    """(lon, lat, depth or None, u, v) of a curvilinear or per-column-depth forecast on a regular grid.

    The grid spans the forecast's lon/lat range at about its native spacing (the median
    distance between neighbouring points); the levels are the forecast's own, or for
    terrain-following levels the median depth of each level at the first time.
    """
    from planner.forecast.resample import resample

    src = forecast.source
    if forecast.depth_m is None:
        levels = np.array([0.0])
    elif forecast.depth_m.ndim == 1:
        levels = np.asarray(forecast.depth_m, dtype=np.float64)
    else:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN levels
            med = np.nanmedian(forecast.depth_m[0].reshape(forecast.n_levels, -1), axis=1)
        levels = np.unique(np.clip(med[np.isfinite(med)], 0.0, None))
        if levels.size == 0:
            raise WorldError(f"{src}: no finite level depths; expected terrain-following levels over water")
    if forecast.is_regular:  # per-column depths only: keep the forecast's own lon/lat
        grid = Grid(lon_deg=forecast.lon_deg, lat_deg=forecast.lat_deg, depth_m=levels)
    else:
        grid = _native_grid(forecast, levels)
    fields = [resample(forecast, grid, time_index=t) for t in range(forecast.n_times)]
    u = np.stack([f[0] for f in fields])
    v = np.stack([f[1] for f in fields])
    depth = None if forecast.depth_m is None else grid.depth_m
    return grid.lon_deg, grid.lat_deg, depth, u, v


def _native_grid(forecast: Forecast, levels: NDArray[np.float64]) -> Grid:
    """A regular grid over a curvilinear forecast's lon/lat range at its median point spacing."""
    lon2, lat2 = forecast.lon_deg, forecast.lat_deg
    mid_lat = math.radians(float(np.nanmean(lat2)))
    steps = []
    for ax in (0, 1):
        dx = np.diff(lon2, axis=ax) * math.cos(mid_lat)
        dy = np.diff(lat2, axis=ax)
        steps.append(float(np.nanmedian(np.hypot(dx, dy))))
    spacing_deg = min(steps)  # in degrees of latitude
    west, east = float(np.nanmin(lon2)), float(np.nanmax(lon2))
    south, north = float(np.nanmin(lat2)), float(np.nanmax(lat2))
    if not (spacing_deg > 0 and west < east and south < north):
        raise WorldError(f"{forecast.source}: cannot find the spacing of its lon/lat points; expected a 2-D grid")
    nx = round((east - west) * math.cos(mid_lat) / spacing_deg) + 1
    ny = round((north - south) / spacing_deg) + 1
    scale = math.sqrt(max(1.0, nx * ny / _MAX_RESAMPLED_POINTS))
    nx, ny = max(2, int(nx / scale)), max(2, int(ny / scale))
    return Grid.from_bbox(BBox(west_deg=west, south_deg=south, east_deg=east, north_deg=north), nx=nx, ny=ny,
                          depths_m=levels)
