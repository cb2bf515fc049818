"""Ocean current forecasts: reading netCDF files into ``Forecast`` values.

This is the only module of the project that reads netCDF (xarray and netCDF4; pyproj is
imported lazily, only for projected grids). ``open_forecast`` turns a file into a
``Forecast`` whose velocities are eastward/northward m/s with NaN for land (spec section 1:
"Products that store grid-relative components ... are rotated to east/north when they are
read"). ``planner.forecast.resample`` puts a forecast time step onto a planning ``Grid`` exactly
as spec section 1 prescribes.

Supported layouts:

- regular lon/lat products (HYCOM/RTOFS ``water_u``, Copernicus ``uo``, any CF
  ``eastward_sea_water_velocity``), 1-D coordinates, optional depth axis;
- projected or curvilinear structured grids (ROMS output interpolated to z-levels, e.g.
  NorKyst-800): x/y components rotated with the CF ``grid_mapping`` (or an ``angle``
  variable), lon/lat read from the file or computed from X/Y with the projection;
- ROMS and CROCO native C-grid output: u/v averaged to rho points, land masks applied,
  rotated by ``angle``, s-levels converted to per-column depths.

Large files and ensembles (docs/forecasts-large.md): ``open_forecast(path, bbox=,
time_index=, member=)`` reads only a window of the file: the velocities are dask arrays
(xarray chunks) until the time step, the ensemble member and, on regular lon/lat grids, the
lon/lat ranges around the bbox are selected; only that part is read. ``forecast_times`` reads
just the time axis, ``ensemble_size`` the number of members.
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import os
import re
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError, GridError

if TYPE_CHECKING:
    from planner.contract.geodesy import BBox

# --------------------------------------------------------------------------------------
# The Forecast value
# --------------------------------------------------------------------------------------


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
        for name, axis, bound in (("lon_deg", lon, _MAX_ABS_LON_DEG), ("lat_deg", lat, 90.0)):
            finite = axis[np.isfinite(axis)]
            if finite.size and (finite.min() < -bound or finite.max() > bound):
                raise ForecastError(
                    f"{src}: {name}: values {finite.min():g}..{finite.max():g} lie outside [-{bound:g}, {bound:g}] "
                    "degrees; expected longitudes and latitudes in degrees (check the coordinate variables and their units)"
                )
        _check_time_range(time_s, src)
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
            _parse_origin(self.time_origin, src)
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
        origin = _parse_origin(self.time_origin, self.source)
        return origin + np.round(self.time_s * 1000.0).astype("timedelta64[ms]")

    def step_index(self, file_time_index: int) -> int:
        """Index into ``time_s`` (and the velocities' T axis) of the file's time step ``file_time_index``.

        The same number for a forecast that holds every step; 0 for a window opened with
        ``time_index=file_time_index``. ForecastError when this value does not hold that step.
        """
        if isinstance(file_time_index, bool) or not isinstance(file_time_index, (int, np.integer)):
            raise ForecastError(f"{self.source}: time index: expected an integer; got {file_time_index!r}")
        index = int(file_time_index)
        held = None if self.window is None else self.window.time_index
        if held is None:
            if not 0 <= index < self.n_times:
                raise ForecastError(
                    f"{self.source}: time index {index} out of range: the forecast has {self.n_times} time steps, "
                    f"valid indices 0..{self.n_times - 1}"
                )
            return index
        if index != held:
            raise ForecastError(
                f"{self.source}: time index {index}: this forecast was opened with time_index={held} and holds only "
                f"that step of the file's {self.window.n_times}; open the file again with time_index={index}"  # type: ignore[union-attr]
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


def _check_time_range(time_s: NDArray[np.float64], src: str) -> None:
    if time_s.size and np.max(np.abs(time_s)) > _MAX_ABS_TIME_S:
        raise ForecastError(
            f"{src}: time_s: {np.max(np.abs(time_s)):g} s from the time origin; expected times within "
            f"{_MAX_ABS_TIME_S:g} s (about 300,000 years) of it (check the time units)"
        )


def _frozen(a: Any) -> NDArray[np.float64]:
    arr = np.array(a, dtype=np.float64)  # always a copy, so the caller's array cannot change ours
    arr.setflags(write=False)
    return arr


def _parse_origin(origin: str, src: str) -> np.datetime64:
    text = origin.strip()
    if text.endswith("Z"):
        text = text[:-1]
    try:
        return np.datetime64(text, "ms")
    except ValueError as exc:
        raise ForecastError(
            f"{src}: time_origin: expected an ISO-8601 UTC time such as '2023-02-25T12:00:00Z'; got {origin!r}"
        ) from exc


# --------------------------------------------------------------------------------------
# Vocabulary: which variables are currents, which coordinates are which
# --------------------------------------------------------------------------------------

# CF standard names of east/north components (spec section 1: velocities must be east/north).
_EAST_NORTH_STANDARD_NAMES = (
    ("eastward_sea_water_velocity", "northward_sea_water_velocity"),
    ("surface_eastward_sea_water_velocity", "surface_northward_sea_water_velocity"),
    ("eastward_sea_water_velocity_assuming_no_tide", "northward_sea_water_velocity_assuming_no_tide"),
    ("baroclinic_eastward_sea_water_velocity", "baroclinic_northward_sea_water_velocity"),
    ("barotropic_eastward_sea_water_velocity", "barotropic_northward_sea_water_velocity"),
)
# Grid-relative components (ROMS xi/eta, projection X/Y): rotated when read.
_GRID_XY_STANDARD_NAMES = (
    ("x_sea_water_velocity", "y_sea_water_velocity"),
    ("sea_water_x_velocity", "sea_water_y_velocity"),
    ("sea_water_x_velocity_at_u_location", "sea_water_y_velocity_at_v_location"),
    ("sea_water_surface_x_velocity", "sea_water_surface_y_velocity"),
    ("surface_sea_water_x_velocity", "surface_sea_water_y_velocity"),
)
# Common variable names, tried when no standard_name matches.
_COMMON_NAMES = (
    ("water_u", "water_v"),
    ("uo", "vo"),
    ("u_eastward", "v_northward"),
    ("ucur", "vcur"),
    ("u", "v"),
    ("U", "V"),
    ("u_sur", "v_sur"),
)

_TIME_NAMES = {"time", "t", "ocean_time", "time_counter", "valid_time", "times", "mt", "scrum_time"}
_DEPTH_NAMES = {"depth", "z", "lev", "level", "levels", "deptht", "depthu", "depthv", "zlev", "depth_below_surface"}
_S_NAMES = {"s_rho", "s_w", "sigma", "s"}
_LAT_NAMES = {"lat", "latitude", "nav_lat", "lat_rho", "y_lat", "lats"}
_LON_NAMES = {"lon", "longitude", "nav_lon", "lon_rho", "x_lon", "long", "lons"}
_Y_NAMES = {"y", "yc", "eta", "eta_rho", "eta_u", "eta_v", "j", "ny", "rlat", "nj"}
_X_NAMES = {"x", "xc", "xi", "xi_rho", "xi_u", "xi_v", "i", "nx", "rlon", "ni"}

# Ensemble member dimensions: CF's standard_name "realization" (and its name), ECMWF/Copernicus
# "number", and the common "member"/"ensemble"/"ens" spellings.
_MEMBER_NAMES = {
    "member", "members", "member_id", "ensemble_member", "realization", "realisation", "ensemble", "number", "ens",
}  # fmt: skip
_MEMBER_STANDARD_NAMES = {"realization", "realisation", "ensemble_member"}

_DEG_EAST = {"degrees_east", "degree_east", "degree_e", "degrees_e", "degreee", "degreese"}
_DEG_NORTH = {"degrees_north", "degree_north", "degree_n", "degrees_n", "degreen", "degreesn"}

_TIME_UNIT_S = {
    "s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0,
    "min": 60.0, "mins": 60.0, "minute": 60.0, "minutes": 60.0,
    "h": 3600.0, "hr": 3600.0, "hrs": 3600.0, "hour": 3600.0, "hours": 3600.0,
    "d": 86400.0, "day": 86400.0, "days": 86400.0,
}  # fmt: skip
_STANDARD_CALENDARS = {"", "standard", "gregorian", "proleptic_gregorian"}

# Finite values beyond this are undeclared fill (no ocean current is 1 km/s).
_MAX_PLAUSIBLE_SPEED_M_S = 1000.0
# Longitudes run -180..180 or 0..360 (a few products go further west); beyond this a file's
# "degrees" are something else.
_MAX_ABS_LON_DEG = 360.0
# Times this far from their origin overflow datetime64[ms] arithmetic (about 292,000 years).
_MAX_ABS_TIME_S = 1e13

# The loader reads whole velocity variables and works on float64 copies of them (about ten
# arrays of this size at the peak): a larger file must be subset before planning. Checked
# before anything is read, so a damaged header that claims a huge dimension costs nothing.
MAX_VALUES_PER_VARIABLE = 100_000_000
# With bbox=/time_index=/member=, the limit above applies to the part read, not to the file; the
# 1-D axes still read whole (time, lon, lat) are refused beyond this length (a damaged header).
MAX_AXIS_POINTS = 10_000_000
# Nodes kept beyond the ones that the interpolation of a bbox uses, on each side (spec section 1).
WINDOW_MARGIN_NODES = 2


# What netCDF4/xarray/pyproj raise on damaged or unexpected files; wrapped into ForecastError.
_LIBRARY_ERRORS = (
    OSError, ValueError, KeyError, TypeError, RuntimeError, IndexError, AttributeError, ArithmeticError, MemoryError,
)


def _attr(var: xr.DataArray | xr.Variable, key: str) -> str:
    value = var.attrs.get(key, "")
    return value.strip() if isinstance(value, str) else str(value)


def _norm_units(units: str) -> str:
    return units.strip().lower().replace(" ", "").replace("_", "")


def _is_lon_like(name: str, var: xr.DataArray | xr.Variable) -> bool:
    std = _attr(var, "standard_name").lower()
    if std == "longitude":
        return True
    units = _norm_units(_attr(var, "units"))
    if units in {u.replace("_", "") for u in _DEG_EAST}:
        return True
    if std or units:
        return False
    return name.lower() in _LON_NAMES


def _is_lat_like(name: str, var: xr.DataArray | xr.Variable) -> bool:
    std = _attr(var, "standard_name").lower()
    if std == "latitude":
        return True
    units = _norm_units(_attr(var, "units"))
    if units in {u.replace("_", "") for u in _DEG_NORTH}:
        return True
    if std or units:
        return False
    return name.lower() in _LAT_NAMES


def _dim_role(ds: xr.Dataset, dim: str) -> str | None:
    """'T', 'Z', 'S' (terrain-following), 'Y', 'X' or None, from the dimension's coordinate variable or name."""
    name = dim.lower()
    if dim in ds.variables and ds.variables[dim].ndim == 1:
        var = ds.variables[dim]
        axis = _attr(var, "axis").upper()
        std = _attr(var, "standard_name").lower()
        units = _attr(var, "units").lower()
        if std.startswith("ocean_s_coordinate") or std.startswith("ocean_sigma") or name in _S_NAMES:
            return "S"
        if axis in {"T", "Z", "Y", "X"}:
            return axis
        if std == "time" or " since " in f" {units} ":
            return "T"
        if std in {"depth", "height", "altitude"} or _attr(var, "positive").lower() in {"up", "down"}:
            return "Z"
        if std in {"latitude", "projection_y_coordinate", "grid_latitude"} or _is_lat_like(dim, var):
            return "Y"
        if std in {"longitude", "projection_x_coordinate", "grid_longitude"} or _is_lon_like(dim, var):
            return "X"
    if name in _TIME_NAMES or name.startswith("time"):
        return "T"
    if name in _S_NAMES:
        return "S"
    if name in _DEPTH_NAMES:
        return "Z"
    if name in _LAT_NAMES or name in _Y_NAMES or name.startswith("eta_"):
        return "Y"
    if name in _LON_NAMES or name in _X_NAMES or name.startswith("xi_"):
        return "X"
    return None


# --------------------------------------------------------------------------------------
# Opening files
# --------------------------------------------------------------------------------------


def file_identity(path: Path, label: str | None = None) -> str:
    """``sha256:`` + the first 16 hex characters of the SHA-256 of the file's bytes."""
    digest = hashlib.sha256()
    try:
        with path.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError as exc:
        raise ForecastError(
            f"{label or path}: cannot read the file ({exc.strerror or exc}); check the path and permissions"
        ) from exc
    return "sha256:" + digest.hexdigest()[:16]


# Lazily opened: no index is built from a coordinate at open time, so a damaged header that
# claims a huge dimension is refused (MAX_VALUES_PER_VARIABLE) before anything is read.
_LAZY_OPEN = (
    {"create_default_indexes": False}
    if "create_default_indexes" in inspect.signature(xr.open_dataset).parameters
    else {}
)


def _open_dataset(path: str | os.PathLike[str], what: str) -> tuple[xr.Dataset, str, Path]:
    label = os.fspath(path)
    p = Path(label)
    if not p.exists():
        raise ForecastError(f"{label}: {what} not found; check the path")
    if not p.is_file():
        raise ForecastError(f"{label}: {what} is not a regular file; expected a netCDF file")
    _check_complete(p, label, what)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # xarray's SerializationWarnings about odd encodings
            ds = xr.open_dataset(
                p,
                engine="netcdf4",
                decode_times=False,
                decode_timedelta=False,
                decode_coords=False,
                mask_and_scale=True,  # CF fill -> NaN (land, spec section 1); never fillna(0)
                **_LAZY_OPEN,
            )
    except _LIBRARY_ERRORS as exc:
        raise ForecastError(
            f"{label}: cannot open {what} as netCDF ({type(exc).__name__}: {exc}); expected a netCDF-3 or "
            "netCDF-4 file of ocean currents"
        ) from exc
    return ds, label, p


class _CutHeader(Exception):
    """The file ends inside its own header."""


# netCDF-3 external types (NC_BYTE .. NC_UINT64) and their sizes in bytes.
_CDF_TYPE_BYTES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 4, 6: 8, 7: 1, 8: 2, 9: 4, 10: 8, 11: 8}


