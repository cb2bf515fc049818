"""Large forecasts and ensembles: ``open_forecast(path, bbox=, time_index=, member=)`` (docs/forecasts-large.md).

A window of a file (one time step, one member, the lon/lat ranges around a bbox) must resample
onto any grid inside the bbox exactly (bit for bit) as the whole file does, must be read without
reading the rest of the file, and must keep the whole file's identity. Files are written here to
tmp_path (synthetic Southern California Bight, double gyre, hand-made axes and ensembles); the
real files of the shared ocean folder are used when it is present.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import netCDF4
import numpy as np
import pytest
import xarray as xr

from planner.contract.errors import ForecastError
from planner.forecast import (
    WINDOW_MARGIN_NODES,
    Forecast,
    ensemble_size,
    forecast_times,
    nearest_time_index,
    open_forecast,
)
from planner.grid import Grid
from planner.contract.geodesy import BBox
from planner.forecast.resample import resample
from tests.support import REPO

DATA_DIR = Path(os.environ.get("LRAUV_OCEAN_DATA") or REPO.parent / "shared" / "data" / "ocean")
needs_data = pytest.mark.skipif(not DATA_DIR.is_dir(), reason=f"ocean data folder missing: {DATA_DIR}")
DEPTHS = [0.0, 2.5, 5.0, 12.5, 15.0, 20.0]  # between levels, on levels, below the last level (land)


def _box(w: float, s: float, e: float, n: float) -> BBox:
    return BBox(west_deg=float(w), south_deg=max(float(s), -90.0), east_deg=float(e), north_deg=min(float(n), 90.0))


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit for bit (NaN and -0.0 included)."""
    a, b = np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint64), b.view(np.uint64)))


def _assert_resamples_alike(full: Forecast, path: Path, bbox: BBox, t: int, sizes: list[tuple[int, int]],
                            depths: list[float] = DEPTHS, **kw: Any) -> Forecast:
    window = open_forecast(path, bbox=bbox, time_index=t, **kw)
    assert window.identity == full.identity and window.source == full.source
    for nx, ny in sizes:
        grid = Grid.from_bbox(bbox, nx=nx, ny=ny, depths_m=depths)
        whole_u, whole_v = resample(full, grid, time_index=t)
        part_u, part_v = resample(window, grid, time_index=window.step_index(t))
        assert _same(whole_u, part_u) and _same(whole_v, part_v), (path.name, bbox, t, nx, ny)
    return window


def _boxes(lon: np.ndarray, lat: np.ndarray) -> list[BBox]:
    """Interior boxes on and between nodes, boxes touching each edge of the file, boxes reaching past it."""
    return [
        _box(lon[0], lat[0], lon[-1], lat[-1]),  # the whole file
        _box(lon[3] + 1e-3, lat[5] - 2e-3, lon[9] + 3.7e-3, lat[11]),  # interior, off and on nodes
        _box(lon[10] + 1e-4, lat[10] + 1e-4, lon[10] + 2e-3, lat[10] + 3e-3),  # inside one cell
        _box(lon[0], lat[0], lon[4], lat[6]),  # south-west corner, on the edge nodes
        _box(lon[-6], lat[-5], lon[-1], lat[-1]),  # north-east corner, on the edge nodes
        _box(lon[0] - 0.3, lat[2], lon[5] + 5e-4, lat[-1] + 0.2),  # past the west and north edges
        _box(lon[-3] - 1e-3, lat[0] - 0.5, lon[-1] + 0.5, lat[7]),  # past the east and south edges
        _box(lon[-1], lat[-1] - 0.02, lon[-1] + 0.3, lat[-1]),  # only the last column is inside
    ]


# ---------------------------------------------------------------------------------------
# Windows resample exactly as the whole file
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def gyre_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre

    return write_gyre(tmp_path_factory.mktemp("gyre") / "gyre.nc", DoubleGyreSettings(hours=12.0))


