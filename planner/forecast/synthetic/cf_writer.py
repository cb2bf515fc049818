"""Writing synthetic forecasts as CF-1.8 netCDF-4: grid axes, coordinates, time axis, encoding, atomic write.

Shared by ``planner.forecast.synthetic.scb``, ``double_gyre`` and ``ensemble`` so that their
files have one layout: ``u``, ``v`` (float32, m/s, NaN fill) on ``(time, depth, lat, lon)``,
the time axis in "hours since" the issue time, coordinates described by CF attributes (spec
section 1). Nothing here comes from the reader: ``planner.forecast`` reads these files like any
model file.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import pathlib
from typing import Any, Protocol

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.atomic import atomic_target
from planner.contract.errors import PlannerError

DIMS = ("time", "depth", "lat", "lon")
# CF-1.8 standard names: the reader finds the velocities by them (spec section 1).
U_ATTRS = {"standard_name": "eastward_sea_water_velocity", "long_name": "eastward current", "units": "m s-1"}
V_ATTRS = {"standard_name": "northward_sea_water_velocity", "long_name": "northward current", "units": "m s-1"}


class GridBox(Protocol):
    """A lon/lat box and a grid spacing (``SyntheticSettings``, ``DoubleGyreSettings``)."""

    @property
    def west_deg(self) -> float: ...
    @property
    def south_deg(self) -> float: ...
    @property
    def east_deg(self) -> float: ...
    @property
    def north_deg(self) -> float: ...
    @property
    def spacing_deg(self) -> float: ...


class FieldError(PlannerError):
    """A bad settings field; ``field`` lets ``planner.cli.forecast`` name the command-line option."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


def check_field(ok: object, what: str, name: str, expected: str, got: object) -> None:
    """Raise ``FieldError`` for ``name`` of ``what`` ("tidal settings") unless ``ok``."""
    if not ok:
        raise FieldError(name, f"{what}: `{name}` must be {expected}; got {got!r}")


def is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def check_analytic(settings: object, scalars: tuple[str, ...], what: str) -> None:
    """The checks an analytic source's frozen settings share: its box, spacing, depths and times.

    ``scalars`` (the box's four edges among them) must be finite numbers and become floats; the
    depths a strictly increasing tuple of floats >= 0; ``step_h <= hours``; ``issue_time`` ISO 8601.
    """
    s: Any = settings
    edges = ("west_deg", "south_deg", "east_deg", "north_deg")
    for name in scalars:
        value = getattr(s, name)
        check_field(is_number(value) and math.isfinite(value), what, "bbox" if name in edges else name,
                    "a finite number", value)
        object.__setattr__(s, name, float(value))
    check_field(np.ndim(s.depths_m) == 1 and all(is_number(d) for d in s.depths_m), what,
                "depths_m", "a sequence of numbers", s.depths_m)
    object.__setattr__(s, "depths_m", tuple(float(d) for d in s.depths_m))
    box = (s.west_deg, s.south_deg, s.east_deg, s.north_deg)
    check_field(s.west_deg < s.east_deg and s.south_deg < s.north_deg and -90.0 < s.south_deg and s.north_deg < 90.0
                and s.east_deg - s.west_deg <= 360.0, what, "bbox", "WEST < EAST and -90 < SOUTH < NORTH < 90", box)
    check_field(s.spacing_deg > 0, what, "spacing_deg", "a number > 0", s.spacing_deg)
    nx, ny = grid_counts(s)
    check_field(nx >= 2 and ny >= 2, what, "spacing_deg", f"small enough for 2 points per axis in the box {box}",
                s.spacing_deg)
    depths = np.asarray(s.depths_m)
    check_field(depths.size >= 1 and bool(np.all(np.isfinite(depths))) and bool(np.all(depths >= 0))
                and bool(np.all(np.diff(depths) > 0)), what,
                "depths_m", "non-negative depths in metres, strictly increasing", s.depths_m)
    check_field(s.hours > 0, what, "hours", "a number > 0", s.hours)
    check_field(s.step_h > 0, what, "step_h", "a number > 0", s.step_h)
    if s.step_h > s.hours:  # names both: either option may be the wrong one
        raise FieldError("hours, step_h", f"{what}: `step_h` must be at most `hours` "
                         f"(two time steps at least); got step_h={s.step_h:g}, hours={s.hours:g}")
    try:
        parse_time(s.issue_time)
    except PlannerError:
        check_field(False, what, "issue_time", "an ISO 8601 time like 2026-01-15T00:00:00Z", s.issue_time)


def parse_time(text: str) -> dt.datetime:
    """ISO 8601 time; without a zone it is UTC. Returns an aware UTC datetime."""
    try:
        parsed = dt.datetime.fromisoformat(str(text).strip())
    except ValueError:
        raise PlannerError(
            f"synthetic settings: `issue_time` must be an ISO 8601 time like 2026-01-15T00:00:00Z; got {text!r}"
        ) from None
    if parsed.tzinfo is None:
        parsed = parsed.replace(tzinfo=dt.timezone.utc)
    return parsed.astimezone(dt.timezone.utc)


def grid_counts(box: GridBox) -> tuple[int, int]:
    """``(nx, ny)``: points on the box edges about ``spacing_deg`` apart (spec section 1)."""
    nx = int(round((box.east_deg - box.west_deg) / box.spacing_deg)) + 1
    ny = int(round((box.north_deg - box.south_deg) / box.spacing_deg)) + 1
    return nx, ny