def _check_complete(p: Path, label: str, what: str) -> None:
    """Refuse an empty or truncated file from its own header, before the netCDF library reads it.

    A cut netCDF-4 (HDF5) file fails to open with a bare "HDF error"; a cut netCDF-3 file opens and
    reads zeros where its data is missing. Both headers say how long the file must be: HDF5's
    superblock stores the end-of-file address, a netCDF-3 header every variable's offset and shape.
    """
    try:
        size = p.stat().st_size
        if size == 0:
            raise ForecastError(f"{label}: {what} is empty (0 bytes); expected a netCDF file")
        with p.open("rb") as fh:
            head = fh.read(8)
            fh.seek(0)
            if head[:3] == b"CDF" and len(head) >= 4 and head[3] in (1, 2, 5):
                kind, need = "netCDF-3", _netcdf3_min_size(fh, head[3], size)
            elif head == b"\x89HDF\r\n\x1a\n":
                kind, need = "netCDF-4/HDF5", _hdf5_min_size(fh.read(96))
            else:
                return
    except _CutHeader:
        raise ForecastError(
            f"{label}: truncated or damaged {what}: its header runs past the end of the file ({size:,} bytes); "
            "copy or download it again"
        ) from None
    except OSError as exc:
        raise ForecastError(f"{label}: cannot read the {what} ({exc.strerror or exc})") from None
    if need is not None and size < need:
        raise ForecastError(
            f"{label}: truncated {what}: its {kind} header says the file holds at least {need:,} bytes, the file has "
            f"{size:,} ({100.0 * size / need:.3g} %); copy or download it again"
        )


def _hdf5_min_size(sb: bytes) -> int | None:
    """End-of-file address from an HDF5 superblock at offset 0 (versions 0 to 3), or None when not stated."""
    if len(sb) < 16:
        raise _CutHeader
    version = sb[8]
    if version in (0, 1):
        n_off = sb[13]
        at = 24 + (4 if version == 1 else 0)
        fields = (at, at + 2 * n_off)  # base address, end-of-file address
    elif version in (2, 3):
        n_off = sb[9]
        fields = (12, 12 + 2 * n_off)
    else:
        return None
    if n_off not in (2, 4, 8):
        return None
    if len(sb) < fields[1] + n_off:
        raise _CutHeader
    base, eof = (int.from_bytes(sb[f : f + n_off], "little") for f in fields)
    undefined = (1 << (8 * n_off)) - 1
    if eof == undefined:
        return None
    return (0 if base == undefined else base) + eof


