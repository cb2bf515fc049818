"""planner.forecast.synthetic.scb: a synthetic SCB forecast that reads like a real CF model file.

Files are written to tmp_path and read back with netCDF4 (a real file, not the
in-memory dataset); properties are checked, not pinned numbers.
"""

from __future__ import annotations

import ast
import datetime as dt
import pathlib

import netCDF4
import numpy as np
import pytest
import xarray as xr

from planner.forecast.synthetic import scb as synthetic
from planner.contract.errors import LrauvError
from planner.forecast.synthetic.scb import SyntheticSettings, current_at, synthesize, write_synthetic

DEFAULT = SyntheticSettings()


def _read(path: pathlib.Path) -> dict[str, object]:
    """Everything the tests need from a file, read with netCDF4 (CF masking on: fill -> NaN)."""
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_mask(False)  # _FillValue is NaN, so the raw values already carry it
        return {
            "attrs": {k: nc.getncattr(k) for k in nc.ncattrs()},
            "var_attrs": {name: {k: var.getncattr(k) for k in var.ncattrs()} for name, var in nc.variables.items()},
            "dims": {name: var.dimensions for name, var in nc.variables.items()},
            "dtypes": {name: var.dtype for name, var in nc.variables.items()},
            "lon": nc["lon"][:],
            "lat": nc["lat"][:],
            "depth": nc["depth"][:],
            "time": nc["time"][:],
            "u": nc["u"][:],
            "v": nc["v"][:],
        }


