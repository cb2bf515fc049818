"""planner.forecast.perturb: a copy of a forecast file with its currents early and scaled.

Real netCDF files written to tmp_path, perturbed, and read back with the project's reader. The
tidal channel's own forecast error (``with_forecast_error``) is the reference for the sign of the
phase error: a copy of the truth that runs an hour early must be that forecast.
"""

from __future__ import annotations

import pathlib

import netCDF4
import numpy as np
import pytest

from planner.cli import main
from planner.forecast import open_forecast
from planner.forecast.perturb import shifted_in_time, write_perturbed
from planner.forecast.synthetic.tidal import TidalSettings, with_forecast_error, write_tidal
from tests.conftest import SHARED_OCEAN

TRUTH = TidalSettings(hours=13.0, residual_m_s=0.0)  # hourly steps; no residual: the amplitude error scales it all


def test_copy_running_an_hour_early_is_the_tidal_forecast_with_that_error(tmp_path: pathlib.Path) -> None:
    truth = write_tidal(tmp_path / "truth.nc", TRUTH)
    copy = write_perturbed(truth, tmp_path / "copy.nc", phase_error_h=1.0, amplitude_error=-0.2)
    expected = open_forecast(write_tidal(tmp_path / "forecast.nc",
                                         with_forecast_error(TRUTH, phase_error_h=1.0, amplitude_error=-0.2)))
    got = open_forecast(copy)
    assert np.array_equal(got.time_s, expected.time_s) and got.time_origin == expected.time_origin
    land = np.isnan(expected.u_east_m_s)
    assert land.any() and np.array_equal(np.isnan(got.u_east_m_s), land)
    # Whole steps: the copy at step n is the truth's step n + 1, so it matches the analytic forecast
    # (to float32) at every step but the last, which keeps the truth's last step.
    for a, b in ((got.u_east_m_s, expected.u_east_m_s), (got.v_north_m_s, expected.v_north_m_s)):
        assert np.nanmax(np.abs(a[:-1] - b[:-1])) < 1e-6
        assert np.nanmax(np.abs(a[-1] - b[-1])) > 0.01  # the truth's last step, persisted: not the forecast's
    assert "running 1 h early" in netCDF4.Dataset(copy).history


def test_shifted_in_time_between_uneven_steps() -> None:
    time_s = np.array([0.0, 3600.0, 3 * 3600.0, 6 * 3600.0])
    values = np.broadcast_to(time_s[None, :, None], (2, 4, 3)).copy()  # a field equal to its own time
    values[1, 1, 0] = np.nan  # land in one step (1 h) at one node
    out = shifted_in_time(values, time_s, axis=1, shift_s=5400.0)
    want = np.clip(time_s + 5400.0, 0.0, time_s[-1])
    assert np.allclose(out[0], want[:, None])  # linear in time: interpolation is exact
    # The NaN reaches only the values read between its step and the next (1.5 h and 2.5 h); a time
    # exactly on a step (3 h) reads that step alone.
    assert np.isnan(out[1, :, 0]).tolist() == [True, True, False, False]
    assert np.isnan(shifted_in_time(values, time_s, axis=1, shift_s=7200.0)[1, :, 0]).tolist() == [True, False, False, False]
    assert np.array_equal(shifted_in_time(values, time_s, axis=1, shift_s=0.0), values, equal_nan=True)
    late = shifted_in_time(values, time_s, axis=1, shift_s=-3600.0)  # a negative error: the currents run late
    assert late[0, :, 1].tolist() == [0.0, 0.0, 7200.0, 5 * 3600.0]


def _packed_file(path: pathlib.Path, steps: int) -> pathlib.Path:
    """A regular-grid file with int16 velocities packed by scale_factor and a fill value."""
    with netCDF4.Dataset(path, "w") as nc:
        nc.createDimension("time", steps)
        nc.createDimension("lat", 4)
        nc.createDimension("lon", 5)
        t = nc.createVariable("time", "f8", ("time",))
        t.units = "hours since 2026-01-15 00:00:00"
        t[:] = np.arange(steps, dtype=float)
        for name, values, units in (("lat", np.linspace(33.3, 33.36, 4), "degrees_north"),
                                    ("lon", np.linspace(-118.2, -118.12, 5), "degrees_east")):
            var = nc.createVariable(name, "f8", (name,))
            var.units = units
            var[:] = values
        for name, std in (("u", "eastward_sea_water_velocity"), ("v", "northward_sea_water_velocity")):
            var = nc.createVariable(name, "i2", ("time", "lat", "lon"), fill_value=np.int16(-32768))
            var.scale_factor = 0.001
            var.units = "m s-1"
            var.standard_name = std
            data = np.ma.masked_array(np.full((steps, 4, 5), 0.5), mask=False)
            data[:, 0, 0] = np.ma.masked  # land
            var[:] = data
    return path


def test_packed_velocities_are_written_unpacked_and_scaled(tmp_path: pathlib.Path) -> None:
    src = _packed_file(tmp_path / "packed.nc", steps=3)
    # Times 1.2: 0.6 m/s would still fit int16 at 0.001, but a larger factor would not; the copy is float.
    copy = write_perturbed(src, tmp_path / "copy.nc", amplitude_error=0.2)
    fc = open_forecast(copy)
    assert np.isnan(fc.u_east_m_s[:, 0, 0, 0]).all()
    assert np.allclose(fc.u_east_m_s[:, 0, 1:, :], 0.6) and np.allclose(fc.v_north_m_s[:, 0, :, 1:], 0.6)
    with netCDF4.Dataset(copy) as nc:
        assert nc["u"].dtype == np.float32 and "scale_factor" not in nc["u"].ncattrs()


def test_bad_errors_get_one_line_and_no_file(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _packed_file(tmp_path / "one.nc", steps=1)
    for args, words in ((["--amplitude-error", "-1.5"], "amplitude_error"),
                        (["--phase-error-h", "2"], "two or more time steps"),
                        (["--variables", "u"], "--variables")):
        out = tmp_path / "out.nc"
        assert main(["forecast", "perturb", str(src), str(out), *args]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err and "Traceback" not in err
        assert not out.exists()
    assert main(["forecast", "perturb", str(src), str(tmp_path / "amp.nc"), "--amplitude-error", "-0.5"]) == 0
    assert np.allclose(open_forecast(tmp_path / "amp.nc").u_east_m_s[0, 0, 1:, :], 0.25)


def test_the_copy_of_a_projected_file_reads_as_its_source_does(tmp_path: pathlib.Path) -> None:
    """A real file with projection x/y components (rotated to east/north when read): the error is linear, so
    the copy with zero phase error and amplitude F reads as (1 + F) times the source, east and north."""
    source = SHARED_OCEAN / "roms_zlevel_norkyst800_20151116_surface_hourly.nc"
    if not source.exists():
        pytest.skip(f"the shared ocean data's NorKyst-800 file is not at {SHARED_OCEAN} (set LRAUV_OCEAN_DATA); "
                    "the synthetic files above test the rest")
    copy = write_perturbed(source, tmp_path / "copy.nc", amplitude_error=-0.2)
    a, b = open_forecast(source, time_index=5), open_forecast(copy, time_index=5)
    assert np.array_equal(np.isnan(a.u_east_m_s), np.isnan(b.u_east_m_s))
    assert np.nanmax(np.abs(0.8 * a.u_east_m_s - b.u_east_m_s)) < 1e-5
    assert np.nanmax(np.abs(0.8 * a.v_north_m_s - b.v_north_m_s)) < 1e-5