def _netcdf3_min_size(fh: Any, version: int, size: int) -> int | None:
    """Bytes a classic (1), 64-bit offset (2) or CDF-5 (5) netCDF file needs, from its header.

    Layout: the NetCDF Classic and 64-bit Offset Format specification (Unidata, NetCDF User's Guide,
    "File Format Specifications"), and CDF-5 for 8-byte counts.
    """
    count_bytes = 8 if version == 5 else 4
    offset_bytes = 4 if version == 1 else 8

    def take(n: int) -> bytes:
        if n > size - fh.tell():  # also keeps a garbage length from allocating gigabytes
            raise _CutHeader
        return fh.read(n)

    def number(n: int) -> int:
        return int.from_bytes(take(n), "big")

    def items(min_bytes: int) -> int:
        tag, n = number(4), number(count_bytes)
        if tag == 0 and n == 0:  # ABSENT
            return 0
        if n * min_bytes > size - fh.tell():
            raise _CutHeader
        return n

    def name() -> None:
        take((number(count_bytes) + 3) // 4 * 4)

    def attributes() -> None:
        for _ in range(items(12)):
            name()
            nc_type, n = number(4), number(count_bytes)
            take((n * _CDF_TYPE_BYTES.get(nc_type, 1) + 3) // 4 * 4)

    take(4)  # magic
    numrecs = number(count_bytes)
    dims = []
    for _ in range(items(8)):
        name()
        dims.append(number(count_bytes))
    attributes()
    need = fh.tell()
    records: list[tuple[int, int]] = []  # (begin, bytes per record) of record variables
    for _ in range(items(16)):
        name()
        n_dims = number(count_bytes)
        if n_dims * count_bytes > size - fh.tell():
            raise _CutHeader
        dim_ids = [number(count_bytes) for _ in range(n_dims)]
        attributes()
        nc_type = number(4)
        number(count_bytes)  # vsize: clipped for large variables; recomputed from the shape
        begin = number(offset_bytes)
        shape = [dims[d] if 0 <= d < len(dims) else 0 for d in dim_ids]
        per_value = _CDF_TYPE_BYTES.get(nc_type, 1)
        if shape and dim_ids[0] < len(dims) and dims[dim_ids[0]] == 0:
            n = per_value
            for length in shape[1:]:
                n *= length
            records.append((begin, n))
        else:
            n = per_value
            for length in shape:
                n *= length
            need = max(need, begin + n)
    if records and numrecs not in (0, (1 << (8 * count_bytes)) - 1):
        # One record holds every record variable, each padded to 4 bytes unless it is the only one.
        record_size = records[0][1] if len(records) == 1 else sum((n + 3) // 4 * 4 for _, n in records)
        need = max(need, *(begin + (numrecs - 1) * record_size + n for begin, n in records))
    return need


def open_forecast(
    path: str | os.PathLike[str],
    *,
    variables: tuple[str, str] | None = None,
    grid_file: str | os.PathLike[str] | None = None,
    bbox: BBox | None = None,
    time_index: int | None = None,
    member: int | None = None,
) -> Forecast:
    """Read a current forecast file into a ``Forecast`` (east/north m/s, NaN = land; spec section 1).

    ``variables`` names the (u, v) variables when they cannot be found by CF standard name or
    common name. ``grid_file`` supplies what a ROMS/CROCO output file lacks (lon/lat, masks,
    h, angle). Every failure raises ``ForecastError`` naming the file and what to do.

    Reading part of a file (docs/forecasts-large.md): ``time_index`` keeps one time step (the
    Forecast's ``time_s`` then has that one value), ``member`` one ensemble member (required
    when the file has a member dimension of more than one member), and ``bbox`` (a
    ``planner.grid.BBox``), on regular lon/lat grids, the lon/lat index ranges that the bbox's
    interpolation uses plus ``WINDOW_MARGIN_NODES`` nodes on each side (clipped at the file's
    edges). The velocities are dask arrays until that selection is made, so only the selected
    part is read. ``identity`` stays the whole file's; ``window`` says what was kept; resampling
    the window onto a grid inside the bbox gives the whole file's values bit for bit. Curvilinear,
    projected and ROMS/CROCO files keep their whole horizontal grid (``bbox`` is not used there).
    """
    label = os.fspath(path)
    if variables is not None:
        if (
            not isinstance(variables, (tuple, list))
            or len(variables) != 2
            or not all(isinstance(n, str) and n for n in variables)
        ):
            raise ForecastError(f"{label}: variables: expected two variable names (U, V); got {variables!r}")
    want = _Want.checked(label, bbox=bbox, time_index=time_index, member=member)
    ds, label, p = _open_dataset(path, "forecast file")
    grid_ds: xr.Dataset | None = None
    grid_label: str | None = None
    try:
        if grid_file is not None:
            grid_ds, grid_label, _ = _open_dataset(grid_file, "grid file")
        ctx = _Context(ds=ds, label=label, grid_ds=grid_ds, grid_label=grid_label)
        with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            # Damaged values (a fill value that does not fit its type, NaN cast to an integer) must
            # not print numpy warnings beside the CLI's one error line; the notes say what matters.
            warnings.simplefilter("ignore", RuntimeWarning)
            # The file's hash is taken once its header has been checked: a damaged header that
            # claims gigabytes is refused before its bytes are read.
            return _load(ctx, lambda: file_identity(p, label), variables, want)
    except ForecastError:
        raise
    except GridError as exc:
        raise ForecastError(f"{label}: {exc}") from exc
    except _LIBRARY_ERRORS as exc:
        raise ForecastError(
            f"{label}: could not read the forecast ({type(exc).__name__}: {exc}); the file may be damaged or "
            "of an unsupported layout"
        ) from exc
    finally:
        ds.close()
        if grid_ds is not None:
            grid_ds.close()


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
        origin = _parse_origin(self.time_origin, self.source)
        return origin + np.round(self.time_s * 1000.0).astype("timedelta64[ms]")


def forecast_times(path: str | os.PathLike[str], *, variables: tuple[str, str] | None = None) -> ForecastTimes:
    """The time axis of a forecast file (seconds from its origin, as ``Forecast.time_s``), without reading currents.

    Reads the header and the 1-D time coordinate of the velocity variables only, so it is cheap
    for any file size: use it to turn a date into a time index before ``open_forecast(time_index=)``.
    It makes the checks that ``open_forecast`` makes before it reads the time axis, in the same
    order and with the same messages, so a broken file is refused here as it would be there.
    """
    return _scan(path, variables, times=True)


def ensemble_size(path: str | os.PathLike[str], *, variables: tuple[str, str] | None = None) -> int:
    """Number of ensemble members in a forecast file: the size of its member dimension, 1 when it has none.

    Member dimensions are recognised by name (member, realization, ensemble, number, ens, ...) or
    by the CF standard_name ``realization`` of their coordinate variable. Reads the header only;
    it refuses only what makes the count unknowable (no such file, not netCDF, two member
    dimensions), and leaves every other problem to ``open_forecast``. Without ``variables`` and
    with velocity variables it cannot find, it counts the file's one member-like dimension.
    """
    return _scan(path, variables, times=False).n_members


def _scan(path: str | os.PathLike[str], variables: tuple[str, str] | None, *, times: bool) -> ForecastTimes:
    label = os.fspath(path)
    if variables is not None and (
        not isinstance(variables, (tuple, list)) or len(variables) != 2 or not all(isinstance(n, str) and n for n in variables)
    ):
        raise ForecastError(f"{label}: variables: expected two variable names (U, V); got {variables!r}")
    ds, label, _ = _open_dataset(path, "forecast file")
    try:
        with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            if not times:
                return _count_members(ds, label, variables)
            # The checks of _load and its loaders that come before the time axis is read.
            u_name, v_name, _ = _find_velocity_variables(ds, label, variables)
            u_var, v_var = ds[u_name], ds[v_name]
            for name, var in ((u_name, u_var), (v_name, v_var)):
                _check_packing(var, name, label)
                _check_numeric(var, f"variable {name}", label)
            found = _member_dim(ds, u_var, v_var, u_name, v_name, label)
            n_members = 1
            if found is not None:
                n_members = int(u_var.sizes[found])
                u_var, v_var = u_var.isel({found: 0}), v_var.isel({found: 0})
            for name, var in ((u_name, u_var), (v_name, v_var)):
                _check_axes(var, name, label)
            if _is_c_grid(ds, u_var, v_var):
                time_dim = _c_grid_dims(ds, u_var, u_name, label).get("T")
                _c_grid_dims(ds, v_var, v_name, label)
            else:
                if u_var.dims != v_var.dims or u_var.shape != v_var.shape:
                    raise ForecastError(
                        f"{label}: variables {u_name} {tuple(u_var.dims)} and {v_name} {tuple(v_var.dims)} are on "
                        "different grids; expected both on the same (time, depth, lat, lon) grid, or a ROMS/CROCO "
                        "C-grid with eta_/xi_ dims"
                    )
                time_dim = _assign_roles(ds, u_var, u_name, label).get("T")
                for var, name in ((u_var, u_name), (v_var, v_name)):
                    _velocity_factor(var, name, label, [])
            time_s, origin = _read_time(ds, u_var, label, time_dim, [])
            _check_time_range(time_s, label)
            return ForecastTimes(source=label, time_s=time_s, time_origin=origin, n_members=n_members,
                                 member_dim=found)
    except ForecastError:
        raise
    except _LIBRARY_ERRORS as exc:
        raise ForecastError(
            f"{label}: could not read the forecast's header ({type(exc).__name__}: {exc}); the file may be "
            "damaged or of an unsupported layout"
        ) from exc
    finally:
        ds.close()


def _count_members(ds: xr.Dataset, label: str, variables: tuple[str, str] | None) -> ForecastTimes:
    try:
        u_name, v_name, _ = _find_velocity_variables(ds, label, variables)
    except ForecastError:
        if variables is not None:
            raise
        # Velocities not found by name: open_forecast will say so; count a member-like dimension.
        dims = [str(d) for d in ds.dims if str(d).lower() in _MEMBER_NAMES or (
            str(d) in ds.variables and _attr(ds.variables[str(d)], "standard_name").lower() in _MEMBER_STANDARD_NAMES)]
        n = int(ds.sizes[dims[0]]) if len(dims) == 1 else 1
        return ForecastTimes(source=label, time_s=np.zeros(1), time_origin=None, n_members=n,
                             member_dim=dims[0] if len(dims) == 1 else None)
    u_var, v_var = ds[u_name], ds[v_name]
    found = _member_dim(ds, u_var, v_var, u_name, v_name, label)
    n = 1 if found is None else int(u_var.sizes[found])
    return ForecastTimes(source=label, time_s=np.zeros(1), time_origin=None, n_members=n, member_dim=found)


@dataclass(frozen=True, kw_only=True)
class _Want:
    """What part of the file to read: every field None reads the whole file (the default)."""

    bbox: BBox | None = None
    time_index: int | None = None
    member: int | None = None

    @property
    def partial(self) -> bool:
        return self.bbox is not None or self.time_index is not None or self.member is not None

    @classmethod
    def checked(cls, label: str, *, bbox: Any, time_index: Any, member: Any) -> _Want:
        from planner.contract.geodesy import BBox

        if bbox is not None and not isinstance(bbox, BBox):
            raise ForecastError(f"{label}: bbox: expected a planner.grid.BBox; got {type(bbox).__name__}")
        for name, value in (("time_index", time_index), ("member", member)):
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ForecastError(f"{label}: {name}: expected an integer >= 0; got {value!r}")
        return cls(
            bbox=bbox,
            time_index=None if time_index is None else int(time_index),
            member=None if member is None else int(member),
        )


@dataclass(frozen=True, kw_only=True)
class _Context:
    """The open file (and optional grid file) plus a label for error messages."""

    ds: xr.Dataset
    label: str
    grid_ds: xr.Dataset | None
    grid_label: str | None
    # Selections (member, time step) applied to every variable found that has the dimension.
    select: dict[str, int | slice] = field(default_factory=dict)

    def find(
        self, names: tuple[str, ...], shape: tuple[int, ...] | None = None
    ) -> tuple[str, xr.DataArray, str] | None:
        """First variable among ``names`` (main file, then grid file) with the given shape: (name, var, where)."""
        for dset, where in ((self.ds, self.label), (self.grid_ds, self.grid_label)):
            if dset is None:
                continue
            for name in names:
                if name in dset.variables:
                    var = dset[name]
                    chosen = {d: s for d, s in self.select.items() if d in var.dims}
                    if chosen:
                        var = var.isel(chosen)
                    if shape is None or tuple(var.shape) == tuple(shape):
                        return name, var, str(where)
        return None

    def grid_hint(self) -> str:
        return "" if self.grid_ds is not None else "; pass --grid-file GRID.nc (grid_file=) with the model grid"


def _load(
    ctx: _Context, identity: Callable[[], str], variables: tuple[str, str] | None, want: _Want = _Want()
) -> Forecast:
    ds, label = ctx.ds, ctx.label
    u_name, v_name, kind = _find_velocity_variables(ds, label, variables)
    u_var, v_var = ds[u_name], ds[v_name]
    member_note = None
    member_info: tuple[str, int, int] | None = None  # (dimension, members, member held)
    for name, var in ((u_name, u_var), (v_name, v_var)):
        _check_packing(var, name, label)
        _check_numeric(var, f"variable {name}", label)
    found = _member_dim(ds, u_var, v_var, u_name, v_name, label)
    if found is not None and want.member is None and int(u_var.sizes[found]) == 1:
        found = None  # one member and none asked for: read as before (a size-1 extra dimension is dropped)
    if found is not None:
        n_members = int(u_var.sizes[found])
        if want.member is None and n_members > 1:
            raise ForecastError(
                f"{label}: {u_name}/{v_name} have an ensemble member dimension {found!r} with {n_members} members; "
                f"expected one forecast: give member= (0..{n_members - 1}) to read one member, or plan the "
                "ensemble with the CLI's ensemble planning"
            )
        k = 0 if want.member is None else want.member
        if k >= n_members:
            raise ForecastError(
                f"{label}: member {k} out of range: the file has {n_members} ensemble member(s) along "
                f"dimension {found!r}; expected member= in 0..{n_members - 1}"
            )
        u_var, v_var = u_var.isel({found: k}), v_var.isel({found: k})
        ctx = replace(ctx, select={**ctx.select, found: k})
        member_info = (found, n_members, k)
        member_note = f"ensemble member {k} of {n_members} (dimension {found!r})"
    elif want.member is not None and want.member != 0:
        raise ForecastError(
            f"{label}: member {want.member} out of range: the file has no ensemble member dimension (expected one "
            f"named {', '.join(sorted(_MEMBER_NAMES))} or with standard_name realization), so it is one "
            "forecast; only member=0 (or no member=) is valid"
        )
    if want.partial:
        for name, var in ((u_name, u_var), (v_name, v_var)):
            _check_axes(var, name, label)
    else:
        for name, var in ((u_name, u_var), (v_name, v_var)):
            _check_size(var, name, label)
    notes: list[str] = [f"variables: {u_name}, {v_name}" + _describe_std_names(u_var, v_var)]
    if member_note is not None:
        notes.append(member_note)
    if _is_c_grid(ds, u_var, v_var):
        parts = _load_c_grid(ctx, u_var, v_var, u_name, v_name, kind, notes, want)
    else:
        parts = _load_structured(ctx, u_var, v_var, u_name, v_name, kind, notes, want)
    u, v = parts["u"], parts["v"]
    finite = np.isfinite(u) & np.isfinite(v)
    part: str = parts.get("part", "")
    if not np.any(finite) and parts.get("lon_index") is None:
        if part:
            raise ForecastError(
                f"{label}: variables {u_name}/{v_name} hold no finite current values in the part read ({part}): "
                "all missing, fill or land; expected at least one water point there; check the bbox, time step "
                "and member, or pass --variables U,V to pick other variables"
            )
        raise ForecastError(
            f"{label}: variables {u_name}/{v_name} hold no finite current values (all missing, fill or land); "
            "expected at least one water point; check the file or pass --variables U,V to pick other variables"
        )
    if part:
        # A lon/lat window may lie wholly on land (the file has water elsewhere); planning on it then
        # says so, as it would on the whole file.
        notes.append(f"read part of the file: {part}" + ("" if np.any(finite) else " (all land)"))
    notes.append(f"land (NaN in u or v): {100.0 * (1.0 - finite.mean()):.1f} % of values")
    window = None
    if want.partial or member_info is not None:
        window = ForecastWindow(
            n_times=parts["file_n_times"],
            time_index=want.time_index,
            n_members=1 if member_info is None else member_info[1],
            member=None if member_info is None else member_info[2],
            member_dim=None if member_info is None else member_info[0],
            lon_index=parts.get("lon_index"),
            lat_index=parts.get("lat_index"),
            file_lon_deg=parts.get("file_lon"),
            file_lat_deg=parts.get("file_lat"),
        )
    return Forecast(
        source=label,
        identity=identity(),
        time_s=parts["time_s"],
        time_origin=parts["time_origin"],
        lon_deg=parts["lon"],
        lat_deg=parts["lat"],
        depth_m=parts["depth"],
        u_east_m_s=u,
        v_north_m_s=v,
        notes=tuple(notes),
        variables=(u_name, v_name),
        covers_surface=parts.get("covers_surface", True),
        window=window,
    )


def _member_dim(
    ds: xr.Dataset, u_var: xr.DataArray, v_var: xr.DataArray, u_name: str, v_name: str, label: str
) -> str | None:
    """The velocities' ensemble member dimension, or None (by name or CF standard_name realization)."""
    found = []
    for d in (str(d) for d in u_var.dims):
        by_name = d.lower() in _MEMBER_NAMES
        by_std = d in ds.variables and _attr(ds.variables[d], "standard_name").lower() in _MEMBER_STANDARD_NAMES
        by_axis = d in ds.variables and _attr(ds.variables[d], "_CoordinateAxisType").lower() == "ensemble"
        if by_name or by_std or by_axis:
            found.append(d)
    if not found:
        return None
    if len(found) > 1:
        raise ForecastError(
            f"{label}: {u_name} has several ensemble member dimensions {tuple(found)}; expected at most one"
        )
    d = found[0]
    if d not in v_var.dims or v_var.sizes[d] != u_var.sizes[d]:
        raise ForecastError(
            f"{label}: {u_name} has the ensemble member dimension {d!r} ({u_var.sizes[d]} members) but {v_name} "
            f"{tuple(str(x) for x in v_var.dims)} does not have it with the same size; expected both to have it"
        )
    return d


def _check_axes(var: xr.DataArray, name: str, label: str) -> None:
    """Refuse dimensions too long for their 1-D coordinates to be read whole (damaged headers), from the header."""
    for d, size in zip(var.dims, var.shape):
        if int(size) > MAX_AXIS_POINTS:
            n = 1
            for length in var.shape:
                n *= int(length)
            dims = " x ".join(f"{dd} {int(ss):,}" for dd, ss in zip(var.dims, var.shape))
            raise ForecastError(
                f"{label}: variable {name} declares {n:,} values ({dims}), {int(size):,} of them along {d}; expected "
                f"at most {MAX_AXIS_POINTS:,} points along any dimension (its coordinates are read whole to find the "
                "part to read): check a damaged dimension, or subset the file"
            )


def _have_dask() -> bool:
    return importlib.util.find_spec("dask") is not None


def _lazy(var: xr.DataArray) -> xr.DataArray:
    """The variable as a dask array in "auto" chunks (nothing read yet), or as it is when dask is missing.

    Selecting from it and computing reads only the selected part (dask fuses the slices into the
    netCDF read; xarray's own lazy indexing does the same without dask).
    """
    if not _have_dask():
        return var
    return var.chunk("auto")


def _computed(var: xr.DataArray) -> xr.DataArray:
    """Values of a (possibly dask-backed) selection, computed in this thread (netCDF reads are not thread-safe)."""
    if var.chunks is None:
        return var
    return var.compute(scheduler="synchronous")


def _time_step(time_s: NDArray[np.float64], want: _Want, label: str) -> int | None:
    """The time step to keep (None: every step); a partial read checks the whole time axis as a Forecast would."""
    if want.partial:
        _check_time_range(time_s, label)
    if want.time_index is None:
        return None
    n = int(time_s.size)
    if want.time_index >= n:
        raise ForecastError(
            f"{label}: time_index {want.time_index} out of range: the file has {n} time step(s); expected "
            f"time_index in 0..{n - 1}"
        )
    return want.time_index


def _check_numeric(var: xr.DataArray | xr.Variable, what: str, label: str) -> None:
    """Refuse text, character, boolean or compound variables before their values are read."""
    kind = np.dtype(var.dtype).kind
    if kind not in "fiu":
        shown = "text" if kind in "SUO" else str(var.dtype)
        raise ForecastError(
            f"{label}: {what} holds {shown} values (dtype {var.dtype}, dimensions {tuple(str(d) for d in var.dims)}); "
            "expected numbers (floating point, or integers packed with scale_factor/add_offset)"
        )


def _numbers(var: xr.DataArray | xr.Variable, what: str, label: str) -> NDArray[np.float64]:
    """A coordinate or grid variable's values as float64, after checking that they are numbers."""
    _check_numeric(var, what, label)
    return np.asarray(var.values, dtype=np.float64)


def _check_size(var: xr.DataArray, name: str, label: str, *, part: str | None = None) -> None:
    """Refuse a velocity variable (or, with ``part``, the selection from it) too large to load, from its shape alone."""
    n = 1
    for size in var.shape:
        n *= int(size)
    if n > MAX_VALUES_PER_VARIABLE:
        dims = " x ".join(f"{d} {int(s):,}" for d, s in zip(var.dims, var.shape))
        if part is not None:
            raise ForecastError(
                f"{label}: the part of variable {name} to read ({part}) holds {n:,} values ({dims}); expected at "
                f"most {MAX_VALUES_PER_VARIABLE:,}: give a smaller bbox, one time_index and one member"
            )
        raise ForecastError(
            f"{label}: variable {name} declares {n:,} values ({dims}); expected at most "
            f"{MAX_VALUES_PER_VARIABLE:,} per velocity variable: subset the file to the region, depths and times "
            "to plan on (e.g. ncks -d lon,W,E -d lat,S,N -d time,0,N), or check a damaged dimension"
        )


def _check_packing(var: xr.DataArray, name: str, label: str) -> None:
    """scale_factor and add_offset (moved to ``encoding`` by xarray) must be finite numbers, scale_factor non-zero."""
    for key in ("scale_factor", "add_offset"):
        value = var.encoding.get(key, var.attrs.get(key))
        if value is None:
            continue
        arr = np.asarray(value)
        if arr.dtype.kind not in "fiu" or arr.size != 1 or not np.isfinite(arr.astype(np.float64)).all():
            raise ForecastError(
                f"{label}: variable {name}: {key} {value!r} is not a finite number; expected one number (CF packing)"
            )
        if key == "scale_factor" and float(arr.ravel()[0]) == 0.0:
            raise ForecastError(
                f"{label}: variable {name}: scale_factor is 0, which would make every current 0 m/s; expected a "
                "non-zero number (CF packing)"
            )


def _describe_std_names(u_var: xr.DataArray, v_var: xr.DataArray) -> str:
    su, sv = _attr(u_var, "standard_name"), _attr(v_var, "standard_name")
    return f" (standard_name {su} / {sv})" if su or sv else " (no standard_name)"


def _find_velocity_variables(ds: xr.Dataset, label: str, variables: tuple[str, str] | None) -> tuple[str, str, str]:
    """(u name, v name, kind); kind is 'east_north', 'grid_xy' or 'unknown' (named, no standard_name)."""
    if variables is not None:
        missing = [n for n in variables if n not in ds.data_vars]
        if missing:
            raise ForecastError(
                f"{label}: variables: {', '.join(repr(m) for m in missing)} not in the file; "
                f"expected two of its data variables, e.g. {_candidate_list(ds)}; "
                "pass --variables U,V with names from that list"
            )
        u_name, v_name = variables
        return u_name, v_name, _kind_of(ds[u_name], ds[v_name])
    by_std: dict[str, str] = {}
    for name, var in ds.data_vars.items():
        std = _attr(var, "standard_name").lower()
        if std and std not in by_std and var.ndim >= 2:
            by_std[std] = str(name)
    for pairs, kind in ((_EAST_NORTH_STANDARD_NAMES, "east_north"), (_GRID_XY_STANDARD_NAMES, "grid_xy")):
        for su, sv in pairs:
            if su in by_std and sv in by_std:
                return by_std[su], by_std[sv], kind
    for un, vn in _COMMON_NAMES:
        if un in ds.data_vars and vn in ds.data_vars and ds[un].ndim >= 2 and ds[vn].ndim >= 2:
            return un, vn, _kind_of(ds[un], ds[vn])
    raise ForecastError(
        f"{label}: no ocean current variables found: expected variables with standard_name "
        "eastward_sea_water_velocity/northward_sea_water_velocity (or x_/y_sea_water_velocity with a grid "
        "angle or projection) or common names (water_u/water_v, uo/vo, u/v); the file has "
        f"{_candidate_list(ds)}; pass --variables U,V to name them"
    )


def _candidate_list(ds: xr.Dataset) -> str:
    names = [str(n) for n, var in ds.data_vars.items() if var.ndim >= 2]
    shown = ", ".join(names[:20]) + (", ..." if len(names) > 20 else "")
    return f"data variables [{shown}]" if names else "no data variables with 2 or more dimensions"


def _kind_of(u_var: xr.DataArray, v_var: xr.DataArray) -> str:
    stds = {_attr(u_var, "standard_name").lower(), _attr(v_var, "standard_name").lower()}
    if any(s for pair in _EAST_NORTH_STANDARD_NAMES for s in pair if s in stds):
        return "east_north"
    if any("_x_" in s or s.startswith("x_") or "_y_" in s or s.startswith("y_") for s in stds if s):
        return "grid_xy"
    return "unknown"


def _is_c_grid(ds: xr.Dataset, u_var: xr.DataArray, v_var: xr.DataArray) -> bool:
    """ROMS/CROCO native output: staggered u/v, eta/xi dimensions or s-coordinate levels."""
    if u_var.ndim < 2 or v_var.ndim < 2:
        return False
    hu, hv = tuple(u_var.dims[-2:]), tuple(v_var.dims[-2:])
    if hu != hv:
        return True
    if all(str(d).startswith(("eta_", "xi_")) for d in hu):
        return True
    return any(_dim_role(ds, str(d)) == "S" for d in u_var.dims)


# --------------------------------------------------------------------------------------
# Shared reading helpers: units, time, masking
# --------------------------------------------------------------------------------------


def _velocity_factor(var: xr.DataArray, name: str, label: str, notes: list[str]) -> float:
    """Factor to m/s from the variable's units (cm/s and mm/s are converted)."""
    raw = _attr(var, "units")
    if not raw:
        notes.append(f"{name} has no units attribute: assumed m/s")
        return 1.0
    u = raw.lower().strip()
    for long, short in (
        ("centimeters", "cm"), ("centimetres", "cm"), ("centimeter", "cm"), ("centimetre", "cm"),
        ("millimeters", "mm"), ("millimetres", "mm"), ("millimeter", "mm"), ("millimetre", "mm"),
        ("meters", "m"), ("metres", "m"), ("meter", "m"), ("metre", "m"),
        ("seconds", "s"), ("second", "s"), ("secs", "s"), ("sec", "s"),
    ):  # fmt: skip
        u = u.replace(long, short)
    u = re.sub(r"\s*per\s*", "/", u)
    u = re.sub(r"[\s.*^]", "", u)
    u = u.replace("s-1", "/s").replace("s**-1", "/s")
    if u in {"m/s", "m//s"}:
        return 1.0
    if u in {"cm/s", "cm//s"}:
        notes.append(f"{name}: units {raw!r} converted to m/s (x 0.01)")
        return 0.01
    if u in {"mm/s", "mm//s"}:
        notes.append(f"{name}: units {raw!r} converted to m/s (x 0.001)")
        return 0.001
    raise ForecastError(
        f"{label}: variable {name}: units {raw!r} not understood; expected m/s (e.g. 'm s-1', 'meter second-1') or cm/s"
    )


def _velocity_values(var: xr.DataArray, name: str, label: str, notes: list[str]) -> NDArray[np.float64]:
    """Decoded values (CF fill -> NaN, never 0), in m/s, float64."""
    factor = _velocity_factor(var, name, label, notes)
    values = np.asarray(var.values, dtype=np.float64)
    packed = "scale_factor" in var.encoding or "add_offset" in var.encoding
    if not packed:
        # CF valid range (netCDF4's auto-masking does the same); only meaningful for unpacked data.
        vmin, vmax = var.attrs.get("valid_min"), var.attrs.get("valid_max")
        if "valid_range" in var.attrs:
            vmin, vmax = np.asarray(var.attrs["valid_range"]).ravel()[:2]
        with np.errstate(invalid="ignore"):
            bad = np.zeros(values.shape, dtype=bool)
            if vmin is not None:
                bad |= values < float(vmin)
            if vmax is not None:
                bad |= values > float(vmax)
        if np.any(bad):
            notes.append(f"{name}: {int(bad.sum())} values outside the CF valid range set to NaN")
            values = np.where(bad, np.nan, values)
    with np.errstate(invalid="ignore"):
        huge = np.abs(values) > _MAX_PLAUSIBLE_SPEED_M_S / factor
    if np.any(huge):
        notes.append(
            f"{name}: {int(huge.sum())} values beyond {_MAX_PLAUSIBLE_SPEED_M_S:g} m/s taken as undeclared fill (NaN)"
        )
        values = np.where(huge, np.nan, values)
    return values * factor if factor != 1.0 else values


def _parse_time_units(units: str, label: str, name: str) -> tuple[float, str | None]:
    """(seconds per unit, ISO origin or None) from CF units such as 'hours since 2023-02-25 12:00:00'."""
    text = units.strip()
    m = re.match(r"^\s*([A-Za-z]+)\s+since\s+(.+?)\s*$", text, re.IGNORECASE)
    if m is None:
        factor = _TIME_UNIT_S.get(text.lower())
        if factor is None:
            raise ForecastError(
                f"{label}: time variable {name}: units {units!r} not understood; expected e.g. "
                "'hours since 2023-02-25 12:00:00' or 'seconds'"
            )
        return factor, None
    factor = _TIME_UNIT_S.get(m.group(1).lower())
    if factor is None:
        raise ForecastError(
            f"{label}: time variable {name}: unit {m.group(1)!r} in {units!r} not supported; expected seconds, "
            "minutes, hours or days"
        )
    ref = re.match(
        r"^(\d{1,4})-(\d{1,2})-(\d{1,2})(?:[T\s]+(\d{1,2}):(\d{1,2})(?::(\d{1,2})(?:\.(\d*))?)?)?"
        r"\s*(Z|UTC|GMT|[+-]\d{1,2}(?::?\d{2})?)?$",
        m.group(2).strip(),
        re.IGNORECASE,
    )
    if ref is None:
        raise ForecastError(
            f"{label}: time variable {name}: reference date in {units!r} not understood; expected "
            "'UNIT since YYYY-MM-DD[ HH:MM:SS][Z]'"
        )
    year, month, day, hh, mm, ss, frac, tz = ref.groups()
    stamp = f"{int(year):04d}-{int(month):02d}-{int(day):02d}T{int(hh or 0):02d}:{int(mm or 0):02d}:{int(ss or 0):02d}"
    try:
        origin = np.datetime64(stamp, "ms")
    except ValueError as exc:
        raise ForecastError(f"{label}: time variable {name}: invalid reference date in {units!r}") from exc
    if frac:
        origin = origin + np.timedelta64(int(round(float("0." + frac) * 1000)), "ms")
    if tz and tz.upper() not in {"Z", "UTC", "GMT"}:
        sign = -1 if tz.startswith("-") else 1
        digits = tz[1:].replace(":", "")
        hours, minutes = (int(digits[:-2]), int(digits[-2:])) if len(digits) > 2 else (int(digits), 0)
        origin = origin - sign * np.timedelta64(hours * 60 + minutes, "m")  # local time minus offset = UTC
    text_origin = str(origin.astype("datetime64[s]")) if origin == origin.astype("datetime64[s]") else str(origin)
    return factor, text_origin + "Z"


def _read_time(
    ds: xr.Dataset, var: xr.DataArray, label: str, time_dim: str | None, notes: list[str]
) -> tuple[NDArray[np.float64], str | None]:
    """(seconds since origin, ISO origin or None) for the variable's time dimension."""
    if time_dim is None:
        notes.append("no time axis: one time step at t = 0 s")
        return np.zeros(1), None
    tvar_name = None
    if time_dim in ds.variables and ds.variables[time_dim].ndim == 1:
        tvar_name = time_dim
    else:
        for name, cand in ds.variables.items():
            if cand.dims == (time_dim,) and (
                _attr(cand, "standard_name") == "time" or " since " in f" {_attr(cand, 'units')} "
            ):
                tvar_name = str(name)
                break
    n = int(var.sizes[time_dim])
    if tvar_name is None:
        notes.append(f"time dimension {time_dim!r} has no coordinate variable: steps numbered 0..{n - 1} s")
        return np.arange(n, dtype=np.float64), None
    tvar = ds.variables[tvar_name]
    values = _numbers(tvar, f"time variable {tvar_name}", label)
    if not np.all(np.isfinite(values)):
        raise ForecastError(f"{label}: time variable {tvar_name} has missing values; expected {n} finite times")
    units = _attr(tvar, "units")
    if not units:
        notes.append(f"time variable {tvar_name} has no units: taken as seconds, no reference date")
        factor, origin = 1.0, None
    else:
        factor, origin = _parse_time_units(units, label, tvar_name)
    calendar = _attr(tvar, "calendar").lower()
    if origin is not None and calendar not in _STANDARD_CALENDARS:
        notes.append(f"time calendar {calendar!r} is not the standard one: dates derived from it are approximate")
    time_s = values * factor
    if time_s.size > 1 and np.any(np.diff(time_s) <= 0):
        raise ForecastError(
            f"{label}: time variable {tvar_name}: expected strictly increasing times; got {values.tolist()[:8]}"
        )
    if origin is None:
        notes.append(f"time units {units!r} give no reference date: time_origin is None, times are model seconds")
    else:
        notes.append(f"time: {tvar_name} in {units!r}")
    return time_s, origin


# --------------------------------------------------------------------------------------
# Structured grids: regular lon/lat, projected X/Y, curvilinear with 2-D lon/lat
# --------------------------------------------------------------------------------------


def _assign_roles(ds: xr.Dataset, var: xr.DataArray, name: str, label: str) -> dict[str, str]:
    """Map 'T', 'Z', 'Y', 'X' to the variable's dimensions; size-1 extras are dropped later."""
    dims = [str(d) for d in var.dims]
    if len(dims) < 2:
        raise ForecastError(f"{label}: variable {name} has dimensions {dims}; expected at least (lat, lon) or (y, x)")
    roles: dict[str, str] = {}
    for d in dims:
        r = _dim_role(ds, d)
        if r == "S":
            r = "Z"
        if r is not None and r not in roles:
            roles[r] = d
    if "Y" not in roles or "X" not in roles:
        rest = [d for d in dims if d not in roles.values()]
        if "Y" in roles or "X" in roles or len(rest) < 2:
            horizontal = dims[-2:]
        else:
            horizontal = rest[-2:]
        roles["Y"], roles["X"] = horizontal
        for key in ("T", "Z"):
            if key in roles and roles[key] in horizontal:
                del roles[key]
    leftovers = [d for d in dims if d not in roles.values()]
    for d in leftovers:
        if var.sizes[d] == 1:
            continue
        if "T" not in roles:
            roles["T"] = d
        else:
            raise ForecastError(
                f"{label}: variable {name} has a dimension {d!r} of size {var.sizes[d]} that is not time, depth, "
                f"latitude or longitude; expected dimensions like (time, depth, lat, lon); got {tuple(dims)}"
            )
    return roles


def _to_tzyx(var: xr.DataArray, roles: dict[str, str]) -> xr.DataArray:
    for d in [str(d) for d in var.dims if str(d) not in roles.values()]:
        var = var.isel({d: 0})
    if "T" not in roles:
        var = var.expand_dims("__t")
    if "Z" not in roles:
        var = var.expand_dims("__z")
    order = [roles.get("T", "__t"), roles.get("Z", "__z"), roles["Y"], roles["X"]]
    return var.transpose(*order)


def _load_structured(
    ctx: _Context,
    u_var: xr.DataArray,
    v_var: xr.DataArray,
    u_name: str,
    v_name: str,
    kind: str,
    notes: list[str],
    want: _Want,
) -> dict[str, Any]:
    ds, label = ctx.ds, ctx.label
    if u_var.dims != v_var.dims or u_var.shape != v_var.shape:
        raise ForecastError(
            f"{label}: variables {u_name} {tuple(u_var.dims)} and {v_name} {tuple(v_var.dims)} are on different "
            "grids; expected both on the same (time, depth, lat, lon) grid, or a ROMS/CROCO C-grid with eta_/xi_ dims"
        )
    roles = _assign_roles(ds, u_var, u_name, label)
    ydim, xdim, tdim = roles["Y"], roles["X"], roles.get("T")
    # Everything but the velocities' values is read first (units, time, depth, the lon/lat axes), so
    # that the part to read is known before any value is; the notes keep the order of a whole read
    # (velocities, time, depth, axes).
    for var, name in ((u_var, u_name), (v_var, v_name)):
        _velocity_factor(var, name, label, [])  # unit errors first, as before
    later: list[str] = []
    time_s, origin = _read_time(ds, u_var, label, tdim, later)
    file_n_times = int(time_s.size)
    depth = _read_depth_axis(ds, u_var, label, roles.get("Z"), later)
    reverse_depth = depth is not None and depth.size > 1 and depth[0] > depth[-1]
    if reverse_depth:
        assert depth is not None
        depth = depth[::-1]
        later.append("depth levels reversed to shallowest first")
    if depth is not None and depth.size > 1 and np.any(np.diff(depth) <= 0):
        raise ForecastError(
            f"{label}: depth levels of {u_name}: expected strictly monotonic depths; got {depth.tolist()[:12]}"
        )
    t = _time_step(time_s, want, label)
    select: dict[str, slice] = {}
    part: list[str] = []
    if t is not None:
        if tdim is not None:
            select[tdim] = slice(t, t + 1)
        time_s = time_s[t : t + 1]
        part.append(f"time step {t} of {file_n_times}")

    xcoord = ds.variables[xdim] if xdim in ds.variables and ds.variables[xdim].ndim == 1 else None
    ycoord = ds.variables[ydim] if ydim in ds.variables and ds.variables[ydim].ndim == 1 else None
    grid_mapping = _grid_mapping_var(ds, u_var)
    regular = xcoord is not None and ycoord is not None and _is_lon_like(xdim, xcoord) and _is_lat_like(ydim, ycoord)
    window: dict[str, Any] = {}
    orient: _Orientation | None = None
    if regular:
        assert xcoord is not None and ycoord is not None
        orient = _orientation(
            _numbers(xcoord, f"coordinate {xdim}", label), _numbers(ycoord, f"coordinate {ydim}", label),
            label, xdim, ydim, later,
        )
        x0, x1, y0, y1 = 0, orient.lon.size, 0, orient.lat.size
        if want.bbox is not None:
            x0, x1, y0, y1 = _regular_window(orient.lon, orient.lat, want.bbox, label)
            window = {
                "lon_index": (x0, x1), "lat_index": (y0, y1), "file_lon": orient.lon, "file_lat": orient.lat,
            }
            part.append(
                f"lon {orient.lon[x0]:.6g}..{orient.lon[x1 - 1]:.6g} ({x1 - x0} of {orient.lon.size} points), "
                f"lat {orient.lat[y0]:.6g}..{orient.lat[y1 - 1]:.6g} ({y1 - y0} of {orient.lat.size})"
            )
        if want.partial:  # a whole read reads the repeated column too and drops it afterwards, as always
            select[xdim] = orient.file_slice(x0, x1, axis="x")
            select[ydim] = orient.file_slice(y0, y1, axis="y")

    def values(var: xr.DataArray, name: str) -> NDArray[np.float64]:
        if want.partial:
            var = _lazy(var).isel(select)
            _check_size(var, name, label, part="; ".join(part) or "the whole variable")
            var = _computed(var)
        elif select:
            var = var.isel(select)
        return _velocity_values(_to_tzyx(var, roles), name, label, notes)

    u = values(u_var, u_name)
    v = values(v_var, v_name)
    if reverse_depth:
        u, v = u[:, ::-1], v[:, ::-1]
    notes.extend(later)
    common = {"time_s": time_s, "time_origin": origin, "file_n_times": file_n_times, "part": "; ".join(part)}
    if orient is not None:
        u, v = orient.apply(u, whole=not want.partial), orient.apply(v, whole=not want.partial)
        lon, lat = orient.lon, orient.lat
        if want.bbox is not None:
            lon, lat = lon[window["lon_index"][0] : window["lon_index"][1]], lat[window["lat_index"][0] : window["lat_index"][1]]
        if kind == "grid_xy":
            notes.append("x/y components on a regular lon/lat grid: x is east and y is north, no rotation")
        elif kind == "unknown":
            notes.append("no standard_name on the velocities: taken as eastward/northward on the lon/lat grid")
        return {
            "u": u, "v": v, "lon": np.ascontiguousarray(lon), "lat": np.ascontiguousarray(lat), "depth": depth,
            **common, **window,
        }

    ny, nx = int(u_var.sizes[ydim]), int(u_var.sizes[xdim])
    lonlat = _find_2d_lonlat(ctx, u_var, ydim, xdim)
    crs = None
    xy: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    if grid_mapping is not None and xcoord is not None and ycoord is not None:
        crs = _crs_from_grid_mapping(grid_mapping, label)
        xy = (_numbers(xcoord, f"coordinate {xdim}", label), _numbers(ycoord, f"coordinate {ydim}", label))
    if lonlat is not None:
        lon, lat, where = lonlat
        notes.append(f"2-D lon/lat from {where}")
    elif crs is not None and xy is not None:
        lon, lat = _lonlat_from_projection(crs, xy[0], xy[1])
        notes.append(f"no lon/lat variables: computed from {xdim}/{ydim} with grid_mapping {grid_mapping.name!r}")
    else:
        raise ForecastError(
            f"{label}: no longitude/latitude for {u_name} on ({ydim}, {xdim}): expected 1-D lon/lat coordinate "
            "variables, 2-D lon/lat variables (e.g. named in the 'coordinates' attribute), or X/Y coordinates with a "
            "CF grid_mapping to compute them; add them to the file or pass --grid-file GRID.nc with 2-D lon/lat"
        )
    if not np.any(np.isfinite(lon) & np.isfinite(lat)):
        raise ForecastError(f"{label}: lon/lat for {u_name} are all missing; expected finite degrees")

    if kind == "east_north":
        pass
    elif crs is not None and xy is not None:
        cos_x, sin_x, cos_y, sin_y = _projection_axes(crs, xy[0], xy[1])
        u, v = u * cos_x + v * cos_y, u * sin_x + v * sin_y
        between = np.arctan2(sin_y * cos_x - cos_y * sin_x, cos_y * cos_x + sin_y * sin_x)  # angle x-axis -> y-axis
        skew = float(np.degrees(np.nanmax(np.abs(between - np.pi / 2))))
        notes.append(
            f"rotated projection x/y components to east/north with grid_mapping {grid_mapping.name!r} "
            f"({_crs_text(crs)}): local x-axis direction from the projection at every point"
            + (f"; axes depart from perpendicular by up to {skew:.3g} deg" if skew > 1e-6 else "")
        )
        if kind == "unknown":
            notes.append("no standard_name on the velocities: taken as projection x/y components (projected grid)")
    else:
        found = ctx.find(("angle",), (ny, nx))
        if found is None:
            raise ForecastError(
                f"{label}: {u_name}/{v_name} are grid-relative (x/y) components on a curvilinear grid but there is no "
                "grid_mapping and no 'angle' variable to rotate them to east/north; pass --grid-file GRID.nc with "
                "'angle', or --variables with eastward/northward variables"
            )
        angle = np.asarray(found[1].values, dtype=np.float64)
        u, v = _rotate(u, v, angle)
        notes.append(f"rotated grid x/y components to east/north by 'angle' from {found[2]}")
    return {"u": u, "v": v, "lon": lon, "lat": lat, "depth": depth, **common}


def _read_depth_axis(
    ds: xr.Dataset, var: xr.DataArray, label: str, zdim: str | None, notes: list[str]
) -> NDArray[np.float64] | None:
    """Depth levels (positive down) for a z-level variable; None when it has no depth axis at all."""
    if zdim is not None:
        n = int(var.sizes[zdim])
        if zdim not in ds.variables or ds.variables[zdim].ndim != 1:
            if n == 1:
                notes.append(f"depth dimension {zdim!r} of size 1 without values: treated as no depth axis")
                return None
            raise ForecastError(
                f"{label}: depth dimension {zdim!r} ({n} levels) has no coordinate variable with the depths; "
                "expected a 1-D variable of the same name in metres"
            )
        zvar = ds.variables[zdim]
    else:
        zvar = None
        coords = str(var.attrs.get("coordinates", "")).split()
        for cname in coords + ["depth"]:
            if cname in ds.variables and ds.variables[cname].ndim == 0:
                cand = ds.variables[cname]
                if _attr(cand, "standard_name") in {"depth", "height"} or cname.lower() in _DEPTH_NAMES:
                    zvar = cand
                    zdim = cname
                    break
        if zvar is None:
            notes.append("no depth axis: the field applies to every layer (spec section 1)")
            return None
    values = np.atleast_1d(_numbers(zvar, f"depth variable {zdim}", label))
    if not np.all(np.isfinite(values)):
        raise ForecastError(f"{label}: depth variable {zdim} has missing values; expected finite depths in metres")
    units = _attr(zvar, "units").lower()
    if units in {"cm", "centimeters", "centimetres"}:
        values = values / 100.0
    elif units not in {"", "m", "meter", "meters", "metre", "metres"}:
        raise ForecastError(f"{label}: depth variable {zdim}: units {units!r} not supported; expected metres")
    positive = _attr(zvar, "positive").lower()
    std = _attr(zvar, "standard_name").lower()
    elevation = positive == "" and np.all(values <= 0) and np.any(values < 0)
    if positive == "up" or std in {"height", "altitude"} or elevation:
        values = -values
        notes.append(f"depth variable {zdim} is elevation (positive up): negated to depth positive down")
    if np.any(values < 0):
        sense = f"positive = {positive!r}" if positive else "no 'positive' attribute, values of both signs"
        above = ", ".join(f"{d:g}" for d in values[values < 0][:6])
        raise ForecastError(
            f"{label}: depth variable {zdim}: levels above the sea surface ({above} m as depth, {sense}); expected "
            "depths >= 0 m positive down, or heights <= 0 with positive = 'up'"
        )
    if values.size == 1:
        notes.append(
            f"one depth level at {values[0]:g} m ({zdim}): layers shallower take it, deeper layers are land "
            "(spec section 1)"
        )
    else:
        notes.append(f"{values.size} fixed depth levels from {zdim}: {', '.join(f'{d:g}' for d in values)} m")
    return values


@dataclass(frozen=True, eq=False)
class _Orientation:
    """How a regular file's lon/lat axes become the Forecast's: flips to ascending, a repeated wrap column dropped."""

    lon: NDArray[np.float64]  # the Forecast's axes (ascending, wrap column dropped)
    lat: NDArray[np.float64]
    flip_x: bool
    flip_y: bool
    drop_last_x: bool
    n_x_file: int
    n_y_file: int

    def file_slice(self, start: int, stop: int, *, axis: str) -> slice:
        """The file's index range of the Forecast's ``[start, stop)`` along lon ('x') or lat ('y')."""
        flip, n = (self.flip_x, self.n_x_file) if axis == "x" else (self.flip_y, self.n_y_file)
        return slice(n - stop, n - start) if flip else slice(start, stop)

    def apply(self, a: NDArray[np.float64], *, whole: bool) -> NDArray[np.float64]:
        """(T, Z, Y, X) values in file order -> the Forecast's order; ``whole``: all file columns were read."""
        if self.flip_y:
            a = a[:, :, ::-1, :]
        if self.flip_x:
            a = a[:, :, :, ::-1]
        if whole and self.drop_last_x:
            a = a[..., :-1]
        return np.ascontiguousarray(a)


def _orientation(
    lon: NDArray[np.float64], lat: NDArray[np.float64], label: str, xdim: str, ydim: str, notes: list[str]
) -> _Orientation:
    """Flip descending axes to ascending and drop a duplicated wrap-around column (spec section 1 grids)."""
    n_x_file, n_y_file = lon.size, lat.size
    for name, axis, bound in ((xdim, lon, _MAX_ABS_LON_DEG), (ydim, lat, 90.0)):
        if not np.all(np.isfinite(axis)):
            raise ForecastError(f"{label}: coordinate {name} has missing values; expected finite degrees")
        if axis.min() < -bound or axis.max() > bound:
            raise ForecastError(
                f"{label}: coordinate {name}: values {axis.min():g}..{axis.max():g} lie outside [-{bound:g}, {bound:g}]; "
                "expected degrees (check the variable and its units)"
            )
    flip_y = lat.size > 1 and lat[0] > lat[-1]
    if flip_y:
        lat = lat[::-1]
        notes.append(f"latitude {ydim} was descending: flipped to ascending")
    flip_x = lon.size > 1 and lon[0] > lon[-1]
    if flip_x:
        lon = lon[::-1]
        notes.append(f"longitude {xdim} was descending: flipped to ascending")
    drop = lon.size > 2 and abs(lon[-1] - lon[0] - 360.0) < 1e-6
    if drop:
        lon = lon[:-1]
        notes.append(f"longitude {xdim}: last column repeats the first (+360 deg): dropped")
    for name, axis in ((xdim, lon), (ydim, lat)):
        if axis.size > 1 and np.any(np.diff(axis) <= 0):
            raise ForecastError(
                f"{label}: coordinate {name}: expected strictly monotonic values; got {axis[:8].tolist()}..."
            )
    if is_periodic_lon(lon):
        notes.append("longitude spans 360 deg: treated as periodic (wraps at the date line)")
    return _Orientation(
        lon=np.ascontiguousarray(lon), lat=np.ascontiguousarray(lat), flip_x=bool(flip_x), flip_y=bool(flip_y),
        drop_last_x=bool(drop), n_x_file=int(n_x_file), n_y_file=int(n_y_file),
    )


def _snap_bound(axis: NDArray[np.float64]) -> float:
    """An upper bound of ``planner.forecast.resample``'s snapping tolerance on this axis (a thousandth of its spacing)."""
    if axis.size < 2:
        return 0.0
    return 1e-3 * float(np.min(np.diff(axis)))


def _bracket(axis: NDArray[np.float64], lo: float, hi: float) -> tuple[int, int]:
    """Indices of the last node at or below ``lo`` and the first at or above ``hi`` (clipped to the axis)."""
    i0 = int(np.searchsorted(axis, lo, side="right")) - 1
    i1 = int(np.searchsorted(axis, hi, side="left"))
    return max(i0, 0), min(i1, axis.size - 1)


def _regular_window(
    lon: NDArray[np.float64], lat: NDArray[np.float64], bbox: BBox, label: str
) -> tuple[int, int, int, int]:
    """``[x0, x1)`` and ``[y0, y1)`` of the nodes that resampling any grid inside ``bbox`` uses, plus the margin.

    Targets are the bbox's longitudes moved by multiples of 360 deg into the axis' range, as
    ``planner.forecast.resample`` moves them (a periodic axis counts its closing node, first + 360 deg).
    A periodic axis whose window would need the seam keeps every column.
    """
    periodic = is_periodic_lon(lon)
    axis = np.append(lon, lon[0] + 360.0) if periodic else lon
    tol = _snap_bound(axis)
    lo, hi = float(axis[0]) - tol, float(axis[-1]) + tol
    west, east = float(bbox.west_deg), float(bbox.east_deg)
    brackets = []
    if east - west >= 360.0:
        brackets.append((0, axis.size - 1))
    else:
        for k in range(int(np.ceil((lo - east) / 360.0)), int(np.floor((hi - west) / 360.0)) + 1):
            p, q = max(west + 360.0 * k, lo), min(east + 360.0 * k, hi)
            if p <= q:
                brackets.append(_bracket(axis, p, q))
    tol_y = _snap_bound(lat)
    p_y, q_y = max(float(bbox.south_deg), float(lat[0]) - tol_y), min(float(bbox.north_deg), float(lat[-1]) + tol_y)
    if not brackets or p_y > q_y:
        raise ForecastError(
            f"{label}: bbox {bbox.west_deg:g},{bbox.south_deg:g},{bbox.east_deg:g},{bbox.north_deg:g} lies outside the "
            f"forecast, which covers lon {lon[0]:.4f}..{lon[-1]:.4f}, lat {lat[0]:.4f}..{lat[-1]:.4f}; expected a bbox "
            "that overlaps it"
        )
    i0, i1 = min(b[0] for b in brackets), max(b[1] for b in brackets)
    if periodic and i1 >= lon.size:  # the closing node is column 0 again: keep the whole circle
        x0, x1 = 0, lon.size
    else:
        x0, x1 = max(i0 - WINDOW_MARGIN_NODES, 0), min(i1 + WINDOW_MARGIN_NODES, lon.size - 1) + 1
    j0, j1 = _bracket(lat, p_y, q_y)
    y0, y1 = max(j0 - WINDOW_MARGIN_NODES, 0), min(j1 + WINDOW_MARGIN_NODES, lat.size - 1) + 1
    return x0, x1, y0, y1


def _find_2d_lonlat(
    ctx: _Context, var: xr.DataArray, ydim: str, xdim: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], str] | None:
    ds = ctx.ds
    names = str(var.attrs.get("coordinates", "")).split() + [str(n) for n in ds.variables]
    for dset, where in ((ds, ctx.label), (ctx.grid_ds, ctx.grid_label)):
        if dset is None:
            continue
        lon_name = lat_name = None
        for name in names if dset is ds else [str(n) for n in dset.variables]:
            if name not in dset.variables:
                continue
            cand = dset.variables[name]
            if cand.ndim != 2 or tuple(cand.shape) != (var.sizes[ydim], var.sizes[xdim]):
                continue
            if lon_name is None and _is_lon_like(name, cand):
                lon_name = name
            elif lat_name is None and _is_lat_like(name, cand):
                lat_name = name
        if lon_name and lat_name:
            lon = _numbers(dset.variables[lon_name], f"longitude {lon_name}", str(where))
            lat = _numbers(dset.variables[lat_name], f"latitude {lat_name}", str(where))
            if dset.variables[lon_name].dims == (xdim, ydim) and ydim != xdim:
                lon, lat = lon.T, lat.T
            return lon, lat, f"{lon_name}/{lat_name} in {where}"
    return None


def _grid_mapping_var(ds: xr.Dataset, var: xr.DataArray) -> xr.DataArray | None:
    name = _attr(var, "grid_mapping")
    if not name:
        return None
    name = name.split(":")[0].split()[0]
    return ds[name] if name in ds.variables else None


def _crs_from_grid_mapping(gm: xr.DataArray, label: str) -> Any:
    import pyproj  # lazily: only projected grids need it

    attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in gm.attrs.items()}
    attempts: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for key in ("crs_wkt", "spatial_ref", "proj4", "proj4text", "proj4_string"):
            if key in attrs:
                try:
                    return pyproj.CRS.from_user_input(attrs[key])
                except pyproj.exceptions.CRSError as exc:
                    attempts.append(f"{key}: {exc}")
        try:
            return pyproj.CRS.from_cf(attrs)
        except (pyproj.exceptions.CRSError, KeyError, ValueError, TypeError) as exc:
            attempts.append(f"CF attributes: {exc}")
    raise ForecastError(
        f"{label}: grid_mapping {gm.name!r}: cannot build a projection ({'; '.join(attempts)}); expected CF "
        "grid_mapping attributes or a proj4/crs_wkt attribute"
    )


def _crs_text(crs: Any) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return str(crs.to_proj4())
        except Exception:  # noqa: BLE001 - only for a note; the CRS itself is valid
            return str(crs.name)


def _lonlat_from_projection(
    crs: Any, x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    import pyproj

    transformer = pyproj.Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    xx, yy = np.meshgrid(x, y)
    lon, lat = transformer.transform(xx, yy)
    return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)


def _projection_axes(
    crs: Any, x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Unit vectors (east, north components) of the projection's +X and +Y axes at every (Y, X) point.

    Central differences of a step 1e-3 of the grid spacing, mapped to the local east/north
    plane; velocity east = u*cos_x + v*cos_y, north = u*sin_x + v*sin_y (exact rotation for
    conformal projections such as polar stereographic).
    """
    import pyproj

    transformer = pyproj.Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    xx, yy = np.meshgrid(x, y)
    spacing = [np.median(np.abs(np.diff(a))) for a in (x, y) if a.size > 1]
    step = 1e-3 * (min(spacing) if spacing else 1.0)

    def direction(dx: float, dy: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        lon_p, lat_p = transformer.transform(xx + dx, yy + dy)
        lon_m, lat_m = transformer.transform(xx - dx, yy - dy)
        dlon = (np.asarray(lon_p) - np.asarray(lon_m) + 180.0) % 360.0 - 180.0
        dlat = np.asarray(lat_p) - np.asarray(lat_m)
        east = dlon * np.cos(np.radians(0.5 * (np.asarray(lat_p) + np.asarray(lat_m))))
        norm = np.hypot(east, dlat)
        return east / norm, dlat / norm

    cos_x, sin_x = direction(step, 0.0)
    cos_y, sin_y = direction(0.0, step)
    return cos_x, sin_x, cos_y, sin_y


def _rotate(
    u: NDArray[np.float64], v: NDArray[np.float64], angle: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Grid xi/eta components to east/north; ``angle`` is from east to the xi axis (ROMS convention)."""
    c, s = np.cos(angle), np.sin(angle)
    return u * c - v * s, u * s + v * c


# --------------------------------------------------------------------------------------
# ROMS / CROCO native C-grid output
# --------------------------------------------------------------------------------------


def _load_c_grid(
    ctx: _Context,
    u_var: xr.DataArray,
    v_var: xr.DataArray,
    u_name: str,
    v_name: str,
    kind: str,
    notes: list[str],
    want: _Want,
) -> dict[str, Any]:
    ds, label = ctx.ds, ctx.label
    hint = ctx.grid_hint()

    lon_found = ctx.find(("lon_rho",)) or None
    lat_found = ctx.find(("lat_rho",)) or None
    if lon_found is None or lat_found is None:
        where = "the file" if ctx.grid_ds is None else f"the file or the grid file {ctx.grid_label}"
        raise ForecastError(
            f"{label}: ROMS/CROCO C-grid variables {u_name}/{v_name} but no lon_rho/lat_rho (rho-point longitude/"
            f"latitude) in {where}{hint}"
        )
    lon = _numbers(lon_found[1], "lon_rho", lon_found[2])
    lat = _numbers(lat_found[1], "lat_rho", lat_found[2])
    if lon.ndim != 2 or lon.shape != lat.shape:
        raise ForecastError(
            f"{label}: lon_rho/lat_rho: expected two 2-D arrays of equal shape; got {lon.shape}, {lat.shape}"
        )
    ny, nx = lon.shape
    rho_ydim, rho_xdim = (str(d) for d in lon_found[1].dims)
    for nm, arr in (("lon_rho", lon), ("lat_rho", lat)):
        finite = arr[np.isfinite(arr)]
        if finite.size == 0 or np.ptp(finite) == 0.0:
            raise ForecastError(
                f"{label}: {nm} in {lon_found[2]} is constant or missing (broken packing?); "
                f"expected varying degrees{hint}"
            )
    notes.append(f"ROMS/CROCO C-grid: rho grid {ny} x {nx} ({rho_ydim}, {rho_xdim}), lon/lat from {lon_found[2]}")

    u_roles = _c_grid_dims(ds, u_var, u_name, label)
    v_roles = _c_grid_dims(ds, v_var, v_name, label)
    if u_roles.get("S") != v_roles.get("S") or u_roles.get("T") != v_roles.get("T"):
        raise ForecastError(
            f"{label}: {u_name} {tuple(u_var.dims)} and {v_name} {tuple(v_var.dims)} have different time/level "
            "dimensions; expected the same"
        )
    # One time step (time_index=): the time axis is read first and the step selected before any value.
    early: tuple[NDArray[np.float64], str | None] | None = None
    time_notes: list[str] = []
    t = None
    part = ""
    if want.partial:
        for var, name in ((u_var, u_name), (v_var, v_name)):
            _velocity_factor(var, name, label, [])  # unit errors first, as before
        early = _read_time(ds, u_var, label, u_roles.get("T"), time_notes)
        t = _time_step(early[0], want, label)
        if t is not None:
            part = f"time step {t} of {early[0].size}"
            if "T" in u_roles:
                step = {u_roles["T"]: slice(t, t + 1)}
                u_var, v_var = _lazy(u_var).isel(step), _lazy(v_var).isel(step)
                ctx = replace(ctx, select={**ctx.select, **step})
        for var, name in ((u_var, u_name), (v_var, v_name)):
            _check_size(var, name, label, part=part or "the whole variable")
        u_var, v_var = _computed(_lazy(u_var)), _computed(_lazy(v_var))
    u = _velocity_values(_to_c_tsyx(u_var, u_roles), u_name, label, notes)
    v = _velocity_values(_to_c_tsyx(v_var, v_roles), v_name, label, notes)
    (nyu, nxu), (nyv, nxv) = u.shape[-2:], v.shape[-2:]
    u_xdim, v_ydim = u_roles["X"], v_roles["Y"]
    if nyu != ny or nxu not in (nx - 1, nx):
        raise ForecastError(
            f"{label}: {u_name} horizontal shape ({nyu}, {nxu}) does not fit the rho grid ({ny}, {nx}); expected "
            f"({ny}, {nx - 1}) for u points or ({ny}, {nx}){hint}"
        )
    if nxv != nx or nyv not in (ny - 1, ny):
        raise ForecastError(
            f"{label}: {v_name} horizontal shape ({nyv}, {nxv}) does not fit the rho grid ({ny}, {nx}); expected "
            f"({ny - 1}, {nx}) for v points or ({ny}, {nx}){hint}"
        )
    u_stag = nxu == nx - 1 or u_xdim != rho_xdim
    v_stag = nyv == ny - 1 or v_ydim != rho_ydim
    if (u_stag and nxu == nx) or (v_stag and nyv == ny):
        notes.append(
            "u/v point dimensions have the rho sizes (subsetting artifact): u[i] taken between rho i and i+1, "
            "v[j] between rho j and j+1"
        )

    # Land masks (1 = water): land u/v are not NaN in these files (spec section 1 'land').
    mask_rho_f = ctx.find(("mask_rho",), (ny, nx))
    mask_rho = None if mask_rho_f is None else _mask01(mask_rho_f[1])
    mask_u = _c_grid_mask(ctx, "mask_u", (nyu, nxu), mask_rho, "x", notes)
    mask_v = _c_grid_mask(ctx, "mask_v", (nyv, nxv), mask_rho, "y", notes)
    if mask_u is not None:
        u = np.where(mask_u, u, np.nan)
    if mask_v is not None:
        v = np.where(mask_v, v, np.nan)
    if u_stag or v_stag:
        u = _to_rho(u, nx, axis=-1) if u_stag else u
        v = _to_rho(v, ny, axis=-2) if v_stag else v
        notes.append(
            "u/v averaged from u/v points to rho points (a NaN neighbour makes the point land); rho points on the "
            "domain edge without two neighbours are land"
        )
    if mask_rho is not None:
        u = np.where(mask_rho, u, np.nan)
        v = np.where(mask_rho, v, np.nan)
        notes.append(f"mask_rho applied from {mask_rho_f[2]}")
    if mask_rho is None and mask_u is None and mask_v is None:
        notes.append("no mask_rho/mask_u/mask_v found: land is only where the file's values are missing")

    if kind != "east_north":
        angle_f = ctx.find(("angle",), (ny, nx))
        if angle_f is None:
            raise ForecastError(
                f"{label}: {u_name}/{v_name} are grid-relative (xi/eta) components but no 'angle' at rho points "
                f"({ny}, {nx}) was found to rotate them to east/north{hint}"
            )
        angle = np.asarray(angle_f[1].values, dtype=np.float64)
        if not np.all(np.isfinite(angle)):
            angle = np.where(np.isfinite(angle), angle, np.nan)
        u, v = _rotate(u, v, angle)
        notes.append(
            f"rotated xi/eta components to east/north by 'angle' from {angle_f[2]} "
            f"({np.nanmin(angle):.4g}..{np.nanmax(angle):.4g} rad)"
        )

    if early is None:
        time_s, origin = _read_time(ds, u_var, label, u_roles.get("T"), notes)
    else:
        time_s, origin = early
        notes.extend(time_notes)
    file_n_times = int(time_s.size)
    if t is not None:
        time_s = time_s[t : t + 1]
    depth = None
    covers_surface = True
    if "S" in u_roles and _dim_role(ds, u_roles["S"]) != "S":
        # Fixed z-levels on a ROMS grid (e.g. rho-point output interpolated to depths).
        depth = _read_depth_axis(ds, u_var, label, u_roles["S"], notes)
        if depth is not None and depth.size > 1 and depth[0] > depth[-1]:
            depth, u, v = depth[::-1], u[:, ::-1], v[:, ::-1]
        if depth is not None and depth.size > 1 and np.any(np.diff(depth) <= 0):
            raise ForecastError(f"{label}: depth levels of {u_name}: expected strictly monotonic depths")
    elif "S" in u_roles:
        depth, covers_surface = _s_level_depths(ctx, u_roles["S"], (ny, nx), time_s.size, u_roles.get("T"), notes)
        # Shallowest level first (spec section 1 orders layers by depth).
        depth, u, v = depth[:, ::-1], u[:, ::-1], v[:, ::-1]
    else:
        notes.append("no vertical axis on the velocities (surface field): the field applies to every layer")
    return {
        "u": np.ascontiguousarray(u),
        "v": np.ascontiguousarray(v),
        "lon": lon,
        "lat": lat,
        "depth": None if depth is None else np.ascontiguousarray(depth),
        "time_s": time_s,
        "time_origin": origin,
        "covers_surface": covers_surface,
        "file_n_times": file_n_times,
        "part": part,
    }


def _c_grid_dims(ds: xr.Dataset, var: xr.DataArray, name: str, label: str) -> dict[str, str]:
    dims = [str(d) for d in var.dims]
    if len(dims) < 2 or len(dims) > 4:
        raise ForecastError(
            f"{label}: {name} has dimensions {tuple(dims)}; expected (time, s_rho, eta, xi) or (time, eta, xi)"
        )
    roles = {"Y": dims[-2], "X": dims[-1]}
    for d in dims[:-2]:
        r = _dim_role(ds, d)
        if r in ("S", "Z") and "S" not in roles:
            roles["S"] = d
        elif r == "T" and "T" not in roles:
            roles["T"] = d
        elif var.sizes[d] != 1:
            if "T" not in roles and d == dims[0]:
                roles["T"] = d
            else:
                raise ForecastError(
                    f"{label}: {name}: dimension {d!r} is neither time nor an s-level axis; expected "
                    f"(time, s_rho, eta, xi); got {tuple(dims)}"
                )
    return roles


def _to_c_tsyx(var: xr.DataArray, roles: dict[str, str]) -> xr.DataArray:
    mapped = {"T": roles.get("T"), "Z": roles.get("S"), "Y": roles["Y"], "X": roles["X"]}
    return _to_tzyx(var, {k: d for k, d in mapped.items() if d is not None})


def _mask01(var: xr.DataArray) -> NDArray[np.bool_]:
    """Water where the (possibly packed, 0.99998) mask is above one half; NaN masks are land."""
    values = np.asarray(var.values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return values > 0.5


def _c_grid_mask(
    ctx: _Context,
    name: str,
    shape: tuple[int, int],
    mask_rho: NDArray[np.bool_] | None,
    axis: str,
    notes: list[str],
) -> NDArray[np.bool_] | None:
    found = ctx.find((name,), shape)
    if found is not None:
        notes.append(f"{name} applied from {found[2]}")
        return _mask01(found[1])
    if mask_rho is None:
        return None
    ny, nx = mask_rho.shape
    if axis == "x":
        right = np.minimum(np.arange(shape[1]) + 1, nx - 1)
        mask = mask_rho[:, : shape[1]] & mask_rho[:, right]
    else:
        up = np.minimum(np.arange(shape[0]) + 1, ny - 1)
        mask = mask_rho[: shape[0], :] & mask_rho[up, :]
    notes.append(f"{name} not in the file: derived from mask_rho (water where both rho neighbours are water)")
    return mask


def _to_rho(a: NDArray[np.float64], n_rho: int, *, axis: int) -> NDArray[np.float64]:
    """Average staggered values to rho points: value k sits between rho k and k+1 (C-grid)."""
    a = np.moveaxis(a, axis, -1)
    out = np.full(a.shape[:-1] + (n_rho,), np.nan)
    m = min(a.shape[-1] - 1, n_rho - 1)
    out[..., 1 : 1 + m] = 0.5 * (a[..., :m] + a[..., 1 : m + 1])
    return np.moveaxis(out, -1, axis)


def _s_level_depths(
    ctx: _Context,
    s_dim: str,
    rho_shape: tuple[int, int],
    n_times: int,
    time_dim: str | None,
    notes: list[str],
) -> tuple[NDArray[np.float64], bool]:
    """Depth (positive down) of every s-level, (T, N, Y, X) in file order (bottom first), and covers_surface."""
    ds, label = ctx.ds, ctx.label
    hint = ctx.grid_hint()
    n = int(ds.sizes[s_dim])
    s_name = s_dim if s_dim in ds.variables else None
    if s_name is None:
        raise ForecastError(f"{label}: s-level dimension {s_dim!r} has no coordinate variable with s values")
    s_var = ds[s_name]
    s = np.asarray(s_var.values, dtype=np.float64)
    cs_found = ctx.find(("Cs_r", "Cs_rho"), (n,))
    hc_found = ctx.find(("hc",))
    h_found = ctx.find(("h",), rho_shape)
    missing = [nm for nm, f in (("Cs_r (or Cs_rho)", cs_found), ("hc", hc_found), ("h", h_found)) if f is None]
    if missing:
        raise ForecastError(
            f"{label}: s-level velocities need {', '.join(missing)} to compute depths; not found in the file"
            f"{' or the grid file' if ctx.grid_ds is not None else ''}{hint}"
        )
    assert cs_found is not None and hc_found is not None and h_found is not None
    cs = np.asarray(cs_found[1].values, dtype=np.float64)
    hc = float(np.asarray(hc_found[1].values, dtype=np.float64).ravel()[0])
    h = np.asarray(h_found[1].values, dtype=np.float64)
    vt_found = ctx.find(("Vtransform",))
    if vt_found is not None:
        vtransform = int(round(float(np.asarray(vt_found[1].values).ravel()[0])))
    elif str(s_var.attrs.get("Vtransform", "")).strip():
        vtransform = int(str(s_var.attrs["Vtransform"]).strip())
    elif _attr(s_var, "standard_name").endswith("g2"):
        vtransform = 2
    elif _attr(s_var, "standard_name").endswith("g1"):
        vtransform = 1
    else:
        raise ForecastError(
            f"{label}: s-level depths need Vtransform (1 or 2); no 'Vtransform' variable or attribute and no "
            "standard_name ocean_s_coordinate_g1/g2 on the s variable"
        )
    if vtransform not in (1, 2):
        raise ForecastError(f"{label}: Vtransform = {vtransform} not supported; expected 1 or 2")
    zeta_found = ctx.find(("zeta",))
    if zeta_found is not None and zeta_found[1].shape[-2:] == rho_shape:
        zvar = zeta_found[1]
        if time_dim is not None and time_dim in zvar.dims:
            zvar = zvar.transpose(time_dim, *[d for d in zvar.dims if d != time_dim])
            zeta = np.asarray(zvar.values, dtype=np.float64).reshape(n_times, *rho_shape)
        else:
            zeta = np.broadcast_to(np.asarray(zvar.values, dtype=np.float64).reshape(rho_shape), (n_times, *rho_shape))
        zeta = np.where(np.isfinite(zeta), zeta, 0.0)  # land fill: the velocities there are NaN anyway
    else:
        zeta = np.zeros((n_times, *rho_shape))
        notes.append("no zeta in the file: free surface taken as 0 for s-level depths")
    s4 = s[None, :, None, None]
    c4 = cs[None, :, None, None]
    h4 = h[None, None, :, :]
    z4 = zeta[:, None, :, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        if vtransform == 2:
            z0 = (hc * s4 + h4 * c4) / (hc + h4)
            z = z4 + (z4 + h4) * z0
        else:
            z0 = hc * s4 + (h4 - hc) * c4
            z = z0 + z4 * (1.0 + z0 / h4)
    depth = -z
    notes.append(
        f"{n} s-levels ({s_name}) converted to depths per column with Vtransform={vtransform}, hc={hc:g}, "
        f"{cs_found[0]}, h from {h_found[2]}, zeta"
    )
    covers_surface = True
    if "s_w" in ds.variables:
        s_w = np.sort(np.asarray(ds["s_w"].values, dtype=np.float64))
        if s_w.size > n + 1 and s_w.size >= 2 and np.max(s) < s_w[-2]:
            covers_surface = False
            notes.append(
                f"only {n} of {s_w.size - 1} s-levels kept and the top kept level (s = {np.max(s):.4g}) is not the "
                "model's top level: depths above it at each column are not covered and count as land (interpretation "
                "of spec section 1's 'shallower than the first level' rule, which is meant for z-level products)"
            )
    return depth, covers_surface


# --------------------------------------------------------------------------------------
# Resampling onto the planning grid (spec section 1)
# --------------------------------------------------------------------------------------


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
        moment = np.datetime64(when, "ms")
    except (ValueError, TypeError) as exc:
        raise ForecastError(f"{forecast.source}: time: expected a numpy.datetime64; got {when!r}") from exc
    if np.isnat(moment):
        raise ForecastError(f"{forecast.source}: time: expected a date and time; got NaT")
    origin = _parse_origin(forecast.time_origin, forecast.source)
    offset_s = float((moment - origin) / np.timedelta64(1, "ms")) / 1000.0
    times = forecast.time_s
    step = float(np.median(np.diff(times))) if times.size > 1 else 86400.0
    if offset_s < times[0] - step or offset_s > times[-1] + step:
        first, last = _iso(forecast, times[0]), _iso(forecast, times[-1])
        raise ForecastError(
            f"{forecast.source}: time {moment.astype('datetime64[s]')}Z is outside the forecast ({first} .. {last}) "
            f"by more than one time step ({step:g} s); choose a time within the forecast"
        )
    return int(np.argmin(np.abs(times - offset_s)))


def _iso(forecast: Forecast | ForecastTimes, t_s: float) -> str:
    if forecast.time_origin is None:
        return f"{t_s:g} s"
    origin = _parse_origin(forecast.time_origin, forecast.source)
    return str((origin + np.timedelta64(int(round(t_s * 1000)), "ms")).astype("datetime64[s]")) + "Z"


def describe(forecast: Forecast) -> str:
    """Multi-line summary for ``lrauv forecast info FILE``."""
    n_t, n_z, n_y, n_x = forecast.shape
    lines = [f"source:     {forecast.source}", f"identity:   {forecast.identity}"]
    if forecast.is_regular:
        lines.append(f"layout:     regular lon/lat grid, {n_x} x {n_y} (lon x lat)")
    else:
        lines.append(f"layout:     curvilinear grid with 2-D lon/lat, {n_x} x {n_y} (x x y)")
    if forecast.variables:
        lines.append(f"variables:  {', '.join(forecast.variables)} -> eastward, northward (m/s)")
    times = forecast.time_s
    step = f", step {_duration(float(np.median(np.diff(times))))}" if times.size > 1 else ""
    if forecast.time_origin is not None:
        lines.append(f"time:       {n_t} steps, {_iso(forecast, times[0])} .. {_iso(forecast, times[-1])}{step}")
    else:
        lines.append(f"time:       {n_t} steps, {times[0]:g} .. {times[-1]:g} s (no reference date){step}")
    depth = forecast.depth_m
    if depth is None:
        lines.append("depth:      none (the field applies to every layer)")
    elif depth.ndim == 1:
        lines.append(f"depth:      {depth.size} level(s): {', '.join(f'{d:g}' for d in depth)} m")
    else:
        d0 = depth[0]
        lines.append(
            f"depth:      {n_z} terrain-following levels per column; at time 0 the first level lies at "
            f"{np.nanmin(d0[0]):.3g}..{np.nanmax(d0[0]):.3g} m, "
            f"the last at {np.nanmin(d0[-1]):.3g}..{np.nanmax(d0[-1]):.3g} m"
            + ("" if forecast.covers_surface else "; above the first level: not covered (land)")
        )
    lines.append(
        f"lon:        {np.nanmin(forecast.lon_deg):.4f} .. {np.nanmax(forecast.lon_deg):.4f} deg E; "
        f"lat: {np.nanmin(forecast.lat_deg):.4f} .. {np.nanmax(forecast.lat_deg):.4f} deg N"
    )
    u, v = forecast.u_east_m_s, forecast.v_north_m_s
    water0 = np.isfinite(u[0, 0]) & np.isfinite(v[0, 0])
    lines.append(f"land:       {100.0 * (1.0 - water0.mean()):.1f} % of points at time 0, first level")
    speed = np.hypot(u, v)
    speed = speed[np.isfinite(speed)]
    if speed.size:
        p50, p90, p99 = np.percentile(speed, [50, 90, 99])
        lines.append(f"speed:      p50 {p50:.3f}, p90 {p90:.3f}, p99 {p99:.3f}, max {speed.max():.3f} m/s")
    else:
        lines.append("speed:      no water points")
    if forecast.notes:
        lines.append("notes:")
        lines.extend(f"  - {n}" for n in forecast.notes)
    return "\n".join(lines)


def _duration(seconds: float) -> str:
    for unit, size in (("d", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size and abs(seconds / size - round(seconds / size)) < 1e-9:
            return f"{seconds / size:g} {unit}"
    return f"{seconds:g} s"


def is_periodic_lon(lon: NDArray[np.float64]) -> bool:
    """A regular longitude axis that closes the circle (its last step back to the first is one spacing)."""
    if lon.size < 3:
        return False
    step = float(np.median(np.diff(lon)))
    return abs((lon[-1] - lon[0]) + step - 360.0) <= 0.01 * step