@pytest.mark.parametrize("kind", ["synthetic", "gyre"])
def test_windows_resample_bit_for_bit_as_the_whole_file(kind: str, synthetic_forecast: Path, gyre_file: Path) -> None:
    path = synthetic_forecast if kind == "synthetic" else gyre_file
    full = open_forecast(path)
    assert full.window is None
    later = full.n_times - 5
    for bbox in _boxes(full.lon_deg, full.lat_deg):
        for t in (0, later):
            window = _assert_resamples_alike(full, path, bbox, t, [(2, 2), (7, 5), (23, 17)])
            w = window.window
            assert w is not None and w.time_index == t and w.n_times == full.n_times
            x0, x1 = w.lon_index  # type: ignore[misc]
            y0, y1 = w.lat_index  # type: ignore[misc]
            # The window is the file's values, untouched, with the whole file's time and identity.
            assert window.shape == (1, full.n_levels, y1 - y0, x1 - x0)
            assert _same(window.u_east_m_s, full.u_east_m_s[t : t + 1, :, y0:y1, x0:x1])
            assert _same(window.v_north_m_s, full.v_north_m_s[t : t + 1, :, y0:y1, x0:x1])
            assert _same(window.lon_deg, full.lon_deg[x0:x1]) and _same(window.lat_deg, full.lat_deg[y0:y1])
            assert window.time_s.tolist() == [full.time_s[t]] and window.time_origin == full.time_origin
            assert _same(window.depth_m, full.depth_m)  # type: ignore[arg-type]
            assert _same(w.file_lon_deg, full.lon_deg) and _same(w.file_lat_deg, full.lat_deg)  # type: ignore[arg-type]
            # The nodes bracketing the bbox's edges, plus WINDOW_MARGIN_NODES more, clipped at the file's edges.
            for (lo, hi), axis, (west, east) in (
                ((x0, x1), full.lon_deg, (bbox.west_deg, bbox.east_deg)),
                ((y0, y1), full.lat_deg, (bbox.south_deg, bbox.north_deg)),
            ):
                below = max(int(np.searchsorted(axis, west, side="right")) - 1, 0)
                above = min(int(np.searchsorted(axis, east, side="left")), axis.size - 1)
                assert lo == max(below - WINDOW_MARGIN_NODES, 0)
                assert hi == min(above + WINDOW_MARGIN_NODES, axis.size - 1) + 1
    small = open_forecast(path, bbox=_boxes(full.lon_deg, full.lat_deg)[2], time_index=later)
    assert small.shape[2] <= 2 + 2 * WINDOW_MARGIN_NODES and small.shape[3] <= 2 + 2 * WINDOW_MARGIN_NODES


def _write_axes_file(path: Path, lon: np.ndarray, lat: np.ndarray, n_t: int = 4, seed: int = 0) -> Path:
    """u/v (time, depth, lat, lon) on the given axes in the given order, with land (NaN) patches."""
    rng = np.random.default_rng(seed)
    shape = (n_t, 3, lat.size, lon.size)
    u = rng.normal(0.0, 0.3, shape)
    v = rng.normal(0.0, 0.3, shape)
    land = rng.random(shape[2:]) < 0.15
    u[:, :, land] = np.nan
    v[:, 1:, land] = np.nan
    ds = xr.Dataset(
        {
            "uo": (("time", "depth", "lat", "lon"), u, {"units": "m s-1", "standard_name": "eastward_sea_water_velocity"}),
            "vo": (("time", "depth", "lat", "lon"), v, {"units": "m s-1", "standard_name": "northward_sea_water_velocity"}),
        },
        coords={
            "time": ("time", np.arange(n_t) * 6.0, {"units": "hours since 2026-01-15 00:00:00"}),
            "depth": ("depth", [0.0, 5.0, 15.0], {"units": "m", "positive": "down"}),
            "lat": ("lat", lat, {"units": "degrees_north"}),
            "lon": ("lon", lon, {"units": "degrees_east"}),
        },
    )
    ds.to_netcdf(path)
    return path