def lon_lat_axes(box: GridBox) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Longitudes ``(nx,)`` and latitudes ``(ny,)``, points on the box edges (spec section 1)."""
    nx, ny = grid_counts(box)
    lon = np.linspace(box.west_deg, box.east_deg, nx)
    lat = np.linspace(box.south_deg, box.north_deg, ny)
    return lon, lat


def coordinates(
    times: NDArray[np.datetime64], depth: NDArray[np.float64], lat: NDArray[np.float64], lon: NDArray[np.float64]
) -> dict[str, tuple[str, NDArray[np.generic], dict[str, str]]]:
    """The four coordinate variables with their CF attributes."""
    return {
        "time": ("time", times, {"standard_name": "time", "long_name": "time", "axis": "T"}),
        "depth": ("depth", depth, {"standard_name": "depth", "long_name": "depth below sea surface",
                                   "units": "m", "positive": "down", "axis": "Z"}),
        "lat": ("lat", lat, {"standard_name": "latitude", "long_name": "latitude",
                             "units": "degrees_north", "axis": "Y"}),
        "lon": ("lon", lon, {"standard_name": "longitude", "long_name": "longitude",
                             "units": "degrees_east", "axis": "X"}),
    }


def layered_dataset(
    u_m_s: NDArray[np.floating], v_m_s: NDArray[np.floating], *, lon: NDArray[np.float64], lat: NDArray[np.float64],
    depth: NDArray[np.float64], hours: NDArray[np.float64], issued: dt.datetime, attrs: dict[str, object],
) -> xr.Dataset:
    """A two-dimensional field ``(time, lat, lon)`` the same at every depth, as a CF-1.8 dataset whose
    time axis is ``hours`` since ``issued``: the analytic sources' files (double gyre, tidal channel)."""
    shape = (hours.size, depth.size, lat.size, lon.size)
    u4 = np.broadcast_to(u_m_s[:, None].astype(np.float32), shape).copy()
    v4 = np.broadcast_to(v_m_s[:, None].astype(np.float32), shape).copy()
    origin = issued.replace(tzinfo=None)
    times = np.datetime64(origin, "ns") + np.round(hours * 3.6e12).astype("timedelta64[ns]")
    ds = xr.Dataset(data_vars={"u": (DIMS, u4, dict(U_ATTRS)), "v": (DIMS, v4, dict(V_ATTRS))},
                    coords=coordinates(times, depth, lat, lon), attrs=attrs)
    set_time_units(ds, origin)
    return ds


def write_dataset(path: str | os.PathLike[str], ds: xr.Dataset) -> pathlib.Path:
    """``ds`` as netCDF-4 with the time axis in hours, atomically (``write_netcdf``)."""
    ds = with_numeric_time(ds)
    return write_netcdf(path, ds, netcdf_encoding(ds))


def set_time_units(ds: xr.Dataset, origin: dt.datetime) -> None:
    """Encode the time axis as float hours since ``origin`` (naive UTC), standard calendar."""
    ds["time"].encoding.update({"units": f"hours since {origin:%Y-%m-%d %H:%M:%S}", "calendar": "standard",
                                "dtype": "float64"})


def netcdf_encoding(ds: xr.Dataset) -> dict[str, dict[str, object]]:
    """netCDF encoding of the dataset's variables: float32 velocities with NaN fill, compressed per time step.

    No fill value on coordinates.
    """
    chunks = (1, ds.sizes["depth"], ds.sizes["lat"], ds.sizes["lon"])
    velocity = {"dtype": "float32", "_FillValue": np.float32(np.nan), "zlib": True, "complevel": 4,
                "shuffle": True, "chunksizes": chunks}
    encoding: dict[str, dict[str, object]] = {
        "u": dict(velocity),
        "v": dict(velocity),
        "h": {"dtype": "float32", "_FillValue": np.float32(np.nan)},
        "lat": {"_FillValue": None},
        "lon": {"_FillValue": None},
        "depth": {"_FillValue": None},
        "time": {"dtype": "float64", "_FillValue": None},
    }
    return {name: enc for name, enc in encoding.items() if name in ds.variables}


def with_numeric_time(ds: xr.Dataset) -> xr.Dataset:
    """The time axis as float hours with its CF units and calendar as attributes.

    xarray would otherwise rewrite ``hours since 2026-01-15 00:00:00`` as
    ``hours since 2026-01-15``; both are CF, but the file should say the issue time in full.
    """
    units = ds["time"].encoding["units"]
    origin = np.datetime64(dt.datetime.strptime(units.removeprefix("hours since "), "%Y-%m-%d %H:%M:%S"), "ns")
    hours = (ds["time"].values - origin) / np.timedelta64(1, "h")
    attrs = {**ds["time"].attrs, "units": units, "calendar": ds["time"].encoding["calendar"]}
    return ds.assign_coords(time=("time", hours.astype(np.float64), attrs))


def write_netcdf(
    path: str | os.PathLike[str], ds: xr.Dataset, encoding: dict[str, dict[str, object]]
) -> pathlib.Path:
    """Write ``ds`` as netCDF-4 atomically (``planner.contract.atomic``): readers never see a partial file."""
    target = pathlib.Path(path)
    with atomic_target(target) as tmp:
        ds.to_netcdf(tmp, mode="w", format="NETCDF4", engine="netcdf4", encoding=encoding)
    return target