@pytest.fixture(scope="module")
def truth_file(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return write_synthetic(tmp_path_factory.mktemp("truth") / "truth.nc", DEFAULT)


@pytest.fixture(scope="module")
def truth(truth_file: pathlib.Path) -> dict[str, object]:
    return _read(truth_file)


def test_cf_global_attributes(truth: dict) -> None:
    attrs = truth["attrs"]
    assert attrs["Conventions"] == "CF-1.8"
    for key in ("title", "institution", "source", "history", "seed", "issue_time"):
        assert key in attrs, key
    assert attrs["source"].startswith("lrauv synthetic generator v")
    assert int(attrs["seed"]) == 0
    assert attrs["synthetic_role"] == "truth"
    assert attrs["issue_time"] == "2026-01-15T00:00:00Z"


def test_cf_variable_attributes(truth: dict) -> None:
    va, dims, dtypes = truth["var_attrs"], truth["dims"], truth["dtypes"]
    for name, std in (("u", "eastward_sea_water_velocity"), ("v", "northward_sea_water_velocity")):
        assert va[name]["standard_name"] == std
        assert va[name]["units"] == "m s-1"
        assert va[name]["long_name"]
        assert np.isnan(va[name]["_FillValue"])
        assert dims[name] == ("time", "depth", "lat", "lon")
        assert dtypes[name] == np.float32
    assert {k: va["lat"][k] for k in ("units", "standard_name", "axis")} == {
        "units": "degrees_north", "standard_name": "latitude", "axis": "Y"}
    assert {k: va["lon"][k] for k in ("units", "standard_name", "axis")} == {
        "units": "degrees_east", "standard_name": "longitude", "axis": "X"}
    assert {k: va["depth"][k] for k in ("units", "positive", "axis")} == {"units": "m", "positive": "down", "axis": "Z"}
    assert va["time"]["units"] == "hours since 2026-01-15 00:00:00"
    assert va["time"]["calendar"] == "standard"
    assert va["time"]["axis"] == "T"
    for coord in ("lat", "lon", "depth", "time"):
        assert dims[coord] == (coord,)
        assert "_FillValue" not in va[coord], coord


def test_region_edges_exact(truth: dict) -> None:
    lon, lat = truth["lon"], truth["lat"]
    assert lon[0] == -118.26 and lon[-1] == -117.70
    assert lat[0] == 33.30 and lat[-1] == 33.70
    assert lon.size == 57 and lat.size == 41
    np.testing.assert_allclose(np.diff(lon), 0.01, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.diff(lat), 0.01, rtol=0, atol=1e-9)


def test_depths_and_hourly_time(truth: dict) -> None:
    assert truth["depth"].tolist() == [0.0, 5.0, 10.0, 15.0]
    t = truth["time"]
    assert t.size == 73
    assert t[0] == 0.0 and np.all(np.diff(t) == 1.0)
    first = netCDF4.num2date(t[0], truth["var_attrs"]["time"]["units"], "standard")
    assert (first.year, first.month, first.day, first.hour) == (2026, 1, 15, 0)


def test_xarray_decodes_like_a_model_file(truth_file: pathlib.Path) -> None:
    with xr.open_dataset(truth_file) as ds:
        assert ds["time"].values[0] == np.datetime64("2026-01-15T00:00:00")
        assert (ds["time"].values[1] - ds["time"].values[0]) == np.timedelta64(1, "h")
        assert ds["u"].dtype == np.float32
        assert ds["u"].attrs["standard_name"] == "eastward_sea_water_velocity"


def test_land_present_and_growing_with_depth(truth: dict) -> None:
    u, v = truth["u"], truth["v"]
    land = np.isnan(u)
    assert np.array_equal(land, np.isnan(v))
    assert np.all(land == land[:1])  # land does not move with time
    fraction = land[0].mean(axis=(1, 2))
    assert 0.05 < fraction[0] < 0.60 and 0.05 < fraction[-1] < 0.60
    assert fraction[-1] > fraction[0]
    assert np.all(np.diff(fraction) >= 0)
    # Land at one layer is land at every deeper layer; some cells are water at 0 m and land at 15 m.
    assert np.all(land[0, 1:] >= land[0, :-1])
    assert np.any(~land[0, 0] & land[0, -1])


def test_land_is_north_east_of_the_coast(truth: dict) -> None:
    lon, lat, land = truth["lon"], truth["lat"], np.isnan(truth["u"][0, 0])

    def at(lon_deg: float, lat_deg: float) -> bool:
        return bool(land[np.argmin(np.abs(lat - lat_deg)), np.argmin(np.abs(lon - lon_deg))])

    assert at(-117.72, 33.68)  # inland of Laguna/Dana Point
    assert not at(-118.20, 33.35)  # offshore, south-west
    assert not at(-117.93, 33.57)  # just off Newport
    assert at(-117.90, 33.64)  # Costa Mesa


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_speeds_in_range_and_weaker_at_depth(seed: int) -> None:
    ds = synthesize(SyntheticSettings(seed=seed))
    speed = np.hypot(ds["u"].values, ds["v"].values)
    assert np.nanmax(speed) <= 0.5
    assert np.nanmedian(speed) >= 0.05
    mean_by_layer = np.nanmean(speed, axis=(0, 2, 3))
    assert mean_by_layer[-1] < mean_by_layer[0]


def test_file_speeds(truth: dict) -> None:
    speed = np.hypot(truth["u"], truth["v"])
    assert np.nanmax(speed) <= 0.5
    assert np.nanmedian(speed) >= 0.05
    assert np.nanmean(speed[:, -1]) < np.nanmean(speed[:, 0])


def test_same_seed_same_arrays_other_seed_differs(tmp_path: pathlib.Path) -> None:
    a = _read(write_synthetic(tmp_path / "a.nc", SyntheticSettings(seed=5)))
    b = _read(write_synthetic(tmp_path / "b.nc", SyntheticSettings(seed=5)))
    c = _read(write_synthetic(tmp_path / "c.nc", SyntheticSettings(seed=6)))
    for name in ("u", "v", "lon", "lat", "depth", "time"):
        assert a[name].tobytes() == b[name].tobytes(), name
    assert not np.array_equal(a["u"], c["u"], equal_nan=True)
    assert not np.array_equal(a["v"], c["v"], equal_nan=True)


def test_issues_get_closer_to_the_truth(tmp_path: pathlib.Path, truth: dict) -> None:
    t0 = dt.datetime(2026, 1, 15, tzinfo=dt.timezone.utc)
    rms = []
    previous_issue_time = None
    for n in range(4):
        issue = _read(write_synthetic(tmp_path / f"issue{n}.nc", DEFAULT, issue_number=n))
        attrs = issue["attrs"]
        assert int(attrs["issue_number"]) == n and attrs["synthetic_role"] == "forecast"
        issued = dt.datetime.fromisoformat(attrs["issue_time"])
        assert issued == synthetic.issue_datetime(DEFAULT, issue_number=n)
        assert issue["var_attrs"]["time"]["units"] == f"hours since {issued:%Y-%m-%d %H:%M:%S}"
        if previous_issue_time is not None:
            assert issued - previous_issue_time == dt.timedelta(hours=6)
        previous_issue_time = issued
        assert np.array_equal(np.isnan(issue["u"]), np.isnan(truth["u"][: issue["u"].shape[0]]))
        # Align by absolute time: issue hour h is truth hour h + offset.
        offset = int((issued - t0).total_seconds() // 3600)
        keep = truth["time"].size - offset
        du = issue["u"][:keep] - truth["u"][offset:]
        dv = issue["v"][:keep] - truth["v"][offset:]
        rms.append(float(np.sqrt(np.nanmean(du**2 + dv**2))))
    assert all(later < earlier for earlier, later in zip(rms, rms[1:])), rms
    truth_rms = float(np.sqrt(np.nanmean(truth["u"] ** 2 + truth["v"] ** 2)))
    assert 0.2 < rms[0] / truth_rms < 0.4  # documented default: 0.3 relative at issue 0


def test_issue_relative_error_is_as_documented() -> None:
    settings = SyntheticSettings(seed=3, hours=24)
    lon = np.linspace(settings.west_deg, settings.east_deg, 57)
    lat = np.linspace(settings.south_deg, settings.north_deg, 41)
    for n in range(4):
        ds = synthesize(settings, issue_number=n)
        hours = np.arange(settings.hours + 1) + n * settings.issue_interval_h
        ut, vt = current_at(settings, hours[:, None, None, None] * 3600.0, lon[None, None, None, :],
                            lat[None, None, :, None], np.array(settings.depths_m)[None, :, None, None])
        du, dv = ds["u"].values - ut, ds["v"].values - vt
        relative = np.sqrt(np.nanmean(du**2 + dv**2) / np.nanmean(ut**2 + vt**2))
        assert relative == pytest.approx(0.3 * 0.5**n, rel=0.05)


def test_error_scale_zero_gives_the_truth() -> None:
    settings = SyntheticSettings(seed=2, hours=6, error_scale=0.0)
    forecast = synthesize(settings, issue_number=0)
    truth = synthesize(settings)
    np.testing.assert_array_equal(forecast["u"].values, truth["u"].values)


def test_atomic_write_leaves_no_temporary_files(tmp_path: pathlib.Path) -> None:
    target = tmp_path / "forecast.nc"
    assert write_synthetic(target, SyntheticSettings(hours=3)) == target
    write_synthetic(target, SyntheticSettings(hours=3, seed=1))  # replaces in place
    assert sorted(p.name for p in tmp_path.iterdir()) == ["forecast.nc"]
    assert int(_read(target)["attrs"]["seed"]) == 1


def test_failed_write_keeps_the_old_file_and_no_temporary(tmp_path: pathlib.Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "forecast.nc"
    write_synthetic(target, SyntheticSettings(hours=3))
    before = target.read_bytes()

    def boom(self: xr.Dataset, *args: object, **kwargs: object) -> None:
        pathlib.Path(args[0]).write_bytes(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", boom)
    with pytest.raises(OSError, match="disk full"):
        write_synthetic(target, SyntheticSettings(hours=3, seed=9))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["forecast.nc"]
    assert target.read_bytes() == before


@pytest.mark.parametrize("issue_number", [None, 1])
def test_current_at_agrees_with_grid_samples(tmp_path: pathlib.Path, issue_number: int | None) -> None:
    settings = SyntheticSettings(seed=4, hours=12)
    data = _read(write_synthetic(tmp_path / "f.nc", settings, issue_number=issue_number))
    offset_h = 0.0 if issue_number is None else issue_number * settings.issue_interval_h
    for h in (0, 5, 12):
        for layer, depth in enumerate(data["depth"]):
            lon2, lat2 = np.meshgrid(data["lon"], data["lat"])
            u, v = current_at(settings, (h + offset_h) * 3600.0, lon2, lat2, depth, issue_number=issue_number)
            assert u.shape == lon2.shape
            np.testing.assert_allclose(u, data["u"][h, layer], rtol=0, atol=1e-6, equal_nan=True)
            np.testing.assert_allclose(v, data["v"][h, layer], rtol=0, atol=1e-6, equal_nan=True)


def test_current_at_between_grid_points() -> None:
    # Off-grid points and times: finite over water, NaN on land, smooth in time.
    t = np.linspace(0.0, 3600.0, 61)
    u, v = current_at(DEFAULT, t, -118.123, 33.4567, 7.5)
    assert u.shape == (61,) and np.all(np.isfinite(u)) and np.all(np.isfinite(v))
    assert np.max(np.abs(np.diff(u))) < 0.01
    u_land, v_land = current_at(DEFAULT, 0.0, -117.75, 33.65, 0.0)
    assert np.isnan(u_land) and np.isnan(v_land)


def test_bad_settings_fail_loudly() -> None:
    with pytest.raises(LrauvError, match="depths_m"):
        SyntheticSettings(depths_m=(5.0, 0.0))
    with pytest.raises(LrauvError, match="issue_time"):
        SyntheticSettings(issue_time="yesterday")
    with pytest.raises(LrauvError, match="bbox"):
        SyntheticSettings(west_deg=-117.0, east_deg=-118.0)
    with pytest.raises(LrauvError, match="issue_number"):
        synthesize(SyntheticSettings(hours=1), issue_number=-1)


def test_does_not_use_the_reader() -> None:
    """The generator writes a file the reader must read like any other: it shares no reader code."""
    tree = ast.parse(pathlib.Path(synthetic.__file__).read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    assert {m for m in imported if m and m.startswith("planner")} <= {"planner.contract.errors", "planner.contract.atomic", "planner.contract.geodesy", "planner.forecast.synthetic.cf_writer"}


def test_settings_accept_lists_and_stay_hashable() -> None:
    settings = SyntheticSettings(depths_m=[0, 5], eddy_radius_km=[4, 6], hours=2)
    assert settings.depths_m == (0.0, 5.0) and settings.eddy_radius_km == (4.0, 6.0)
    assert hash(settings) == hash(SyntheticSettings(depths_m=(0.0, 5.0), eddy_radius_km=(4.0, 6.0), hours=2))
    assert synthesize(settings)["u"].shape == (3, 2, 41, 57)
