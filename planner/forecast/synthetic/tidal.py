"""A tidal channel on a shelf: an M2 tidal current through a constriction, written as a CF-1.8 netCDF forecast.

An east-west channel between two coasts crosses the lon/lat box; it is widest at both ends
(``mouth_width_m``) and narrows to ``neck_width_m`` at the box's mid longitude. Its full
width at ``X`` metres east of the box centre is::

    W(X) = mouth - (mouth - neck) exp(-(X / neck_length)^2)

and the coasts lie at ``Y = +-W(X) / 2`` about the box's mid latitude (``Y`` metres north of
the centre). Beyond them is land: ``u`` and ``v`` are NaN, as the other sources write land.
A semi-diurnal M2 tide plus a small steady residual flows along the channel::

    S(t) = residual + amplitude cos(omega t + phase),   omega = 2 pi / period
    u = S(t) neck / W(X)
    v = u Y W'(X) / W(X)

``u`` (east) is the same across a section, so the transport through every section,
``u W = S(t) neck`` per metre of depth, is the same: the flow speeds up through the neck
and slows in the mouths, as a constant-depth channel must to conserve mass. ``v`` (north)
is what keeps the field exactly non-divergent: ``du/dX + dv/dY = 0`` everywhere, and on the
coasts ``v / u = +-W' / 2``, the coast's slope, so no water crosses them. The stream function
is ``psi = -S(t) neck Y / W(X)`` (``u = -dpsi/dY``, ``v = dpsi/dX``); the coasts are two
of its streamlines. Why this shape: a plug flow (the same speed across a section, as
between frictionless walls) makes ``amplitude`` the exact tidal speed on the neck's section,
and the Gaussian neck keeps ``W`` smooth so ``v`` is continuous.

The defaults: a 37 x 22 km box, a channel 9 km wide at the ends and 6 km at the neck
(``neck_length`` 8 km), a 0.8 m/s tide at the neck (0.53 m/s at the ends) on a 0.05 m/s
eastward residual. On the neck a 0.5 m/s vehicle is outrun 57 % of the time, and along the
whole channel the tide's amplitude is above 0.5 m/s. At ``t = 0`` with phase 0 the flood runs
east at full strength; half a period later the ebb runs west.

Period: M2, the principal lunar semi-diurnal constituent, whose speed is 28.9841042 deg/h
(NOAA CO-OPS harmonic constituents; Doodson 1921), a period of 12.4206012 h.

Units: the box is mapped onto metres with the spec's flat metric at the box's mid latitude
(``R = 6371 km``), as ``planner.forecast.synthetic.double_gyre`` does, so the field is
non-divergent in metres whatever the box. ``t`` is seconds since ``issue_time``. The field
is the same at every depth: in a shallow, well-mixed channel the tidal current is nearly
uniform above the bottom boundary layer.

Forecast error: a forecast is simply another settings value, as for the double gyre. An
evaluation takes the defaults (or any settings) as the **truth**, plans on a file written
from a perturbed copy and flies the vehicle in ``tidal_velocity(truth, ...)``:

- ``replace(truth, phase_rad=truth.phase_rad + 2 * pi * 1.0 / truth.period_h)``: a one-hour
  timing error (the forecast's tide runs an hour ahead of the truth: the forecast at ``t`` is
  the truth at ``t + 1 h``);
- ``replace(truth, amplitude_m_s=0.8 * truth.amplitude_m_s)``: a 20 % amplitude error;
- ``replace(truth, amplitude_m_s=0.0)``: a forecast that knows only the residual current.

``with_forecast_error(truth, phase_error_h=..., amplitude_error=...)`` makes the first two
(``lrauv forecast tidal --phase-error-h H --amplitude-error F``).

The file layout, CF attributes, encoding and atomic writing are those of the other synthetic
sources (``planner.forecast.synthetic.cf_writer``); ``planner.forecast`` reads the file like any
model file.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import pathlib
from dataclasses import dataclass, replace

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from planner.contract.geodesy import EARTH_RADIUS_M
from planner.forecast.synthetic.cf_writer import (
    FieldError,
    check_analytic,
    check_field,
    is_number,
    layered_dataset,
    lon_lat_axes,
    parse_time,
    write_dataset,
)

__all__ = [
    "GENERATOR_VERSION",
    "M2_PERIOD_H",
    "TidalSettings",
    "box_size_m",
    "channel_width_m",
    "global_attrs",
    "synthesize_tidal",
    "tidal_axes",
    "tidal_velocity",
    "with_forecast_error",
    "write_tidal",
]

GENERATOR_VERSION = "1.0"

# M2 speed 28.9841042 deg/h (NOAA CO-OPS harmonic constituents): 360 / 28.9841042 hours.
M2_PERIOD_H = 12.4206012

_REFERENCE = ("M2 constituent speed 28.9841042 deg/h: NOAA CO-OPS, harmonic constituents "
              "(tidesandcurrents.noaa.gov); Doodson, The harmonic development of the tide-generating "
              "potential, Proc. R. Soc. A 100 (1921) 305-329")


def _check(ok: object, name: str, expected: str, got: object) -> None:
    check_field(ok, "tidal settings", name, expected, got)


@dataclass(frozen=True, kw_only=True)
class TidalSettings:
    """Everything that determines a tidal channel file; same settings, same arrays.

    Grid: points on the box edges, ``linspace(west, east, nx)`` with
    ``nx = round((east - west) / spacing_deg) + 1`` (as ``planner.forecast.synthetic.scb``);
    the defaults give 81 x 41 points. Times: ``0, step_h, 2 step_h, ...`` up to ``hours``,
    hour 0 at ``issue_time``. The channel is centred on the box; ``amplitude_m_s`` and
    ``residual_m_s`` are speeds on the neck's section (positive: eastward).
    """

    west_deg: float = -118.20
    south_deg: float = 33.30
    east_deg: float = -117.80
    north_deg: float = 33.50
    spacing_deg: float = 0.005
    depths_m: tuple[float, ...] = (0.0, 5.0, 10.0, 15.0)
    hours: float = 72.0
    step_h: float = 1.0
    issue_time: str = "2026-01-15T00:00:00Z"
    amplitude_m_s: float = 0.8
    period_h: float = M2_PERIOD_H
    phase_rad: float = 0.0
    residual_m_s: float = 0.05
    mouth_width_m: float = 9000.0
    neck_width_m: float = 6000.0
    neck_length_m: float = 8000.0

    def __post_init__(self) -> None:
        scalars = ("west_deg", "south_deg", "east_deg", "north_deg", "spacing_deg", "hours", "step_h",
                   "amplitude_m_s", "period_h", "phase_rad", "residual_m_s", "mouth_width_m", "neck_width_m",
                   "neck_length_m")
        check_analytic(self, scalars, "tidal settings")
        _check(self.amplitude_m_s >= 0, "amplitude_m_s", "a speed >= 0 in m/s", self.amplitude_m_s)
        _check(self.period_h > 0, "period_h", "a period > 0 in hours", self.period_h)
        _check(self.neck_width_m > 0, "neck_width_m", "a width > 0 in metres", self.neck_width_m)
        _check(self.mouth_width_m >= self.neck_width_m, "mouth_width_m",
               f"at least `neck_width_m` ({self.neck_width_m:g} m): the channel narrows to its neck",
               self.mouth_width_m)
        _check(self.neck_length_m > 0, "neck_length_m", "a length > 0 in metres", self.neck_length_m)
        height_m = box_size_m(self)[1]
        if self.mouth_width_m > height_m:  # names both: the box or the channel may be the wrong one
            raise FieldError("bbox, mouth_width_m", f"tidal settings: `mouth_width_m` must fit in the `bbox`'s "
                              f"height ({height_m:.0f} m) so that both coasts lie inside it; "
                              f"got mouth_width_m={self.mouth_width_m:g}")
        # A neck narrower than two grid rows could close the channel on the grid.
        row_m = EARTH_RADIUS_M * math.radians(self.spacing_deg)
        _check(self.neck_width_m >= 2.0 * row_m, "spacing_deg",
               f"at most half the neck width in degrees of latitude (neck_width_m = {self.neck_width_m:g} m, "
               f"{math.degrees(0.5 * self.neck_width_m / EARTH_RADIUS_M):.4g} deg) so the grid resolves the neck",
               self.spacing_deg)


def with_forecast_error(truth: TidalSettings, *, phase_error_h: float = 0.0,
                        amplitude_error: float = 0.0) -> TidalSettings:
    """A forecast of ``truth`` whose tide runs ``phase_error_h`` hours early, its amplitude times ``1 + amplitude_error``.

    The phase moves by ``2 pi phase_error_h / period_h``, so the forecast at ``t`` is the
    truth's tide at ``t + phase_error_h`` (the residual is unchanged).
    """
    _check(is_number(phase_error_h) and math.isfinite(phase_error_h), "phase_error_h",
           "a finite number of hours", phase_error_h)
    _check(is_number(amplitude_error) and math.isfinite(amplitude_error) and amplitude_error >= -1.0,
           "amplitude_error", "a finite number >= -1 (the amplitude is multiplied by 1 + amplitude_error)",
           amplitude_error)
    phase = truth.phase_rad + 2.0 * math.pi * float(phase_error_h) / truth.period_h
    return replace(truth, phase_rad=phase, amplitude_m_s=truth.amplitude_m_s * (1.0 + float(amplitude_error)))


# --------------------------------------------------------------------------- field


def box_size_m(settings: TidalSettings) -> tuple[float, float]:
    """``(width_m, height_m)`` of the box in the flat metric at its mid latitude (R = 6371 km)."""
    mid_lat = math.radians(0.5 * (settings.south_deg + settings.north_deg))
    width = EARTH_RADIUS_M * math.cos(mid_lat) * math.radians(settings.east_deg - settings.west_deg)
    height = EARTH_RADIUS_M * math.radians(settings.north_deg - settings.south_deg)
    return width, height


def _local_m(
    settings: TidalSettings, lon_deg: NDArray[np.float64], lat_deg: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(X, Y)`` metres east and north of the box centre, flat metric at the mid latitude."""
    s = settings
    mid_lat = 0.5 * (s.south_deg + s.north_deg)
    mid_lon = 0.5 * (s.west_deg + s.east_deg)
    x_m = EARTH_RADIUS_M * math.cos(math.radians(mid_lat)) * np.radians(lon_deg - mid_lon)
    y_m = EARTH_RADIUS_M * np.radians(lat_deg - mid_lat)
    return x_m, y_m


