"""CF conventions as the readers need them: coordinate names and roles, units, time (any CF calendar) and depth.

Which dimension is time, depth, an s-level axis, latitude or longitude (from CF ``axis``,
``standard_name``, ``units``, ``positive`` or, failing those, common names); velocity units to
m/s; CF time units to seconds since an origin; depth levels to metres positive down
(spec section 1). Every refusal is a ``ForecastError`` naming the file and the variable.
"""

from __future__ import annotations

import re

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.calendars import decode_calendar_times, needs_cftime
from planner.forecast.model import parse_origin

# Common coordinate names, used when a dimension's variable has no CF axis, standard_name or units.
_TIME_NAMES = {"time", "t", "ocean_time", "time_counter", "valid_time", "times", "mt", "scrum_time"}
_DEPTH_NAMES = {"depth", "z", "lev", "level", "levels", "deptht", "depthu", "depthv", "zlev", "depth_below_surface"}
_S_NAMES = {"s_rho", "s_w", "sigma", "s"}
_LAT_NAMES = {"lat", "latitude", "nav_lat", "lat_rho", "y_lat", "lats"}
_LON_NAMES = {"lon", "longitude", "nav_lon", "lon_rho", "x_lon", "long", "lons"}
_Y_NAMES = {"y", "yc", "eta", "eta_rho", "eta_u", "eta_v", "j", "ny", "rlat", "nj"}
_X_NAMES = {"x", "xc", "xi", "xi_rho", "xi_u", "xi_v", "i", "nx", "rlon", "ni"}

_DEG_EAST = {"degrees_east", "degree_east", "degree_e", "degrees_e", "degreee", "degreese"}
_DEG_NORTH = {"degrees_north", "degree_north", "degree_n", "degrees_n", "degreen", "degreesn"}

_TIME_UNIT_S = {
    "s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0,
    "min": 60.0, "mins": 60.0, "minute": 60.0, "minutes": 60.0,
    "h": 3600.0, "hr": 3600.0, "hrs": 3600.0, "hour": 3600.0, "hours": 3600.0,
    "d": 86400.0, "day": 86400.0, "days": 86400.0,
}  # fmt: skip

# Finite values beyond this are undeclared fill (no ocean current is 1 km/s).
_MAX_PLAUSIBLE_SPEED_M_S = 1000.0


def attr(var: xr.DataArray | xr.Variable, key: str) -> str:
    """A variable attribute as stripped text; "" when absent."""
    value = var.attrs.get(key, "")
    return value.strip() if isinstance(value, str) else str(value)


def _norm_units(units: str) -> str:
    return units.strip().lower().replace(" ", "").replace("_", "")


def is_lon_like(name: str, var: xr.DataArray | xr.Variable) -> bool:
    """Longitude by CF standard_name or degrees_east units; by name only when it has neither."""
    std = attr(var, "standard_name").lower()
    if std == "longitude":
        return True
    units = _norm_units(attr(var, "units"))
    if units in {u.replace("_", "") for u in _DEG_EAST}:
        return True
    if std or units:
        return False
    return name.lower() in _LON_NAMES


def is_lat_like(name: str, var: xr.DataArray | xr.Variable) -> bool:
    """Latitude by CF standard_name or degrees_north units; by name only when it has neither."""
    std = attr(var, "standard_name").lower()
    if std == "latitude":
        return True
    units = _norm_units(attr(var, "units"))
    if units in {u.replace("_", "") for u in _DEG_NORTH}:
        return True
    if std or units:
        return False
    return name.lower() in _LAT_NAMES


def dim_role(ds: xr.Dataset, dim: str) -> str | None:
    """'T', 'Z', 'S' (terrain-following), 'Y', 'X' or None, from the dimension's coordinate variable or name."""
    name = dim.lower()
    if dim in ds.variables and ds.variables[dim].ndim == 1:
        var = ds.variables[dim]
        axis = attr(var, "axis").upper()
        std = attr(var, "standard_name").lower()
        units = attr(var, "units").lower()
        if std.startswith("ocean_s_coordinate") or std.startswith("ocean_sigma") or name in _S_NAMES:
            return "S"
        if axis in {"T", "Z", "Y", "X"}:
            return axis
        if std == "time" or " since " in f" {units} ":
            return "T"
        if std in {"depth", "height", "altitude"} or attr(var, "positive").lower() in {"up", "down"}:
            return "Z"
        if std in {"latitude", "projection_y_coordinate", "grid_latitude"} or is_lat_like(dim, var):
            return "Y"
        if std in {"longitude", "projection_x_coordinate", "grid_longitude"} or is_lon_like(dim, var):
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


