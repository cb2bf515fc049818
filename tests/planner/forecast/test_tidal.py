"""planner.forecast.synthetic.tidal: an M2 tidal current through a channel with a constriction, as a CF forecast file.

Files are written to tmp_path and read back with the project's reader,
``planner.forecast.open_forecast``; properties of the flow (period, peak speed, mass
conservation, land) are checked against the analytic formula, not pinned numbers.
"""

from __future__ import annotations

import math
import pathlib
from dataclasses import replace

import netCDF4
import numpy as np
import pytest

from planner.cli import build_parser, main
from planner.cli.forecast import tidal_settings_from_args
from planner.contract.errors import LrauvError
from planner.contract.geodesy import EARTH_RADIUS_M
from planner.contract.mission import load_mission
from planner.forecast import open_forecast
from planner.forecast.synthetic.tidal import (
    M2_PERIOD_H,
    TidalSettings,
    box_size_m,
    channel_width_m,
    synthesize_tidal,
    tidal_velocity,
    with_forecast_error,
    write_tidal,
)

REPO = pathlib.Path(__file__).resolve().parents[3]
DEFAULT = TidalSettings()
SHORT = TidalSettings(hours=13.0)
MID_LON = 0.5 * (DEFAULT.west_deg + DEFAULT.east_deg)
MID_LAT = 0.5 * (DEFAULT.south_deg + DEFAULT.north_deg)


