"""Tests for planner.forecast: reading real ocean files and resampling them (spec section 1).

Real files live in the shared data folder next to the repository (``shared/data/ocean``,
override with LRAUV_OCEAN_DATA); tests that need them are skipped when it is missing.
Expected values are computed here from the raw files opened independently with
netCDF4.Dataset (auto mask/scale), not through the loader.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path
from typing import Any, Callable

import netCDF4
import numpy as np
import pytest
import xarray as xr

from planner.contract.errors import ForecastError
from planner.forecast import Forecast, describe, nearest_time_index, open_forecast
from planner.forecast.resample import resample
from planner.grid import Grid
from planner.contract.geodesy import BBox
from tests.support import REPO

DATA_DIR = Path(
    os.environ.get("LRAUV_OCEAN_DATA") or REPO.parent / "shared" / "data" / "ocean"
)
HAVE_DATA = DATA_DIR.is_dir()
needs_data = pytest.mark.skipif(
    not HAVE_DATA, reason=f"ocean data folder missing: {DATA_DIR} (set LRAUV_OCEAN_DATA to its location)"
)

GRID_ONLY = "croco_benguela_grd.nc"
HYCOM = "hycom_fmrc_wa_coast_20230302_surface.nc"
CMEMS = "cmems_glo12_uovo_20240101_natl_surface.nc"
CMEMS_GLOBAL = "cmems_glo12_uovo_202401_global_1deg_5day_surface.nc"
NORDIC_SMALL = "roms_native_nordic4km_20160202_slevels_small.nc"
NORDIC = "roms_native_nordic4km_20160202_slevels.nc"
WCOFS = "roms_native_wcofs_20241017_surface.nc"
CROCO = "croco_benguela_his.nc"
NORKYST_3D = "roms_zlevel_norkyst800_20160114_3d.nc"
NORKYST_SURF = "roms_zlevel_norkyst800_20151116_surface_hourly.nc"
# Every forecast file in the folder is expected to load.
EXPECTED_TO_LOAD = {HYCOM, CMEMS, CMEMS_GLOBAL, NORDIC_SMALL, NORDIC, WCOFS, CROCO, NORKYST_3D, NORKYST_SURF}


def _listing() -> list[str]:
    if not HAVE_DATA:
        return []
    return sorted(p.name for p in DATA_DIR.iterdir() if p.is_file() and p.name not in {GRID_ONLY, "INVENTORY.md"})


def _file_params() -> list[Any]:
    names = _listing()
    if not names:
        return [pytest.param(None, marks=pytest.mark.skip(reason=f"ocean data folder missing or empty: {DATA_DIR}"))]
    return [pytest.param(n, id=n) for n in names]


def _raw(name: str) -> netCDF4.Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return netCDF4.Dataset(DATA_DIR / name)


def _raw_values(ds: netCDF4.Dataset, var: str, index: Any = ...) -> np.ndarray:
    """Decoded values with auto mask/scale; masked -> NaN."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.ma.filled(np.ma.asarray(ds[var][index], dtype=np.float64), np.nan)


def _unmasked_scaled(ds: netCDF4.Dataset, var: str) -> np.ndarray:
    """Scaled values without valid-range masking (Cs_r in Nordic has a valid range in unpacked units)."""
    v = ds[var]
    v.set_auto_mask(False)
    return np.asarray(v[:], dtype=np.float64)


@pytest.fixture(scope="module")
def load() -> Callable[..., Forecast]:
    """Each real file is opened at most once per module."""
    cache: dict[tuple[str, str], Forecast] = {}

    def _load(name: str, grid_file: str | None = None) -> Forecast:
        key = (name, grid_file or "")
        if key not in cache:
            cache[key] = open_forecast(
                DATA_DIR / name, grid_file=None if grid_file is None else DATA_DIR / grid_file
            )
        return cache[key]

    return _load


# ---------------------------------------------------------------------------------------
# Every real file
# ---------------------------------------------------------------------------------------


@needs_data
def test_folder_holds_the_inventory_files() -> None:
    assert EXPECTED_TO_LOAD <= set(_listing()), f"missing from {DATA_DIR}: {EXPECTED_TO_LOAD - set(_listing())}"


@pytest.mark.parametrize("name", _file_params())
def test_every_file_loads_or_is_refused_clearly(name: str, load: Callable[..., Forecast]) -> None:
    try:
        fc = load(name)
    except ForecastError as exc:
        assert name not in EXPECTED_TO_LOAD, f"{name} should load but was refused: {exc}"
        assert name in str(exc) and len(str(exc)) > 60
        return
    assert name in EXPECTED_TO_LOAD, f"{name} loaded; add it to EXPECTED_TO_LOAD with value checks"
    t, z, y, x = fc.u_east_m_s.shape
    assert fc.v_north_m_s.shape == (t, z, y, x) and fc.time_s.shape == (t,)
    assert fc.source.endswith(name)
    assert fc.identity == "sha256:" + hashlib.sha256((DATA_DIR / name).read_bytes()).hexdigest()[:16]
    water = np.isfinite(fc.u_east_m_s) & np.isfinite(fc.v_north_m_s)
    assert 0.3 < water.mean() < 0.95  # INVENTORY: land 27..42 % (plus C-grid edge points)
    assert np.nanmax(np.hypot(fc.u_east_m_s, fc.v_north_m_s)) < 5.0
    assert np.all(np.isnan(fc.u_east_m_s) == np.isnan(fc.v_north_m_s)) or name == HYCOM
    assert not fc.u_east_m_s.flags.writeable
    text = describe(fc)
    assert name in text and fc.identity in text and "speed" in text


