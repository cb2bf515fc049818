"""A forecast on 0..360 longitudes (HYCOM's regional files) plans exactly as the same field on -180..180.

Two real netCDF files hold the same currents, one on lon 240..250, the other on -120..-110
(the first's axis turned by -360 deg, exactly); ``lrauv plan`` runs in-process on each.
A table is always on -180..180, the longitudes the vehicle reports over MAVLink.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from planner.cli import main
from planner.contract.geodesy import BBox
from planner.contract.table import PolicyTable
from planner.forecast import open_forecast
from planner.forecast.resample import resample
from planner.grid import Grid

_LON_360 = 240.0 + 0.4 * np.arange(26)  # 240..250; 0.4 deg is no binary fraction: rounding shows
_LAT = 30.0 + 0.3 * np.arange(17)
BOX_180 = "--bbox=-119.3,30.7,-111.1,34.3"
GOAL_180 = "--goal=-115.7,32.5,0"


def _write(path: Path, lon: np.ndarray) -> Path:
    """One surface step of a gyre-like field with an island (NaN), on the given longitudes."""
    x = (np.arange(_LON_360.size) / (_LON_360.size - 1))[None, :]
    y = (np.arange(_LAT.size) / (_LAT.size - 1))[:, None]
    u = 0.4 * np.sin(np.pi * x) * np.cos(np.pi * y) + 0.05
    v = -0.4 * np.cos(np.pi * x) * np.sin(np.pi * y)
    island = (np.abs(x - 0.3) < 0.1) & (np.abs(y - 0.6) < 0.15)
    u, v = np.where(island, np.nan, u)[None], np.where(island, np.nan, v)[None]
    ds = xr.Dataset(
        {"water_u": (("time", "lat", "lon"), u, {"units": "m/s", "standard_name": "eastward_sea_water_velocity"}),
         "water_v": (("time", "lat", "lon"), v, {"units": "m/s", "standard_name": "northward_sea_water_velocity"})},
        coords={"time": ("time", [0.0], {"units": "hours since 2023-03-02 12:00:00", "standard_name": "time"}),
                "lat": ("lat", _LAT, {"units": "degrees_north"}),
                "lon": ("lon", lon, {"units": "degrees_east"})})
    ds.to_netcdf(path)
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("lon")
    return _write(d / "east360.nc", _LON_360), _write(d / "west180.nc", _LON_360 - 360.0)  # the turn is exact


def _plan(forecast: Path, out: Path, *grid: str) -> PolicyTable:
    assert main(["plan", "--forecast", str(forecast), *grid, "--depths=0", "--model=paper", "--criterion=robust",
                 f"--out={out}", f"--export-values={out.with_suffix('.npz')}", "--quiet"]) == 0
    return PolicyTable.load(out)


def _same_plan(a: PolicyTable, b: PolicyTable, a_out: Path, b_out: Path) -> None:
    assert (a.lon0_deg, a.dlon_deg, a.lat0_deg, a.dlat_deg, a.nx, a.ny) == (
        b.lon0_deg, b.dlon_deg, b.lat0_deg, b.dlat_deg, b.nx, b.ny)
    assert np.array_equal(a.actions, b.actions)
    assert np.array_equal(np.load(a_out.with_suffix(".npz"))["cost"], np.load(b_out.with_suffix(".npz"))["cost"])


def test_a_box_on_minus_180_plans_a_0_360_file_as_the_same_field_on_minus_180(files, tmp_path):
    east, west = files
    a = _plan(east, tmp_path / "east.lrpt", BOX_180, "--nx=21", "--ny=13", GOAL_180)
    b = _plan(west, tmp_path / "west.lrpt", BOX_180, "--nx=21", "--ny=13", GOAL_180)
    _same_plan(a, b, tmp_path / "east.lrpt", tmp_path / "west.lrpt")
    assert a.lon0_deg == -119.3 and np.isfinite(np.load(tmp_path / "east.npz")["cost"]).any()


def test_resampling_a_0_360_file_gives_the_same_currents_bit_for_bit(files):
    east, west = files
    grid = Grid.from_bbox(BBox(west_deg=-119.3, south_deg=30.7, east_deg=-111.1, north_deg=34.3), nx=21, ny=13,
                          depths_m=[0.0])
    u_east, v_east = resample(open_forecast(east), grid, time_index=0)
    u_west, v_west = resample(open_forecast(west), grid, time_index=0)
    assert np.array_equal(u_east, u_west, equal_nan=True) and np.array_equal(v_east, v_west, equal_nan=True)
    assert np.isnan(u_east).any() and np.isfinite(u_east).sum() > 200  # the island, and water around it


def test_the_files_own_grid_and_a_box_on_0_360_give_tables_on_minus_180(files, tmp_path):
    east, west = files
    a = _plan(east, tmp_path / "own_east.lrpt", "--goal=244.0,32.6,0")  # the file's own grid, goal on 0..360
    b = _plan(west, tmp_path / "own_west.lrpt", "--goal=-116.0,32.6,0")
    _same_plan(a, b, tmp_path / "own_east.lrpt", tmp_path / "own_west.lrpt")
    assert a.lon0_deg == -120.0 and a.goal_lon_deg == -116.0
    c = _plan(east, tmp_path / "box360.lrpt", "--bbox=240.7,30.7,248.9,34.3", "--nx=21", "--ny=13",
              "--goal=244.3,32.5,0")
    d = _plan(west, tmp_path / "box180.lrpt", BOX_180, "--nx=21", "--ny=13", GOAL_180)
    assert c.lon0_deg == pytest.approx(d.lon0_deg, abs=1e-12) and c.nx == d.nx  # 240.7 - 360 is -119.3 to a few ulp
    assert np.array_equal(c.actions, d.actions)