def axis_variable(ds: xr.Dataset, dim: str) -> xr.Variable | None:
    """The dimension's 1-D coordinate variable (same name), or None."""
    return ds.variables[dim] if dim in ds.variables and ds.variables[dim].ndim == 1 else None


def check_numeric(var: xr.DataArray | xr.Variable, what: str, label: str) -> None:
    """Refuse text, character, boolean or compound variables before their values are read."""
    kind = np.dtype(var.dtype).kind
    if kind not in "fiu":
        shown = "text" if kind in "SUO" else str(var.dtype)
        raise ForecastError(
            f"{label}: {what} holds {shown} values (dtype {var.dtype}, dimensions {tuple(str(d) for d in var.dims)}); "
            "expected numbers (floating point, or integers packed with scale_factor/add_offset)"
        )


def numbers(var: xr.DataArray | xr.Variable, what: str, label: str) -> NDArray[np.float64]:
    """A coordinate or grid variable's values as float64, after checking that they are numbers."""
    check_numeric(var, what, label)
    return np.asarray(var.values, dtype=np.float64)


def check_packing(var: xr.DataArray, name: str, label: str) -> None:
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


def describe_std_names(u_var: xr.DataArray, v_var: xr.DataArray) -> str:
    """The velocities' standard names, for the Forecast's notes."""
    su, sv = attr(u_var, "standard_name"), attr(v_var, "standard_name")
    return f" (standard_name {su} / {sv})" if su or sv else " (no standard_name)"


def velocity_factor(var: xr.DataArray, name: str, label: str, notes: list[str]) -> float:
    """Factor to m/s from the variable's units (cm/s and mm/s are converted)."""
    raw = attr(var, "units")
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


def velocity_values(var: xr.DataArray, name: str, label: str, notes: list[str]) -> NDArray[np.float64]:
    """Decoded values (CF fill -> NaN, never 0), in m/s, float64."""
    factor = velocity_factor(var, name, label, notes)
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


def read_time(
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
                attr(cand, "standard_name") == "time" or " since " in f" {attr(cand, 'units')} "
            ):
                tvar_name = str(name)
                break
    n = int(var.sizes[time_dim])
    if tvar_name is None:
        notes.append(f"time dimension {time_dim!r} has no coordinate variable: steps numbered 0..{n - 1} s")
        return np.arange(n, dtype=np.float64), None
    tvar = ds.variables[tvar_name]
    values = numbers(tvar, f"time variable {tvar_name}", label)
    if not np.all(np.isfinite(values)):
        raise ForecastError(f"{label}: time variable {tvar_name} has missing values; expected {n} finite times")
    units = attr(tvar, "units")
    if not units:
        notes.append(f"time variable {tvar_name} has no units: taken as seconds, no reference date")
        factor, origin = 1.0, None
    else:
        factor, origin = _parse_time_units(units, label, tvar_name)
    calendar = attr(tvar, "calendar").lower()
    if origin is not None and needs_cftime(calendar, parse_origin(origin, label)):
        time_s, origin, note = decode_calendar_times(values, factor, units, calendar, label, tvar_name)
        notes.append(note)
    else:
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


def _scalar_depth(ds: xr.Dataset, var: xr.DataArray) -> tuple[str, xr.Variable] | None:
    """(name, variable) of the 0-d depth named in ``var``'s ``coordinates`` (or called 'depth'); None without one."""
    coords = str(var.attrs.get("coordinates", "")).split()
    for cname in coords + ["depth"]:
        if cname in ds.variables and ds.variables[cname].ndim == 0:
            cand = ds.variables[cname]
            if attr(cand, "standard_name") in {"depth", "height"} or cname.lower() in _DEPTH_NAMES:
                return cname, cand
    return None


def read_depth_axis(
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
        scalar = _scalar_depth(ds, var)
        if scalar is None:
            notes.append("no depth axis: the field applies to every layer (spec section 1)")
            return None
        zdim, zvar = scalar
    values = np.atleast_1d(numbers(zvar, f"depth variable {zdim}", label))
    if not np.all(np.isfinite(values)):
        raise ForecastError(f"{label}: depth variable {zdim} has missing values; expected finite depths in metres")
    units = attr(zvar, "units").lower()
    if units in {"cm", "centimeters", "centimetres"}:
        values = values / 100.0
    elif units not in {"", "m", "meter", "meters", "metre", "metres"}:
        raise ForecastError(f"{label}: depth variable {zdim}: units {units!r} not supported; expected metres")
    positive = attr(zvar, "positive").lower()
    std = attr(zvar, "standard_name").lower()
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
