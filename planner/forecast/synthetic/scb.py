"""Synthetic ocean forecasts for the Southern California Bight, written as CF-1.8 netCDF.

The paper plans over ROMS forecasts of the Southern California Bight (SCB),
33.30..33.70 N, 117.70..118.26 W, at 0, 5, 10 and 15 m (paper, section
"Simulation results"). This module makes a deterministic stand-in for such a
forecast: an analytic current field, ``current_at``, sampled on a regular grid by
``synthesize`` and written by ``write_synthetic`` as a file that any CF reader
reads like a model file (velocities found by CF standard name, coordinates by CF
attributes, land as ``_FillValue`` NaN; spec section 1).

What the field is made of (all speeds in m/s, distances in km):

- **Coast and land.** A smoothed polyline through Point Fermin, Long Beach,
  Seal Beach, Huntington Beach, Newport, Corona del Mar, Laguna Beach, Dana
  Point and San Clemente; land lies north-east of it. A synthetic bathymetry
  deepens offshore, gently on the San Pedro shelf in the north-west and steeply
  off Laguna and Dana Point in the south-east, with one small offshore shoal.
  A point is land at a depth when the sea floor is no deeper than that depth,
  so land grows with depth (spec section 1: "a cell may be water at 0 m and
  land at 15 m").
- **Eddies.** Isolated Gaussian vortices, ``v_theta(r) = V (r/R) exp((1 - r^2/R^2)/2)``
  (peak speed ``V`` at radius ``R``; Carton, "Hydrodynamical modeling of oceanic
  vortices", Surv. Geophys. 22, 2001), of radius 3..8 km as seen in the SCB
  (DiGiacomo and Holt, "Satellite observations of small coastal ocean eddies in
  the Southern California Bight", JGR 106(C10), 2001), drifting slowly
  westward, waxing and waning, damped within a few km of the coast.
- **Shelf current.** A poleward alongshore jet a few km offshore (the winter
  inshore countercurrent; Hickey, "Circulation over the Santa Monica-San Pedro
  basin and shelf", Prog. Oceanogr. 30, 1992), an equatorward background
  offshore, and barotropic M2 (12.4206 h) and K1 (23.9345 h) alongshore tides.
- **Submesoscale variability.** A few non-divergent plane waves of 8..30 km
  wavelength drifting at a few cm/s.

Everything except the tide weakens with depth, ``exp(-z / depth_efold_m)``,
and veers clockwise with depth (Ekman, 1905). Speeds are clipped at
``max_speed_m_s``.

Forecast issues: the field for a seed is the **truth** (``issue_number=None``).
Issue ``n`` (0, 1, 2, ...) is issued ``n * issue_interval_h`` hours after
``issue_time`` and equals the truth plus an error: the same scene with perturbed
eddy positions, sizes, strengths and drifts, perturbed shelf current and tidal
phases, plus extra random plane waves. The error is scaled by a gain, fitted
once per issue, so that over water on the issue's own grid and time window
``RMS|forecast - truth| / RMS|truth| = error_scale * error_decay ** n``
(defaults 0.3 * 0.5**n), before the speed clip. A newer issue is closer to the
truth. ``error_draw`` (default None) picks one of many independent error draws
of the same size for an issue (ensemble members, ``planner.forecast.synthetic.ensemble``); None is
the one draw that files without it have always had.

Times: ``current_at`` takes seconds since ``settings.issue_time`` (the start of
the scenario and the issue time of issue 0) for truth and every issue alike;
a file's time axis is "hours since" its own issue time.

Nothing of the reader is imported (only ``planner.contract`` and the writer's
``planner.forecast.synthetic.cf_writer``): ``planner.forecast`` reads these files exactly as it
reads a model's.
"""

from __future__ import annotations

import datetime as dt
import functools
import os
import pathlib
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from planner.contract.errors import PlannerError
from planner.contract.geodesy import M_PER_DEG_LAT
from planner.forecast.synthetic.cf_writer import (
    DIMS,
    U_ATTRS,
    V_ATTRS,
    coordinates,
    grid_counts,
    lon_lat_axes,
    netcdf_encoding,
    parse_time,
    set_time_units,
    with_numeric_time,
    write_netcdf,
)

__all__ = [
    "GENERATOR_VERSION",
    "SyntheticSettings",
    "bottom_depth_m",
    "current_at",
    "global_attrs",
    "issue_datetime",
    "synthesize",
    "write_synthetic",
]

GENERATOR_VERSION = "1.0"

_KM_PER_DEG_LAT = M_PER_DEG_LAT / 1000.0
# Local flat-earth metric for the analytic field, fixed at the paper's region centre
# so that the field does not depend on the box it is sampled on.
_REF_LON_DEG = -117.98
_REF_LAT_DEG = 33.50
_KM_PER_DEG_LON = _KM_PER_DEG_LAT * float(np.cos(np.radians(_REF_LAT_DEG)))

