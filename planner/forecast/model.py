"""The ``Forecast`` value and the time axis values (``ForecastTimes``, ``nearest_time_index``).

Pure numpy: what a reader hands back, checked once when it is built. Velocities are
eastward/northward m/s with NaN for land (spec section 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ForecastError

# Longitudes run -180..180 or 0..360 (a few products go further west); beyond this a file's
# "degrees" are something else.
MAX_ABS_LON_DEG = 360.0
# Times this far from their origin overflow datetime64[ms] arithmetic (about 292,000 years).
_MAX_ABS_TIME_S = 1e13


@dataclass(frozen=True, eq=False, kw_only=True)
class Forecast:
    """A current forecast, eastward/northward m/s, NaN = land (spec section 1).

    Velocity arrays are ``(T, Z, Y, X)``. Regular grids have 1-D ``lon_deg`` (X,) and
    ``lat_deg`` (Y,), both strictly increasing; curvilinear and projected grids have 2-D
    ``lon_deg``/``lat_deg`` (Y, X). ``depth_m`` is None (no depth axis: the field applies to
    every layer, Z = 1), (Z,) fixed levels (positive down, strictly increasing), or
    (T, Z, Y, X) per-column depths of terrain-following levels, shallowest level first.
    """

    source: str
    identity: str
    time_s: NDArray[np.float64]
    time_origin: str | None
    lon_deg: NDArray[np.float64]
    lat_deg: NDArray[np.float64]
    depth_m: NDArray[np.float64] | None
    u_east_m_s: NDArray[np.float64]
    v_north_m_s: NDArray[np.float64]
    notes: tuple[str, ...] = ()
    # Names of the file's two velocity variables, for `describe`.
    variables: tuple[str, ...] = ()
    # True: a layer shallower than the first level takes that level's value (spec section 1).
    # False when the first level is not the model's top level (CROCO files that keep only the
    # bottom s-levels): depths above the first level are not covered and count as land.
    covers_surface: bool = True
    # Where this value sits in its file when only part of it was read (open_forecast with bbox=,
    # time_index= or member=); None: the whole file.
    window: ForecastWindow | None = None

    def __post_init__(self) -> None:
        src = self.source
        time_s = _frozen(self.time_s)
        u = _frozen(self.u_east_m_s)
        v = _frozen(self.v_north_m_s)
        lon = _frozen(self.lon_deg)
        lat = _frozen(self.lat_deg)
        depth = None if self.depth_m is None else _frozen(self.depth_m)
        if time_s.ndim != 1 or time_s.size < 1 or not np.all(np.isfinite(time_s)):
            raise ForecastError(f"{src}: time_s: expected a 1-D array of finite seconds; got shape {time_s.shape}")
        if time_s.size > 1 and np.any(np.diff(time_s) <= 0):
            raise ForecastError(f"{src}: time_s: expected strictly increasing times; got {time_s.tolist()[:6]}...")
        if u.ndim != 4 or u.shape != v.shape:
            raise ForecastError(
                f"{src}: u/v: expected two arrays of the same shape (T, Z, Y, X); got {u.shape} and {v.shape}"
            )
        n_t, n_z, n_y, n_x = u.shape
        if n_t != time_s.size:
            raise ForecastError(f"{src}: u/v have {n_t} time steps but time_s has {time_s.size}")
        if lon.ndim == 1 and lat.ndim == 1:
            if lon.shape != (n_x,) or lat.shape != (n_y,):
                raise ForecastError(
                    f"{src}: lon/lat: expected shapes ({n_x},) and ({n_y},) to match u/v {u.shape}; "
                    f"got {lon.shape} and {lat.shape}"
                )
            for name, axis in (("lon_deg", lon), ("lat_deg", lat)):
                if not np.all(np.isfinite(axis)) or (axis.size > 1 and np.any(np.diff(axis) <= 0)):
                    raise ForecastError(f"{src}: {name}: expected finite, strictly increasing values")
        elif lon.ndim == 2 and lat.ndim == 2:
            if lon.shape != (n_y, n_x) or lat.shape != (n_y, n_x):
                raise ForecastError(
                    f"{src}: 2-D lon/lat: expected shape ({n_y}, {n_x}) to match u/v {u.shape}; "
                    f"got {lon.shape} and {lat.shape}"
                )
        else:
            raise ForecastError(f"{src}: lon/lat: expected both 1-D or both 2-D; got {lon.ndim}-D and {lat.ndim}-D")
        for name, axis, bound in (("lon_deg", lon, MAX_ABS_LON_DEG), ("lat_deg", lat, 90.0)):
            finite = axis[np.isfinite(axis)]
            if finite.size and (finite.min() < -bound or finite.max() > bound):
                raise ForecastError(
                    f"{src}: {name}: values {finite.min():g}..{finite.max():g} lie outside [-{bound:g}, {bound:g}] "
                    "degrees; expected longitudes and latitudes in degrees (check the coordinate variables and their units)"
                )
        check_time_range(time_s, src)
        if depth is None:
            if n_z != 1:
                raise ForecastError(f"{src}: depth_m is None (no depth axis) but u/v have {n_z} levels; expected 1")
        elif depth.ndim == 1:
            if depth.shape != (n_z,) or not np.all(np.isfinite(depth)) or np.any(np.diff(depth) <= 0):
                raise ForecastError(
                    f"{src}: depth_m: expected {n_z} finite levels, positive down, strictly increasing; "
                    f"got {depth.tolist()[:12]}"
                )
        elif depth.shape != u.shape:
            raise ForecastError(f"{src}: per-column depth_m: expected shape {u.shape}; got {depth.shape}")
        if self.time_origin is not None:
            parse_origin(self.time_origin, src)
        if self.window is not None:
            _check_window(self.window, time_s.size, lon, lat, src)
        arrays = {"time_s": time_s, "u_east_m_s": u, "v_north_m_s": v, "lon_deg": lon, "lat_deg": lat}
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "depth_m", depth)
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        object.__setattr__(self, "variables", tuple(str(n) for n in self.variables))

    @property
    def n_times(self) -> int:
        return int(self.u_east_m_s.shape[0])

    @property
    def n_levels(self) -> int:
        return int(self.u_east_m_s.shape[1])

    @property
    def shape(self) -> tuple[int, int, int, int]:
        """``(T, Z, Y, X)``."""
        t, z, y, x = self.u_east_m_s.shape
        return (int(t), int(z), int(y), int(x))

    @property
    def is_regular(self) -> bool:
        """True for 1-D lon/lat axes (separable interpolation, spec section 1)."""
        return self.lon_deg.ndim == 1

    @property
    def has_per_column_depth(self) -> bool:
        return self.depth_m is not None and self.depth_m.ndim == 4

    @property
    def times(self) -> NDArray[np.datetime64] | None:
        """Time steps as ``datetime64[ms]`` (UTC), or None when the file gives no reference date."""
        if self.time_origin is None:
            return None
        origin = parse_origin(self.time_origin, self.source)
        return origin + np.round(self.time_s * 1000.0).astype("timedelta64[ms]")

    def step_index(self, file_time_index: int) -> int:
        """Index into ``time_s`` (and the velocities' T axis) of the file's time step ``file_time_index``.

        The same number for a forecast that holds every step; 0 for a window opened with
        ``time_index=file_time_index``. ForecastError when this value does not hold that step.
        """
        if isinstance(file_time_index, bool) or not isinstance(file_time_index, (int, np.integer)):
            raise ForecastError(f"{self.source}: time index: expected an integer; got {file_time_index!r}")
        index = int(file_time_index)
        window = self.window
        held = None if window is None else window.time_index
        if window is None or held is None:
            if not 0 <= index < self.n_times:
                raise ForecastError(
                    f"{self.source}: time index {index} out of range: the forecast has {self.n_times} time steps, "
                    f"valid indices 0..{self.n_times - 1}"
                )
            return index
        if index != held:
            raise ForecastError(
                f"{self.source}: time index {index}: this forecast was opened with time_index={held} and holds only "
                f"that step of the file's {window.n_times}; open the file again with time_index={index}"
            )
        return 0

    @property
    def file_lon_lat(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Longitudes and latitudes of the whole file's grid (this value's own unless it is a lon/lat window)."""
        w = self.window
        if w is not None and w.file_lon_deg is not None and w.file_lat_deg is not None:
            return w.file_lon_deg, w.file_lat_deg
        return self.lon_deg, self.lat_deg


@dataclass(frozen=True, eq=False, kw_only=True)
class ForecastWindow:
    """The part of its file a ``Forecast`` holds (``open_forecast`` with ``bbox=``, ``time_index=``, ``member=``).

    Index ranges are ``[start, stop)`` along the file's axes as the Forecast orders them
    (ascending lon/lat, a repeated +360 deg column dropped); None means the whole axis.
    ``file_lon_deg``/``file_lat_deg`` are the whole file's 1-D axes of a regular grid when a
    lon/lat window was cut (None otherwise): ``planner.forecast.resample`` takes its snapping
    tolerance and longitude wrap from them, so a window resamples exactly as the whole file.
    """

    n_times: int  # time steps in the file
    time_index: int | None = None  # the file's step held (time_s has that one value); None: every step
    n_members: int = 1  # ensemble members in the file (1: no member dimension)
    member: int | None = None  # the member held; None: opened without member=
    member_dim: str | None = None
    lon_index: tuple[int, int] | None = None
    lat_index: tuple[int, int] | None = None
    file_lon_deg: NDArray[np.float64] | None = None
    file_lat_deg: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        for name in ("file_lon_deg", "file_lat_deg"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _frozen(value))
        for name in ("lon_index", "lat_index"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, (int(value[0]), int(value[1])))


def _check_window(w: ForecastWindow, n_t: int, lon: NDArray[np.float64], lat: NDArray[np.float64], src: str) -> None:
    if not isinstance(w, ForecastWindow):
        raise ForecastError(f"{src}: window: expected a ForecastWindow; got {type(w).__name__}")
    if w.time_index is not None and (n_t != 1 or not 0 <= w.time_index < w.n_times):
        raise ForecastError(
            f"{src}: window: time step {w.time_index} of {w.n_times} held, so time_s must have one value; got {n_t}"
        )
    if w.member is not None and not 0 <= w.member < w.n_members:
        raise ForecastError(f"{src}: window: member {w.member} out of range 0..{w.n_members - 1}")
    for name, index, whole, axis in (
        ("lon", w.lon_index, w.file_lon_deg, lon),
        ("lat", w.lat_index, w.file_lat_deg, lat),
    ):
        if index is None:
            continue
        if whole is None or axis.ndim != 1 or not np.array_equal(whole[index[0] : index[1]], axis):
            raise ForecastError(f"{src}: window: {name} index range {index} does not match the file's {name} axis")


def check_time_range(time_s: NDArray[np.float64], src: str) -> None:
    """Refuse times too far from their origin for datetime64[ms] (a wrong time unit, most likely)."""
    if time_s.size and np.max(np.abs(time_s)) > _MAX_ABS_TIME_S:
        raise ForecastError(
            f"{src}: time_s: {np.max(np.abs(time_s)):g} s from the time origin; expected times within "
            f"{_MAX_ABS_TIME_S:g} s (about 300,000 years) of it (check the time units)"
        )


def _frozen(a: Any) -> NDArray[np.float64]:
    arr = np.array(a, dtype=np.float64)  # always a copy, so the caller's array cannot change ours
    arr.setflags(write=False)
    return arr


def parse_origin(origin: str, src: str) -> np.datetime64:
    """``time_origin`` ('2023-02-25T12:00:00Z') as ``datetime64[ms]`` (UTC)."""
    text = origin.strip()
    if text.endswith("Z"):
        text = text[:-1]
    try:
        return np.datetime64(text, "ms")
    except ValueError as exc:
        raise ForecastError(
            f"{src}: time_origin: expected an ISO-8601 UTC time such as '2023-02-25T12:00:00Z'; got {origin!r}"
        ) from exc


@dataclass(frozen=True, eq=False, kw_only=True)
class ForecastTimes:
    """A forecast file's time axis and ensemble size, read without its velocities (``forecast_times``).

    ``source``, ``time_s`` and ``time_origin`` mean what they mean on a ``Forecast`` (the whole
    file's steps), so ``nearest_time_index`` accepts this value too.
    """

    source: str
    time_s: NDArray[np.float64]
    time_origin: str | None
    n_members: int = 1
    member_dim: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_s", _frozen(self.time_s))

    @property
    def n_times(self) -> int:
        return int(self.time_s.size)

    @property
    def times(self) -> NDArray[np.datetime64] | None:
        if self.time_origin is None:
            return None
        origin = parse_origin(self.time_origin, self.source)
        return origin + np.round(self.time_s * 1000.0).astype("timedelta64[ms]")


def nearest_time_index(forecast: Forecast | ForecastTimes, when: np.datetime64) -> int:
    """Index of the forecast time nearest to ``when`` (ties: the earlier step).

    ``forecast`` may be a ``ForecastTimes`` (``forecast_times(path)``): the index is then the
    file's, ready for ``open_forecast(path, time_index=...)``.

    Raises ForecastError when the forecast has no reference date, or when ``when`` lies more
    than one time step before the first or after the last time (a one-step forecast allows one day).
    """
    if forecast.time_origin is None:
        raise ForecastError(
            f"{forecast.source}: the forecast's times have no reference date (units without 'since'); "
            "choose the time step by position with --time-index"
        )
    try:
        moment = np.datetime64(when, "ms")  # type: ignore[call-overload]  # numpy's stubs lack the (datetime64, unit) overload
    except (ValueError, TypeError) as exc:
        raise ForecastError(f"{forecast.source}: time: expected a numpy.datetime64; got {when!r}") from exc
    if np.isnat(moment):
        raise ForecastError(f"{forecast.source}: time: expected a date and time; got NaT")
    origin = parse_origin(forecast.time_origin, forecast.source)
    offset_s = float((moment - origin) / np.timedelta64(1, "ms")) / 1000.0
    times = forecast.time_s
    step = float(np.median(np.diff(times))) if times.size > 1 else 86400.0
    if offset_s < times[0] - step or offset_s > times[-1] + step:
        first, last = iso_time(forecast, times[0]), iso_time(forecast, times[-1])
        raise ForecastError(
            f"{forecast.source}: time {moment.astype('datetime64[s]')}Z is outside the forecast ({first} .. {last}) "
            f"by more than one time step ({step:g} s); choose a time within the forecast"
        )
    return int(np.argmin(np.abs(times - offset_s)))


def iso_time(forecast: Forecast | ForecastTimes, t_s: float) -> str:
    """``t_s`` seconds as an ISO UTC time ('2023-02-25T12:00:00Z'), or '3600 s' without a reference date."""
    if forecast.time_origin is None:
        return f"{t_s:g} s"
    origin = parse_origin(forecast.time_origin, forecast.source)
    return str((origin + np.timedelta64(int(round(t_s * 1000)), "ms")).astype("datetime64[s]")) + "Z"


def lon_shifts(west_deg: float, east_deg: float, lo_deg: float, hi_deg: float) -> range:
    """The whole turns k for which ``[west, east] + 360 k`` overlaps ``[lo, hi]``: where a box given in one
    longitude convention (-180..180 or 0..360) meets a file in the other. Empty when they never meet."""
    return range(int(np.ceil((lo_deg - east_deg) / 360.0)), int(np.floor((hi_deg - west_deg) / 360.0)) + 1)


def is_periodic_lon(lon: NDArray[np.float64]) -> bool:
    """A regular longitude axis that closes the circle (its last step back to the first is one spacing)."""
    if lon.size < 3:
        return False
    step = float(np.median(np.diff(lon)))
    return abs((lon[-1] - lon[0]) + step - 360.0) <= 0.01 * step
