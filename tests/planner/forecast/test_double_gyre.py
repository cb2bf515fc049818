"""planner.forecast.synthetic.double_gyre: the analytic double gyre (Shadden et al. 2005) as a CF forecast file.

Files are written to tmp_path and read back with the project's reader,
``planner.forecast.open_forecast``; properties of the flow are checked against
the analytic formula, not pinned numbers.
"""

from __future__ import annotations

import math
import pathlib
from dataclasses import replace

import netCDF4
import numpy as np
import pytest
import xarray as xr

from planner.cli import build_parser
from planner.cli.forecast import settings_from_args
from planner.forecast.synthetic.double_gyre import (
    DoubleGyreSettings,
    box_size_m,
    gyre_velocity,
    synthesize_gyre,
    write_gyre,
)
from planner.contract.errors import LrauvError
from planner.forecast import open_forecast
from planner.contract.geodesy import EARTH_RADIUS_M

DEFAULT = DoubleGyreSettings()
SHORT = DoubleGyreSettings(hours=12.0)


@pytest.fixture(scope="module")
def gyre_file(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return write_gyre(tmp_path_factory.mktemp("gyre") / "gyre.nc", SHORT)


def _x_of(settings: DoubleGyreSettings, lon: np.ndarray) -> np.ndarray:
    return 2.0 * (lon - settings.west_deg) / (settings.east_deg - settings.west_deg)


def _dividing_x(settings: DoubleGyreSettings, t_s: float) -> float:
    """Where f(x, t) = a x^2 + (1 - 2a) x = 1 (Shadden et al. 2005)."""
    a = settings.eps * math.sin(2 * math.pi * t_s / (settings.period_h * 3600.0) + settings.phase_rad)
    if abs(a) < 1e-12:
        return 1.0
    b = 1.0 - 2.0 * a
    return (-b + math.sqrt(b * b + 4.0 * a)) / (2.0 * a)


def test_default_box_is_two_to_one_in_metres() -> None:
    width_m, height_m = box_size_m(DEFAULT)
    assert width_m / height_m == pytest.approx(2.0, rel=1e-4)
    assert width_m == pytest.approx(37_140.0, abs=10.0)
    assert synthesize_gyre(replace(DEFAULT, hours=2.0))["u"].shape == (3, 4, 34, 81)


def test_reader_reads_the_file(gyre_file: pathlib.Path) -> None:
    fc = open_forecast(gyre_file)
    assert fc.shape == (13, 4, 34, 81) and fc.is_regular
    np.testing.assert_allclose(fc.time_s, np.arange(13) * 3600.0)
    assert fc.times is not None and str(fc.times[0]) == "2026-01-15T00:00:00.000"
    np.testing.assert_array_equal(fc.depth_m, SHORT.depths_m)
    assert (fc.lon_deg[0], fc.lon_deg[-1]) == (SHORT.west_deg, SHORT.east_deg)
    assert (fc.lat_deg[0], fc.lat_deg[-1]) == (SHORT.south_deg, SHORT.north_deg)
    assert np.all(np.isfinite(fc.u_east_m_s)) and np.all(np.isfinite(fc.v_north_m_s))  # no land
    with netCDF4.Dataset(gyre_file) as nc:
        assert nc.getncattr("Conventions") == "CF-1.8"
        assert "Shadden" in nc.getncattr("references")
        assert nc["u"].getncattr("standard_name") == "eastward_sea_water_velocity"
        assert nc["v"].getncattr("standard_name") == "northward_sea_water_velocity"
        assert nc["time"].getncattr("units") == "hours since 2026-01-15 00:00:00"
        assert nc["u"].dtype == np.float32


def test_grid_values_equal_the_analytic_field(gyre_file: pathlib.Path) -> None:
    fc = open_forecast(gyre_file)
    lon2, lat2 = np.meshgrid(fc.lon_deg, fc.lat_deg)
    for n, t_s in enumerate(fc.time_s):
        u, v = gyre_velocity(SHORT, lon2, lat2, t_s)
        for layer in range(fc.n_levels):  # the same field at every depth
            np.testing.assert_allclose(fc.u_east_m_s[n, layer], u, rtol=0, atol=1e-6)
            np.testing.assert_allclose(fc.v_north_m_s[n, layer], v, rtol=0, atol=1e-6)


def test_gyre_velocity_broadcasts() -> None:
    u, v = gyre_velocity(DEFAULT, np.linspace(-118.2, -117.8, 5)[:, None], 33.35, np.arange(3.0) * 3600.0)
    assert u.shape == v.shape == (5, 3)


@pytest.mark.parametrize("settings", [DEFAULT, replace(DEFAULT, eps=0.25, phase_rad=1.0),
                                      replace(DEFAULT, north_deg=33.6, peak_speed_m_s=0.3)])
def test_non_divergent(settings: DoubleGyreSettings) -> None:
    lon = np.linspace(settings.west_deg, settings.east_deg, 201)
    lat = np.linspace(settings.south_deg, settings.north_deg, 101)
    mid = math.radians(0.5 * (settings.south_deg + settings.north_deg))
    dx_m = EARTH_RADIUS_M * math.cos(mid) * math.radians(lon[1] - lon[0])
    dy_m = EARTH_RADIUS_M * math.radians(lat[1] - lat[0])
    scale = settings.peak_speed_m_s / min(dx_m, dy_m)  # speed / cell size
    for t_s in (0.0, 2.5 * 3600.0, 7.0 * 3600.0):
        u, v = gyre_velocity(settings, lon[None, :], lat[:, None], t_s)
        dudx = (u[1:-1, 2:] - u[1:-1, :-2]) / (2 * dx_m)
        dvdy = (v[2:, 1:-1] - v[:-2, 1:-1]) / (2 * dy_m)
        assert np.max(np.abs(dudx)) > 0.01 * scale  # each term is far from zero...
        assert np.max(np.abs(dudx + dvdy)) < 1e-4 * scale  # ...their sum is not


def test_no_flow_through_the_box_edges() -> None:
    fc = synthesize_gyre(SHORT)
    u, v = fc["u"].values, fc["v"].values
    assert np.max(np.abs(u[..., 0])) < 1e-6 and np.max(np.abs(u[..., -1])) < 1e-6
    assert np.max(np.abs(v[..., 0, :])) < 1e-6 and np.max(np.abs(v[..., -1, :])) < 1e-6


@pytest.mark.parametrize("peak", [0.5, 0.2])
@pytest.mark.parametrize("north_deg", [33.467, 33.40, 33.70])  # 2:1, wider, taller than 2:1
def test_peak_speed_of_the_steady_gyre(peak: float, north_deg: float) -> None:
    settings = replace(DEFAULT, eps=0.0, peak_speed_m_s=peak, north_deg=north_deg, hours=1.0)
    ds = synthesize_gyre(settings)
    speed = np.hypot(ds["u"].values, ds["v"].values)
    assert float(speed.max()) == pytest.approx(peak, rel=0.01)
    lon = np.linspace(settings.west_deg, settings.east_deg, 401)
    lat = np.linspace(settings.south_deg, settings.north_deg, 201)
    u, v = gyre_velocity(settings, lon[None, :], lat[:, None], 1234.0)
    assert float(np.hypot(u, v).max()) == pytest.approx(peak, rel=1e-6)


def test_centre_line_and_opposite_rotation() -> None:
    settings = replace(DEFAULT, eps=0.0, hours=1.0)
    ds = synthesize_gyre(settings)
    lon, lat = ds["lon"].values, ds["lat"].values
    u, v = ds["u"].values[0, 0], ds["v"].values[0, 0]
    centre = int(np.argmin(np.abs(lon - 0.5 * (settings.west_deg + settings.east_deg))))
    assert lon[centre] == pytest.approx(-118.0)
    assert np.max(np.abs(u[:, centre])) < 1e-6  # the dividing line x = 1
    assert np.all(v[1:-1, centre] < 0)  # both gyres flow south along it
    # Relative vorticity dv/dx - du/dy at the gyre centres: clockwise west, counter-clockwise east.
    dx = np.gradient(lon)[None, :]
    dy = np.gradient(lat)[:, None]
    vort = np.gradient(v, axis=1) / dx - np.gradient(u, axis=0) / dy
    x = _x_of(settings, lon)
    mid_row = len(lat) // 2
    west = vort[mid_row, np.argmin(np.abs(x - 0.5))]
    east = vort[mid_row, np.argmin(np.abs(x - 1.5))]
    assert west < 0 < east
    assert np.all(vort[1:-1, 1:centre - 1] < 0) and np.all(vort[1:-1, centre + 2:-1] > 0)
    # North edge: the western gyre flows east, the eastern one west.
    assert np.all(u[-1, 1:centre] > 0) and np.all(u[-1, centre + 1:-1] < 0)


def test_time_variation_moves_the_dividing_line(gyre_file: pathlib.Path) -> None:
    fc = open_forecast(gyre_file)  # eps = 0.1, period 12 h, phase 0
    x = _x_of(SHORT, fc.lon_deg)
    row = int(np.argmin(np.abs(fc.lat_deg - (SHORT.south_deg + 0.25 * (SHORT.north_deg - SHORT.south_deg)))))
    found = {}
    for hour in (0, 3, 6, 9):
        u = fc.u_east_m_s[hour, 0, row, 1:-1]
        xs = x[1:-1]
        k = np.flatnonzero(np.diff(np.sign(u)) != 0)
        assert k.size == 1, hour  # one sign change of u along the row: the dividing line
        k0 = int(k[0])
        found[hour] = xs[k0] - u[k0] * (xs[k0 + 1] - xs[k0]) / (u[k0 + 1] - u[k0])
        assert found[hour] == pytest.approx(_dividing_x(SHORT, hour * 3600.0), abs=0.005)
    assert found[3] == pytest.approx(1.099, abs=0.005) and found[9] == pytest.approx(0.901, abs=0.005)
    assert found[0] == pytest.approx(1.0, abs=0.005) and found[6] == pytest.approx(1.0, abs=0.005)
    # A steady forecast of the same gyre keeps it at x = 1: that is its error.
    steady = synthesize_gyre(replace(SHORT, eps=0.0))["u"].values
    centre = int(np.argmin(np.abs(x - 1.0)))
    assert np.max(np.abs(steady[:, :, :, centre])) < 1e-6
    assert abs(fc.u_east_m_s[3, 0, row, centre]) > 0.05


def test_phase_shifts_time() -> None:
    t = np.arange(0.0, 12.0, 0.5) * 3600.0
    lon, lat = -118.13, 33.33
    shifted = replace(DEFAULT, phase_rad=math.pi / 2)
    u_a, v_a = gyre_velocity(DEFAULT, lon, lat, t + 3 * 3600.0)  # a quarter period later
    u_b, v_b = gyre_velocity(shifted, lon, lat, t)
    np.testing.assert_allclose(u_a, u_b, atol=1e-12)
    np.testing.assert_allclose(v_a, v_b, atol=1e-12)


@pytest.mark.parametrize(
    ("changes", "name"),
    [
        ({"eps": 0.7}, "eps"),
        ({"eps": -0.1}, "eps"),
        ({"eps": float("nan")}, "eps"),
        ({"eps": "0.1"}, "eps"),
        ({"peak_speed_m_s": 0.0}, "peak_speed_m_s"),
        ({"period_h": -1.0}, "period_h"),
        ({"phase_rad": float("inf")}, "phase_rad"),
        ({"hours": 0}, "hours"),
        ({"hours": True}, "hours"),
        ({"step_h": 0.0}, "step_h"),
        ({"hours": 2.0, "step_h": 3.0}, "step_h"),
        ({"spacing_deg": 0.0}, "spacing_deg"),
        ({"spacing_deg": 1.0}, "spacing_deg"),
        ({"depths_m": (5.0, 0.0)}, "depths_m"),
        ({"depths_m": ()}, "depths_m"),
        ({"issue_time": "yesterday"}, "issue_time"),
        ({"west_deg": -117.0}, "bbox"),
        ({"north_deg": 95.0}, "bbox"),
    ],
)
def test_bad_settings_name_the_field(changes: dict, name: str) -> None:
    with pytest.raises(LrauvError, match=f"`{name}"):
        DoubleGyreSettings(**changes)


def test_settings_are_hashable_and_normalised() -> None:
    settings = DoubleGyreSettings(depths_m=[0, 5], hours=6)
    assert settings.depths_m == (0.0, 5.0) and settings.hours == 6.0
    assert hash(settings) == hash(DoubleGyreSettings(depths_m=(0.0, 5.0), hours=6.0))
    with pytest.raises(AttributeError):
        settings.eps = 0.2  # type: ignore[misc]


def _parse(*argv: str) -> DoubleGyreSettings:
    """Options as ``lrauv forecast gyre`` parses them (the real parser: defaults must agree with the settings)."""
    return settings_from_args(build_parser().parse_args(["forecast", "gyre", "out.nc", *argv]))


def test_command_line_options() -> None:
    assert _parse() == DEFAULT
    got = _parse("--peak-speed-m-s", "0.3", "--eps", "0", "--period-h", "10", "--phase-rad", "1.5",
                 "--hours", "6", "--step-h", "0.5", "--spacing-deg", "0.01",
                 "--bbox", "-118.3,33.2,-117.9,33.4", "--depths", "0,10", "--issue-time", "2026-02-01T06:00:00Z")
    assert got == DoubleGyreSettings(peak_speed_m_s=0.3, eps=0.0, period_h=10.0, phase_rad=1.5, hours=6.0,
                                     step_h=0.5, spacing_deg=0.01, west_deg=-118.3, south_deg=33.2,
                                     east_deg=-117.9, north_deg=33.4, depths_m=(0.0, 10.0),
                                     issue_time="2026-02-01T06:00:00Z")


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["--eps", "0.9"], "--eps"),
        (["--peak-speed-m-s", "-1"], "--peak-speed-m-s"),
        (["--period-h", "0"], "--period-h"),
        (["--phase-rad", "nan"], "--phase-rad"),
        (["--hours", "0.5"], "--hours"),
        (["--spacing-deg", "5"], "--spacing-deg"),
        (["--bbox", "-118,33"], "--bbox"),
        (["--bbox", "-117,33,-118,34"], "--bbox"),
        (["--bbox", "a,b,c,d"], "--bbox"),
        (["--depths", "10,5"], "--depths"),
        (["--issue-time", "soon"], "--issue-time"),
    ],
)
def test_bad_options_name_the_option(argv: list[str], option: str) -> None:
    with pytest.raises(LrauvError) as info:
        _parse(*argv)
    assert str(info.value).startswith(option), str(info.value)