@pytest.fixture(scope="module")
def tidal_file(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return write_tidal(tmp_path_factory.mktemp("tidal") / "tidal.nc", SHORT)


def _metres_per_deg(settings: TidalSettings) -> tuple[float, float]:
    mid = math.radians(0.5 * (settings.south_deg + settings.north_deg))
    return EARTH_RADIUS_M * math.cos(mid) * math.pi / 180.0, EARTH_RADIUS_M * math.pi / 180.0


def test_default_grid_and_channel() -> None:
    width_m, height_m = box_size_m(DEFAULT)
    assert width_m == pytest.approx(37_130.0, abs=10.0) and height_m == pytest.approx(22_240.0, abs=10.0)
    assert synthesize_tidal(replace(DEFAULT, hours=2.0))["u"].shape == (3, 4, 41, 81)
    assert DEFAULT.period_h == M2_PERIOD_H == pytest.approx(360.0 / 28.9841042, abs=1e-6)
    widths = channel_width_m(DEFAULT, [DEFAULT.west_deg, MID_LON, DEFAULT.east_deg])
    assert widths[1] == pytest.approx(DEFAULT.neck_width_m)
    assert widths[0] == widths[2] == pytest.approx(DEFAULT.mouth_width_m, rel=0.01)


def test_reader_reads_the_file(tidal_file: pathlib.Path) -> None:
    fc = open_forecast(tidal_file)
    assert fc.shape == (14, 4, 41, 81) and fc.is_regular
    np.testing.assert_allclose(fc.time_s, np.arange(14) * 3600.0)
    assert fc.times is not None and str(fc.times[0]) == "2026-01-15T00:00:00.000"
    np.testing.assert_array_equal(fc.depth_m, SHORT.depths_m)
    assert (fc.lon_deg[0], fc.lon_deg[-1]) == (SHORT.west_deg, SHORT.east_deg)
    assert (fc.lat_deg[0], fc.lat_deg[-1]) == (SHORT.south_deg, SHORT.north_deg)
    with netCDF4.Dataset(tidal_file) as nc:
        assert nc.getncattr("Conventions") == "CF-1.8"
        assert "M2" in nc.getncattr("references")
        assert nc["u"].getncattr("standard_name") == "eastward_sea_water_velocity"
        assert nc["v"].getncattr("standard_name") == "northward_sea_water_velocity"
        assert nc["time"].getncattr("units") == "hours since 2026-01-15 00:00:00"
        assert nc["u"].dtype == np.float32
        assert float(nc.getncattr("tidal_amplitude_m_s")) == SHORT.amplitude_m_s


def test_grid_values_equal_the_analytic_field(tidal_file: pathlib.Path) -> None:
    fc = open_forecast(tidal_file)
    for n, t_s in enumerate(fc.time_s):
        for layer, depth in enumerate(SHORT.depths_m):  # the same field at every depth
            u, v = tidal_velocity(SHORT, t_s, fc.lat_deg[:, None], fc.lon_deg[None, :], depth)
            np.testing.assert_allclose(fc.u_east_m_s[n, layer], u, rtol=0, atol=1e-6, equal_nan=True)
            np.testing.assert_allclose(fc.v_north_m_s[n, layer], v, rtol=0, atol=1e-6, equal_nan=True)
    # Sample points: the neck's centre at the issue time, flood east at full strength.
    row = int(np.argmin(np.abs(fc.lat_deg - MID_LAT)))
    col = int(np.argmin(np.abs(fc.lon_deg - MID_LON)))
    assert fc.u_east_m_s[0, 2, row, col] == pytest.approx(SHORT.residual_m_s + SHORT.amplitude_m_s, abs=1e-6)
    assert fc.v_north_m_s[0, 2, row, col] == pytest.approx(0.0, abs=1e-6)


def test_tidal_velocity_broadcasts() -> None:
    u, v = tidal_velocity(DEFAULT, np.arange(3.0)[:, None] * 3600.0, MID_LAT,
                          np.linspace(-118.2, -117.8, 5)[None, :], np.array([0.0, 5.0])[:, None, None])
    assert u.shape == v.shape == (2, 3, 5)
    assert np.all(np.isfinite(u)) and np.all(u[0] == u[1])


def test_land_is_nan_and_water_is_between_the_coasts(tidal_file: pathlib.Path) -> None:
    fc = open_forecast(tidal_file)
    _, m_lat = _metres_per_deg(SHORT)
    y_m = (fc.lat_deg - MID_LAT)[:, None] * m_lat
    water = np.abs(y_m) <= 0.5 * channel_width_m(SHORT, fc.lon_deg)[None, :]
    for u_or_v in (fc.u_east_m_s, fc.v_north_m_s):
        assert np.all(np.isnan(u_or_v[:, :, ~water])) and np.all(np.isfinite(u_or_v[:, :, water]))
    assert not water[0].any() and not water[-1].any()  # coasts along the south and north edges
    assert water[:, 0].any() and water[:, -1].any()  # open at the west and east ends
    col = int(np.argmin(np.abs(fc.lon_deg - MID_LON)))
    assert water[:, col].sum() < water[:, 0].sum()  # the neck is narrower than the mouths


def test_peak_speed_reaches_the_amplitude_and_outruns_a_slow_vehicle() -> None:
    ds = synthesize_tidal(replace(DEFAULT, hours=M2_PERIOD_H, step_h=M2_PERIOD_H / 24))
    speed = np.hypot(ds["u"].values, ds["v"].values)
    peak = DEFAULT.amplitude_m_s + DEFAULT.residual_m_s  # at the neck's centre, full flood
    assert float(np.nanmax(speed)) == pytest.approx(peak, rel=1e-6)
    # The tide alone is faster than 0.5 m/s all along the channel's centre line...
    lon = np.linspace(DEFAULT.west_deg, DEFAULT.east_deg, 401)
    assert np.all(DEFAULT.amplitude_m_s * DEFAULT.neck_width_m / channel_width_m(DEFAULT, lon) > 0.5)
    # ...and at the neck outruns a 0.5 m/s vehicle about half of the time.
    t = np.linspace(0.0, DEFAULT.period_h * 3600.0, 10_000, endpoint=False)
    u, _ = tidal_velocity(DEFAULT, t, MID_LAT, MID_LON, 0.0)
    assert 0.4 < float(np.mean(np.abs(u) > 0.5)) < 0.7


def test_period_is_m2_and_half_a_period_reverses_the_tide() -> None:
    lat = np.linspace(DEFAULT.south_deg, DEFAULT.north_deg, 41)[:, None]
    lon = np.linspace(DEFAULT.west_deg, DEFAULT.east_deg, 81)[None, :]
    period_s = M2_PERIOD_H * 3600.0
    for t_s in (0.0, 3.3 * 3600.0, 40.0 * 3600.0):
        u0, v0 = tidal_velocity(DEFAULT, t_s, lat, lon, 0.0)
        u1, v1 = tidal_velocity(DEFAULT, t_s + period_s, lat, lon, 0.0)
        np.testing.assert_allclose(u1, u0, atol=1e-9, equal_nan=True)
        np.testing.assert_allclose(v1, v0, atol=1e-9, equal_nan=True)
    tide_only = replace(DEFAULT, residual_m_s=0.0)
    u0, v0 = tidal_velocity(tide_only, 1234.0, lat, lon, 0.0)
    u_half, v_half = tidal_velocity(tide_only, 1234.0 + 0.5 * period_s, lat, lon, 0.0)
    np.testing.assert_allclose(u_half, -u0, atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(v_half, -v0, atol=1e-9, equal_nan=True)


@pytest.mark.parametrize("settings", [DEFAULT, replace(DEFAULT, neck_width_m=3000.0, neck_length_m=4000.0,
                                                       phase_rad=1.0, residual_m_s=-0.1)])
def test_non_divergent_on_the_water(settings: TidalSettings) -> None:
    lon = np.linspace(settings.west_deg, settings.east_deg, 401)
    lat = np.linspace(settings.south_deg, settings.north_deg, 241)
    m_lon, m_lat = _metres_per_deg(settings)
    dx_m, dy_m = m_lon * (lon[1] - lon[0]), m_lat * (lat[1] - lat[0])
    for t_s in (0.0, 2.5 * 3600.0, 7.0 * 3600.0):
        u, v = tidal_velocity(settings, t_s, lat[:, None], lon[None, :], 0.0)
        dudx = (u[1:-1, 2:] - u[1:-1, :-2]) / (2 * dx_m)
        dvdy = (v[2:, 1:-1] - v[:-2, 1:-1]) / (2 * dy_m)
        wet = np.isfinite(dudx) & np.isfinite(dvdy)  # the whole stencil in water
        assert wet.sum() > 1000
        term = np.max(np.abs(dudx[wet]))
        assert term > 1e-6  # the flow speeds up and slows down along the channel (1/s)...
        # ...and v makes up for it: what is left is the differences' truncation error (v = 0 leaves all of it).
        assert np.max(np.abs((dudx + dvdy)[wet])) < 5e-3 * term


def test_the_same_transport_through_every_section() -> None:
    s = DEFAULT
    _, m_lat = _metres_per_deg(s)
    lat = np.linspace(s.south_deg, s.north_deg, 20_001)
    dy_m = m_lat * (lat[1] - lat[0])
    for t_s in (0.0, 4.0 * 3600.0):
        transports = []
        for lon in np.linspace(s.west_deg, s.east_deg, 9):
            u, _ = tidal_velocity(s, t_s, lat, lon, 0.0)
            transports.append(float(np.nansum(u)) * dy_m)  # m^2/s per metre of depth
        along = s.residual_m_s + s.amplitude_m_s * math.cos(2 * math.pi * t_s / (s.period_h * 3600.0))
        np.testing.assert_allclose(transports, along * s.neck_width_m, rtol=2e-3)


def test_no_flow_through_the_coasts() -> None:
    s = replace(DEFAULT, neck_width_m=4000.0)
    m_lon, m_lat = _metres_per_deg(s)
    lon = np.linspace(s.west_deg, s.east_deg, 4001)
    width = channel_width_m(s, lon)
    slope = np.gradient(width, lon * m_lon, edge_order=2)  # dW/dX by differences
    for side in (1.0, -1.0):
        lat = MID_LAT + side * 0.5 * width * (1 - 1e-9) / m_lat  # just inside the coast
        u, v = tidal_velocity(s, 1800.0, lat, lon, 0.0)
        np.testing.assert_allclose(v / u, side * 0.5 * slope, atol=1e-4)  # along the coast's slope


def test_phase_error_shifts_the_tide_in_time() -> None:
    lat, lon = MID_LAT + 0.01, -118.05
    t = np.arange(0.0, 13.0, 0.5) * 3600.0
    forecast = with_forecast_error(DEFAULT, phase_error_h=1.0)
    assert forecast == replace(DEFAULT, phase_rad=DEFAULT.phase_rad + 2 * math.pi * 1.0 / DEFAULT.period_h)
    u_truth, v_truth = tidal_velocity(DEFAULT, t + 3600.0, lat, lon, 0.0)  # the truth an hour later
    u_fc, v_fc = tidal_velocity(forecast, t, lat, lon, 0.0)
    np.testing.assert_allclose(u_fc, u_truth, atol=1e-12)
    np.testing.assert_allclose(v_fc, v_truth, atol=1e-12)
    assert np.max(np.abs(u_fc - tidal_velocity(DEFAULT, t, lat, lon, 0.0)[0])) > 0.1  # a real error


def test_amplitude_error_scales_the_tide_not_the_residual() -> None:
    lat = np.linspace(DEFAULT.south_deg, DEFAULT.north_deg, 41)[:, None]
    lon = np.linspace(DEFAULT.west_deg, DEFAULT.east_deg, 81)[None, :]
    forecast = with_forecast_error(DEFAULT, amplitude_error=-0.2)
    assert forecast == replace(DEFAULT, amplitude_m_s=0.8 * DEFAULT.amplitude_m_s)
    calm = replace(DEFAULT, amplitude_m_s=0.0)  # the residual alone
    for t_s in (0.0, 2.0 * 3600.0, 5.0 * 3600.0):
        u_truth, v_truth = tidal_velocity(DEFAULT, t_s, lat, lon, 0.0)
        u_fc, v_fc = tidal_velocity(forecast, t_s, lat, lon, 0.0)
        u_calm, v_calm = tidal_velocity(calm, t_s, lat, lon, 0.0)
        np.testing.assert_allclose(u_fc - u_calm, 0.8 * (u_truth - u_calm), atol=1e-12, equal_nan=True)
        np.testing.assert_allclose(v_fc - v_calm, 0.8 * (v_truth - v_calm), atol=1e-12, equal_nan=True)


@pytest.mark.parametrize(
    ("changes", "name"),
    [
        ({"amplitude_m_s": -0.1}, "amplitude_m_s"),
        ({"amplitude_m_s": float("nan")}, "amplitude_m_s"),
        ({"amplitude_m_s": "0.8"}, "amplitude_m_s"),
        ({"period_h": 0.0}, "period_h"),
        ({"phase_rad": float("inf")}, "phase_rad"),
        ({"residual_m_s": float("nan")}, "residual_m_s"),
        ({"neck_width_m": 0.0}, "neck_width_m"),
        ({"mouth_width_m": 5000.0}, "mouth_width_m"),
        ({"mouth_width_m": 30_000.0}, "mouth_width_m"),
        ({"north_deg": 33.35}, "mouth_width_m"),
        ({"neck_length_m": -1.0}, "neck_length_m"),
        ({"hours": 0}, "hours"),
        ({"hours": True}, "hours"),
        ({"step_h": 0.0}, "step_h"),
        ({"hours": 2.0, "step_h": 3.0}, "step_h"),
        ({"spacing_deg": 0.0}, "spacing_deg"),
        ({"spacing_deg": 0.03}, "spacing_deg"),
        ({"depths_m": (5.0, 0.0)}, "depths_m"),
        ({"depths_m": ()}, "depths_m"),
        ({"issue_time": "yesterday"}, "issue_time"),
        ({"west_deg": -117.0}, "bbox"),
        ({"north_deg": 95.0}, "bbox"),
    ],
)
def test_bad_settings_name_the_field(changes: dict, name: str) -> None:
    with pytest.raises(LrauvError, match=f"`{name}") as info:
        TidalSettings(**changes)
    assert name in getattr(info.value, "field")


@pytest.mark.parametrize(("kwargs", "name"), [({"phase_error_h": float("nan")}, "phase_error_h"),
                                              ({"amplitude_error": -1.5}, "amplitude_error")])
def test_bad_forecast_errors_name_the_argument(kwargs: dict, name: str) -> None:
    with pytest.raises(LrauvError, match=f"`{name}`"):
        with_forecast_error(DEFAULT, **kwargs)


def test_settings_are_hashable_and_normalised() -> None:
    settings = TidalSettings(depths_m=[0, 5], hours=6)  # type: ignore[arg-type]  # normalised
    assert settings.depths_m == (0.0, 5.0) and settings.hours == 6.0
    assert hash(settings) == hash(TidalSettings(depths_m=(0.0, 5.0), hours=6.0))
    with pytest.raises(AttributeError):
        settings.amplitude_m_s = 0.5  # type: ignore[misc]


def _parse(*argv: str) -> TidalSettings:
    """Options as ``lrauv forecast tidal`` parses them (the real parser: defaults must agree with the settings)."""
    return tidal_settings_from_args(build_parser().parse_args(["forecast", "tidal", "out.nc", *argv]))


def test_command_line_options() -> None:
    assert _parse() == DEFAULT
    got = _parse("--amplitude-m-s", "1.0", "--period-h", "12", "--phase-rad", "0.5", "--residual-m-s", "0",
                 "--mouth-width-m", "10000", "--neck-width-m", "5000", "--neck-length-m", "6000",
                 "--hours", "6", "--step-h", "0.5", "--spacing-deg", "0.01",
                 "--bbox", "-118.3,33.2,-117.9,33.4", "--depths", "0,10", "--issue-time", "2026-02-01T06:00:00Z")
    assert got == TidalSettings(amplitude_m_s=1.0, period_h=12.0, phase_rad=0.5, residual_m_s=0.0,
                                mouth_width_m=10_000.0, neck_width_m=5000.0, neck_length_m=6000.0, hours=6.0,
                                step_h=0.5, spacing_deg=0.01, west_deg=-118.3, south_deg=33.2, east_deg=-117.9,
                                north_deg=33.4, depths_m=(0.0, 10.0), issue_time="2026-02-01T06:00:00Z")
    # The forecast errors: a tide an hour early, 20 % weaker; the phase error counts hours of the given period.
    assert _parse("--phase-error-h", "1", "--amplitude-error", "-0.2") == with_forecast_error(
        DEFAULT, phase_error_h=1.0, amplitude_error=-0.2)
    assert _parse("--period-h", "12", "--phase-error-h", "3").phase_rad == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["--amplitude-m-s", "-1"], "--amplitude-m-s"),
        (["--period-h", "0"], "--period-h"),
        (["--phase-rad", "nan"], "--phase-rad"),
        (["--residual-m-s", "inf"], "--residual-m-s"),
        (["--neck-width-m", "20000"], "--mouth-width-m"),
        (["--phase-error-h", "nan"], "--phase-error-h"),
        (["--amplitude-error", "-2"], "--amplitude-error"),
        (["--hours", "0.5"], "--hours"),
        (["--spacing-deg", "5"], "--spacing-deg"),
        (["--bbox", "-118,33"], "--bbox"),
        (["--bbox", "-117,33,-118,34"], "--bbox"),
        (["--bbox", "-118.2,33.38,-117.8,33.42"], "--bbox"),  # too low for the channel
        (["--depths", "10,5"], "--depths"),
        (["--issue-time", "soon"], "--issue-time"),
    ],
)
def test_bad_options_name_the_option(argv: list[str], option: str) -> None:
    with pytest.raises(LrauvError) as info:
        _parse(*argv)
    assert str(info.value).startswith(option), str(info.value)