# Coast vertices (lon, lat), west to east; land lies north-east of the line.
# Point Fermin, Long Beach, Seal Beach, Huntington Beach, Newport Beach,
# Corona del Mar, Laguna Beach, Dana Point, San Clemente.
_COAST_DEG = np.array(
    [
        (-118.290, 33.705),
        (-118.190, 33.755),
        (-118.100, 33.740),
        (-118.005, 33.655),
        (-117.930, 33.607),
        (-117.870, 33.590),
        (-117.785, 33.540),
        (-117.700, 33.460),
        (-117.610, 33.420),
    ]
)
_COAST_SMOOTHING_DEG = 0.008  # width of the rounded corners at the vertices

_M2_PERIOD_S = 12.4206012 * 3600.0
_K1_PERIOD_S = 23.9344696 * 3600.0


# --------------------------------------------------------------------------- helpers


def _check(ok: object, name: str, expected: str, got: object) -> None:
    if not ok:
        raise PlannerError(f"synthetic settings: `{name}` must be {expected}; got {got!r}")


def _check_issue(issue_number: int | None) -> int | None:
    if issue_number is None:
        return None
    if isinstance(issue_number, bool) or not isinstance(issue_number, (int, np.integer)) or issue_number < 0:
        raise PlannerError(f"synthetic: `issue_number` must be None (truth) or an integer >= 0; got {issue_number!r}")
    return int(issue_number)


def _issue_offset_h(settings: SyntheticSettings, issue_number: int | None) -> float:
    return 0.0 if issue_number is None else issue_number * settings.issue_interval_h