def _width_and_slope(settings: TidalSettings, x_m: NDArray[np.float64]) -> tuple[NDArray[np.float64],
                                                                                  NDArray[np.float64]]:
    """``W(X)`` and ``dW/dX`` of the Gaussian neck."""
    s = settings
    r = x_m / s.neck_length_m
    dip = (s.mouth_width_m - s.neck_width_m) * np.exp(-r * r)
    return s.mouth_width_m - dip, dip * 2.0 * r / s.neck_length_m


def channel_width_m(settings: TidalSettings, lon_deg: ArrayLike) -> NDArray[np.float64]:
    """The channel's full width ``W`` in metres at these longitudes."""
    lon = np.asarray(lon_deg, dtype=np.float64)
    x_m, _ = _local_m(settings, lon, np.zeros_like(lon))
    return _width_and_slope(settings, x_m)[0]


def tidal_velocity(
    settings: TidalSettings, t_s: ArrayLike, lat_deg: ArrayLike, lon_deg: ArrayLike, depth_m: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(u_east_m_s, v_north_m_s)`` of the tidal channel at any points; NaN on land.

    ``t_s`` is seconds since ``settings.issue_time``; the arguments broadcast. The field does
    not depend on depth (``depth_m`` only shapes the result). Outside the box the channel goes
    on with its mouth width.
    """
    s = settings
    t = np.asarray(t_s, dtype=np.float64)
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    depth = np.asarray(depth_m, dtype=np.float64)
    shape = np.broadcast_shapes(t.shape, lat.shape, lon.shape, depth.shape)
    x_m, y_m = _local_m(s, lon, lat)
    width_m, slope = _width_and_slope(s, x_m)
    omega = 2.0 * np.pi / (s.period_h * 3600.0)
    along = s.residual_m_s + s.amplitude_m_s * np.cos(omega * t + s.phase_rad)
    # The same transport through every section: u W = S(t) neck; v keeps du/dX + dv/dY = 0.
    u = along * (s.neck_width_m / width_m)
    v = u * y_m * slope / width_m
    water = np.abs(y_m) <= 0.5 * width_m
    u_out = np.broadcast_to(np.where(water, u, np.nan), shape).astype(np.float64, copy=True)
    v_out = np.broadcast_to(np.where(water, v, np.nan), shape).astype(np.float64, copy=True)
    return u_out, v_out


def tidal_axes(settings: TidalSettings) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Longitudes ``(nx,)``, latitudes ``(ny,)`` on the box edges, and the time axis in hours."""
    lon, lat = lon_lat_axes(settings)
    n_t = int(math.floor(settings.hours / settings.step_h + 1e-9)) + 1
    return lon, lat, np.arange(n_t, dtype=np.float64) * settings.step_h


def synthesize_tidal(settings: TidalSettings = TidalSettings()) -> xr.Dataset:
    """``tidal_velocity`` on the settings' grid as a CF-1.8 dataset.

    Variables ``u``, ``v`` (float32, m/s, NaN on land) have dims ``(time, depth, lat, lon)``;
    every layer holds the same field. The time axis is hours since ``issue_time``.
    """
    lon, lat, hours = tidal_axes(settings)
    depth = np.asarray(settings.depths_m, dtype=np.float64)
    u, v = tidal_velocity(settings, hours[:, None, None] * 3600.0, lat[:, None], lon[None, :], 0.0)
    issued = parse_time(settings.issue_time)
    return layered_dataset(u, v, lon=lon, lat=lat, depth=depth, hours=hours, issued=issued,
                           attrs=global_attrs(settings, issued, float(hours[-1])))


def write_tidal(
    path: str | os.PathLike[str], settings: TidalSettings = TidalSettings()
) -> pathlib.Path:
    """Write ``synthesize_tidal(settings)`` to ``path`` as netCDF-4, atomically (``planner.contract.atomic``).

    Readers never see a partial file; a failure leaves the old file, if any, and
    no temporary file. Missing parent folders are created. Returns the path.
    """
    return write_dataset(path, synthesize_tidal(settings))


# --------------------------------------------------------------------------- dataset


def global_attrs(settings: TidalSettings, issued: dt.datetime, last_h: float) -> dict[str, object]:
    """Global attributes: CF-1.8 plus ACDD discovery fields and the channel's parameters."""
    s = settings
    end = issued + dt.timedelta(hours=last_h)
    stamp = "%Y-%m-%dT%H:%M:%SZ"
    return {
        "Conventions": "CF-1.8",
        "title": "Analytic M2 tidal currents in a channel with a constriction",
        "institution": "lrauv-feedback project (analytic data, not a model run)",
        "source": f"lrauv tidal channel generator v{GENERATOR_VERSION} (planner.forecast.synthetic.tidal)",
        "history": f"created by planner.forecast.synthetic.tidal v{GENERATOR_VERSION}; deterministic, no wall-clock time",
        "references": _REFERENCE,
        "comment": ("u = S(t) neck / W(X), v = u Y W'(X) / W(X), S = residual + amplitude cos(omega t + phase), "
                    "W = mouth - (mouth - neck) exp(-(X / neck_length)^2); coasts at Y = +-W/2 about the box "
                    "centre, land NaN; the same at every depth; non-divergent."),
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
        "tidal_amplitude_m_s": s.amplitude_m_s,
        "tidal_period_hours": s.period_h,
        "tidal_phase_rad": s.phase_rad,
        "tidal_residual_m_s": s.residual_m_s,
        "tidal_mouth_width_m": s.mouth_width_m,
        "tidal_neck_width_m": s.neck_width_m,
        "tidal_neck_length_m": s.neck_length_m,
        "settings": repr(s),
    }
