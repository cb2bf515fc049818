"""The analytic double gyre current field, written as a CF-1.8 netCDF forecast.

The time-dependent double gyre of Shadden, Lekien and Marsden, "Definition and
properties of Lagrangian coherent structures from finite-time Lyapunov
exponents in two-dimensional aperiodic flows", Physica D 212 (2005) 271-304.
On the non-dimensional box ``x`` in [0, 2] (west to east), ``y`` in
[0, 1] (south to north) the stream function is::

    psi(x, y, t) = A sin(pi f(x, t)) sin(pi y)
    f(x, t) = a(t) x^2 + b(t) x,  a = eps sin(omega t + phase),  b = 1 - 2 a

with ``u = -dpsi/dy`` (east) and ``v = dpsi/dx`` (north). Two counter-rotating
gyres (clockwise in the west, counter-clockwise in the east) fill the box; the
line between them, where ``f = 1``, lies at ``x = 1`` when ``a = 0`` and swings
east and west with period ``2 pi / omega`` to about ``x = 1 +- eps`` (1.099 and
0.901 at ``eps = 0.1``). No flow crosses the box edges.

Units: the box is mapped onto ``DoubleGyreSettings``' lon/lat box with the
spec's flat metric at the box's mid latitude (``R = 6371 km``). Each axis has
its own length scale, ``Lx`` = half the width and ``Ly`` = the height in
metres, and the physical stream function is ``Psi0 psi(X / Lx, Y / Ly, t)``,
so the field is exactly non-divergent in metres whatever the box. ``Psi0`` is
chosen so that the **peak speed over the box at eps = 0** (``pi A`` in the
non-dimensional field) is ``peak_speed_m_s``; with ``eps > 0`` the northward
speed can reach ``(1 + 2 eps)`` times that. The default box, 37.1 km x 18.6 km,
is 2:1 in metres (to 2e-5), so ``Lx = Ly`` and the gyres are round. ``t`` is seconds since
``issue_time``, ``omega = 2 pi / period_h``. The field is the same at every
depth (the classic gyre is two-dimensional) and there is no land.

Forecast error: a forecast is simply another settings value. An evaluation
takes the defaults (or any settings) as the **truth**, plans on a file written
from a perturbed copy, e.g. ``replace(truth, eps=0.0)`` (the steady gyre: right
on average, wrong in its oscillation), ``replace(truth, phase_rad=pi / 2)`` (a
timing error) or ``replace(truth, peak_speed_m_s=0.4)`` (a strength error), and
flies the vehicle in ``gyre_velocity(truth, ...)``.

The file layout, CF attributes, encoding and atomic writing are those of
``planner.forecast.synthetic.scb`` (``planner.forecast.synthetic.cf_writer``); ``planner.forecast``
reads the file like any model file.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import pathlib
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from planner.contract.geodesy import EARTH_RADIUS_M
from planner.forecast.synthetic.cf_writer import (
    check_analytic,
    check_field,
    layered_dataset,
    lon_lat_axes,
    parse_time,
    write_dataset,
)

__all__ = [
    "GENERATOR_VERSION",
    "DoubleGyreSettings",
    "box_size_m",
    "global_attrs",
    "gyre_axes",
    "gyre_velocity",
    "synthesize_gyre",
    "write_gyre",
]

GENERATOR_VERSION = "1.0"

_REFERENCE = (
    "Shadden, Lekien and Marsden, Definition and properties of Lagrangian coherent structures from "
    "finite-time Lyapunov exponents in two-dimensional aperiodic flows, Physica D 212 (2005) 271-304"
)


def _check(ok: object, name: str, expected: str, got: object) -> None:
    check_field(ok, "double gyre settings", name, expected, got)


@dataclass(frozen=True, kw_only=True)
class DoubleGyreSettings:
    """Everything that determines a double gyre file; same settings, same arrays.

    Grid: points on the box edges, ``linspace(west, east, nx)`` with
    ``nx = round((east - west) / spacing_deg) + 1`` (as ``planner.forecast.synthetic.scb``);
    the defaults give 81 x 34 points. Times: ``0, step_h, 2 step_h, ...`` up to
    ``hours``, hour 0 at ``issue_time``. ``north_deg = 33.467`` makes the default
    box twice as wide as tall in metres at its mid latitude (37.14 km x 18.57 km).
    """

    west_deg: float = -118.20
    south_deg: float = 33.30
    east_deg: float = -117.80
    north_deg: float = 33.467
    spacing_deg: float = 0.005
    depths_m: tuple[float, ...] = (0.0, 5.0, 10.0, 15.0)
    hours: float = 48.0
    step_h: float = 1.0
    issue_time: str = "2026-01-15T00:00:00Z"
    peak_speed_m_s: float = 0.5
    eps: float = 0.1
    period_h: float = 12.0
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        scalars = ("west_deg", "south_deg", "east_deg", "north_deg", "spacing_deg", "hours", "step_h",
                   "peak_speed_m_s", "eps", "period_h", "phase_rad")
        check_analytic(self, scalars, "double gyre settings")
        _check(self.peak_speed_m_s > 0, "peak_speed_m_s", "a speed > 0 in m/s", self.peak_speed_m_s)
        _check(0.0 <= self.eps <= 0.5, "eps", "in [0, 0.5] (f(x, t) must stay increasing in x)", self.eps)
        _check(self.period_h > 0, "period_h", "a period > 0 in hours", self.period_h)


# --------------------------------------------------------------------------- field


def box_size_m(settings: DoubleGyreSettings) -> tuple[float, float]:
    """``(width_m, height_m)`` of the box in the flat metric at its mid latitude (R = 6371 km)."""
    mid_lat = math.radians(0.5 * (settings.south_deg + settings.north_deg))
    width = EARTH_RADIUS_M * math.cos(mid_lat) * math.radians(settings.east_deg - settings.west_deg)
    height = EARTH_RADIUS_M * math.radians(settings.north_deg - settings.south_deg)
    return width, height


def gyre_velocity(
    settings: DoubleGyreSettings, lon_deg: ArrayLike, lat_deg: ArrayLike, t_s: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(u_east_m_s, v_north_m_s)`` of the double gyre (Shadden et al. 2005) at any points.

    ``t_s`` is seconds since ``settings.issue_time``; the arguments broadcast.
    Points outside the box get the same analytic formula (no masking).
    """
    s = settings
    lon = np.asarray(lon_deg, dtype=np.float64)
    lat = np.asarray(lat_deg, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    x = 2.0 * (lon - s.west_deg) / (s.east_deg - s.west_deg)
    y = (lat - s.south_deg) / (s.north_deg - s.south_deg)
    omega = 2.0 * np.pi / (s.period_h * 3600.0)
    a = s.eps * np.sin(omega * t + s.phase_rad)
    b = 1.0 - 2.0 * a
    f = a * x * x + b * x
    dfdx = 2.0 * a * x + b
    width_m, height_m = box_size_m(s)
    lx_m, ly_m = 0.5 * width_m, height_m
    # Psi = Psi0 psi(X/Lx, Y/Ly): u = -dPsi/dY, v = dPsi/dX; Psi0 = peak min(Lx, Ly) / pi.
    l_min = min(lx_m, ly_m)
    u = -s.peak_speed_m_s * (l_min / ly_m) * np.sin(np.pi * f) * np.cos(np.pi * y)
    v = s.peak_speed_m_s * (l_min / lx_m) * np.cos(np.pi * f) * np.sin(np.pi * y) * dfdx
    return u, v


def gyre_axes(settings: DoubleGyreSettings) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Longitudes ``(nx,)``, latitudes ``(ny,)`` on the box edges, and the time axis in hours."""
    lon, lat = lon_lat_axes(settings)
    n_t = int(math.floor(settings.hours / settings.step_h + 1e-9)) + 1
    return lon, lat, np.arange(n_t, dtype=np.float64) * settings.step_h


def synthesize_gyre(settings: DoubleGyreSettings = DoubleGyreSettings()) -> xr.Dataset:
    """``gyre_velocity`` on the settings' grid as a CF-1.8 dataset.

    Variables ``u``, ``v`` (float32, m/s) have dims ``(time, depth, lat, lon)``;
    every layer holds the same field. The time axis is hours since ``issue_time``.
    """
    lon, lat, hours = gyre_axes(settings)
    depth = np.asarray(settings.depths_m, dtype=np.float64)
    u, v = gyre_velocity(settings, lon[None, :], lat[:, None], hours[:, None, None] * 3600.0)
    issued = parse_time(settings.issue_time)
    return layered_dataset(u, v, lon=lon, lat=lat, depth=depth, hours=hours, issued=issued,
                           attrs=global_attrs(settings, issued, float(hours[-1])))


def write_gyre(
    path: str | os.PathLike[str], settings: DoubleGyreSettings = DoubleGyreSettings()
) -> pathlib.Path:
    """Write ``synthesize_gyre(settings)`` to ``path`` as netCDF-4, atomically (``planner.contract.atomic``).

    Readers never see a partial file; a failure leaves the old file, if any, and
    no temporary file. Missing parent folders are created. Returns the path.
    """
    return write_dataset(path, synthesize_gyre(settings))


# --------------------------------------------------------------------------- dataset


def global_attrs(settings: DoubleGyreSettings, issued: dt.datetime, last_h: float) -> dict[str, object]:
    """Global attributes: CF-1.8 plus ACDD discovery fields and the gyre's parameters."""
    s = settings
    end = issued + dt.timedelta(hours=last_h)
    width_m, height_m = box_size_m(s)
    stamp = "%Y-%m-%dT%H:%M:%SZ"
    return {
        "Conventions": "CF-1.8",
        "title": "Analytic double gyre currents (Shadden, Lekien and Marsden 2005)",
        "institution": "lrauv-feedback project (analytic data, not a model run)",
        "source": f"lrauv double gyre generator v{GENERATOR_VERSION} (planner.forecast.synthetic.double_gyre)",
        "history": f"created by planner.forecast.synthetic.double_gyre v{GENERATOR_VERSION}; deterministic, no wall-clock time",
        "references": _REFERENCE,
        "comment": ("psi = A sin(pi f(x,t)) sin(pi y), f = a x^2 + b x, a = eps sin(omega t + phase), b = 1 - 2a, "
                    "x = 0..2 west to east, y = 0..1 south to north; the same at every depth; no land."),
        "issue_time": f"{issued:{stamp}}",
        "forecast_reference_time": f"{issued:{stamp}}",
        "time_coverage_start": f"{issued:{stamp}}",
        "time_coverage_end": f"{end:{stamp}}",
        "geospatial_lat_min": s.south_deg,
        "geospatial_lat_max": s.north_deg,
        "geospatial_lon_min": s.west_deg,
        "geospatial_lon_max": s.east_deg,
        "geospatial_vertical_min": s.depths_m[0],
        "geospatial_vertical_max": s.depths_m[-1],
        "geospatial_vertical_positive": "down",
        "gyre_peak_speed_m_s": s.peak_speed_m_s,
        "gyre_eps": s.eps,
        "gyre_period_hours": s.period_h,
        "gyre_phase_rad": s.phase_rad,
        "gyre_box_width_m": width_m,
        "gyre_box_height_m": height_m,
        "settings": repr(s),
    }