@dataclass(frozen=True, kw_only=True)
class SyntheticSettings:
    """Everything that determines a synthetic scenario; same settings, same arrays.

    Grid: points on the box edges, ``linspace(west, east, nx)`` with
    ``nx = round((east - west) / spacing_deg) + 1`` (so about ``spacing_deg``
    apart; spec section 1); the defaults give the paper's box, 57 x 41 points.
    Times: ``hours + 1`` hourly steps, hour 0 at the issue time.

    Random draws come from ``numpy.random.default_rng(seed)``; eddy centres are
    drawn inside the box, so the box is part of the scenario (the coast,
    bathymetry and everything else are fixed functions of longitude and latitude).
    Speed defaults are chosen so that over water the median speed is about
    0.07..0.10 m/s and the maximum stays under ``max_speed_m_s`` almost
    everywhere before clipping (eddies 0.12..0.28 m/s at their radius, shelf
    jet 0.12 m/s poleward, background 0.08 m/s equatorward, tides 0.06 + 0.03 m/s).
    """

    seed: int = 0
    hours: int = 72
    spacing_deg: float = 0.01
    depths_m: tuple[float, ...] = (0.0, 5.0, 10.0, 15.0)
    issue_time: str = "2026-01-15T00:00:00Z"
    # The paper's region (GIS order names, as planner.grid.BBox).
    west_deg: float = -118.26
    south_deg: float = 33.30
    east_deg: float = -117.70
    north_deg: float = 33.70
    # Eddies.
    n_eddies: int = 4
    eddy_radius_km: tuple[float, float] = (3.0, 8.0)
    eddy_speed_m_s: tuple[float, float] = (0.12, 0.28)
    eddy_drift_m_s: float = 0.03
    # Shelf current, background and tide (alongshore; positive = equatorward, towards the south-east).
    shelf_speed_m_s: float = -0.12
    shelf_jet_km: float = 3.0
    background_speed_m_s: float = 0.08
    tide_m2_m_s: float = 0.06
    tide_k1_m_s: float = 0.03
    # Submesoscale plane waves.
    n_waves: int = 6
    wave_speed_m_s: float = 0.03
    # Vertical structure.
    depth_efold_m: float = 20.0
    veer_deg_per_m: float = 1.5
    max_speed_m_s: float = 0.5
    # Bathymetry: near-shore slope, north-west (San Pedro shelf) and south-east (Dana Point).
    shelf_slope_nw_m_per_km: float = 6.0
    shelf_slope_se_m_per_km: float = 25.0
    basin_depth_m: float = 600.0
    shoal_lon_deg: float = -118.10
    shoal_lat_deg: float = 33.50
    shoal_crest_m: float | None = 8.0
    shoal_radius_km: float = 2.5
    # Forecast issues.
    error_scale: float = 0.3
    error_decay: float = 0.5
    issue_interval_h: float = 6.0
    # Which independent error draw an issue uses: None (the default draw) or an integer >= 0
    # (ensemble member; planner.forecast.synthetic.ensemble). Left out of repr so that files without it keep their bytes.
    error_draw: int | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        # Tuples of floats, so that settings stay hashable (scenes are cached per settings).
        for name in ("depths_m", "eddy_radius_km", "eddy_speed_m_s"):
            value = getattr(self, name)
            _check(np.ndim(value) == 1, name, "a sequence of numbers", value)
            object.__setattr__(self, name, tuple(float(x) for x in value))
        _check(len(self.eddy_radius_km) == 2 and len(self.eddy_speed_m_s) == 2,
               "eddy_radius_km and eddy_speed_m_s", "(min, max) pairs", (self.eddy_radius_km, self.eddy_speed_m_s))
        _check(isinstance(self.seed, int) and not isinstance(self.seed, bool) and self.seed >= 0,
               "seed", "an integer >= 0", self.seed)
        _check(isinstance(self.hours, int) and not isinstance(self.hours, bool) and self.hours >= 1,
               "hours", "an integer >= 1", self.hours)
        _check(np.isfinite(self.spacing_deg) and self.spacing_deg > 0, "spacing_deg", "a number > 0", self.spacing_deg)
        values = (self.west_deg, self.south_deg, self.east_deg, self.north_deg)
        _check(bool(np.all(np.isfinite(values))) and self.west_deg < self.east_deg and self.south_deg < self.north_deg,
               "bbox", "finite WEST < EAST and SOUTH < NORTH", values)
        nx, ny = grid_counts(self)
        _check(nx >= 2 and ny >= 2, "spacing_deg", "at least 2 points per axis in the box", self.spacing_deg)
        depths = np.asarray(self.depths_m, dtype=np.float64)
        _check(depths.ndim == 1 and depths.size >= 1 and bool(np.all(np.isfinite(depths)))
               and bool(np.all(depths >= 0)) and bool(np.all(np.diff(depths) > 0)),
               "depths_m", "non-negative depths in metres, strictly increasing", self.depths_m)
        parse_time(self.issue_time)
        _check(isinstance(self.n_eddies, int) and self.n_eddies >= 0, "n_eddies", "an integer >= 0", self.n_eddies)
        _check(isinstance(self.n_waves, int) and self.n_waves >= 0, "n_waves", "an integer >= 0", self.n_waves)
        r_lo, r_hi = self.eddy_radius_km
        _check(0 < r_lo <= r_hi, "eddy_radius_km", "0 < min <= max", self.eddy_radius_km)
        s_lo, s_hi = self.eddy_speed_m_s
        _check(0 <= s_lo <= s_hi, "eddy_speed_m_s", "0 <= min <= max", self.eddy_speed_m_s)
        for name in ("depth_efold_m", "max_speed_m_s", "shelf_jet_km", "shelf_slope_nw_m_per_km",
                     "shelf_slope_se_m_per_km", "basin_depth_m", "shoal_radius_km", "issue_interval_h"):
            value = getattr(self, name)
            _check(np.isfinite(value) and value > 0, name, "a number > 0", value)
        _check(self.error_scale >= 0, "error_scale", "a number >= 0", self.error_scale)
        _check(0 < self.error_decay < 1, "error_decay", "a number in (0, 1)", self.error_decay)
        _check(self.error_draw is None or (isinstance(self.error_draw, (int, np.integer))
                                           and not isinstance(self.error_draw, bool) and self.error_draw >= 0),
               "error_draw", "None or an integer >= 0", self.error_draw)
        if self.error_draw is not None:
            object.__setattr__(self, "error_draw", int(self.error_draw))
        if self.shoal_crest_m is not None:
            _check(0 < self.shoal_crest_m < self.basin_depth_m, "shoal_crest_m",
                   "None or a depth between 0 and basin_depth_m", self.shoal_crest_m)


# --------------------------------------------------------------------------- public API


def synthesize(settings: SyntheticSettings = SyntheticSettings(), *, issue_number: int | None = None) -> xr.Dataset:
    """The field of ``current_at`` on the settings' grid, as a CF-1.8 dataset.

    ``issue_number=None`` is the truth; ``n >= 0`` is forecast issue ``n``, whose
    time axis starts at its own issue time (``issue_datetime``). Variables ``u``,
    ``v`` (float32, m/s, NaN on land) have dims ``(time, depth, lat, lon)``.
    """
    n = _check_issue(issue_number)
    lon, lat = lon_lat_axes(settings)
    depth = np.asarray(settings.depths_m, dtype=np.float64)
    hours = np.arange(settings.hours + 1, dtype=np.float64)
    t_s = (hours + _issue_offset_h(settings, n)) * 3600.0
    u, v = _sample(settings, n, t_s[:, None, None, None], lon[None, None, None, :],
                   lat[None, None, :, None], depth[None, :, None, None])
    return _dataset(settings, n, lon, lat, depth, hours, u.astype(np.float32), v.astype(np.float32))