def test_cli_writes_a_forecast_and_refuses_a_bad_option(tmp_path: pathlib.Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "out" / "forecast.nc"
    assert main(["forecast", "tidal", str(target), "--hours", "2", "--phase-error-h", "1",
                 "--amplitude-error", "-0.2"]) == 0
    assert "wrote" in capsys.readouterr().out
    fc = open_forecast(target)
    assert fc.n_times == 3
    u, _ = tidal_velocity(with_forecast_error(DEFAULT, phase_error_h=1.0, amplitude_error=-0.2),
                          fc.time_s[:, None, None], fc.lat_deg[:, None], fc.lon_deg[None, :], 0.0)
    np.testing.assert_allclose(fc.u_east_m_s[:, 0], u, atol=1e-6, equal_nan=True)
    assert main(["forecast", "tidal", str(tmp_path / "bad.nc"), "--amplitude-error", "-3"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--amplitude-error" in err and "Traceback" not in err
    assert not (tmp_path / "bad.nc").exists()


def test_atomic_write_replaces_in_place(tmp_path: pathlib.Path) -> None:
    target = tmp_path / "tidal.nc"
    assert write_tidal(target, replace(DEFAULT, hours=2.0)) == target
    write_tidal(target, replace(DEFAULT, hours=2.0, amplitude_m_s=0.5))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tidal.nc"]
    with netCDF4.Dataset(target) as nc:
        assert float(nc.getncattr("tidal_amplitude_m_s")) == 0.5


def test_eval_mission_fits_the_channel() -> None:
    mission = load_mission(REPO / "missions" / "eval-tidal.yaml")
    assert mission.vehicle.cruise_speed_m_s == 0.5
    assert mission.settings.model == "physical" and mission.settings.criterion == "expected"
    box = mission.region.bbox
    assert box is not None
    assert DEFAULT.west_deg <= box.west_deg < box.east_deg <= DEFAULT.east_deg
    assert DEFAULT.south_deg <= box.south_deg < box.north_deg <= DEFAULT.north_deg
    goal = mission.goals[0].goal
    u, _ = tidal_velocity(DEFAULT, 0.0, goal.lat_deg, goal.lon_deg, goal.depth_m)
    assert np.isfinite(u) and goal.lon_deg > MID_LON  # in the water, past the neck from the west half