def test_flipped_axes_and_a_repeated_wrap_column(tmp_path: Path) -> None:
    """Descending lat and lon, and a global 0..360 axis whose last column repeats the first."""
    desc = _write_axes_file(tmp_path / "desc.nc", np.linspace(-117.0, -118.5, 31), np.linspace(34.0, 33.0, 21))
    full = open_forecast(desc)
    assert any("flipped" in n for n in full.notes)
    for bbox in _boxes(full.lon_deg, full.lat_deg):
        for t in (0, 3):
            _assert_resamples_alike(full, desc, bbox, t, [(2, 2), (9, 6)])

    globe = _write_axes_file(tmp_path / "globe.nc", np.arange(0.0, 360.1, 10.0), np.arange(-60.0, 61.0, 10.0), seed=1)
    full = open_forecast(globe)
    assert full.lon_deg.size == 36 and any("repeats the first" in n for n in full.notes)
    boxes = [
        _box(-30.0, -15.0, 25.0, 30.0),  # across the seam at 0 deg, in -180..180 numbers
        _box(330.0, -15.0, 385.0, 30.0),  # the same box in 0..360 numbers
        _box(352.0, 0.0, 359.5, 5.0),  # between the last column and the closing node
        _box(-150.0, -50.0, -120.0, -20.0),  # west longitudes of a 0..360 file
        _box(100.0, -60.0, 140.0, 60.0),
        _box(0.0, -60.0, 350.0, 60.0),
    ]
    for bbox in boxes:
        for t in (1, 2):
            window = _assert_resamples_alike(full, globe, bbox, t, [(2, 2), (12, 7), (40, 9)])
            w = window.window
            assert w is not None
            if bbox.west_deg == -150.0:
                assert w.lon_index == (19, 27)  # nodes 210..240 deg east and two more on each side
            if bbox.east_deg - bbox.west_deg < 100.0 and bbox.west_deg in (-30.0, 330.0, 352.0):
                assert w.lon_index == (0, 36)  # the seam is needed: the whole circle is kept


def test_window_notes_fields_and_defaults(synthetic_forecast: Path) -> None:
    full = open_forecast(synthetic_forecast)
    window = open_forecast(synthetic_forecast, bbox=_box(-118.1, 33.4, -118.0, 33.5), time_index=3)
    assert full.window is None and "read part of the file" not in " ".join(full.notes)
    assert any(n.startswith("read part of the file: time step 3 of 25; lon ") for n in window.notes)
    # Everything read before the velocities keeps its notes, in the whole read's order.
    assert window.notes[:-2] == tuple(n for n in full.notes[:-1])
    assert window.variables == full.variables and window.covers_surface == full.covers_surface
    assert window.step_index(3) == 0 and full.step_index(3) == 3
    with pytest.raises(ForecastError, match="holds only that step"):
        window.step_index(4)
    lon, lat = window.file_lon_lat
    assert _same(lon, full.lon_deg) and _same(lat, full.lat_deg)
    only_time = open_forecast(synthetic_forecast, time_index=5)
    assert only_time.shape == (1, *full.shape[1:]) and only_time.window.lon_index is None  # type: ignore[union-attr]
    assert _same(only_time.u_east_m_s, full.u_east_m_s[5:6])
    only_box = open_forecast(synthetic_forecast, bbox=_box(-118.1, 33.4, -118.0, 33.5))
    assert only_box.n_times == full.n_times and only_box.window.time_index is None  # type: ignore[union-attr]
    grid = Grid.from_bbox(_box(-118.1, 33.4, -118.0, 33.5), nx=11, ny=11, depths_m=DEPTHS)
    assert all(_same(a, b) for a, b in zip(resample(full, grid, time_index=20), resample(only_box, grid, time_index=20)))


def test_all_land_window_opens_and_resamples_to_land(synthetic_forecast: Path) -> None:
    """The synthetic forecast's north-east corner is land: the window opens; planning there finds no water."""
    full = open_forecast(synthetic_forecast)
    bbox = _box(-117.74, 33.64, -117.70, 33.70)
    window = _assert_resamples_alike(full, synthetic_forecast, bbox, 2, [(5, 5)])
    assert np.all(np.isnan(window.u_east_m_s)) and any("(all land)" in n for n in window.notes)


def test_time_axis_alone_and_nearest_step(synthetic_forecast: Path) -> None:
    full = open_forecast(synthetic_forecast)
    times = forecast_times(synthetic_forecast)
    assert _same(times.time_s, full.time_s) and times.time_origin == full.time_origin
    assert times.source == full.source and times.n_times == full.n_times and times.n_members == 1
    assert np.array_equal(times.times, full.times)  # type: ignore[arg-type]
    when = np.datetime64("2026-01-15T07:20")
    assert nearest_time_index(times, when) == nearest_time_index(full, when) == 7
    with pytest.raises(ForecastError, match="outside the forecast"):
        nearest_time_index(times, np.datetime64("2026-02-15T00:00"))