@needs_data
def test_grid_only_file_is_refused_with_what_is_missing() -> None:
    with pytest.raises(ForecastError) as info:
        open_forecast(DATA_DIR / GRID_ONLY)
    msg = str(info.value)
    assert GRID_ONLY in msg and "no ocean current variables" in msg and "--variables" in msg


# ---------------------------------------------------------------------------------------
# Regular lon/lat products against the raw files
# ---------------------------------------------------------------------------------------


@needs_data
def test_hycom_values_time_and_fill(load: Callable[..., Forecast]) -> None:
    fc = load(HYCOM)
    raw = _raw(HYCOM)
    lat = np.asarray(raw["lat"][:], dtype=np.float64)
    lon = np.asarray(raw["lon"][:], dtype=np.float64)
    flip_y = lat[0] > lat[-1]
    assert np.array_equal(fc.lat_deg, np.sort(lat)) and np.array_equal(fc.lon_deg, lon)
    assert fc.depth_m is None and fc.n_levels == 1
    for t, j, i in [(0, 0, 0), (3, 10, 5), (16, 51, 25), (8, 30, 12), (5, 40, 20)]:
        jj = len(lat) - 1 - j if flip_y else j
        for var, arr in (("water_u", fc.u_east_m_s), ("water_v", fc.v_north_m_s)):
            expected = _raw_values(raw, var, (t, j, i))
            got = arr[t, 0, jj, i]
            assert (np.isnan(expected) and np.isnan(got)) or got == expected, (var, t, j, i)
    # 999 fill became NaN (about 34 % land), never 0 or 999.
    assert np.isnan(fc.u_east_m_s).mean() == pytest.approx(0.343, abs=0.02)
    assert np.nanmax(np.abs(fc.u_east_m_s)) < 5
    assert fc.time_origin == "2023-02-25T12:00:00Z"
    assert fc.time_s[0] == 120 * 3600.0 and fc.n_times == 17
    assert fc.times is not None and fc.times[0] == np.datetime64("2023-03-02T12:00")
    assert fc.times[-1] == np.datetime64("2023-03-04T12:00")
    raw.close()


@needs_data
def test_cmems_values_and_scalar_depth(load: Callable[..., Forecast]) -> None:
    fc = load(CMEMS)
    raw = _raw(CMEMS)
    assert fc.depth_m is not None and fc.depth_m.shape == (1,)
    assert fc.depth_m[0] == pytest.approx(0.494025, abs=1e-6)
    lat = np.asarray(raw["latitude"][:], dtype=np.float64)
    assert np.array_equal(fc.lat_deg, lat) and fc.lon_deg[0] == -100.0 and fc.lon_deg[-1] == 20.0
    for j, i in [(0, 0), (100, 200), (300, 900), (660, 1440), (500, 1000)]:
        for var, arr in (("uo", fc.u_east_m_s), ("vo", fc.v_north_m_s)):
            expected = _raw_values(raw, var, (0, j, i))
            got = arr[0, 0, j, i]
            assert (np.isnan(expected) and np.isnan(got)) or got == expected
    assert fc.time_origin == "2024-01-01T00:00:00Z" and fc.time_s.tolist() == [0.0]
    raw.close()


# ---------------------------------------------------------------------------------------
# ROMS / CROCO native C-grid: averaging, masks, rotation, s-levels
# ---------------------------------------------------------------------------------------


def _hand_rho(
    raw: netCDF4.Dataset, uname: str, vname: str, t: int, k: int | None, j: int, i: int
) -> tuple[float, float]:
    """East/north at rho (j, i) by hand: average u (i-1, i) and v (j-1, j), then rotate by angle."""
    idx_u = (t, k) if k is not None else (t,)
    u = _raw_values(raw, uname, idx_u + (j, slice(i - 1, i + 1)))
    v = _raw_values(raw, vname, idx_u + (slice(j - 1, j + 1), i))
    mu = _raw_values(raw, "mask_u", (j, slice(i - 1, i + 1))) if "mask_u" in raw.variables else np.ones(2)
    mv = _raw_values(raw, "mask_v", (slice(j - 1, j + 1), i)) if "mask_v" in raw.variables else np.ones(2)
    assert np.all(mu == 1) and np.all(mv == 1), "pick a water cell"
    ur, vr = u.mean(), v.mean()
    a = float(_raw_values(raw, "angle", (j, i)))
    return ur * np.cos(a) - vr * np.sin(a), ur * np.sin(a) + vr * np.cos(a)