def write_synthetic(
    path: str | os.PathLike[str],
    settings: SyntheticSettings = SyntheticSettings(),
    *,
    issue_number: int | None = None,
) -> pathlib.Path:
    """Write ``synthesize(settings, issue_number=...)`` to ``path`` as netCDF-4, atomically.

    The file is written to a temporary file in the same directory and moved into
    place with ``os.replace``; readers never see a partial file, and a failure
    leaves no temporary file behind. Returns the path written.
    """
    ds_file = with_numeric_time(synthesize(settings, issue_number=issue_number))
    return write_netcdf(path, ds_file, netcdf_encoding(ds_file))


def current_at(
    settings: SyntheticSettings,
    t_s: ArrayLike,
    lon_deg: ArrayLike,
    lat_deg: ArrayLike,
    depth_m: ArrayLike,
    *,
    issue_number: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eastward and northward current (m/s) anywhere; NaN on land.

    ``t_s`` is seconds since ``settings.issue_time`` (for every issue: issue ``n``'s
    file hour ``h`` is ``t_s = 3600 * (h + n * issue_interval_h)``). Inputs
    broadcast against each other; outputs have the broadcast shape, float64.
    ``synthesize`` samples exactly this function (then rounds to float32).
    """
    n = _check_issue(issue_number)
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (t_s, lon_deg, lat_deg, depth_m)))
    return _sample(settings, n, *arrays)


def bottom_depth_m(settings: SyntheticSettings, lon_deg: ArrayLike, lat_deg: ArrayLike) -> NDArray[np.float64]:
    """Sea-floor depth (m, positive down; negative on land). Land at depth ``z`` where this is ``<= z``."""
    lon, lat = np.broadcast_arrays(np.asarray(lon_deg, dtype=np.float64), np.asarray(lat_deg, dtype=np.float64))
    return _coast_geometry(settings, lon, lat).bottom_m


def issue_datetime(settings: SyntheticSettings, *, issue_number: int | None) -> dt.datetime:
    """Issue time (UTC, aware) of issue ``n``, ``issue_time + n * issue_interval_h``; the truth's is ``issue_time``."""
    n = _check_issue(issue_number)
    return parse_time(settings.issue_time) + dt.timedelta(hours=_issue_offset_h(settings, n))


# --------------------------------------------------------------------------- scene


@dataclass(frozen=True, eq=False, kw_only=True)
class _Scene:
    """Random parameters of one field; arrays are per eddy ``(n_eddies,)`` or per wave ``(n_waves,)``.

    Scenes are cached, so their arrays are made read-only.
    """

    eddy_x_km: NDArray[np.float64]
    eddy_y_km: NDArray[np.float64]
    eddy_vx_m_s: NDArray[np.float64]
    eddy_vy_m_s: NDArray[np.float64]
    eddy_radius_km: NDArray[np.float64]
    eddy_speed_m_s: NDArray[np.float64]  # signed: > 0 counter-clockwise (cyclonic)
    eddy_life_rad_s: NDArray[np.float64]
    eddy_life_phase: NDArray[np.float64]
    wave_kx: NDArray[np.float64]  # rad/km
    wave_ky: NDArray[np.float64]
    wave_omega_rad_s: NDArray[np.float64]
    wave_phase: NDArray[np.float64]
    wave_amp_m_s: NDArray[np.float64]
    shelf_m_s: float
    background_m_s: float
    m2_m_s: float
    m2_phase: float
    k1_m_s: float
    k1_phase: float

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if isinstance(value, np.ndarray):
                frozen = np.array(value, dtype=np.float64)
                frozen.setflags(write=False)
                object.__setattr__(self, name, frozen)


@dataclass(frozen=True, eq=False, kw_only=True)
class _Coast:
    """Coast-relative geometry of points: all arrays have the points' shape."""

    x_km: NDArray[np.float64]
    y_km: NDArray[np.float64]
    offshore_km: NDArray[np.float64]  # distance from the coast, > 0 at sea
    along_x: NDArray[np.float64]  # unit alongshore vector, towards the south-east
    along_y: NDArray[np.float64]
    bottom_m: NDArray[np.float64]


@functools.lru_cache(maxsize=64)
def _truth_scene(settings: SyntheticSettings) -> _Scene:
    """The truth's parameters, drawn from ``default_rng(seed)`` in a fixed order."""
    rng = np.random.default_rng(settings.seed)
    s = settings
    ne = s.n_eddies
    # Eddy centres: uniform over the box, kept where the water is deep and the
    # coast at least one radius away (rejection sampling, bounded).
    radius = rng.uniform(*s.eddy_radius_km, size=ne)
    x0 = np.empty(ne)
    y0 = np.empty(ne)
    for e in range(ne):
        for _attempt in range(200):
            lon = rng.uniform(s.west_deg, s.east_deg)
            lat = rng.uniform(s.south_deg, s.north_deg)
            geo = _coast_geometry(s, np.array(lon), np.array(lat))
            if float(geo.offshore_km) > radius[e] + 1.0:
                break
        x0[e], y0[e] = float(geo.x_km), float(geo.y_km)
    speed = rng.uniform(*s.eddy_speed_m_s, size=ne) * rng.choice([-1.0, 1.0], size=ne)
    drift_dir = np.pi + rng.uniform(-np.pi / 3, np.pi / 3, size=ne)  # westward, +-60 deg
    drift = s.eddy_drift_m_s * rng.uniform(0.5, 1.5, size=ne)
    life_period_s = rng.uniform(3.0, 8.0, size=ne) * 86400.0
    life_phase = rng.uniform(0.0, 2 * np.pi, size=ne)

    nw = s.n_waves
    wavelength_km = rng.uniform(8.0, 30.0, size=nw)
    wave_dir = rng.uniform(0.0, 2 * np.pi, size=nw)
    k = 2 * np.pi / wavelength_km
    wave_c = rng.uniform(0.01, 0.05, size=nw)  # phase speed m/s
    wave_phase = rng.uniform(0.0, 2 * np.pi, size=nw)
    wave_amp = s.wave_speed_m_s * rng.uniform(0.5, 1.5, size=nw)
    m2_phase, k1_phase = rng.uniform(0.0, 2 * np.pi, size=2)
    return _Scene(
        eddy_x_km=x0, eddy_y_km=y0,
        eddy_vx_m_s=drift * np.cos(drift_dir), eddy_vy_m_s=drift * np.sin(drift_dir),
        eddy_radius_km=radius, eddy_speed_m_s=speed,
        eddy_life_rad_s=2 * np.pi / life_period_s, eddy_life_phase=life_phase,
        wave_kx=k * np.cos(wave_dir), wave_ky=k * np.sin(wave_dir),
        wave_omega_rad_s=k * wave_c / 1000.0, wave_phase=wave_phase, wave_amp_m_s=wave_amp,
        shelf_m_s=s.shelf_speed_m_s, background_m_s=s.background_speed_m_s,
        m2_m_s=s.tide_m2_m_s, m2_phase=float(m2_phase), k1_m_s=s.tide_k1_m_s, k1_phase=float(k1_phase),
    )


@functools.lru_cache(maxsize=64)
def _forecast_scene(settings: SyntheticSettings, issue_number: int) -> _Scene:
    """The truth's scene with errors of relative size ``error_scale * error_decay**n``.

    Drawn from ``default_rng([seed, 1, n])``, independently per issue, or with
    ``error_draw = k`` from ``default_rng([seed, 2, n, k])`` (independent draws
    of the same size); the gain in ``_error_gain`` then makes the relative RMS error exact.
    """
    truth = _truth_scene(settings)
    if settings.error_draw is None:
        rng = np.random.default_rng([settings.seed, 1, issue_number])
    else:
        rng = np.random.default_rng([settings.seed, 2, issue_number, settings.error_draw])
    a = settings.error_scale * settings.error_decay**issue_number
    ne = truth.eddy_x_km.size
    nw = settings.n_waves
    # Extra plane waves: the "smooth random perturbation".
    wavelength_km = rng.uniform(8.0, 30.0, size=nw)
    wave_dir = rng.uniform(0.0, 2 * np.pi, size=nw)
    k = 2 * np.pi / wavelength_km
    wave_c = rng.uniform(0.01, 0.05, size=nw)
    extra_amp = a * settings.background_speed_m_s * rng.uniform(0.5, 1.5, size=nw)
    return _Scene(
        eddy_x_km=truth.eddy_x_km + a * truth.eddy_radius_km * rng.standard_normal(ne),
        eddy_y_km=truth.eddy_y_km + a * truth.eddy_radius_km * rng.standard_normal(ne),
        eddy_vx_m_s=truth.eddy_vx_m_s + a * settings.eddy_drift_m_s * rng.standard_normal(ne),
        eddy_vy_m_s=truth.eddy_vy_m_s + a * settings.eddy_drift_m_s * rng.standard_normal(ne),
        eddy_radius_km=truth.eddy_radius_km * np.exp(0.5 * a * rng.standard_normal(ne)),
        eddy_speed_m_s=truth.eddy_speed_m_s * (1.0 + a * rng.standard_normal(ne)),
        eddy_life_rad_s=truth.eddy_life_rad_s,
        eddy_life_phase=truth.eddy_life_phase + a * rng.standard_normal(ne),
        wave_kx=np.concatenate([truth.wave_kx, k * np.cos(wave_dir)]),
        wave_ky=np.concatenate([truth.wave_ky, k * np.sin(wave_dir)]),
        wave_omega_rad_s=np.concatenate([truth.wave_omega_rad_s, k * wave_c / 1000.0]),
        wave_phase=np.concatenate([truth.wave_phase + a * rng.standard_normal(nw),
                                   rng.uniform(0.0, 2 * np.pi, size=nw)]),
        wave_amp_m_s=np.concatenate([truth.wave_amp_m_s, extra_amp]),
        shelf_m_s=truth.shelf_m_s * (1.0 + a * float(rng.standard_normal())),
        background_m_s=truth.background_m_s * (1.0 + a * float(rng.standard_normal())),
        m2_m_s=truth.m2_m_s, m2_phase=truth.m2_phase + a * float(rng.standard_normal()),
        k1_m_s=truth.k1_m_s, k1_phase=truth.k1_phase + a * float(rng.standard_normal()),
    )


# --------------------------------------------------------------------------- field


def _coast_geometry(settings: SyntheticSettings, lon: NDArray[np.float64], lat: NDArray[np.float64]) -> _Coast:
    """Coast-relative coordinates and bathymetry of points ``lon``, ``lat`` (same shape)."""
    # Coast latitude c(lon): the polyline with corners rounded by softplus, so
    # that c and its slope are smooth (c' is a sum of logistic steps).
    xs, ys = _COAST_DEG[:, 0], _COAST_DEG[:, 1]
    slopes = np.diff(ys) / np.diff(xs)
    w = _COAST_SMOOTHING_DEG
    coast_lat = ys[0] + slopes[0] * (lon - xs[0])
    coast_slope = np.full_like(lon, slopes[0])
    for kk in range(1, slopes.size):
        z = (lon - xs[kk]) / w
        coast_lat = coast_lat + (slopes[kk] - slopes[kk - 1]) * w * np.logaddexp(0.0, z)
        coast_slope = coast_slope + (slopes[kk] - slopes[kk - 1]) * 0.5 * (1.0 + np.tanh(0.5 * z))
    m = coast_slope * (_KM_PER_DEG_LAT / _KM_PER_DEG_LON)  # km north per km east
    norm = np.sqrt(1.0 + m * m)
    offshore = (coast_lat - lat) * _KM_PER_DEG_LAT / norm
    x_km = (lon - _REF_LON_DEG) * _KM_PER_DEG_LON
    y_km = (lat - _REF_LAT_DEG) * _KM_PER_DEG_LAT

    # Bathymetry: slope at the coast grows linearly in longitude from Seal Beach
    # (-118.10) to Dana Point (-117.70), saturating at the basin depth offshore.
    frac = np.clip((lon - (-118.10)) / (-117.70 - (-118.10)), 0.0, 1.0)
    slope_nw, slope_se = settings.shelf_slope_nw_m_per_km, settings.shelf_slope_se_m_per_km
    slope = slope_nw + frac * (slope_se - slope_nw)
    h_basin = settings.basin_depth_m
    bottom = h_basin * -np.expm1(-slope * offshore / h_basin)
    if settings.shoal_crest_m is not None:
        sx = (lon - settings.shoal_lon_deg) * _KM_PER_DEG_LON
        sy = (lat - settings.shoal_lat_deg) * _KM_PER_DEG_LAT
        # Flat-topped shoal: g = exp(-(r/R)^4) keeps the top near the crest depth out to about R/2.
        q = (sx * sx + sy * sy) / settings.shoal_radius_km**2
        g = np.exp(-q * q)
        crest = settings.shoal_crest_m
        bottom = np.where(bottom > crest, bottom - (bottom - crest) * g, bottom)
    return _Coast(x_km=x_km, y_km=y_km, offshore_km=offshore, along_x=1.0 / norm, along_y=m / norm, bottom_m=bottom)


def _raw_field(
    settings: SyntheticSettings,
    scene: _Scene,
    geo: _Coast,
    t_s: NDArray[np.float64],
    depth_m: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unclipped current (m/s), NaN on land; arrays broadcast as ``t_s`` x points x ``depth_m``."""
    d = np.maximum(geo.offshore_km, 0.0)
    coast_damping = -np.expm1(-d / 2.0)  # eddies fade within ~2 km of the coast
    # Baroclinic surface field: eddies + waves + shelf jet + background.
    u = np.zeros(np.broadcast_shapes(np.shape(t_s), geo.x_km.shape))
    v = np.zeros_like(u)
    for e in range(scene.eddy_x_km.size):
        xc = scene.eddy_x_km[e] + scene.eddy_vx_m_s[e] * t_s / 1000.0
        yc = scene.eddy_y_km[e] + scene.eddy_vy_m_s[e] * t_s / 1000.0
        dx = geo.x_km - xc
        dy = geo.y_km - yc
        r_e = scene.eddy_radius_km[e]
        life = 0.75 + 0.25 * np.cos(scene.eddy_life_rad_s[e] * t_s + scene.eddy_life_phase[e])
        # v_theta = V (r/R) exp((1 - r^2/R^2)/2): u = -v_theta dy/r, v = v_theta dx/r.
        amp = (scene.eddy_speed_m_s[e] / r_e) * life * np.exp(0.5 * (1.0 - (dx * dx + dy * dy) / (r_e * r_e)))
        u = u - amp * dy
        v = v + amp * dx
    u = u * coast_damping
    v = v * coast_damping
    for w in range(scene.wave_kx.size):
        kx, ky = scene.wave_kx[w], scene.wave_ky[w]
        kk = np.hypot(kx, ky)
        # Stream function psi = (A/k) cos(theta): u = -dpsi/dy, v = dpsi/dx.
        s = scene.wave_amp_m_s[w] * np.sin(kx * geo.x_km + ky * geo.y_km - scene.wave_omega_rad_s[w] * t_s
                                           + scene.wave_phase[w])
        u = u + s * (ky / kk)
        v = v - s * (kx / kk)
    jet_scale = settings.shelf_jet_km
    jet = (d / jet_scale) * np.exp(1.0 - d / jet_scale)
    offshore_ramp = -np.expm1(-d / (3.0 * jet_scale))
    along = scene.shelf_m_s * jet + scene.background_m_s * offshore_ramp
    u = u + along * geo.along_x
    v = v + along * geo.along_y
    # Depth: e-folding decay and clockwise (Ekman) veering.
    decay = np.exp(-depth_m / settings.depth_efold_m)
    angle = -np.radians(settings.veer_deg_per_m) * depth_m
    ca, sa = np.cos(angle) * decay, np.sin(angle) * decay
    u, v = u * ca - v * sa, u * sa + v * ca
    # Barotropic alongshore tide (M2 + K1), depth independent, fading at the coast.
    tide = (scene.m2_m_s * np.cos(2 * np.pi * t_s / _M2_PERIOD_S + scene.m2_phase)
            + scene.k1_m_s * np.cos(2 * np.pi * t_s / _K1_PERIOD_S + scene.k1_phase)) * -np.expm1(-d / 1.0)
    u = u + tide * geo.along_x
    v = v + tide * geo.along_y
    land = geo.bottom_m <= depth_m
    u = np.where(land, np.nan, u)
    v = np.where(land, np.nan, v)
    return u, v


def _sample(
    settings: SyntheticSettings,
    issue_number: int | None,
    t_s: NDArray[np.float64],
    lon: NDArray[np.float64],
    lat: NDArray[np.float64],
    depth: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The clipped field (truth or issue) on broadcastable arrays."""
    lon_b, lat_b = np.broadcast_arrays(lon, lat)
    geo = _coast_geometry(settings, lon_b, lat_b)
    truth = _truth_scene(settings)
    u, v = _raw_field(settings, truth, geo, t_s, depth)
    if issue_number is not None:
        gain = _error_gain(settings, issue_number)
        uf, vf = _raw_field(settings, _forecast_scene(settings, issue_number), geo, t_s, depth)
        u = u + gain * (uf - u)
        v = v + gain * (vf - v)
    return _clip(u, v, settings.max_speed_m_s)


def _clip(
    u: NDArray[np.float64], v: NDArray[np.float64], limit: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Scale vectors faster than ``limit`` down to ``limit``; NaN stays NaN."""
    # Aim a hair below the limit so that float32 rounding cannot push a speed over it.
    target = limit * (1.0 - 1e-6)
    speed = np.hypot(u, v)
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.where(speed > target, target / speed, 1.0)
    return u * factor, v * factor


@functools.lru_cache(maxsize=64)
def _error_gain(settings: SyntheticSettings, issue_number: int) -> float:
    """Gain on ``forecast_scene - truth`` giving the documented relative RMS error.

    Measured over water on the settings' grid, at every layer and every hour of
    issue ``n``'s window, before clipping.
    """
    target = settings.error_scale * settings.error_decay**issue_number
    lon, lat = lon_lat_axes(settings)
    depth = np.asarray(settings.depths_m, dtype=np.float64)
    t_s = (np.arange(settings.hours + 1, dtype=np.float64) + _issue_offset_h(settings, issue_number)) * 3600.0
    lon_b, lat_b = np.broadcast_arrays(lon[None, None, None, :], lat[None, None, :, None])
    geo = _coast_geometry(settings, lon_b, lat_b)
    args = (geo, t_s[:, None, None, None], depth[None, :, None, None])
    ut, vt = _raw_field(settings, _truth_scene(settings), *args)
    uf, vf = _raw_field(settings, _forecast_scene(settings, issue_number), *args)
    truth_ms = float(np.nanmean(ut * ut + vt * vt))
    error_ms = float(np.nanmean((uf - ut) ** 2 + (vf - vt) ** 2))
    if target == 0.0 or not (np.isfinite(error_ms) and error_ms > 0.0):
        return 0.0  # no error asked for, or no water to measure it on
    return float(target * np.sqrt(truth_ms / error_ms))


# --------------------------------------------------------------------------- dataset


def _dataset(
    settings: SyntheticSettings,
    issue_number: int | None,
    lon: NDArray[np.float64],
    lat: NDArray[np.float64],
    depth: NDArray[np.float64],
    hours: NDArray[np.float64],
    u: NDArray[np.float32],
    v: NDArray[np.float32],
) -> xr.Dataset:
    """Wrap the arrays in CF-1.8 metadata."""
    issued = issue_datetime(settings, issue_number=issue_number)
    origin = issued.replace(tzinfo=None)
    times = np.datetime64(origin, "ns") + (hours * 3600.0).astype("timedelta64[s]").astype("timedelta64[ns]")
    kind = "truth" if issue_number is None else f"forecast issue {issue_number}"
    geo = _coast_geometry(settings, *np.broadcast_arrays(lon[None, :], lat[:, None]))
    ds = xr.Dataset(
        data_vars={
            "u": (DIMS, u, dict(U_ATTRS)),
            "v": (DIMS, v, dict(V_ATTRS)),
            "h": (("lat", "lon"), np.where(geo.bottom_m > 0.0, geo.bottom_m, np.nan).astype(np.float32), {
                "standard_name": "sea_floor_depth_below_sea_surface",
                "long_name": "synthetic bathymetry; a cell is land at layers no shallower than this",
                "units": "m",
            }),
        },
        coords=coordinates(times, depth, lat, lon),
        attrs=global_attrs(settings, issue_number, issued, kind),
    )
    set_time_units(ds, origin)
    return ds


def global_attrs(
    settings: SyntheticSettings, issue_number: int | None, issued: dt.datetime, kind: str
) -> dict[str, object]:
    """Global attributes: CF-1.8 plus ACDD discovery fields and the generator's inputs."""
    end = issued + dt.timedelta(hours=settings.hours)
    # error_draw is left out of repr (files without it keep their bytes); a member's file says it here.
    text, draw = repr(settings), ""
    if settings.error_draw is not None:
        text, draw = f"{text[:-1]}, error_draw={settings.error_draw})", f", error draw {settings.error_draw}"
    attrs: dict[str, object] = {
        "Conventions": "CF-1.8",
        "title": f"Synthetic ocean currents, Southern California Bight ({kind})",
        "institution": "lrauv-feedback project (synthetic data, not a model run)",
        "source": f"lrauv synthetic generator v{GENERATOR_VERSION} (planner.forecast.synthetic.scb)",
        "history": (f"created by planner.forecast.synthetic.scb v{GENERATOR_VERSION}, seed={settings.seed}, "
                    f"issue={'truth' if issue_number is None else issue_number}{draw}; deterministic, no wall-clock time"),
        "references": ("Orioke, Alam et al., Feedback Motion Planning for Long-Range Autonomous Underwater "
                       "Vehicles (region and layers); see planner/forecast/synthetic/scb.py for the field's sources"),
        "comment": "Analytic eddies, shelf current, tides and plane waves; land is _FillValue (NaN).",
        "seed": np.int64(settings.seed),
        "synthetic_role": "truth" if issue_number is None else "forecast",
        "issue_time": f"{issued:%Y-%m-%dT%H:%M:%SZ}",
        "forecast_reference_time": f"{issued:%Y-%m-%dT%H:%M:%SZ}",
        "scenario_start_time": f"{parse_time(settings.issue_time):%Y-%m-%dT%H:%M:%SZ}",
        "issue_interval_hours": float(settings.issue_interval_h),
        "error_scale": float(settings.error_scale),
        "error_decay": float(settings.error_decay),
        "time_coverage_start": f"{issued:%Y-%m-%dT%H:%M:%SZ}",
        "time_coverage_end": f"{end:%Y-%m-%dT%H:%M:%SZ}",
        "geospatial_lat_min": float(settings.south_deg),
        "geospatial_lat_max": float(settings.north_deg),
        "geospatial_lon_min": float(settings.west_deg),
        "geospatial_lon_max": float(settings.east_deg),
        "geospatial_vertical_min": float(settings.depths_m[0]),
        "geospatial_vertical_max": float(settings.depths_m[-1]),
        "geospatial_vertical_positive": "down",
        "settings": text,
    }
    if issue_number is not None:
        attrs["issue_number"] = np.int64(issue_number)
        attrs["error_relative_rms"] = float(settings.error_scale * settings.error_decay**issue_number)
        if settings.error_draw is not None:
            attrs["error_draw"] = np.int64(settings.error_draw)
    return attrs