@needs_data
@pytest.mark.parametrize("name", [
    "hycom_fmrc_wa_coast_20230302_surface.nc",
    "cmems_glo12_uovo_20240101_natl_surface.nc",
    "cmems_glo12_uovo_202401_global_1deg_5day_surface.nc",
    "roms_native_nordic4km_20160202_slevels_small.nc",
    "roms_native_wcofs_20241017_surface.nc",
    "roms_zlevel_norkyst800_20151116_surface_hourly.nc",
])
def test_real_files(name: str) -> None:
    """Regular products: bbox windows resample alike; curvilinear and ROMS files: one step is the step."""
    path = DATA_DIR / name
    full = open_forecast(path)
    times = forecast_times(path)
    assert _same(times.time_s, full.time_s)
    for t in sorted({0, full.n_times // 2, full.n_times - 1}):
        step = open_forecast(path, time_index=t)
        assert _same(step.u_east_m_s, full.u_east_m_s[t : t + 1]) and _same(step.v_north_m_s, full.v_north_m_s[t : t + 1])
        if full.has_per_column_depth:
            assert _same(step.depth_m, full.depth_m[t : t + 1])  # type: ignore[index,arg-type]
        if not full.is_regular:
            # bbox is not used on curvilinear grids: the whole horizontal grid, one step.
            lon, lat = full.lon_deg, full.lat_deg
            bbox = _box(np.nanpercentile(lon, 30), np.nanpercentile(lat, 30), np.nanpercentile(lon, 70), np.nanpercentile(lat, 70))
            boxed = _assert_resamples_alike(full, path, bbox, t, [(6, 5)], depths=[0.0, 10.0])
            assert boxed.shape == step.shape and boxed.window.lon_index is None  # type: ignore[union-attr]
    if full.is_regular:
        lon, lat = full.lon_deg, full.lat_deg
        rng = np.random.default_rng(3)
        boxes = _boxes(lon, lat)[:5]
        while len(boxes) < 12:
            i, j = np.sort(rng.choice(lon.size, 2, replace=False)), np.sort(rng.choice(lat.size, 2, replace=False))
            boxes.append(_box(lon[i[0]] + rng.uniform(-0.2, 0.2), lat[j[0]] + rng.uniform(-0.2, 0.2),
                              lon[i[1]] + rng.uniform(0.21, 0.4), lat[j[1]] + rng.uniform(0.21, 0.4)))
        if "global" in name:
            boxes += [_box(170.0, -20.0, 190.0, 10.0), _box(200.0, 0.0, 220.0, 3.0), _box(179.2, 0.0, 179.9, 3.0)]
        for bbox in boxes:
            for t in sorted({0, full.n_times - 1}):
                _assert_resamples_alike(full, path, bbox, t, [(2, 2), (9, 7)], depths=[0.0, 10.0])


# ---------------------------------------------------------------------------------------
# Bad requests
# ---------------------------------------------------------------------------------------


def test_bad_windows_are_refused_naming_the_file(synthetic_forecast: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    name = synthetic_forecast.name
    with pytest.raises(ForecastError, match=rf"{name}: time_index 25 out of range: the file has 25 time step\(s\); expected time_index in 0..24"):
        open_forecast(synthetic_forecast, time_index=25)
    for bad in (-1, True, 1.0, "3"):
        with pytest.raises(ForecastError, match=rf"{name}: time_index: expected an integer >= 0"):
            open_forecast(synthetic_forecast, time_index=bad)  # type: ignore[arg-type]
    with pytest.raises(ForecastError, match=rf"{name}: bbox: expected a planner.grid.BBox; got tuple"):
        open_forecast(synthetic_forecast, bbox=(-118.0, 33.4, -117.9, 33.5))  # type: ignore[arg-type]
    with pytest.raises(ForecastError, match=rf"{name}: bbox 10,50,11,51 lies outside the forecast, which covers lon -118.2600..-117.7000"):
        open_forecast(synthetic_forecast, bbox=_box(10.0, 50.0, 11.0, 51.0))
    with pytest.raises(ForecastError, match="lies outside the forecast"):
        open_forecast(synthetic_forecast, bbox=_box(-118.2, 33.8, -118.0, 34.0))  # north of it
    monkeypatch.setattr("planner.forecast.lazy.MAX_VALUES_PER_VARIABLE", 300)
    with pytest.raises(ForecastError, match=r"the part of variable u to read \(time step 0 of 25; lon .*\) holds 440 values \(time 1 x depth 4 x lat 10 x lon 11\)"):
        open_forecast(synthetic_forecast, bbox=_box(-118.1, 33.4, -118.05, 33.45), time_index=0)
    assert open_forecast(synthetic_forecast, bbox=_box(-118.1, 33.4, -118.09, 33.41), time_index=0).shape == (1, 4, 6, 6)


def test_damaged_header_with_a_window_is_refused_before_reading(tmp_path: Path) -> None:
    """A header that claims 10^8 longitudes: the 1-D axes a window needs are not read whole."""
    path = tmp_path / "huge.nc"
    with netCDF4.Dataset(path, "w", format="NETCDF4") as nc:
        for dim, size in (("time", 1), ("lat", 4), ("lon", 10**8)):
            nc.createDimension(dim, size)
        nc.createVariable("lat", "f8", ("lat",))[:] = [33.3, 33.4, 33.5, 33.6]
        nc["lat"].units = "degrees_north"
        nc.createVariable("lon", "f8", ("lon",), chunksizes=(1 << 20,)).units = "degrees_east"
        for name, std in (("u", "eastward_sea_water_velocity"), ("v", "northward_sea_water_velocity")):
            var = nc.createVariable(name, "f4", ("time", "lat", "lon"), chunksizes=(1, 4, 1 << 16))
            var.standard_name, var.units = std, "m s-1"
    started = time.perf_counter()
    with pytest.raises(ForecastError, match=r"variable u declares 400,000,000 values \(time 1 x lat 4 x lon 100,000,000\), 100,000,000 of them along lon; expected at most 10,000,000 points"):
        open_forecast(path, bbox=_box(-118.0, 33.4, -117.9, 33.5), time_index=0)
    with pytest.raises(ForecastError, match="declares 400,000,000 values"):
        open_forecast(path)  # the whole file: refused by its declared size, as before
    assert time.perf_counter() - started < 5.0


# ---------------------------------------------------------------------------------------
# Ensembles
# ---------------------------------------------------------------------------------------


def _write_ensemble(path: Path, dim: str, n_members: int, *, std_name: str | None = None, n_t: int = 3) -> np.ndarray:
    """u (members, time, depth, lat, lon) with a different field per member; returns u as written."""
    lon, lat = np.linspace(-118.3, -117.9, 21), np.linspace(33.3, 33.6, 16)
    rng = np.random.default_rng(5)
    shape = (n_members, n_t, 2, lat.size, lon.size)
    u = rng.normal(0.0, 0.2, shape).astype(np.float32)
    u[:, :, :, :3, :4] = np.nan  # land
    dims = (dim, "time", "depth", "lat", "lon")
    member_attrs = {"standard_name": std_name} if std_name else {}
    ds = xr.Dataset(
        {
            "u": (dims, u, {"units": "m s-1", "standard_name": "eastward_sea_water_velocity"}),
            "v": (dims, -u, {"units": "m s-1", "standard_name": "northward_sea_water_velocity"}),
        },
        coords={
            dim: (dim, np.arange(n_members, dtype=np.int32), member_attrs),
            "time": ("time", np.arange(n_t, dtype=np.float64), {"units": "hours since 2026-01-15 00:00:00"}),
            "depth": ("depth", [0.0, 10.0], {"units": "m", "positive": "down"}),
            "lat": ("lat", lat, {"units": "degrees_north"}),
            "lon": ("lon", lon, {"units": "degrees_east"}),
        },
    )
    ds.to_netcdf(path, encoding={"u": {"_FillValue": np.float32(np.nan)}, "v": {"_FillValue": np.float32(np.nan)}})
    return u


@pytest.mark.parametrize("dim,std_name", [
    ("member", None), ("realization", None), ("ensemble", None), ("number", None), ("ens", None),
    ("mem", "realization"),  # any name, CF standard_name realization
])
def test_ensemble_member_dimension(tmp_path: Path, dim: str, std_name: str | None) -> None:
    path = tmp_path / f"ens_{dim}.nc"
    u = _write_ensemble(path, dim, 4, std_name=std_name)
    assert ensemble_size(path) == 4 and forecast_times(path).n_members == 4
    assert forecast_times(path).member_dim == dim and forecast_times(path).n_times == 3
    with pytest.raises(ForecastError, match=rf"{path.name}: u/v have an ensemble member dimension '{dim}' with 4 "
                                            r"members; expected one forecast: give member= \(0..3\)"):
        open_forecast(path)
    with pytest.raises(ForecastError, match=rf"{path.name}: member 4 out of range: the file has 4 ensemble member\(s\) "
                                            rf"along dimension '{dim}'; expected member= in 0..3"):
        open_forecast(path, member=4)
    for k in range(4):
        fc = open_forecast(path, member=k)
        assert fc.shape == (3, 2, 16, 21) and _same(fc.u_east_m_s, u[k]) and _same(fc.v_north_m_s, -u[k])
        assert fc.window is not None and (fc.window.member, fc.window.n_members, fc.window.member_dim) == (k, 4, dim)
        assert f"ensemble member {k} of 4 (dimension '{dim}')" in fc.notes
    # A member's window resamples as the member read whole.
    whole = open_forecast(path, member=2)
    bbox = _box(-118.2, 33.32, -118.05, 33.5)
    window = _assert_resamples_alike(whole, path, bbox, 1, [(2, 2), (8, 6)], member=2)
    assert window.window.member == 2 and window.identity == whole.identity  # type: ignore[union-attr]


def test_member_of_a_single_forecast(synthetic_forecast: Path, tmp_path: Path) -> None:
    assert ensemble_size(synthetic_forecast) == 1
    full = open_forecast(synthetic_forecast)
    as_member = open_forecast(synthetic_forecast, member=0)
    assert _same(as_member.u_east_m_s, full.u_east_m_s) and as_member.window.n_members == 1  # type: ignore[union-attr]
    with pytest.raises(ForecastError, match=rf"{synthetic_forecast.name}: member 1 out of range: the file has no "
                                            "ensemble member dimension.*only member=0"):
        open_forecast(synthetic_forecast, member=1)
    with pytest.raises(ForecastError, match="member: expected an integer >= 0"):
        open_forecast(synthetic_forecast, member=-1)
    # One member along a member dimension: read as before without member=.
    one = tmp_path / "one.nc"
    u = _write_ensemble(one, "realization", 1)
    assert ensemble_size(one) == 1
    fc = open_forecast(one)
    assert fc.window is None and _same(fc.u_east_m_s, u[0])


def test_ensemble_files_of_planner_ensemble(tmp_path: Path) -> None:
    """Files written by planner.forecast.synthetic.ensemble (member first, standard_name realization) read member by member."""
    ensemble = pytest.importorskip("planner.forecast.synthetic.ensemble")
    from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre

    base = DoubleGyreSettings(hours=3.0)
    path = ensemble.write_gyre_ensemble(tmp_path / "gyre_ens.nc", base, 3, seed=7, spread=0.2)
    assert ensemble_size(path) == 3
    members = ensemble.gyre_ensemble(base, 3, seed=7, spread=0.2)
    single = open_forecast(write_gyre(tmp_path / "m1.nc", members[1]))
    fc = open_forecast(path, member=1, time_index=2, bbox=_box(-118.1, 33.35, -117.95, 33.45))
    x0, x1 = fc.window.lon_index  # type: ignore[union-attr,misc]
    y0, y1 = fc.window.lat_index  # type: ignore[union-attr,misc]
    assert _same(fc.u_east_m_s, single.u_east_m_s[2:3, :, y0:y1, x0:x1])


# ---------------------------------------------------------------------------------------
# Reading only the window: bytes read and peak memory
# ---------------------------------------------------------------------------------------


def write_large(path: Path, n_t: int, n_z: int, n_y: int, n_x: int) -> int:
    """A regular float32 forecast written quickly with netCDF4 (one chunk per time step); returns u+v bytes."""
    with netCDF4.Dataset(path, "w", format="NETCDF4") as nc:
        for name, size in (("time", n_t), ("depth", n_z), ("lat", n_y), ("lon", n_x)):
            nc.createDimension(name, size)
        t = nc.createVariable("time", "f8", ("time",))
        t.units, t[:] = "hours since 2026-01-15 00:00:00", np.arange(n_t, dtype=np.float64)
        d = nc.createVariable("depth", "f8", ("depth",))
        d.units, d.positive, d[:] = "m", "down", np.arange(n_z) * 5.0
        la = nc.createVariable("lat", "f8", ("lat",))
        la.units, la[:] = "degrees_north", np.linspace(30.0, 30.0 + 0.01 * (n_y - 1), n_y)
        lo = nc.createVariable("lon", "f8", ("lon",))
        lo.units, lo[:] = "degrees_east", np.linspace(-125.0, -125.0 + 0.01 * (n_x - 1), n_x)
        yy, xx = np.meshgrid(np.arange(n_y, dtype=np.float32), np.arange(n_x, dtype=np.float32), indexing="ij")
        base = np.stack([0.5 * np.sin(0.05 * xx + 0.3 * k) * np.cos(0.04 * yy) for k in range(n_z)]).astype(np.float32)
        base[:, :20, :30] = np.nan  # land
        for name, std, sign in (("u", "eastward_sea_water_velocity", 1), ("v", "northward_sea_water_velocity", -1)):
            var = nc.createVariable(name, "f4", ("time", "depth", "lat", "lon"), chunksizes=(1, n_z, n_y, n_x),
                                    fill_value=np.float32(np.nan))
            var.units, var.standard_name = "m s-1", std
            for k in range(n_t):
                var[k] = sign * base + np.float32(0.001 * k)
    return 2 * n_t * n_z * n_y * n_x * 4


def _bytes_read() -> int:
    """Bytes this process has read through read(2)/pread(2) so far (Linux /proc/self/io 'rchar')."""
    with open("/proc/self/io") as fh:
        for line in fh:
            if line.startswith("rchar:"):
                return int(line.split()[1])
    raise AssertionError("no rchar in /proc/self/io")


@pytest.mark.skipif(not os.path.exists("/proc/self/io"), reason="needs Linux /proc/self/io")
def test_window_reads_only_its_part_of_the_file(tmp_path: Path) -> None:
    """Bytes read while opening: the file once for its hash, the header, and the window's chunks; not the rest."""
    from planner.forecast.lazy import read_ready

    path = tmp_path / "mid.nc"
    velocity_bytes = write_large(path, n_t=80, n_z=2, n_y=200, n_x=250)  # 64 MB of u and v
    size = path.stat().st_size
    bbox = _box(-124.0, 31.0, -123.5, 31.4)
    open_forecast(path, bbox=bbox, time_index=1)  # warm up: imports read their own files

    # The velocities are lazily indexed: selecting from them reads nothing; loading reads the part.
    with xr.open_dataset(path, engine="netcdf4", decode_times=False) as ds:
        lazy = ds["u"]
        assert lazy.shape == (80, 2, 200, 250)
        before = _bytes_read()
        part = lazy.isel(time=slice(77, 78), lat=slice(100, 141), lon=slice(100, 151))
        assert _bytes_read() - before < 10_000
        values = read_ready(part).values
        read = _bytes_read() - before
        assert values.shape == (1, 2, 41, 51) and read < 4 * 2 * 200 * 250 * 4  # about one time step's chunk

    before = _bytes_read()
    window = open_forecast(path, bbox=bbox, time_index=77)
    window_extra = _bytes_read() - before - size  # beyond hashing the whole file once
    before = _bytes_read()
    whole = open_forecast(path)
    whole_extra = _bytes_read() - before - size
    print(f"\nbytes read beyond the hash: window {window_extra:,}, whole file {whole_extra:,} "
          f"(velocities {velocity_bytes:,})")
    assert whole_extra >= velocity_bytes  # the instrument sees a whole read
    assert window_extra < 0.2 * velocity_bytes
    assert window.shape == (1, 2, 45, 55) and window.identity == whole.identity


def test_a_window_is_read_without_importing_dask(synthetic_forecast: Path) -> None:
    """xarray's ``load()`` imports dask only to ask whether a variable is dask's; a plan's read does not."""
    code = ("import sys; from planner.forecast import open_forecast; "
            f"fc = open_forecast({str(synthetic_forecast)!r}, time_index=1); "
            "print(fc.shape, 'dask' in sys.modules, 'xarray' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True).stdout
    assert out.split()[-2:] == ["False", "True"], out


# Peak RSS of the measuring process itself: VmHWM, the high-water mark of its own memory map.
# (resource.getrusage(RUSAGE_SELF).ru_maxrss is also printed, but on Linux it keeps the parent's
# high-water mark across fork and exec, so under pytest it reports pytest's own size.)
_MEASURE = r"""
import json, resource, sys, time
import numpy as np
from planner.forecast import open_forecast
from planner.grid import Grid
from planner.contract.geodesy import BBox
from planner.forecast.resample import resample
def hwm():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))
imports = hwm()
bbox = BBox(west_deg=-124.0, south_deg=31.0, east_deg=-123.5, north_deg=31.4)
grid = Grid.from_bbox(bbox, nx=26, ny=21, depths_m=[0.0, 5.0, 10.0])
started = time.perf_counter()
fc = open_forecast(sys.argv[1], bbox=bbox, time_index=int(sys.argv[2]))
opened = time.perf_counter() - started
u, v = resample(fc, grid, time_index=0)
print(json.dumps({"imports_rss": imports, "peak_rss": hwm(), "ru_maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
                  "open_s": opened, "shape": list(fc.shape), "water": int(np.isfinite(u).sum()),
                  "u": float(np.nansum(u)), "v": float(np.nansum(v))}))
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs Linux /proc/self/status (VmHWM)")
def test_peak_memory_stays_below_the_files_velocities(tmp_path: Path) -> None:
    """A 461 MB forecast (120 steps x 4 levels x 300 x 400, float32): a window is read in a fresh process."""
    path = tmp_path / "large.nc"
    started = time.perf_counter()
    velocity_bytes = write_large(path, n_t=120, n_z=4, n_y=300, n_x=400)
    written_s = time.perf_counter() - started
    proc = subprocess.run([sys.executable, "-c", _MEASURE, str(path), "77"], capture_output=True, text=True,
                          cwd=REPO, timeout=300)
    assert proc.returncode == 0, proc.stderr
    m = json.loads(proc.stdout.strip().splitlines()[-1])
    whole_float64 = velocity_bytes * 2  # what the Forecast would hold if the file were read whole
    print(f"\nfile {path.stat().st_size / 1e6:.1f} MB written in {written_s:.1f} s; velocities {velocity_bytes / 1e6:.1f} MB "
          f"(float32), {whole_float64 / 1e6:.1f} MB as float64; window {m['shape']} opened in {m['open_s']:.2f} s; "
          f"peak RSS {m['peak_rss'] / 1e6:.1f} MB, of which imports {m['imports_rss'] / 1e6:.1f} MB "
          f"(ru_maxrss {m['ru_maxrss'] / 1e6:.1f} MB, inherited from this process)")
    assert m["shape"] == [1, 4, 45, 55] and m["water"] == 3 * 26 * 21
    assert m["peak_rss"] < velocity_bytes
    assert m["peak_rss"] - m["imports_rss"] < 0.25 * velocity_bytes
    # The same values as the whole file (read here at one step, to keep this process small too).
    with netCDF4.Dataset(path) as nc:
        assert float(nc["u"][77, 0, 100, 100]) == pytest.approx(0.5 * np.sin(5.0) * np.cos(4.0) + 0.077, abs=1e-6)


# ---------------------------------------------------------------------------------------
# Broken files: refused alike whether read whole, in part, or only their header
# ---------------------------------------------------------------------------------------


def _broken_cases() -> list[Any]:
    from tests.support.broken_netcdf import NETCDF_CASES

    return [pytest.param(build, expected, id=name) for name, build, expected in NETCDF_CASES]


@pytest.fixture(scope="module")
def small_base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from planner.forecast.synthetic.scb import write_synthetic
    from tests.support.broken_netcdf import SMALL

    return write_synthetic(tmp_path_factory.mktemp("base") / "small.nc", SMALL)


@pytest.mark.parametrize("build, expected", _broken_cases())
def test_broken_files_are_refused_alike(build: Any, expected: tuple[str, ...], small_base: Path, tmp_path: Path) -> None:
    """Every broken netCDF of test_broken_files: a one-step read says what a whole read says; the header
    readers (forecast_times, ensemble_size) either succeed (the problem lies in the values) or say it too."""
    path = tmp_path / "forecast.nc"
    build(small_base, path)
    with pytest.raises(ForecastError) as whole:
        open_forecast(path)
    assert all(e in str(whole.value) for e in expected)
    with pytest.raises(ForecastError) as one_step:
        open_forecast(path, time_index=0)
    assert str(one_step.value).startswith(f"{path}: ") and all(e in str(one_step.value) for e in expected)
    for header_only in (forecast_times, ensemble_size):
        try:
            header_only(path)
        except ForecastError as exc:
            assert all(e in str(exc) for e in expected), (header_only.__name__, str(exc))
    try:
        open_forecast(path, time_index=0, bbox=_box(-118.1, 33.4, -117.9, 33.6))
    except ForecastError as exc:
        assert all(e in str(exc) for e in expected)
    else:  # a window wholly of NaN is land, as part of a file with water would be
        assert any("hold no finite current values" in e for e in expected)