def _water_rho_cells(raw: netCDF4.Dataset, count: int) -> list[tuple[int, int]]:
    m = _raw_values(raw, "mask_rho")
    ny, nx = m.shape
    cells = []
    for j in range(1, ny - 1):
        for i in range(1, nx - 1):
            if m[j - 1 : j + 2, i - 1 : i + 2].min() == 1:
                cells.append((j, i))
    step = max(1, len(cells) // count)
    return cells[::step][:count]


@needs_data
def test_nordic_rotation_average_and_levels_by_hand(load: Callable[..., Forecast]) -> None:
    fc = load(NORDIC_SMALL)
    raw = _raw(NORDIC_SMALL)
    n_s = raw.dimensions["s_rho"].size
    assert fc.shape == (3, n_s, 21, 31) and fc.has_per_column_depth
    for j, i in _water_rho_cells(raw, 5):
        for t, k in [(0, n_s - 1), (2, 0), (1, 17)]:
            east, north = _hand_rho(raw, "u", "v", t, k, j, i)
            z = n_s - 1 - k  # the loader puts the shallowest level first
            assert fc.u_east_m_s[t, z, j, i] == pytest.approx(east, abs=2e-6)
            assert fc.v_north_m_s[t, z, j, i] == pytest.approx(north, abs=2e-6)
    # Depth of one level by hand (Vtransform 2): z = zeta + (zeta + h) * (hc*s + h*C) / (hc + h).
    j, i = _water_rho_cells(raw, 1)[0]
    hc = float(_unmasked_scaled(raw, "hc"))
    s = np.asarray(raw["s_rho"][:], dtype=np.float64)
    cs = _unmasked_scaled(raw, "Cs_r")
    h = float(_raw_values(raw, "h", (j, i)))
    zeta = float(_unmasked_scaled(raw, "zeta")[1, j, i])
    k = 20
    zk = zeta + (zeta + h) * (hc * s[k] + h * cs[k]) / (hc + h)
    assert fc.depth_m is not None
    assert fc.depth_m[1, n_s - 1 - k, j, i] == pytest.approx(-zk, abs=1e-3)
    assert np.all(np.diff(fc.depth_m[1, :, j, i]) > 0)
    raw.close()


@needs_data
def test_nordic_land_is_nan_although_raw_values_are_the_add_offset(load: Callable[..., Forecast]) -> None:
    fc = load(NORDIC_SMALL)
    raw = _raw(NORDIC_SMALL)
    mask_rho = _raw_values(raw, "mask_rho")
    mask_u = _raw_values(raw, "mask_u")
    add_offset = float(raw["u"].add_offset)
    land = np.argwhere(mask_rho == 0)
    assert land.size
    for j, i in land[:: max(1, len(land) // 10)]:
        assert _raw_values(raw, "u", (0, 34, j, i)) == pytest.approx(add_offset, abs=1e-6) or mask_u[j, i] == 1
        assert np.all(np.isnan(fc.u_east_m_s[:, :, j, i])) and np.all(np.isnan(fc.v_north_m_s[:, :, j, i]))
    # A water rho point next to a land u-point is land too (the average takes a NaN).
    ny, nx = mask_rho.shape
    hits = [(j, i) for j in range(ny) for i in range(1, nx) if mask_rho[j, i] == 1 and mask_u[j, i - 1] == 0]
    assert hits
    for j, i in hits[:5]:
        assert np.isnan(fc.u_east_m_s[0, 0, j, i])
    raw.close()


@needs_data
def test_wcofs_surface_staggered_by_hand(load: Callable[..., Forecast]) -> None:
    fc = load(WCOFS)
    raw = _raw(WCOFS)
    assert fc.depth_m is None and fc.shape == (4, 1, 68, 37)
    for j, i in _water_rho_cells(raw, 6):
        east, north = _hand_rho(raw, "u_sur", "v_sur", 2, None, j, i)
        assert fc.u_east_m_s[2, 0, j, i] == pytest.approx(east, abs=1e-12)
        assert fc.v_north_m_s[2, 0, j, i] == pytest.approx(north, abs=1e-12)
    assert fc.time_origin == "2016-01-01T00:00:00Z"
    assert fc.times is not None and fc.times[0] == np.datetime64("2024-10-17T01:00")
    raw.close()


@needs_data
def test_croco_with_and_without_grid_file(load: Callable[..., Forecast]) -> None:
    plain = load(CROCO)
    gridded = load(CROCO, GRID_ONLY)
    raw = _raw(CROCO)
    assert plain.time_origin is None and plain.times is None and plain.time_s.tolist() == [0.0, 259200.0]
    assert not plain.covers_surface and any("not covered" in n for n in plain.notes)
    assert np.array_equal(np.isnan(plain.u_east_m_s), np.isnan(gridded.u_east_m_s))
    np.testing.assert_allclose(plain.u_east_m_s, gridded.u_east_m_s, atol=1e-7, equal_nan=True)
    # CROCO land u is 0 in the file; the loader makes it NaN through the mask.
    mask_rho = _raw_values(raw, "mask_rho")
    j, i = np.argwhere(mask_rho == 0)[0]
    assert np.all(np.isnan(plain.u_east_m_s[:, :, j, i]))
    # A cell by hand (u on (eta_rho, xi_u), v on (eta_v, xi_rho)); file level 2 is the top kept one.
    for j, i in _water_rho_cells(raw, 4):
        east, north = _hand_rho(raw, "u", "v", 1, 2, j, i)
        assert plain.u_east_m_s[1, 0, j, i] == pytest.approx(east, abs=1e-7)
        assert plain.v_north_m_s[1, 0, j, i] == pytest.approx(north, abs=1e-7)
        h = float(_raw_values(raw, "h", (j, i)))
        zeta = float(_raw_values(raw, "zeta", (1, j, i)))
        hc, s_top, c_top = float(raw["hc"][:]), float(raw["s_rho"][2]), float(raw["Cs_rho"][2])
        z_top = zeta + (zeta + h) * (hc * s_top + h * c_top) / (hc + h)  # Vtransform 2
        assert plain.depth_m is not None
        assert plain.depth_m[1, 0, j, i] == pytest.approx(-z_top, rel=1e-6)
        assert 0.5 * h < plain.depth_m[1, 0, j, i] < plain.depth_m[1, 2, j, i] < h
    with pytest.raises(ForecastError, match="no reference date"):
        nearest_time_index(plain, np.datetime64("2020-01-01"))
    raw.close()


@needs_data
def test_croco_lacking_grid_variables_needs_the_grid_file(tmp_path: Path, load: Callable[..., Forecast]) -> None:
    stripped = tmp_path / "croco_no_grid.nc"
    with xr.open_dataset(DATA_DIR / CROCO, decode_times=False) as ds:
        ds.drop_vars(["lon_rho", "lat_rho", "lon_u", "lat_u", "lon_v", "lat_v", "mask_rho", "h", "angle"]).to_netcdf(
            stripped
        )
    with pytest.raises(ForecastError) as info:
        open_forecast(stripped)
    assert "croco_no_grid.nc" in str(info.value) and "lon_rho" in str(info.value) and "--grid-file" in str(info.value)
    fc = open_forecast(stripped, grid_file=DATA_DIR / GRID_ONLY)
    reference = load(CROCO, GRID_ONLY)
    np.testing.assert_allclose(fc.u_east_m_s, reference.u_east_m_s, atol=1e-6, equal_nan=True)
    assert np.array_equal(np.isnan(fc.v_north_m_s), np.isnan(reference.v_north_m_s))


# ---------------------------------------------------------------------------------------
# NorKyst z-level files: projection rotation and computed lon/lat
# ---------------------------------------------------------------------------------------


@needs_data
def test_norkyst_rotation_preserves_speed_and_matches_convergence(load: Callable[..., Forecast]) -> None:
    import pyproj

    fc = load(NORKYST_3D)
    raw = _raw(NORKYST_3D)
    assert fc.depth_m is not None and fc.depth_m.tolist() == [0, 3, 10, 15, 25, 50, 75, 100, 150, 200, 250, 300]
    crs = pyproj.CRS.from_proj4(raw["projection_stere"].proj4)
    to_geo = pyproj.Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    geod = pyproj.Geod(a=6371000.0, b=6371000.0)
    x_coord, y_coord = raw["X"][:], raw["Y"][:]
    lon2d = _raw_values(raw, "lon")
    checked = 0
    for t, k, j, i in [(0, 0, 125, 200), (1, 3, 60, 350), (2, 5, 200, 100), (0, 0, 10, 390), (1, 1, 240, 300)]:
        ux = _raw_values(raw, "u", (t, k, j, i))
        vy = _raw_values(raw, "v", (t, k, j, i))
        east, north = fc.u_east_m_s[t, k, j, i], fc.v_north_m_s[t, k, j, i]
        if np.isnan(ux):
            assert np.isnan(east) and np.isnan(north)
            continue
        checked += 1
        assert np.hypot(east, north) == pytest.approx(np.hypot(ux, vy), rel=1e-7, abs=1e-12)
        turn = np.degrees(np.arctan2(north, east) - np.arctan2(vy, ux))
        # Direction of the +X axis at the point: geodesic azimuth from it to a point 1 m further along X.
        (lon_a, lon_b), (lat_a, lat_b) = to_geo.transform([x_coord[i], x_coord[i] + 1.0], [y_coord[j], y_coord[j]])
        azimuth, _, _ = geod.inv(lon_a, lat_a, lon_b, lat_b)
        expected = 90.0 - azimuth  # counter-clockwise from east
        assert (turn - expected + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-4)
        # Polar stereographic with lon_0 = 70: the grid is turned by -(lon - 70) deg.
        assert (turn + (lon2d[j, i] - 70.0) + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-3)
    assert checked >= 3
    raw.close()


@needs_data
def test_norkyst_surface_lonlat_computed_from_projection(load: Callable[..., Forecast]) -> None:
    surf = load(NORKYST_SURF)
    assert surf.lon_deg.shape == (201, 301) and any("computed from X/Y" in n for n in surf.notes)
    assert 2.0 < surf.lon_deg.min() and surf.lon_deg.max() < 9.0
    assert 59.0 < surf.lat_deg.min() and surf.lat_deg.max() < 65.0
    raw_s, raw_3d = _raw(NORKYST_SURF), _raw(NORKYST_3D)
    xs, ys = raw_s["X"][:], raw_s["Y"][:]
    x3, y3 = raw_3d["X"][:], raw_3d["Y"][:]
    shared_x = np.intersect1d(xs, x3)
    shared_y = np.intersect1d(ys, y3)
    assert shared_x.size and shared_y.size
    for x in shared_x[:: max(1, shared_x.size // 4)]:
        for y in shared_y[:: max(1, shared_y.size // 4)]:
            i_s, j_s = int(np.flatnonzero(xs == x)[0]), int(np.flatnonzero(ys == y)[0])
            i_3, j_3 = int(np.flatnonzero(x3 == x)[0]), int(np.flatnonzero(y3 == y)[0])
            assert surf.lon_deg[j_s, i_s] == pytest.approx(float(raw_3d["lon"][j_3, i_3]), abs=1e-9)
            assert surf.lat_deg[j_s, i_s] == pytest.approx(float(raw_3d["lat"][j_3, i_3]), abs=1e-9)
    raw_s.close()
    raw_3d.close()


# ---------------------------------------------------------------------------------------
# resample() on real regular files
# ---------------------------------------------------------------------------------------


def _own_grid(fc: Forecast, depths: list[float]) -> Grid:
    return Grid.from_bbox(
        BBox(
            west_deg=float(fc.lon_deg[0]),
            south_deg=float(fc.lat_deg[0]),
            east_deg=float(fc.lon_deg[-1]),
            north_deg=float(fc.lat_deg[-1]),
        ),
        nx=fc.lon_deg.size,
        ny=fc.lat_deg.size,
        depths_m=depths,
    )


@needs_data
def test_hycom_own_grid_reproduces_raw_values_bit_for_bit(load: Callable[..., Forecast]) -> None:
    fc = load(HYCOM)
    # Corners typed as a user would (decimal text), not the float32 values.
    grid = Grid.from_bbox(
        BBox(west_deg=-125.92, south_deg=47.0, east_deg=-123.92, north_deg=49.04), nx=26, ny=52, depths_m=[0, 5, 10, 15]
    )
    raw = _raw(HYCOM)
    for t in (0, 7):
        u, v = resample(fc, grid, time_index=t)
        assert u.shape == (4, 52, 26) and u.dtype == np.float64
        expected_u, expected_v = _raw_values(raw, "water_u", t), _raw_values(raw, "water_v", t)
        for layer in range(4):  # no depth axis: every layer is the same field
            assert np.array_equal(u[layer], expected_u, equal_nan=True)
            assert np.array_equal(v[layer], expected_v, equal_nan=True)
    raw.close()


@needs_data
def test_cmems_own_grid_reproduces_and_depth_rules(load: Callable[..., Forecast]) -> None:
    fc = load(CMEMS)
    sub = Grid.from_bbox(
        BBox(west_deg=-70.0, south_deg=30.0, east_deg=-60.0, north_deg=40.0), nx=121, ny=121, depths_m=[0.0, 5.0]
    )
    u, v = resample(fc, sub, time_index=0)
    i0 = int(np.argmin(np.abs(fc.lon_deg + 70.0)))
    j0 = int(np.argmin(np.abs(fc.lat_deg - 30.0)))
    expected = fc.u_east_m_s[0, 0, j0 : j0 + 121, i0 : i0 + 121]
    assert np.array_equal(u[0], expected, equal_nan=True)  # 0 m is shallower than 0.494 m: first level
    assert np.all(np.isnan(u[1])) and np.all(np.isnan(v[1]))  # 5 m is deeper than the only level: land


@needs_data
def test_hycom_midpoints_land_and_outside(load: Callable[..., Forecast]) -> None:
    fc = load(HYCOM)
    u0 = fc.u_east_m_s[2, 0]
    lon, lat = fc.lon_deg, fc.lat_deg
    water = np.isfinite(u0)
    # Two water nodes side by side in longitude, and a water node next to a land node.
    pairs = [(j, i) for j in range(len(lat)) for i in range(len(lon) - 1) if water[j, i] and water[j, i + 1]]
    coast = [(j, i) for j in range(len(lat)) for i in range(len(lon) - 1) if water[j, i] and not water[j, i + 1]]
    assert pairs and coast
    j, i = pairs[len(pairs) // 2]
    jc, ic = coast[len(coast) // 2]
    grid = Grid(
        lon_deg=[0.5 * (lon[i] + lon[i + 1]), 0.5 * (lon[ic] + lon[ic + 1]), lon[ic], lon[-1] + 0.05],
        lat_deg=[lat[j], lat[jc]],
        depth_m=[0.0, 100.0],
    )
    u, _ = resample(fc, grid, time_index=2)
    assert u[0, 0, 0] == 0.5 * (u0[j, i] + u0[j, i + 1])  # midpoint of two water nodes: their mean
    assert np.isnan(u[0, 1, 1])  # half weight on a land node: land
    assert u[0, 1, 2] == u0[jc, ic]  # on the water node itself: the land neighbour has zero weight
    assert np.all(np.isnan(u[:, :, 3]))  # east of the forecast: land
    assert np.array_equal(u[0], u[1], equal_nan=True)  # no depth axis: same at 100 m


@needs_data
def test_global_file_wraps_at_the_date_line(load: Callable[..., Forecast]) -> None:
    fc = load(CMEMS_GLOBAL)
    lon, lat = fc.lon_deg, fc.lat_deg
    u0 = fc.u_east_m_s[3, 0]
    j = next(j for j in range(len(lat)) if np.isfinite(u0[j, -1]) and np.isfinite(u0[j, 0]))
    grid = Grid(lon_deg=[lon[-1], lon[-1] + 0.5, lon[0] + 360.0], lat_deg=[lat[j], lat[j + 1]], depth_m=[0.0])
    u, _ = resample(fc, grid, time_index=3)
    assert u[0, 0, 0] == u0[j, -1] and u[0, 0, 2] == u0[j, 0]
    assert u[0, 0, 1] == pytest.approx(0.5 * (u0[j, -1] + u0[j, 0]), abs=1e-12)


@needs_data
def test_curvilinear_real_files_resample(load: Callable[..., Forecast]) -> None:
    fc = load(NORDIC_SMALL)
    # Target exactly on rho points of an interior water cell: the node's own value (per-column levels).
    raw = _raw(NORDIC_SMALL)
    j, i = _water_rho_cells(raw, 3)[1]
    raw.close()
    assert fc.depth_m is not None
    level_depth = float(fc.depth_m[0, 5, j, i])
    grid = Grid(
        lon_deg=[fc.lon_deg[j, i], fc.lon_deg[j, i] + 1e-3],
        lat_deg=[fc.lat_deg[j, i], fc.lat_deg[j, i] + 1e-3],
        depth_m=[level_depth, 5000.0],
    )
    u, v = resample(fc, grid, time_index=0)
    assert u[0, 0, 0] == pytest.approx(fc.u_east_m_s[0, 5, j, i], abs=1e-12)
    assert np.all(np.isnan(u[1]))  # deeper than every column
    croco = load(CROCO)
    g = Grid.from_bbox(BBox(west_deg=10, south_deg=-36, east_deg=16, north_deg=-30), nx=12, ny=12, depths_m=[0.0, 10.0])
    cu, _ = resample(croco, g, time_index=0)
    assert np.all(np.isnan(cu))  # the CROCO file keeps only bottom levels: near-surface layers are not covered


# ---------------------------------------------------------------------------------------
# Synthetic files written with xarray (unit cases)
# ---------------------------------------------------------------------------------------


def _write(
    path: Path,
    *,
    u: np.ndarray,
    v: np.ndarray,
    lon: np.ndarray,
    lat: np.ndarray,
    depth: np.ndarray | None = None,
    units: str = "m s-1",
    names: tuple[str, str] = ("uo", "vo"),
    std: bool = True,
    time_units: str = "hours since 2024-01-01 00:00:00",
) -> Path:
    dims: tuple[str, ...] = ("time", "depth", "lat", "lon") if depth is not None else ("time", "lat", "lon")
    attrs_u = {"units": units, **({"standard_name": "eastward_sea_water_velocity"} if std else {})}
    attrs_v = {"units": units, **({"standard_name": "northward_sea_water_velocity"} if std else {})}
    coords: dict[str, Any] = {
        "time": ("time", np.arange(u.shape[0], dtype=np.float64) * 3.0, {"units": time_units, "standard_name": "time"}),
        "lat": ("lat", lat, {"units": "degrees_north"}),
        "lon": ("lon", lon, {"units": "degrees_east"}),
    }
    if depth is not None:
        coords["depth"] = ("depth", depth, {"units": "m", "positive": "down"})
    ds = xr.Dataset({names[0]: (dims, u, attrs_u), names[1]: (dims, v, attrs_v)}, coords=coords)
    ds.to_netcdf(path)
    return path


def test_synthetic_flips_units_and_depth_interpolation(tmp_path: Path) -> None:
    lon = np.array([10.0, 11.0, 12.0])
    lat = np.array([52.0, 51.0, 50.0])  # descending: flipped on reading
    depth = np.array([0.5, 10.0, 20.0])
    u = np.zeros((2, 3, 3, 3))
    for k, d in enumerate(depth):
        for j, la in enumerate(lat):
            for i, lo in enumerate(lon):
                u[:, k, j, i] = 100.0 * (lo - 10.0) + 10.0 * (la - 50.0) + d  # cm/s, linear in every axis
    u[:, 2, 0, 0] = np.nan  # below the sea floor at (lat 52, lon 10)
    v = -u
    fc = open_forecast(_write(tmp_path / "syn.nc", u=u, v=v, lon=lon, lat=lat, depth=depth, units="cm/s"))
    assert fc.lat_deg.tolist() == [50.0, 51.0, 52.0] and any("flipped" in n for n in fc.notes)
    assert fc.u_east_m_s[0, 1, 2, 1] == pytest.approx(0.01 * (100.0 + 20.0 + 10.0))  # lat 52, lon 11, 10 m
    grid = Grid(lon_deg=[10.0, 10.5, 12.0], lat_deg=[50.25, 52.0], depth_m=[0.0, 5.0, 10.0, 15.0, 25.0])
    gu, gv = resample(fc, grid, time_index=1)
    expect = lambda lo, la, d: 0.01 * (100.0 * (lo - 10.0) + 10.0 * (la - 50.0) + d)  # noqa: E731
    assert gu[0, 0, 1] == pytest.approx(expect(10.5, 50.25, 0.5), abs=1e-12)  # shallower: first level
    assert gu[1, 0, 1] == pytest.approx(expect(10.5, 50.25, 5.0), abs=1e-12)
    assert gu[3, 0, 2] == pytest.approx(expect(12.0, 50.25, 15.0), abs=1e-12)
    assert np.all(np.isnan(gu[4]))  # deeper than the last level
    assert gv[1, 0, 1] == pytest.approx(-expect(10.5, 50.25, 5.0), abs=1e-12)
    assert gu[2, 1, 0] == pytest.approx(expect(10.0, 52.0, 10.0), abs=1e-12)  # exactly on 10 m: NaN at 20 m untouched
    assert np.isnan(gu[3, 1, 0])  # 15 m: half weight on the NaN node
    assert np.isnan(gu[3, 1, 1])  # lon 10.5: the NaN node still has weight 0.5 * 0.5 > 0
    assert gu[3, 1, 2] == pytest.approx(expect(12.0, 52.0, 15.0), abs=1e-12)  # lon 12: zero weight on it
    with pytest.raises(ForecastError, match=r"valid indices 0\.\.1"):
        resample(fc, grid, time_index=2)


def test_synthetic_nan_node_weight_rule_exactly(tmp_path: Path) -> None:
    lon = np.array([0.0, 1.0, 2.0])
    lat = np.array([0.0, 1.0])
    u = np.array([[[1.0, 2.0, np.nan], [3.0, 4.0, 5.0]]])
    fc = open_forecast(_write(tmp_path / "w.nc", u=u, v=u, lon=lon, lat=lat))
    grid = Grid(lon_deg=[0.5, 1.0, 1.5, 2.0], lat_deg=[0.0, 0.5, 1.0], depth_m=[0.0, 7.0])
    gu, _ = resample(fc, grid, time_index=0)
    assert gu[0, 0, 0] == 1.5 and gu[0, 0, 1] == 2.0  # on node 2.0: its NaN neighbour has zero weight
    assert np.isnan(gu[0, 0, 2]) and np.isnan(gu[0, 0, 3]) and np.isnan(gu[0, 1, 2])
    assert gu[0, 1, 0] == 2.5 and gu[0, 2, 2] == 4.5 and gu[0, 2, 3] == 5.0
    assert np.array_equal(gu[0], gu[1], equal_nan=True)  # no depth axis: every layer


def test_synthetic_curvilinear_barycentric(tmp_path: Path) -> None:
    # A rotated 2-D lon/lat grid; the field is linear in lon/lat so barycentric interpolation is exact.
    jj, ii = np.mgrid[0:8, 0:10].astype(np.float64)
    ang = np.radians(25.0)
    lon = 5.0 + 0.1 * (ii * np.cos(ang) - jj * np.sin(ang))
    lat = 60.0 + 0.05 * (ii * np.sin(ang) + jj * np.cos(ang))
    field = 2.0 * lon - 3.0 * lat
    u = field[None, :, :].copy()
    u[0, 3, 4] = np.nan
    ds = xr.Dataset(
        {
            "ue": (("time", "y", "x"), u, {"units": "m/s", "standard_name": "eastward_sea_water_velocity"}),
            "vn": (("time", "y", "x"), -u, {"units": "m/s", "standard_name": "northward_sea_water_velocity"}),
            "nav_lon": (("y", "x"), lon, {"units": "degrees_east", "standard_name": "longitude"}),
            "nav_lat": (("y", "x"), lat, {"units": "degrees_north", "standard_name": "latitude"}),
        },
        coords={"time": ("time", [0.0], {"units": "seconds since 2020-01-01"})},
    )
    path = tmp_path / "curv.nc"
    ds.to_netcdf(path)
    fc = open_forecast(path)
    assert not fc.is_regular and fc.depth_m is None
    # Targets: a water node (exact), an interior point away from the NaN, a node next to the NaN,
    # a point in a triangle touching the NaN, and a point outside the hull.
    pts = [(lon[1, 1], lat[1, 1]), (lon[5, 7] + 0.01, lat[5, 7] + 0.004), (lon[3, 5], lat[3, 5])]
    for plon, plat in pts:
        grid = Grid(lon_deg=[plon, plon + 10.0], lat_deg=[plat, plat + 10.0], depth_m=[0.0, 3.0])
        gu, gv = resample(fc, grid, time_index=0)
        assert gu[0, 0, 0] == pytest.approx(2.0 * plon - 3.0 * plat, abs=1e-9)
        assert gv[1, 0, 0] == pytest.approx(-(2.0 * plon - 3.0 * plat), abs=1e-9)
        assert np.isnan(gu[0, 1, 1])  # far outside the hull
    mid_lon, mid_lat = 0.5 * (lon[3, 4] + lon[3, 5]), 0.5 * (lat[3, 4] + lat[3, 5])
    grid = Grid(lon_deg=[mid_lon, 9.0], lat_deg=[mid_lat, 70.0], depth_m=[0.0])
    gu, _ = resample(fc, grid, time_index=0)
    assert np.isnan(gu[0, 0, 0])
    # Midpoints of the edges around the NaN node: the triangle found may have the NaN node as
    # its third vertex with a round-off weight; snapped to 0, the value is the edge's mean.
    ring = [(2, 3), (2, 4), (2, 5), (3, 5), (4, 5), (4, 4), (4, 3), (3, 3), (2, 3)]
    for (ja, ia), (jb, ib) in zip(ring[:-1], ring[1:]):
        plon, plat = 0.5 * (lon[ja, ia] + lon[jb, ib]), 0.5 * (lat[ja, ia] + lat[jb, ib])
        grid = Grid(lon_deg=[plon, plon + 10.0], lat_deg=[plat, plat + 10.0], depth_m=[0.0])
        gu, _ = resample(fc, grid, time_index=0)
        assert gu[0, 0, 0] == pytest.approx(2.0 * plon - 3.0 * plat, abs=1e-9), ((ja, ia), (jb, ib))


def test_time_lookup(tmp_path: Path) -> None:
    u = np.ones((4, 2, 2))
    fc = open_forecast(_write(tmp_path / "t.nc", u=u, v=u, lon=np.array([0.0, 1.0]), lat=np.array([0.0, 1.0])))
    assert fc.time_origin == "2024-01-01T00:00:00Z" and fc.time_s.tolist() == [0.0, 10800.0, 21600.0, 32400.0]
    assert nearest_time_index(fc, np.datetime64("2024-01-01T04:00")) == 1
    assert nearest_time_index(fc, np.datetime64("2024-01-01T04:30")) == 1  # tie: the earlier step
    assert nearest_time_index(fc, np.datetime64("2024-01-01T11:59")) == 3  # within one step after the end
    with pytest.raises(ForecastError, match="outside the forecast"):
        nearest_time_index(fc, np.datetime64("2024-01-01T12:01"))
    with pytest.raises(ForecastError, match="outside the forecast"):
        nearest_time_index(fc, np.datetime64("2023-12-31T20:00"))
    assert "2024-01-01T09:00:00Z" in describe(fc)


# ---------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ForecastError, match="nope.nc.*not found"):
        open_forecast(tmp_path / "nope.nc")


def test_text_file_is_not_netcdf(tmp_path: Path) -> None:
    path = tmp_path / "notes.nc"
    path.write_text("this is not netCDF\n")
    with pytest.raises(ForecastError, match="notes.nc.*cannot open"):
        open_forecast(path)


def test_unknown_variable_names(tmp_path: Path) -> None:
    u = np.ones((1, 2, 2))
    path = _write(tmp_path / "named.nc", u=u, v=u, lon=np.array([0.0, 1.0]), lat=np.array([0.0, 1.0]))
    with pytest.raises(ForecastError) as info:
        open_forecast(path, variables=("U", "V"))
    assert "named.nc" in str(info.value) and "'U'" in str(info.value) and "uo" in str(info.value)
    assert open_forecast(path, variables=("uo", "vo")).variables == ("uo", "vo")


def test_no_current_variables(tmp_path: Path) -> None:
    u = np.ones((1, 2, 2))
    path = _write(tmp_path / "temp.nc", u=u, v=u, lon=np.array([0.0, 1.0]), lat=np.array([0.0, 1.0]),
                  names=("temp", "salt"), std=False)  # fmt: skip
    with pytest.raises(ForecastError, match=r"temp\.nc: no ocean current variables.*--variables"):
        open_forecast(path)


def test_nan_only_file(tmp_path: Path) -> None:
    u = np.full((1, 2, 2), np.nan)
    path = _write(tmp_path / "empty.nc", u=u, v=u, lon=np.array([0.0, 1.0]), lat=np.array([0.0, 1.0]))
    with pytest.raises(ForecastError, match=r"empty\.nc.*no finite current values"):
        open_forecast(path)


def test_bad_units(tmp_path: Path) -> None:
    u = np.ones((1, 2, 2))
    path = _write(tmp_path / "units.nc", u=u, v=u, lon=np.array([0.0, 1.0]), lat=np.array([0.0, 1.0]), units="knotz")
    with pytest.raises(ForecastError, match=r"units\.nc.*'knotz'.*expected m/s"):
        open_forecast(path)


def test_no_lonlat_and_no_projection(tmp_path: Path) -> None:
    u = np.ones((1, 3, 4))
    ds = xr.Dataset(
        {
            "u": (("time", "y", "x"), u, {"units": "m/s", "standard_name": "x_sea_water_velocity"}),
            "v": (("time", "y", "x"), u, {"units": "m/s", "standard_name": "y_sea_water_velocity"}),
        },
        coords={"time": ("time", [0.0], {"units": "seconds since 2020-01-01"})},
    )
    path = tmp_path / "bare.nc"
    ds.to_netcdf(path)
    with pytest.raises(ForecastError) as info:
        open_forecast(path)
    msg = str(info.value)
    assert "bare.nc" in msg and "no longitude/latitude" in msg and "grid_mapping" in msg and "--grid-file" in msg


def test_forecast_value_validates_shapes() -> None:
    with pytest.raises(ForecastError, match="shape"):
        Forecast(
            source="synthetic",
            identity="synthetic",
            time_s=np.zeros(1),
            time_origin=None,
            lon_deg=np.array([0.0, 1.0]),
            lat_deg=np.array([0.0, 1.0, 2.0]),
            depth_m=None,
            u_east_m_s=np.zeros((1, 1, 2, 2)),
            v_north_m_s=np.zeros((1, 1, 2, 2)),
            notes=(),
        )