def test_atomic_write_replaces_in_place(tmp_path: pathlib.Path) -> None:
    target = tmp_path / "gyre.nc"
    assert write_gyre(target, replace(DEFAULT, hours=2.0)) == target
    write_gyre(target, replace(DEFAULT, hours=2.0, eps=0.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gyre.nc"]
    with netCDF4.Dataset(target) as nc:
        assert float(nc.getncattr("gyre_eps")) == 0.0


def test_failed_write_keeps_the_old_file_and_no_temporary(tmp_path: pathlib.Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "gyre.nc"
    write_gyre(target, replace(DEFAULT, hours=2.0))
    before = target.read_bytes()

    def boom(self: xr.Dataset, *args: object, **kwargs: object) -> None:
        pathlib.Path(args[0]).write_bytes(b"partial")  # type: ignore[arg-type]
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", boom)
    with pytest.raises(OSError, match="disk full"):
        write_gyre(target, replace(DEFAULT, hours=2.0, eps=0.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gyre.nc"]
    assert target.read_bytes() == before


def test_unwritable_targets_fail_clearly_and_leave_nothing(tmp_path: pathlib.Path) -> None:
    settings = replace(DEFAULT, hours=1.0)
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("x")
    with pytest.raises(OSError) as info:
        write_gyre(blocker / "gyre.nc", settings)  # the parent is a file
    assert "not_a_dir" in str(info.value)
    folder = tmp_path / "folder.nc"
    folder.mkdir()
    with pytest.raises(OSError):
        write_gyre(folder, settings)  # the target is a folder: the final rename fails
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.nc", "not_a_dir"]
    assert list(folder.iterdir()) == []
    # A missing parent folder is created, as for every atomic write in the project.
    assert open_forecast(write_gyre(tmp_path / "new" / "gyre.nc", settings)).n_times == 2
