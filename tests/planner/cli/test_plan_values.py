"""A plan's values as CF-1.8 netCDF (and the spec's .npz), and where planning from a mission caches its forecast."""

from __future__ import annotations

from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr

from planner.cli import main
from planner.contract.actions import Action
from planner.forecast.cache import cache_dir
from planner.plan_values import export_values
from tests.support import REPO


def test_cf_values_hold_the_spec_arrays_with_units_and_named_dimensions(demo_plan, tmp_path):
    nc_path = export_values(demo_plan, tmp_path / "v.nc", mission="missions/demo.yaml", history="lrauv plan test")
    npz = np.load(export_values(demo_plan, tmp_path / "v.npz"))
    with netCDF4.Dataset(nc_path) as nc:
        assert nc.Conventions == "CF-1.8" and nc.mission == "missions/demo.yaml"
        assert nc.history.endswith("lrauv plan test") and "paper model, robust criterion" in nc.source
        assert nc.forecast_identity == demo_plan.table.forecast_identity
        assert nc.forecast_time == demo_plan.table.forecast_time
        assert dict(nc.dimensions.items()).keys() == {"depth", "lat", "lon", "heading"}
        for name, units, std, axis in (("lon", "degrees_east", "longitude", "X"), ("lat", "degrees_north", "latitude", "Y"),
                                       ("depth", "m", "depth", "Z")):
            var = nc[name]
            assert (var.dimensions, var.units, var.standard_name, var.axis) == ((name,), units, std, axis)
            assert np.array_equal(var[:], npz[name])
        assert nc["depth"].positive == "down" and nc["heading"].units == "degree"
        assert np.array_equal(nc["heading"][:], np.arange(8) * 45.0)
        cost = nc["cost_to_go"]
        assert cost.dimensions == ("depth", "lat", "lon", "heading") and cost.units == "1" and cost.long_name
        values = cost[:]
        finite = np.isfinite(npz["cost"])
        assert np.array_equal(np.ma.getmaskarray(values), ~finite)  # land and unreachable: the fill value
        assert np.array_equal(values.data[finite], npz["cost"][finite])
        steps = nc["steps"][:]
        assert np.array_equal(steps.filled(-1), npz["steps"]) and nc["steps"]._FillValue == -1
        action = nc["action"]
        meanings = action.flag_meanings.split()
        assert list(action.flag_values) == [a.value for a in sorted(Action)]
        assert meanings[list(action.flag_values).index(Action.AT_GOAL)] == "at_goal"
        assert np.array_equal(action[:], npz["action"]) and np.array_equal(action[:], demo_plan.table.actions)
        assert np.array_equal(nc["flow_dir"][:], npz["flow_dir"]) and "land calm east" in nc["flow_dir"].flag_meanings
        assert np.array_equal(nc["water"][:].astype(bool), demo_plan.model.water)
        assert nc["heading_bearing"].dimensions == ("lat", "heading")
        assert cost.coordinates == "heading_bearing time" and nc["time"].standard_name == "time"
    # The time of the forecast planned on decodes (xarray, CF) to the table's forecast time.
    with xr.open_dataset(nc_path) as ds:
        assert str(ds["time"].values.astype("datetime64[s]")) + "Z" == demo_plan.table.forecast_time
        assert ds["cost_to_go"].dims == ("depth", "lat", "lon", "heading")


def test_a_time_varying_plan_exports_its_slices_along_time(tmp_path, capsys):
    from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre

    gyre = write_gyre(tmp_path / "gyre.nc", DoubleGyreSettings(eps=0.25, hours=3.0, step_h=1.0, depths_m=(0.0, 5.0)))
    out = tmp_path / "tv.nc"
    assert main(["plan", "--forecast", str(gyre), "--model", "physical", "--criterion", "expected",
                 "--bbox", "-118.15,33.32,-117.85,33.45", "--nx", "7", "--ny", "4", "--depths", "0,5",
                 "--goal", "-117.9,33.4,0", "--time-varying", "--horizon-h", "2", "--out", str(tmp_path / "tv.lrpt"),
                 "--export-values", str(out), "--quiet"]) == 0
    assert f"values     {out}" in capsys.readouterr().out
    with xr.open_dataset(out) as ds:
        assert ds["cost_to_go"].dims == ("time", "depth", "lat", "lon", "heading")
        assert ds["cost_to_go"].attrs["units"] == "W h" and ds["time_to_go"].attrs["units"] == "s"
        assert [str(t) for t in ds["time"].values.astype("datetime64[s]")] == [
            "2026-01-15T00:00:00", "2026-01-15T01:00:00", "2026-01-15T02:00:00"]
        assert ds["action"].shape == (3, 2, 4, 7, 8)


def test_an_export_file_of_another_kind_is_refused_before_planning(synthetic_forecast, tmp_path, capsys):
    assert main(["plan", f"--forecast={synthetic_forecast}", "--bbox=-118.26,33.30,-117.70,33.70", "--nx=5",
                 "--ny=4", "--depths=0", "--goal=-117.80,33.40,0", f"--out={tmp_path / 't.lrpt'}",
                 f"--export-values={tmp_path / 'v.csv'}", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "v.csv: expected a file ending in .nc (CF-1.8 netCDF) or .npz" in err
    assert not (tmp_path / "t.lrpt").exists()


def test_the_synthetic_forecast_of_a_mission_goes_to_the_cache_not_beside_it(tmp_path, capsys):
    out = tmp_path / "plans" / "demo.lrpt"
    cache = tmp_path / "cache"
    assert main(["plan", str(REPO / "missions" / "demo.yaml"), "--out", str(out), "--cache-dir", str(cache),
                 "--quiet"]) == 0
    cached = sorted((cache / "forecasts").glob("synthetic_*.nc"))
    assert len(cached) == 1
    printed = capsys.readouterr().out  # lines over 100 columns wrap under their value
    assert printed.startswith("cache      ") and f"synthetic forecast (seed 0, 72 h) {cached[0]}" in " ".join(printed.split())
    assert sorted(p.name for p in out.parent.iterdir()) == ["demo.lrpt"]
    assert not list((REPO / "missions").glob("*.nc"))


def test_the_cache_folder_follows_the_flag_the_variable_and_xdg(monkeypatch, tmp_path):
    monkeypatch.setenv("LRAUV_CACHE_DIR", str(tmp_path / "env"))
    assert cache_dir(tmp_path / "flag") == tmp_path / "flag" and cache_dir() == tmp_path / "env"
    monkeypatch.delenv("LRAUV_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "lrauv"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")  # not absolute: ignored (XDG Base Directory spec)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "lrauv"


@pytest.mark.parametrize("suffix", [".NC", ".nc"])
def test_the_suffix_chooses_netcdf_whatever_its_case(demo_plan, tmp_path, suffix):
    path = export_values(demo_plan, tmp_path / f"v{suffix}")
    assert path.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n"
    assert Path(path).suffix == suffix
